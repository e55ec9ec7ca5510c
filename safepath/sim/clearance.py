"""Executed clearance: the simulated arm's real motion checked against the cell.

Each recorded state of the simulated arm (``/joint_states`` as executed) is checked with
safepath's own collision checker (:class:`safepath.collision.CollisionChecker`, coal) in
the world the arm was in at that moment: holding the vial or not, the vial resting where
the arm released it, and the contacts the route allows on purpose at the step being
executed (as the planner allows them: a line step those of the poses it leaves and
reaches, a free move none).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from ..cell import Cell
    from ..collision import CollisionChecker
    from ..model.robot import Robot
    from ..model.scene import AllowedContact
    from ..model.trajectory import Trajectory

__all__ = ["ExecutedClearance", "MotionWorld", "allowed_by_step", "ClearanceMeter",
           "ExecutedMotion", "executed_clearance", "tcp_deviation"]


@dataclass(frozen=True)
class MotionWorld:
    """The world of one executed motion.

    Attributes:
        held: The held object, or None.
        resting: Where the vial rests when not held (4x4), or None: its scene placement.
    """

    held: str | None
    resting: np.ndarray | None


@dataclass(frozen=True)
class ExecutedClearance:
    """The smallest clearance of the executed motion.

    Attributes:
        clearance: Smallest distance arm (and held vial) to the cell [m] (the contacts
            allowed at the step being executed excluded, as the checker excludes them).
        pair: Its pair of names.
        time: When [s].
        states: Number of executed states checked.
    """

    clearance: float
    pair: tuple[str, str] | None
    time: float
    states: int


def allowed_by_step(cell: Cell, route: str) -> dict[int, tuple[AllowedContact, ...]]:
    """For each step number of ``route``, the contacts allowed on purpose while it runs."""
    steps = cell.route_table()[route].steps
    start = cell.route_table()[route].start
    pose: str | None = start
    out: dict[int, tuple[AllowedContact, ...]] = {}
    for i, step in enumerate(steps):
        if not step.is_motion:
            continue
        goal = step.target.exact_pose if step.target is not None else None
        if step.kind == "line":
            out[i] = tuple(cell.scene.contacts_at(pose)) + tuple(cell.scene.contacts_at(goal))
        else:
            out[i] = ()
        pose = goal
    return out


class ClearanceMeter:
    """Checks executed states, keeping the smallest clearance (checkers built once per
    world and allowed-contact set)."""

    def __init__(self, cell: Cell) -> None:
        self.cell = cell
        self._checkers: dict[tuple, CollisionChecker] = {}
        self._allowed: dict[str, dict[int, tuple[AllowedContact, ...]]] = {}
        self.best = ExecutedClearance(float("inf"), None, float("nan"), 0)

    def _checker(self, world: MotionWorld, allowed: tuple[AllowedContact, ...]
                 ) -> CollisionChecker:
        from ..collision import CheckOptions, CollisionChecker

        resting = None if world.resting is None else world.resting.round(9)
        key = (world.held, None if resting is None else resting.tobytes(), allowed)
        if key not in self._checkers:
            grasp = self.cell.scene.grasp
            rest = {} if resting is None or grasp is None else {grasp.object: resting}
            self._checkers[key] = CollisionChecker(
                self.cell.robot, self.cell.scene, held=world.held, resting=rest,
                allowed=allowed, options=CheckOptions())
        return self._checkers[key]

    def check(self, route: str, step_label: str, world: MotionWorld, times: np.ndarray,
              q: np.ndarray) -> None:
        """Check executed states ``q`` (N, dof) at ``times`` [s], all in one step."""
        if route not in self._allowed:
            # A motion that is no route of the cell (a pour's tilt, stop or return, a
            # monitor's replacement) allows no contact.
            self._allowed[route] = allowed_by_step(self.cell, route) \
                if route in self.cell.route_table() else {}
        head = step_label.split(" ", 1)[0]
        allowed = self._allowed[route].get(int(head), ()) if head.isdigit() else ()
        checker = self._checker(world, allowed)
        best = self.best
        for t, qk in zip(times, q, strict=True):
            d, pair = checker.clearance(qk)
            if d < best.clearance:
                best = ExecutedClearance(d, pair, float(t), best.states)
        self.best = ExecutedClearance(best.clearance, best.pair, best.time,
                                      best.states + len(times))


class ExecutedMotion(Protocol):
    """A motion goal as it ran: sent at ``start``, over at ``end`` (inf: still running),
    the trajectory sent, and the world it ran in."""

    start: float
    end: float
    traj: Trajectory
    world: MotionWorld


def executed_clearance(cell: Cell, recording: Any, motions: Iterable[ExecutedMotion]
                       ) -> ExecutedClearance:
    """The recorded states (``recording``: a :class:`~safepath.sim.twin.Recording`) of
    every motion, each checked in its world with the contacts its step allows."""
    times = np.asarray(recording.time)
    q = np.asarray(recording.q)
    meter = ClearanceMeter(cell)
    for motion in motions:
        end = min(motion.end, times[-1])
        sel = np.flatnonzero((times >= motion.start) & (times <= end))
        if sel.size == 0:
            continue
        # The trajectory's own time: its stamp may lie after the goal was sent.
        offset = getattr(motion, "t0", motion.start)
        labels = [motion.traj.step_at(float(min(max(t - offset, 0.0), motion.traj.duration)))
                  for t in times[sel]]
        k = 0
        while k < sel.size:
            j = k
            while j + 1 < sel.size and labels[j + 1] == labels[k]:
                j += 1
            meter.check(motion.traj.route, labels[k], motion.world, times[sel[k:j + 1]],
                        q[sel[k:j + 1]])
            k = j + 1
    return meter.best


def tcp_deviation(robot: Robot, recording: Any) -> float:
    """Largest executed-vs-commanded TCP distance while goals ran [m] (the tracking
    allowance of the executed clearance)."""
    worst = 0.0
    for q, q_ref, moving in zip(recording.q, recording.q_ref, recording.moving, strict=True):
        if moving:
            worst = max(worst, float(np.linalg.norm(robot.tcp_position(q)
                                                    - robot.tcp_position(q_ref))))
    return worst
