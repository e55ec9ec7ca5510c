"""Fixtures of the twin's tests: the bundled cell's routes, planned once per session."""

from __future__ import annotations

import pytest

from safepath import PlanOptions, Trajectory, plan_cell
from safepath.cell import Cell


@pytest.fixture(scope="session")
def routes(cell: Cell) -> dict[str, Trajectory]:
    """The bundled cell's verified trajectories (do not mutate)."""
    return plan_cell(cell, PlanOptions())
