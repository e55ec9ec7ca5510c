"""Edits of taught poses: live checks, inverse kinematics for TCP drags, saving.

No GUI and no file here: a :class:`~safepath.view.editor.PoseEditor` drives
:class:`PoseEdits` from its joint boxes and its TCP gizmo and shows the :class:`PoseStatus`
it returns; the session writes what :meth:`PoseEdits.to_save` gives through a
:class:`~safepath.view.store.PosesStore`. A pose is checked as
``safepath check`` does: with the gripper empty and, where the scene's grasp allows
it, holding the object, each with the contacts allowed at that pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..cell import Cell
from ..collision import CollisionChecker, StateReport
from ..errors import CollisionError, PoseError, SafepathError
from ..kinematics import solve_ik
from .store import PoseChange, PosesChanged, PosesSnapshot

__all__ = ["OutsideLimits", "PoseStatus", "PoseEdits"]


class OutsideLimits(PoseError):
    """A save refused because an edited pose is outside the joint limits: it is never
    clamped into them (the reviewer would save a pose they did not see checked).

    The message starts with "not saved:", as every refused save's does.

    Attributes:
        pose: The pose.
        q: Its joint vector as edited [rad].
    """

    def __init__(self, violation: str, *, path: Path | None, pose: str, q: np.ndarray) -> None:
        super().__init__(violation, path=path, key=pose)
        self.pose = pose
        self.q = q.copy()

    def __str__(self) -> str:
        where = f" ({self.path.name}, key '{self.key}')" if self.path is not None else ""
        return (f"not saved: pose {self.pose}{where}: {self.reason}; type a value inside "
                "the limits")


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

    def to_json(self) -> dict[str, Any]:
        """The check as the save log records it (clearance in [mm])."""
        clearance = self.clearance
        return {"valid": self.valid, "margin_ok": self.margin_ok,
                "clearance_mm": round(clearance * 1000, 2) if np.isfinite(clearance) else None,
                "collisions": [list(p) for p in self.collisions]}

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
    """One editor's edits of a cell's taught poses, over a base version of the poses file.

    Every edit remembers the saved value it started from (its origin). When the base
    moves on (another editor saved, or the file was reloaded), an edit whose pose was
    changed there becomes a *conflict*: it cannot be saved until the editor takes the
    saved value (:meth:`take_saved`) or keeps its own over it (:meth:`keep_mine`). Edits
    of other poses carry over.

    Args:
        cell: The cell (robot, scene, grasp).
        base: The version of the poses file the edits start from.
        checkers: Collision checkers by (pose, held), shared between editors that are
            used under one lock.
    """

    def __init__(self, cell: Cell, base: PosesSnapshot, *,
                 checkers: dict[tuple[str, bool], CollisionChecker] | None = None) -> None:
        self.cell = cell
        self.base = base
        self.edits: dict[str, np.ndarray] = {}
        self.origins: dict[str, np.ndarray] = {}
        self.conflicts: dict[str, PoseChange] = {}
        self._checkers = {} if checkers is None else checkers

    def q(self, name: str) -> np.ndarray:
        """The pose ``name`` as edited [rad] (a copy).

        Raises:
            PoseError: No pose of that name.
        """
        if name in self.edits:
            return self.edits[name].copy()
        if name not in self.base.poses:
            raise PoseError(f"unknown pose '{name}' (known: {', '.join(self.base.poses)})",
                            path=self.cell.poses_path, key=name)
        return self.base.poses[name].copy()

    def poses(self) -> dict[str, np.ndarray]:
        """Every taught pose, edits applied."""
        return {name: self.q(name) for name in self.base.poses}

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
        origin = self.q(name) if name not in self.edits else None
        self.edits[name] = self.cell.robot.as_joint_vector(q, name=name, check_limits=False)
        if origin is not None:
            self.origins[name] = origin
        return self.status(name)

    def reset(self, name: str) -> PoseStatus:
        """Drop the edit of pose ``name``."""
        self._drop(name)
        return self.status(name)

    def solve_tcp(self, name: str, T_world_tcp: pin.SE3) -> PoseStatus:
        """Edit pose ``name`` so that the TCP is at ``T_world_tcp``, by inverse
        kinematics seeded from the pose as edited.

        Raises:
            IKError: No solution near the current pose (the pose is left as it was).
        """
        return self.set(name, solve_ik(self.cell.robot, T_world_tcp, self.q(name), step=name))

    def invalid(self) -> list[PoseStatus]:
        """Edited poses that are outside the limits or in collision."""
        return [s for s in (self.status(n) for n in self.edits) if not s.valid]

    def rebase(self, base: PosesSnapshot) -> list[str]:
        """Move onto a newer version of the poses file; returns the poses that became
        conflicts (edited here, changed there)."""
        new = []
        for name in list(self.edits):
            saved = base.poses.get(name)
            if saved is None or np.array_equal(saved, self.edits[name]):
                self._drop(name)  # the pose is gone, or saved as edited here: nothing lost
            elif not np.array_equal(saved, self.origins[name]):
                if name not in self.conflicts:
                    new.append(name)
                self.conflicts[name] = PoseChange(name, self.origins[name], saved.copy())
        self.base = base
        return new

    def take_saved(self, name: str) -> PoseStatus:
        """Resolve a conflict by dropping this edit: the saved value wins."""
        self._conflict(name)
        return self.reset(name)

    def keep_mine(self, name: str) -> PoseStatus:
        """Resolve a conflict by keeping this edit over the saved value."""
        self._conflict(name)
        self.origins[name] = self.base.poses[name].copy()
        del self.conflicts[name]
        return self.status(name)

    def to_save(self, *, insist: bool = False) -> tuple[dict[str, np.ndarray],
                                                        dict[str, dict[str, Any]]]:
        """Every pose to write (edits applied) and the check of each edited one.

        Raises:
            SafepathError: Nothing is edited.
            PosesChanged: An edit is in conflict (names the poses and what changed).
            OutsideLimits: An edited pose is outside the joint limits (names the joint
                and its value; ``insist`` does not override it).
            CollisionError: An edited pose is in collision and ``insist`` is false.
        """
        if not self.edits:
            raise SafepathError("nothing to save: no pose is edited")
        if self.conflicts:
            names = self.cell.robot.joint_names
            changes = list(self.conflicts.values())
            what = "; ".join(c.describe(names) for c in changes)
            raise PosesChanged(f"not saved: {', '.join(self.conflicts)} changed in another "
                               f"save while you edited ({what}); take the saved version or "
                               f"keep yours, pose by pose", path=self.cell.poses_file(),
                               changes=changes, conflicts=list(self.conflicts))
        statuses = [self.status(n) for n in self.edits]
        for s in statuses:  # never clamped into the limits: refused, the value named
            violation = self.cell.robot.limit_violation(s.q)
            if violation is not None:
                raise OutsideLimits(violation, path=self.cell.poses_path, pose=s.pose, q=s.q)
        bad = [s for s in statuses if s.collisions]
        if bad and not insist:
            pairs = [p for s in bad for p in s.collisions]
            names_ = ", ".join(s.pose for s in bad)
            raise CollisionError(f"not saved: pose {names_} in collision "
                                 f"({', '.join(f'{a} / {b}' for a, b in pairs)})",
                                 q=bad[0].q, pairs=pairs)
        return self.poses(), {s.pose: s.to_json() for s in statuses}

    def saved(self, base: PosesSnapshot) -> None:
        """The edits were written as ``base``: they are the base now."""
        self.edits.clear()
        self.origins.clear()
        self.conflicts.clear()
        self.base = base

    def _drop(self, name: str) -> None:
        self.edits.pop(name, None)
        self.origins.pop(name, None)
        self.conflicts.pop(name, None)

    def _conflict(self, name: str) -> None:
        if name not in self.conflicts:
            raise SafepathError(f"pose '{name}' is not in conflict")
