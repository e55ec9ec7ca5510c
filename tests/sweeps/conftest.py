"""Fixtures of the sweep tests: a cheap real task, the quality-check twin for 12 s."""

from __future__ import annotations

from pathlib import Path

import pytest

from safepath.sim.quality_check import QualityCheckParams
from safepath.sim.sweep_tasks import QualityCheckTask


def quick_task(cell_dir: Path, *, arrival: float = 2.0) -> QualityCheckTask:
    """The safepath architecture for 12 simulated seconds, a vial every ``arrival`` s on
    average: the first vials ride to the sensor and the arm starts its first cycle (about
    0.5 s of computation per seed once the cell is planned)."""
    params = QualityCheckParams(duration=12.0, arrival_interval=arrival)
    return QualityCheckTask(str(cell_dir), (("safepath", params),),
                            "safepath sim scenes/quality_check_cell --seed {seed} --runs 1 "
                            f"--duration 12 --arrival {arrival:g}")


@pytest.fixture(scope="session")
def task(cell_dir: Path) -> QualityCheckTask:
    """The quick quality-check task."""
    return quick_task(cell_dir)
