"""Edits of taught poses: live checks, inverse kinematics for TCP drags, saving.

No GUI here: a :class:`~safepath.view.editor.PoseEditor` drives :class:`PoseEdits` from
its sliders and its TCP gizmo, and shows the :class:`PoseStatus` it returns. A pose is checked as
``safepath check`` does: with the gripper empty and, where the scene's grasp allows
it, holding the object, each with the contacts allowed at that pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..cell import Cell
from ..collision import CollisionChecker, StateReport
from ..errors import CollisionError, IKError
from ..planning import solve_ik
from ..poses import save_poses

__all__ = ["PoseStatus", "PoseEdits"]


@dataclass(frozen=True)
class PoseStatus:
    """The live check of one (edited) pose.

    Attributes:
        pose: Pose name.
        q: The joint vector [rad].
        reports: ``(held, report)`` for every gripper state the pose is used in.
    """

    pose: str
    q: np.ndarray = field(repr=False)
    reports: tuple[tuple[bool, StateReport], ...]

    @property
    def valid(self) -> bool:
        """Inside the limits and collision-free in every gripper state."""
        return all(r.valid for _, r in self.reports)

    @property
    def margin_ok(self) -> bool:
        """Valid and every safety margin kept."""
        return all(r.margin_ok for _, r in self.reports)

    @property
    def collisions(self) -> tuple[tuple[str, str], ...]:
        """Colliding pairs, over every gripper state."""
        out: dict[tuple[str, str], None] = {}
        for _, r in self.reports:
            out.update(dict.fromkeys(r.collisions))
        return tuple(out)

    @property
    def clearance(self) -> float:
        """Smallest clearance over every gripper state [m]."""
        return min(r.clearance for _, r in self.reports)

    @property
    def worst(self) -> tuple[bool, StateReport]:
        """The gripper state that looks worst (invalid first, then least clearance)."""
        return min(self.reports, key=lambda hr: (hr[1].valid, hr[1].margin_ok,
                                                 hr[1].clearance))

    def summary(self) -> str:
        """Markdown lines for the GUI."""
        lines = []
        for held, r in self.reports:
            state = "holding" if held else "empty"
            if not r.within_limits:
                lines.append(f"- {state}: **outside limits**: {r.limit_violation}")
            elif r.collisions:
                pairs = ", ".join(f"{a} / {b}" for a, b in r.collisions)
                lines.append(f"- {state}: **COLLISION** {pairs}")
            else:
                pair = " / ".join(r.closest_pair) if r.closest_pair else "-"
                low = "" if r.margin_ok else " (**below margin**)"
                lines.append(f"- {state}: valid, clearance {r.clearance * 1000:.1f} mm "
                             f"({pair}){low}")
        return "\n".join(lines)


class PoseEdits:
    """Edits of a cell's taught poses, kept apart from the cell until saved.

    Args:
        cell: The cell; its ``poses`` are updated when the edits are saved.
    """

    def __init__(self, cell: Cell) -> None:
        self.cell = cell
        self.edits: dict[str, np.ndarray] = {}
        self._checkers: dict[tuple[str, bool], CollisionChecker] = {}

    def q(self, name: str) -> np.ndarray:
        """The pose ``name`` as edited [rad] (a copy)."""
        if name in self.edits:
            return self.edits[name].copy()
        return self.cell.pose(name).copy()

    def poses(self) -> dict[str, np.ndarray]:
        """Every taught pose, edits applied."""
        return {name: self.q(name) for name in self.cell.poses}

    def held_states(self, name: str) -> tuple[bool, ...]:
        """Gripper states pose ``name`` is used in (held only where the grasp allows)."""
        grasp = self.cell.scene.grasp
        return (False, True) if grasp is not None and name in grasp.poses else (False,)

    def checker(self, name: str, held: bool) -> CollisionChecker:
        """The checker of pose ``name`` in one gripper state (not thread-safe)."""
        key = (name, held)
        if key not in self._checkers:
            self._checkers[key] = self.cell.checker(held=held, at=name)
        return self._checkers[key]

    def status(self, name: str) -> PoseStatus:
        """Check pose ``name`` as edited."""
        q = self.q(name)
        reports = tuple((held, self.checker(name, held).check(q))
                        for held in self.held_states(name))
        return PoseStatus(name, q, reports)

    def set(self, name: str, q: np.ndarray) -> PoseStatus:
        """Edit pose ``name`` to ``q`` [rad] and check it.

        Raises:
            PoseError: Unknown pose, or not a finite vector of the right length.
        """
        self.cell.pose(name)
        self.edits[name] = self.cell.robot.as_joint_vector(q, name=name, check_limits=False)
        return self.status(name)

    def reset(self, name: str) -> PoseStatus:
        """Drop the edit of pose ``name``."""
        self.edits.pop(name, None)
        return self.status(name)

    def solve_tcp(self, name: str, T_world_tcp: pin.SE3) -> PoseStatus:
        """Edit pose ``name`` so that the TCP is at ``T_world_tcp``, by inverse
        kinematics seeded from the pose as edited.

        Raises:
            IKError: No solution near the current pose (the pose is left as it was).
        """
        q = solve_ik(self.cell.robot, T_world_tcp, self.q(name))
        if q is None:
            raise IKError("no inverse-kinematics solution for the dragged TCP", step=name,
                          fraction=1.0, position=np.array(T_world_tcp.translation))
        return self.set(name, q)

    def invalid(self) -> list[PoseStatus]:
        """Edited poses that are outside the limits or in collision."""
        return [s for s in (self.status(n) for n in self.edits) if not s.valid]

    def save(self, *, insist: bool = False, backup: bool = True) -> Path:
        """Write every pose (edits applied) to the cell's poses file, atomically.

        Args:
            insist: Save even when an edited pose is in collision.
            backup: Keep the previous file as ``poses.yaml~``.

        Raises:
            CollisionError: An edited pose is in collision and ``insist`` is false
                (nothing is written).
            PoseError: A pose outside the joint limits (nothing is written).
        """
        bad = [s for s in self.invalid() if s.collisions]
        if bad and not insist:
            pairs = [p for s in bad for p in s.collisions]
            names = ", ".join(s.pose for s in bad)
            raise CollisionError(f"not saved: pose {names} in collision "
                                 f"({', '.join(f'{a} / {b}' for a, b in pairs)})",
                                 q=bad[0].q, pairs=pairs)
        merged = self.poses()
        save_poses(self.cell.poses_path, merged, self.cell.robot, backup=backup)
        self.cell.poses.update(merged)
        self.edits.clear()
        return self.cell.poses_path
