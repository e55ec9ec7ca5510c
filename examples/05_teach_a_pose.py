"""05 - Teach a pose by its TCP: inverse kinematics started at a taught pose.

    .venv/bin/python examples/05_teach_a_pose.py
"""

import numpy as np

import safepath

cell = safepath.load_cell("scenes/quality_check_cell")
above = cell.robot.tcp_position(cell.pose("low1")) + [0.0, 0.0, 0.05]  # 5 cm over low1
q = cell.pose_from_tcp(above, near="low1")  # the TCP keeps its orientation at low1
report = cell.checker().check(q)
print("joint vector [rad]:", np.round(q, 4))
print(f"TCP at {np.round(cell.robot.tcp_position(q), 4)} m; collision-free {report.valid}, "
      f"clearance {report.clearance * 1000:.1f} mm")
