"""07 - Speed and separation monitoring: a body walks toward the arm while it moves; the
monitor slows and stops it (simulated camera), and the closest approach is measured.

    .venv/bin/python examples/07_watch_for_obstacles.py
"""

import numpy as np

import safepath
from safepath.monitor import Monitor, MonitorOptions
from safepath.monitor.simulation import MovingSphere, simulate
from safepath.ros import split_at_gripper_events

cell = safepath.load_cell("scenes/quality_check_cell")
route = {"phase1": cell.route_table()["phase1"]}
phase1 = safepath.plan_cell(cell, safepath.PlanOptions(), routes=route)["phase1"]
motions = [m for m in split_at_gripper_events(phase1) if isinstance(m, safepath.Trajectory)]
camera = np.eye(4)
camera[:3, 3] = [1.2, 0.3, 0.4]
monitor = Monitor(cell, MonitorOptions(sensors={"cam": camera}, stale_after=0.06))
target = np.array([0.33, 0.30, 0.30])
body = MovingSphere.approach(target + [0.8, 0.0, 0.0], target, 1.0, 0.15, 0.5, leave_at=2.0)
run = simulate(monitor, [(motions[0], "vial"), (motions[1], None)], body, sensor="cam",
               sensor_pose=camera, until=6.0)
kinds = [d.kind for d in run.decisions]
changes = [k for i, k in enumerate(kinds) if i == 0 or k != kinds[i - 1]]
print("decisions:", " > ".join(changes))
print(f"{len(run.replacements)} replacement goals; the arm ended at "
      f"{np.round(run.q[-1], 3)} rad")
