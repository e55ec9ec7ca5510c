"""Fixtures of the monitor tests: phase 1 of the bundled cell, split into its motions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from safepath import Cell, PlanOptions, Trajectory, load_routes, plan_cell
from safepath.monitor import Monitor, MonitorOptions
from safepath.ros import split_at_gripper_events

#: A camera looking at the cell from the +x side, 1.2 m out [m].
CAMERA = np.eye(4)
CAMERA[:3, 3] = [1.2, 0.3, 0.4]


@dataclass(frozen=True)
class Phase1:
    """Phase 1 and its two motions (vial held in the first, not in the second)."""

    trajectory: Trajectory
    motions: tuple[tuple[Trajectory, str | None], ...]


@pytest.fixture(scope="session")
def phase1(cell: Cell) -> Phase1:
    """Phase 1 of the bundled cell, planned once (seed 0)."""
    routes = load_routes(cell.folder / "routes.yaml", poses=list(cell.poses),
                         objects=list(cell.scene.objects))
    traj = plan_cell(cell, PlanOptions(), routes={"phase1": routes["phase1"]})["phase1"]
    motions = [m for m in split_at_gripper_events(traj) if isinstance(m, Trajectory)]
    assert len(motions) == 2
    return Phase1(traj, ((motions[0], "vial"), (motions[1], None)))


def make_monitor(cell: Cell, **changes: object) -> Monitor:
    """A monitor with the test camera and fast sensor timing (30 Hz camera)."""
    settings: dict[str, object] = {"sensors": {"cam": CAMERA}, "stale_after": 0.06, **changes}
    return Monitor(cell, MonitorOptions(**settings))  # type: ignore[arg-type]
