"""Fixtures of the twin's tests: the bundled cell's routes, planned once per session, and
the planned motions' distance to objects added to the cell."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from safepath import PlanOptions, Trajectory, plan_cell
from safepath.cell import Cell
from safepath.collision import CheckOptions, CollisionChecker
from safepath.model.trajectory import GripperEvent
from safepath.ros.goals import split_at_gripper_events
from safepath.sim.clearance import allowed_by_step


@pytest.fixture(scope="session")
def routes(cell: Cell) -> dict[str, Trajectory]:
    """The bundled cell's verified trajectories (do not mutate)."""
    return plan_cell(cell, PlanOptions())


def distances_to(cell: Cell, routes: dict[str, Trajectory], check_cell: Cell,
                 counts: Callable[[str], bool]) -> dict[tuple[str, int], float]:
    """Per motion of each route: the smallest distance [m] of the arm (and the vial it
    holds) to the objects of ``check_cell`` (``cell`` with objects added) whose name
    ``counts``, with safepath's checker, every 10 ms of the planned motion, in the
    motion's world (vial held, or resting where released) and with the contacts its
    step allows."""
    grasp = cell.scene.grasp
    assert grasp is not None
    robot = check_cell.robot
    out: dict[tuple[str, int], float] = {}
    for route in ("phase1", "phase2_safe", "phase2_unsafe"):
        allowed = allowed_by_step(check_cell, route)
        held: str | None = None
        rest = None if route == "phase1" else \
            robot.frame_pose(cell.poses["low1"]).homogeneous @ grasp.T_tcp_object
        last: Trajectory | None = None
        for k, part in enumerate(split_at_gripper_events(routes[route])):
            if isinstance(part, GripperEvent):
                if part.action == "close":
                    held = grasp.object
                else:
                    assert last is not None
                    held = None
                    rest = robot.frame_pose(last.q[-1]).homogeneous @ grasp.T_tcp_object
                continue
            last = part
            times = np.append(np.arange(0.0, part.duration, 0.01), part.duration)
            checkers: dict[tuple, CollisionChecker] = {}
            best = np.inf
            for t, q in zip(times, part.sample(times)[0], strict=True):
                head = part.step_at(float(t)).split(" ", 1)[0]
                step_allowed = allowed.get(int(head), ()) if head.isdigit() else ()
                if step_allowed not in checkers:
                    checkers[step_allowed] = CollisionChecker(
                        robot, check_cell.scene, held=held,
                        resting={} if rest is None else {grasp.object: rest},
                        allowed=step_allowed, options=CheckOptions())
                for pair, d in checkers[step_allowed].distances(q):
                    if any(counts(name) for name in pair):
                        best = min(best, d)
            out[(route, k)] = best
    return out
