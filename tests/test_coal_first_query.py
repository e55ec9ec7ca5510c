"""Coal's distances do not depend on what a process asked coal first.

Without :mod:`safepath.collision._coal_first`, a process that planned the pouring cell
first (its first coal query: a broad-phase collision check of the Gen3 Lite holding the
cup) measured the quality-check cell's clearances up to 3.8e-11 m away from a fresh
process; a sweep's results then depended on which worker ran which seed."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    from safepath import PlanOptions, load_cell, plan_cell
    from safepath.collision import CheckOptions, CollisionChecker

    if sys.argv[1] == "after-pour":
        plan_cell(load_cell("scenes/pouring_cell"), PlanOptions())
    cell = load_cell("scenes/quality_check_cell")
    checker = CollisionChecker(cell.robot, cell.scene, options=CheckOptions())
    rng = np.random.default_rng(7)
    lo, hi = cell.robot.lower, cell.robot.upper
    print(*(repr(checker.clearance(lo + rng.random(cell.robot.dof) * (hi - lo))[0])
            for _ in range(60)))
""")


def _clearances(first: str, repo_root: Path) -> list[str]:
    run = subprocess.run([sys.executable, "-c", SCRIPT, first], cwd=repo_root,
                         capture_output=True, text=True, timeout=300, check=False)
    assert run.returncode == 0, run.stderr
    return run.stdout.split()


def test_clearances_are_the_same_whatever_the_process_planned_before(repo_root: Path
                                                                    ) -> None:
    fresh = _clearances("fresh", repo_root)
    assert len(fresh) == 60 and len(set(fresh)) > 30  # real, varied distances
    assert _clearances("after-pour", repo_root) == fresh
