"""One editor of taught poses in the review session: pick a pose, move it with joint
boxes or the TCP gizmo (inverse kinematics), see its live check, save it.

A :class:`PoseEditor` holds its own :class:`~safepath.view.edits.PoseEdits` and draws
the pose being edited on a :class:`~safepath.view.stage.Stage`, moves a TCP gizmo and
fills an :class:`~safepath.view.panel.EditPanel` (all optional: the editor of the
Python API has no widgets). It does no locking: the session calls it under its lock.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..cell import Cell
from ..errors import SafepathError
from ..planning import initial_world
from .edits import PoseEdits, PoseStatus
from .panel import NO_POSE, EditPanel, show_joint
from .scene_nodes import PoseFrames, pose_of
from .stage import Stage

__all__ = ["PoseEditor"]


class PoseEditor:
    """Edit controls of one editor (see the module docstring).

    Args:
        cell: The cell.
        edits: The edit buffer.
        stage: Where the edited pose is drawn: called when editing starts, so that a
            page's own stage is built only when it edits.
        frames: The taught-pose frames the edited pose moves.
        widgets: The "Edit poses" folder, if any.
        gizmo: The TCP transform control, if any.
    """

    def __init__(self, cell: Cell, edits: PoseEdits, *, stage: Callable[[], Stage],
                 frames: PoseFrames, widgets: EditPanel | None = None,
                 gizmo: Any = None) -> None:
        self.cell = cell
        self.edits = edits
        self.widgets = widgets
        self.gizmo = gizmo
        self.frames = frames
        self._stage = stage
        self.pose: str | None = None

    @property
    def editing(self) -> bool:
        """Whether a pose is being edited."""
        return self.pose is not None

    def edit_pose(self, name: str) -> PoseStatus:
        """Show pose ``name`` (as edited) for editing.

        Raises:
            PoseError: Unknown pose.
        """
        status = self.edits.status(name)
        self.pose = name
        if self.widgets is not None:
            self.widgets.pose.value = name
        self.show(status, move_gizmo=True)
        return status

    def set_joints(self, q: np.ndarray) -> PoseStatus:
        """Edit the selected pose to ``q`` [rad] and check it live."""
        status = self.edits.set(self.selected(), q)
        self.show(status, move_gizmo=True)
        return status

    def set_joint(self, j: int, value: float) -> PoseStatus:
        """Edit joint ``j`` of the selected pose to ``value`` [rad]."""
        q = self.edits.q(self.selected())
        q[j] = value
        return self.set_joints(q)

    def move_tcp(self, T_world_tcp: pin.SE3) -> PoseStatus:
        """Edit the selected pose so that its TCP is at ``T_world_tcp`` (IK).

        Raises:
            IKError: No solution near the pose (it is left as it was).
        """
        status = self.edits.solve_tcp(self.selected(), T_world_tcp)
        self.show(status, move_gizmo=False)
        return status

    def drag_tcp(self, wxyz: np.ndarray, position: np.ndarray) -> PoseStatus:
        """:meth:`move_tcp` from the gizmo's orientation (w, x, y, z) and position [m]."""
        w, x, y, z = (float(v) for v in wxyz)
        rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
        return self.move_tcp(pin.SE3(rotation, np.asarray(position, dtype=float)))

    def reset_pose(self) -> PoseStatus:
        """Drop the edit of the selected pose."""
        status = self.edits.reset(self.selected())
        self.show(status, move_gizmo=True)
        return status

    def leave(self) -> None:
        """Stop editing (the edits are kept)."""
        self.pose = None
        if self.widgets is not None:
            self.widgets.pose.value = NO_POSE
        if self.gizmo is not None:
            self.gizmo.visible = False

    def set_gizmo_visible(self, visible: bool) -> None:
        """Show the TCP gizmo (only while a pose is edited)."""
        if self.gizmo is not None:
            self.gizmo.visible = visible and self.editing

    def selected(self) -> str:
        """The pose being edited.

        Raises:
            SafepathError: No pose is being edited.
        """
        if self.pose is None:
            raise SafepathError("pick a pose to edit first")
        return self.pose

    def refresh(self) -> None:
        """Show the edited pose again (after a save or a change of the base poses)."""
        if self.pose is not None:
            self.show(self.edits.status(self.pose), move_gizmo=True)

    def show(self, status: PoseStatus, *, move_gizmo: bool) -> None:
        """Draw ``status``'s pose in the gripper state that looks worst, and its check."""
        held, _ = status.worst
        grasp = self.cell.scene.grasp
        world = initial_world(self.cell)
        if held and grasp is not None:
            world.held = grasp.object
            world.resting.pop(grasp.object, None)
        self._stage().show(status.q, world, self.edits.checker(status.pose, held))
        self.frames.set(status.pose, status.q)
        if self.gizmo is not None:
            if move_gizmo:
                wxyz, position = pose_of(self.cell.robot.frame_pose(status.q))
                self.gizmo.wxyz, self.gizmo.position = wxyz, position
            enabled = self.widgets is None or bool(self.widgets.gizmo_enabled.value)
            self.gizmo.visible = enabled
        if self.widgets is not None:
            for joint_box, v in zip(self.widgets.joints, status.q, strict=True):
                show_joint(joint_box, float(v))
            mark = "" if status.pose not in self.edits.edits else " (edited, not saved)"
            self.widgets.pose_state.content = (f"**{status.pose}**{mark}\n\n"
                                               f"{status.summary()}")
