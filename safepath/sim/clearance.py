"""Executed clearance: the simulated arm's real motion checked against the cell.

Each recorded state of the simulated arm (``/joint_states`` as executed) is checked with
safepath's own collision checker (:class:`safepath.collision.CollisionChecker`, coal) in
the world the arm was in at that moment: holding the vial or not, the vial resting where
the arm released it, and the contacts the route allows on purpose at the step being
executed (as the planner allows them: a line step those of the poses it leaves and
reaches, a free move none).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..cell import Cell
    from ..collision import CollisionChecker
    from ..scene import AllowedContact

__all__ = ["ExecutedClearance", "MotionWorld", "allowed_by_step", "ClearanceMeter"]


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
        clearance: Smallest distance arm (and held vial) to the cell [m].
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
            self._allowed[route] = allowed_by_step(self.cell, route)
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
