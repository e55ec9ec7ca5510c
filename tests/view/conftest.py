"""Fixtures of the review-session tests: the bundled cell's routes, planned once."""

from __future__ import annotations

from pathlib import Path

import pytest

from safepath import Cell, Trajectory, plan_cell


@pytest.fixture(scope="session")
def trajectories(cell: Cell) -> dict[str, Trajectory]:
    """The bundled cell's routes, planned once (seed 0)."""
    return plan_cell(cell)


@pytest.fixture(scope="session")
def plans_dir(trajectories: dict[str, Trajectory], tmp_path_factory: pytest.TempPathFactory
              ) -> Path:
    """A folder of trajectories as ``safepath plan`` writes them (JSON)."""
    folder = tmp_path_factory.mktemp("plans")
    for name, traj in trajectories.items():
        traj.to_json(folder / f"{name}.json")
    (folder / "summary.json").write_text("{}\n")
    return folder
