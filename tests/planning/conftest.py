"""Shared fixtures and helpers of the planning tests.

Planning the bundled cell takes about a second, so it is planned once per session
(with the stop-and-go baseline) and every test reads the same trajectories. The
detour cell (``tests/data/detour_cell``: the bundled cell plus a post on the direct
high1 -> high2 sweep) is planned once too, for its first route only.

The helpers here are plain functions so that a subprocess can import this module
(``from planning.conftest import trajectory_digest``) and hash a trajectory exactly as the
tests do.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from safepath import PlanOptions, load_cell, plan_cell
from safepath.cell import Cell, Route, load_routes
from safepath.model.scene import AllowedContact
from safepath.model.trajectory import Trajectory

ROOT = Path(__file__).resolve().parents[2]
BUNDLED = ROOT / "scenes" / "quality_check_cell"
DETOUR = ROOT / "tests" / "data" / "detour_cell"
#: Relative excess of a limit a released knot may show: none (the timing is strict).
LIMIT_TOL = 0.0
#: Relative excess the cubic Hermite interpolation *between* knots may show
#: (``Trajectory.sample``): the knots are within the limits, the curve through them may
#: bulge past one by a hair where a joint cruises at its limit on a curved path.
INTERPOLATION_TOL = 1e-3


def trajectory_digest(traj: Trajectory) -> str:
    """SHA-256 of everything a trajectory commands: knots, step labels, gripper events.

    ``info`` is left out: it holds wall-clock planning times.
    """
    h = hashlib.sha256()
    for arr in (traj.t, traj.q, traj.qd, traj.qdd):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(traj.step_index, dtype=np.int64).tobytes())
    h.update("\n".join(traj.steps).encode())
    for e in traj.events:
        h.update(f"{e.time!r}|{e.action}|{e.step}|{e.object}".encode())
    return h.hexdigest()


def route_routes(folder: Path, cell: Cell) -> dict[str, Route]:
    """The routes of a scene folder, validated against the cell."""
    return load_routes(folder, poses=list(cell.poses), objects=list(cell.scene.objects))


@dataclass(frozen=True)
class StepWorld:
    """What the gripper holds and which contacts are allowed during one route step.

    Attributes:
        held: Whether the grasped object is in the gripper.
        allowed: Allowed contacts (lines: those of the poses they leave and reach).
        kind: Step kind.
    """

    held: bool
    allowed: tuple[AllowedContact, ...]
    kind: str


def step_worlds(cell: Cell, route: Route, *, held_at_start: bool = False) -> list[StepWorld]:
    """Gripper state and allowed contacts of each step, derived from the route alone.

    Written independently of the planner: a ``close`` attaches the object, an ``open``
    releases it; a ``line`` may touch what the scene allows at the taught pose it leaves
    and at the one it reaches; a ``move`` may touch nothing.
    """
    out: list[StepWorld] = []
    held = held_at_start
    here: str | None = route.start
    for step in route.steps:
        if step.kind == "close":
            held = True
        elif step.kind == "open":
            held = False
        if not step.is_motion:
            out.append(StepWorld(held, (), step.kind))
            continue
        assert step.target is not None
        goal = step.target.exact_pose
        allowed: tuple[AllowedContact, ...] = ()
        if step.kind == "line":
            allowed = cell.scene.contacts_at(here) + cell.scene.contacts_at(goal)
        out.append(StepWorld(held, allowed, step.kind))
        here = goal
    return out


def object_released_at(cell: Cell, traj: Trajectory) -> np.ndarray:
    """World placement (4x4) of the object where the trajectory's last ``open`` leaves it."""
    grasp = cell.scene.grasp
    assert grasp is not None
    opens = [e for e in traj.events if e.action == "open"]
    assert opens, f"{traj.route} releases nothing"
    q, _, _ = traj.sample([opens[-1].time])
    return cell.robot.frame_pose(q[0]).homogeneous @ grasp.T_tcp_object


def dense_times(traj: Trajectory, period: float) -> np.ndarray:
    """Times every ``period`` [s] from 0 to the end, the end included."""
    times = np.arange(0.0, traj.duration, period)
    return np.append(times, traj.duration)


@dataclass
class Plans:
    """The bundled cell, its routes and their trajectories (with the baseline)."""

    cell: Cell
    routes: dict[str, Route]
    trajectories: dict[str, Trajectory]


@pytest.fixture(scope="session")
def bundled_cell() -> Cell:
    """The bundled quality-check cell."""
    return load_cell(BUNDLED)


@pytest.fixture(scope="session")
def bundled(bundled_cell: Cell) -> Plans:
    """Every route of the bundled cell, planned once (seed 0, stop-and-go baseline on)."""
    routes = route_routes(BUNDLED, bundled_cell)
    trajectories = plan_cell(bundled_cell, PlanOptions(baseline=True), routes=routes)
    return Plans(bundled_cell, routes, trajectories)


@pytest.fixture(scope="session")
def detour_cell() -> Cell:
    """The bundled cell plus a post on the high1 -> high2 sweep."""
    return load_cell(DETOUR)


@pytest.fixture(scope="session")
def detour_phase1(detour_cell: Cell) -> Trajectory:
    """phase1 of the detour cell, default options (seed 0): OMPL finds the detour."""
    routes = route_routes(DETOUR, detour_cell)
    return plan_cell(detour_cell, PlanOptions(), routes={"phase1": routes["phase1"]})["phase1"]
