"""08 - The MuJoCo twin of the quality-check cell: vials on a belt, the cell's controller
closed loop, one minute simulated.

    .venv/bin/python examples/08_run_the_twin.py
"""

from safepath.sim.quality_check import QualityCheckParams, run_quality_check

run = run_quality_check("scenes/quality_check_cell", seed=0,
                        params=QualityCheckParams(duration=60.0))
print(f"{run.duration:.0f} s simulated: {run.vials_arrived} vials arrived, {len(run.cycles)} "
      f"cycles, {run.packaging} packaged, {run.rejected} rejected, {run.unsafe_packaged} unsafe "
      f"packaged; {run.contact_steps} physics steps touching the cell")
