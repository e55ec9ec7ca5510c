"""03 - Plan one motion from Python: a UR5 around a wall, timed and re-checked.

    .venv/bin/python examples/03_plan_one_motion.py
"""

import numpy as np

import safepath
from safepath import Scene, SceneObject, Shape, placement

ur5 = safepath.load_robot("ur5")
scene = Scene(name="desk", robot="ur5", objects=[
    SceneObject("table", Shape("box", (1.2, 1.2, 0.04)), placement((0.3, 0.0, -0.02))),
    SceneObject("wall", Shape("box", (0.04, 0.5, 0.5)), placement((0.45, 0.25, 0.25))),
])
q_start = np.array([-0.6, -1.2, 1.6, -1.97, -1.57, 0.0])
q_goal = np.array([1.4, -1.2, 1.6, -1.97, -1.57, 0.0])
traj = safepath.plan(ur5, scene, q_start, q_goal)
print(f"motion {traj.duration:.2f} s, clearance {traj.info['min_clearance'] * 1000:.1f} mm, "
      f"certified bound {traj.info['clearance_bound'] * 1000:.2f} mm")
