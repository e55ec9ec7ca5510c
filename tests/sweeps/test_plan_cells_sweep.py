"""Batch planning of many cells as a sweep: each seed plans one cell folder; a cell that
plans reports its routes' motion times, one that does not is a failed seed whose error is
one line naming why, with the command that plans it alone."""

from __future__ import annotations

import shutil
from pathlib import Path

from safepath import load_cell, plan_cell
from safepath.planning.batch import PlanCellsTask
from safepath.sweeps import SweepOptions, run_sweep


def test_a_sweep_of_cells_reports_the_routes_and_the_broken_cell(cell_dir: Path,
                                                                 tmp_path: Path) -> None:
    broken = tmp_path / "broken_cell"
    shutil.copytree(cell_dir, broken)
    routes = broken / "routes.yaml"
    routes.write_text(routes.read_text().replace("start: grip", "start: nowhere", 1))
    task = PlanCellsTask((str(cell_dir), str(broken)))
    outcome = run_sweep(task, [0, 1], tmp_path / "sweep", SweepOptions(workers=1))
    planned = plan_cell(load_cell(cell_dir))
    good = outcome.results[0]
    assert good.ok and good.figures["motion_time"] == tuple(t.duration
                                                            for t in planned.values())
    assert good.figures["route.phase1"] == planned["phase1"].duration
    bad = outcome.results[1]
    assert bad.error is not None and "\n" not in bad.error and "nowhere" in bad.error
    [failure] = outcome.report["failures"]
    assert (failure["seed"], failure["replay"]) == (1, f"safepath plan {broken}")
