"""Pose editing in the review session: pick a pose, move it with joint sliders or the
TCP gizmo (inverse kinematics), see its live check, save it.

A mixin of :class:`~safepath.view.session.ReviewSession` (the checks, IK and saving
themselves are in :mod:`safepath.view.editor`); it uses the session's state under the
session's lock.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Literal, cast

import numpy as np
import pinocchio as pin

from ..errors import SafepathError
from ..planning import initial_world
from .editor import PoseStatus
from .panel import NO_POSE
from .scene_nodes import pose_of

if TYPE_CHECKING:
    from .session import ReviewSession

__all__ = ["PoseEditing"]


class PoseEditing:
    """Pose editing controls (see the module docstring)."""

    _playing: bool
    _mode: Literal["review", "edit"]
    _pose: str | None

    def edit_pose(self, name: str) -> PoseStatus:
        """Show pose ``name`` (as edited) for editing; playback pauses.

        Raises:
            PoseError: Unknown pose.
        """
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            status = self.editor.status(name)
            self._playing = False
            self._mode = "edit"
            self._pose = name
            self.panel.pose.value = name
            for slider in (*self.panel.joints, self.panel.reset):
                slider.disabled = False
            self._show_pose(status, move_gizmo=True)
            return status

    def set_joints(self, q: np.ndarray) -> PoseStatus:
        """Edit the selected pose to ``q`` [rad] and check it live."""
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            status = self.editor.set(self._editing(), q)
            self._show_pose(status, move_gizmo=True)
            return status

    def move_tcp(self, T_world_tcp: pin.SE3) -> PoseStatus:
        """Edit the selected pose so that its TCP is at ``T_world_tcp`` (IK).

        Raises:
            IKError: No solution near the pose (it is left as it was).
        """
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            status = self.editor.solve_tcp(self._editing(), T_world_tcp)
            self._show_pose(status, move_gizmo=False)
            return status

    def reset_pose(self) -> PoseStatus:
        """Drop the edit of the selected pose."""
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            status = self.editor.reset(self._editing())
            self._show_pose(status, move_gizmo=True)
            return status

    def save_poses(self, *, insist: bool = False) -> Path:
        """Save the poses (edits applied) to ``poses.yaml``, atomically, with a backup.

        Raises:
            CollisionError: An edited pose collides and ``insist`` is false.
        """
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            path = self.editor.save(insist=insist)
            self._say(f"saved {path.name} (previous version: {path.name}~)")
            if self._mode == "edit" and self._pose is not None:
                self._show_pose(self.editor.status(self._pose), move_gizmo=False)
            return path

    def review(self) -> None:
        """Leave pose editing; show the selected route."""
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            self._mode = "review"
            self._pose = None
            self.panel.pose.value = NO_POSE
            self._gizmo.visible = False
            for slider in (*self.panel.joints, self.panel.reset):
                slider.disabled = True
            if self._route is not None:
                self._show_time()
            else:
                self._show_idle()

    def _editing(self) -> str:
        self = cast("ReviewSession", self)  # the mixin's host
        if self._mode != "edit" or self._pose is None:
            raise SafepathError("pick a pose to edit first")
        return self._pose

    def _show_pose(self, status: PoseStatus, *, move_gizmo: bool) -> None:
        self = cast("ReviewSession", self)  # the mixin's host
        held, _ = status.worst
        grasp = self.cell.scene.grasp
        world = initial_world(self.cell)
        if held and grasp is not None:
            world.held = grasp.object
            world.resting.pop(grasp.object, None)
        self._show(status.q, world, self.editor.checker(status.pose, held))
        self.pose_frames.set(status.pose, status.q)
        for slider, v in zip(self.panel.joints, status.q, strict=True):
            slider.value = float(v)
        if move_gizmo:
            wxyz, position = pose_of(self.cell.robot.frame_pose(status.q))
            self._gizmo.wxyz, self._gizmo.position = wxyz, position
        self._gizmo.visible = bool(self.panel.gizmo_enabled.value)
        mark = "" if status.pose not in self.editor.edits else " (edited, not saved)"
        self.panel.pose_state.content = f"**{status.pose}**{mark}\n\n{status.summary()}"
