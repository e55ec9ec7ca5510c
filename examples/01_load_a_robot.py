"""01 - Load a robot: its joints, limits and TCP.

    .venv/bin/python examples/01_load_a_robot.py [robot]    # ned3pro, gen3_lite, panda, ur5, ...
"""

import sys

import numpy as np

import safepath

name = sys.argv[1] if len(sys.argv) > 1 else "ned3pro"
robot = safepath.load_robot(name)
print(f"{robot.name}: {robot.dof} joints, TCP frame {robot.tcp_frame}")
for j, joint in enumerate(robot.joint_names):
    print(f"  {joint:<10} [{robot.lower[j]:+.3f}, {robot.upper[j]:+.3f}] rad, "
          f"{robot.velocity_limits[j]:.2f} rad/s, {robot.acceleration_limits[j]:.2f} rad/s^2")
q = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
print("TCP at the zero pose [m]:", np.round(robot.tcp_position(q), 4))
