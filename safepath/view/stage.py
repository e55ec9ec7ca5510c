"""The robot and the cell's objects as one drawn state: place them at a joint vector in
a world state, check that state, and colour the colliding geometry red.

A :class:`Stage` draws into one viser scope: the server (every page sees it: the
playback) or one client (a client-scoped node shadows the server's node of the same
name for that page only, so a reviewer editing a pose sees their robot while the others
keep watching the playback).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..cell import Cell
from ..collision import CollisionChecker
from ..planning import WorldState
from .scene_nodes import CellNodes, RobotNodes, RobotStyle

__all__ = ["ShownState", "Stage"]


@dataclass(frozen=True)
class ShownState:
    """The state a stage shows.

    Attributes:
        q: Joint vector [rad].
        valid: Inside the limits and collision-free.
        collisions: Colliding pairs (drawn red).
        held: Object in the gripper, if any.
    """

    q: np.ndarray
    valid: bool
    collisions: tuple[tuple[str, str], ...]
    held: str | None


class Stage:
    """The robot and the cell's objects drawn in one scope.

    Args:
        scope: A ``viser.ViserServer`` (every page) or a ``viser.ClientHandle`` (one page).
        cell: The cell drawn.
        style: Robot style, ``collision`` or ``visual``.
    """

    def __init__(self, scope: Any, cell: Cell, *, style: RobotStyle = "collision") -> None:
        self.scope = scope
        self.cell = cell
        self.robot_nodes = RobotNodes(scope, cell.robot, style=style)
        self.cell_nodes = CellNodes(scope, cell.scene)
        self.shown: ShownState | None = None
        self.checker: CollisionChecker | None = None

    def show(self, q: np.ndarray, world: WorldState, checker: CollisionChecker) -> ShownState:
        """Draw the robot at ``q`` [rad] in ``world``, colliding geometry red."""
        cell = self.cell
        grasp = cell.scene.grasp
        with self.scope.atomic():
            self.robot_nodes.update(q)
            for name, obj in cell.scene.objects.items():
                if not obj.movable:
                    continue
                if world.held == name and grasp is not None:
                    T = cell.robot.frame_pose(q).homogeneous @ grasp.T_tcp_object
                else:
                    T = world.resting.get(name)
                self.cell_nodes.place(name, T)
            valid = checker.is_valid(q)
            pairs = () if valid else tuple(checker.collisions(q))
            names = {n for pair in pairs for n in pair}
            self.robot_nodes.highlight(names)
            self.cell_nodes.highlight(names)
        self.shown = ShownState(np.array(q), valid, pairs, world.held)
        self.checker = checker
        return self.shown

    def remove(self) -> None:
        """Remove every node (a client's stage: the page shows the server's again)."""
        with self.scope.atomic():
            for node in [*self.robot_nodes.all_nodes(), *self.cell_nodes.nodes.values()]:
                node.root.remove()
