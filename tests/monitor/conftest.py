"""Fixtures of the monitor tests: phase 1 of the bundled cell, split into its motions."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from safepath import Cell, PlanOptions, Trajectory, load_routes, plan_cell
from safepath.monitor import Monitor, MonitorOptions
from safepath.ros import split_at_gripper_events

if TYPE_CHECKING:
    from safepath.monitor.node import MonitorNodeCore

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


#: Makes a configured node core: from the given parameters, else on the bundled cell's
#: phase 1 with the default monitor options.
NodeCoreFactory = Callable[..., "MonitorNodeCore"]


@pytest.fixture
def node_core(cell_dir: Path) -> NodeCoreFactory:
    """A factory of configured node cores (their motions planned): ``node_core()`` on the
    bundled cell's phase 1 with the default options, ``node_core(params)`` from
    ``NodeParameters``."""
    from safepath.monitor.node import MonitorNodeCore, NodeParameters

    def make(params: NodeParameters | None = None) -> MonitorNodeCore:
        core = MonitorNodeCore(params or NodeParameters(
            scene=str(cell_dir), route="phase1", options=MonitorOptions()))
        core.configure()
        return core

    return make


def make_monitor(cell: Cell, **changes: object) -> Monitor:
    """A monitor with the test camera and fast sensor timing (30 Hz camera)."""
    settings: dict[str, object] = {"sensors": {"cam": CAMERA}, "stale_after": 0.06, **changes}
    return Monitor(cell, MonitorOptions(**settings))  # type: ignore[arg-type]


class BoxOnRoute:
    """A node core on phase 1 (its lidar at 0.9, 0.6, 0.3 m, re-plans after 0.5 s, a
    parked body taken as a box that never moves: ``parked_speed`` 0), active, the vial
    gripped, and a ball of 1 m radius resting on phase 1's route; :meth:`scan` is the
    lidar's scan of it delivered at ``t``."""

    LIDAR = (0.9, 0.6, 0.30)

    def __init__(self, cell_dir: object) -> None:
        from safepath.monitor.node import MonitorNodeCore, parameters_from_mapping
        from safepath.monitor.simulation import MovingSphere

        params = parameters_from_mapping({
            "scene": str(cell_dir), "scan_frame": "laser", "scan_xyz": list(self.LIDAR),
            "stale_after": 0.15, "replan_after": 0.5, "replan_margin": 0.03,
            "parked_speed": 0.0})
        self.core = MonitorNodeCore(params)
        self.core.configure()
        self.core.activate(0.0)
        self.core.on_gripper_done(0.0)
        self.pose = np.eye(4)
        self.pose[:3, 3] = self.LIDAR
        self.obstacle = MovingSphere.approach([0.33, 0.30, 0.30], [0.0, 0.0, 0.3], 0.0, 0.0,
                                              1.0)

    def scan(self, t: float) -> list[object]:
        from safepath.monitor.observations import Scan
        from safepath.monitor.ros import scan_message
        from safepath.monitor.simulation import lidar_scan

        msg = scan_message(Scan(t, "laser", lidar_scan(self.obstacle, t, self.pose), -np.pi,
                                2 * np.pi / 360, 0.05, 8.0))
        return self.core.on_scan(msg, t)  # type: ignore[return-value]
