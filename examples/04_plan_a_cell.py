"""04 - Plan every route of a cell and write each as JSON and CSV.

    .venv/bin/python examples/04_plan_a_cell.py [scene folder] [output folder]
"""

import sys
import tempfile
from pathlib import Path

import safepath

folder = sys.argv[1] if len(sys.argv) > 1 else "scenes/quality_check_cell"
out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path(tempfile.mkdtemp(prefix="safepath_"))
cell = safepath.load_cell(folder)
trajectories = safepath.plan_cell(cell, safepath.PlanOptions())
out.mkdir(parents=True, exist_ok=True)
for name, traj in trajectories.items():
    traj.to_json(out / f"{name}.json")
    traj.to_csv(out / f"{name}.csv")
    back = safepath.load_trajectory(out / f"{name}.json")
    print(f"{name:<15} {len(traj.steps):2d} steps, {traj.duration:6.3f} s, read back "
          f"{back.duration:6.3f} s")
print(f"written to {out}")
