"""The review session's control panel: its layout and handles, no behaviour.

Shared by every page (server-scoped), top to bottom: a header (cell, robot, status line,
notice); **Playback** (route dropdown, time readout, time slider, Play / Pause, speed,
loop); **Safety** (the shown state's check, the minimum-clearance plot, the joint-speed
plot); **Display** (robot style, taught poses, path), kept last. Each page gets its own
(client-scoped) **Edit poses** folder: an access note with the token field and Unlock
(when editing needs the token), pose dropdown, its live check, one slider per joint,
TCP gizmo, reset, take the saved version / keep mine (conflicts), re-plan, "I insist",
save, reload.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from ..model.robot import Robot

__all__ = ["NO_ROUTE", "NO_POSE", "JOINT_DECIMALS", "typed_joint", "show_joint", "Panel",
           "EditPanel", "build_panel", "build_edit_panel", "clearance_plot_data",
           "speed_plot_data"]

#: Dropdown entries meaning "nothing selected".
NO_ROUTE = "(no plan yet)"
NO_POSE = "(review routes)"
#: Decimals a joint box shows and takes [rad]: 0.1 urad, finer than any encoder. A value
#: typed or pasted with more is rounded to them (:func:`typed_joint`), never cut.
JOINT_DECIMALS = 7
#: Decimals the page's box lets through: its input (Mantine's NumberInput) drops the
#: digits beyond its precision, which would cut a longer value instead of rounding it.
_BOX_DECIMALS = 16
#: Step of a joint box's arrow keys [rad].
JOINT_STEP = 0.001

_JOINT_COLORS = ("#e63946", "#f4a261", "#2a9d8f", "#264653", "#8338ec", "#3a86ff",
                 "#ff006e", "#8ac926")
# Order of the folders kept at the end (pages add their edit folder later).
_LAST = 1e9
# The x axis is seconds, not a date.
_SCALES: dict[str, Any] = {"x": {"time": False}}


@dataclass
class Panel:
    """Handles of the control panel (see the module docstring for the layout)."""

    header: Any
    status: Any
    notice: Any
    route: Any
    readout: Any
    time: Any
    play: Any
    pause: Any
    speed: Any
    loop: Any
    state: Any
    clearance_plot: Any
    speed_plot: Any
    visual_style: Any
    show_poses: Any
    show_path: Any


@dataclass
class EditPanel:
    """Handles of one page's "Edit poses" folder (see the module docstring)."""

    access_note: Any
    token: Any
    unlock: Any
    pose: Any
    pose_state: Any
    joints: list[Any]
    gizmo_enabled: Any
    reset: Any
    take_saved: Any
    keep_mine: Any
    replan: Any
    insist: Any
    save: Any
    to_save: Any
    confirm: Any
    reload: Any

    def enable(self, *, may_edit: bool, editing: bool, conflict: bool,
               pending: bool = False) -> None:
        """Enable what the page may use now (``pending``: a save waits for its
        confirmation)."""
        for handle in (*self.joints, self.reset):
            handle.disabled = not (may_edit and editing)
        self.confirm.visible = may_edit and pending
        for handle in (self.take_saved, self.keep_mine):
            handle.disabled = not (may_edit and conflict)
        for handle in (self.replan, self.save, self.reload, self.insist):
            handle.disabled = not may_edit
        if self.token is not None:
            self.token.visible = self.unlock.visible = not may_edit


def clearance_plot_data(times: np.ndarray, clearance: np.ndarray, margin: float,
                        clear_enough: float) -> tuple[np.ndarray, ...]:
    """Plot arrays: time [s], clearance, margin and "clear enough" lines [mm]."""
    c = np.where(np.isfinite(clearance), clearance, np.nan) * 1000.0
    c = np.nan_to_num(c, nan=float(np.nanmax(c)) if np.isfinite(c).any() else 0.0)
    ones = np.ones_like(times)
    return (np.asarray(times, float), c, ones * margin * 1000.0, ones * clear_enough * 1000.0)


def speed_plot_data(times: np.ndarray, ratio: np.ndarray) -> tuple[np.ndarray, ...]:
    """Plot arrays: time [s], ``|qd| / limit`` per joint, and the limit (1)."""
    return (np.asarray(times, float), *(np.asarray(ratio[:, j], float)
                                        for j in range(ratio.shape[1])),
            np.ones_like(times, dtype=float))


def build_panel(server: viser.ViserServer, robot: Robot, *, title: str, poses: list[str],
                margin: float, clear_enough: float) -> Panel:
    """Add the control panel to ``server``."""
    gui = server.gui
    header = gui.add_markdown(title)
    status = gui.add_markdown("")
    notice = gui.add_markdown("")
    with gui.add_folder("Playback"):
        route = gui.add_dropdown("Route", [NO_ROUTE], initial_value=NO_ROUTE)
        readout = gui.add_markdown("")
        time = gui.add_slider("Time [s]", min=0.0, max=1.0, step=0.01, initial_value=0.0)
        play = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
        pause = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
        speed = gui.add_slider("Speed", min=0.1, max=2.0, step=0.1, initial_value=1.0)
        loop = gui.add_checkbox("Loop", True)
    with gui.add_folder("Safety"):
        state = gui.add_markdown("")
        t0 = np.zeros(2)
        clearance_plot = gui.add_uplot(
            clearance_plot_data(t0, np.zeros(2), margin, clear_enough),
            ({"label": "t [s]"},
             {"label": "clearance [mm]", "stroke": "#2a9d8f", "width": 2},
             {"label": "margin", "stroke": "#e63946", "dash": (6.0, 4.0)},
             {"label": f"{clear_enough * 1000:.0f} mm", "stroke": "#e9c46a", "dash": (6.0, 4.0)}),
            title="Minimum clearance [mm]", aspect=1.6, scales=_SCALES)
        joint_series: list[Any] = [{"label": "t [s]"}]
        for j, name in enumerate(robot.joint_names):
            joint_series.append({"label": name, "stroke": _JOINT_COLORS[j % len(_JOINT_COLORS)],
                                 "width": 1.5})
        joint_series.append({"label": "limit", "stroke": "#e63946", "dash": (6.0, 4.0)})
        speed_plot = gui.add_uplot(
            speed_plot_data(t0, np.zeros((2, robot.dof))), tuple(joint_series),
            title="Joint speed / limit", aspect=1.6, scales=_SCALES)
    with gui.add_folder("Display", expand_by_default=False, order=_LAST):
        visual_style = gui.add_checkbox("Visual style", False,
                                        hint="URDF visual materials instead of per-link "
                                             "collision colours")
        show_poses = gui.add_checkbox("Taught poses", True)
        show_path = gui.add_checkbox("TCP path", True)
    return Panel(header, status, notice, route, readout, time, play, pause, speed, loop,
                 state, clearance_plot, speed_plot, visual_style, show_poses, show_path)


def build_edit_panel(gui: Any, robot: Robot, poses: list[str], *, token: bool
                     ) -> EditPanel:
    """Add an "Edit poses" folder to ``gui`` (one client's); with ``token``, a field to
    enter the edit token and an Unlock button."""
    with gui.add_folder("Edit poses", order=_LAST - 1):
        access_note = gui.add_markdown("")
        token_field = gui.add_text("Edit token", "") if token else None
        unlock = gui.add_button("Unlock editing") if token else None
        pose = gui.add_dropdown("Pose", [NO_POSE, *poses], initial_value=NO_POSE)
        pose_state = gui.add_markdown("Pick a pose to edit it.")
        joints = [_joint_box(gui, name, float(robot.lower[j]), float(robot.upper[j]))
                  for j, name in enumerate(robot.joint_names)]
        gizmo_enabled = gui.add_checkbox("TCP gizmo", True,
                                         hint="Drag the TCP; the joints follow by IK")
        reset = gui.add_button("Reset pose", disabled=True)
        take_saved = gui.add_button("Take the saved version", disabled=True,
                                    hint="Conflict: drop your edit of this pose")
        keep_mine = gui.add_button("Keep my edit", disabled=True,
                                   hint="Conflict: save your edit over the saved version")
        replan = gui.add_button("Re-plan affected routes")
        insist = gui.add_checkbox("I insist (save even in collision)", False)
        save = gui.add_button("Save poses", hint="Shows what would be saved; then confirm")
        to_save = gui.add_markdown("")
        confirm = gui.add_button("Confirm save", color="red", visible=False,
                                 hint="Write the values shown above to the poses file")
        reload = gui.add_button("Reload poses.yaml",
                                hint="Read the file again; your edits of other poses stay")
    return EditPanel(access_note, token_field, unlock, pose, pose_state, joints, gizmo_enabled,
                     reset, take_saved, keep_mine, replan, insist, save, to_save, confirm,
                     reload)


def _joint_box(gui: Any, name: str, lower: float, upper: float) -> Any:
    """A joint's number box: no bounds (never clamped in the page); it shows the values
    the server gives it (:func:`show_joint`: 7 decimals) and lets every typed digit
    through to the server, which rounds (:func:`typed_joint`). A continuous joint's (no
    limits) takes any angle, beyond +-pi too."""
    hint = (f"limits [{lower:.3f}, {upper:.3f}] rad: a value outside them is shown and "
            "refused, never clamped") if np.isfinite(lower) or np.isfinite(upper) else (
        "continuous joint: any angle [rad], beyond +-pi too (a whole turn is the same "
        "placement; a motion goes the short way round)")
    box = gui.add_number(f"{name} [rad]", 0.0, step=JOINT_STEP, disabled=True, hint=hint)
    box.precision = _BOX_DECIMALS  # viser derives 3 decimals from the step
    return box


def typed_joint(value: Any) -> Any:
    """A value typed into a joint box, rounded to :data:`JOINT_DECIMALS` [rad]; anything
    but a number is passed on as it came (the edit refuses it, naming the joint)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) \
            and math.isfinite(value):
        return round(float(value), JOINT_DECIMALS)
    return value


def show_joint(box: Any, value: float) -> None:
    """Show joint value ``value`` [rad] in ``box``, rounded to :data:`JOINT_DECIMALS`;
    unless the box holds what was typed into it and rounded to ``value``, which stays
    as typed (so the server never rewrites a box under the user's fingers)."""
    if typed_joint(box.value) != value:
        box.value = round(value, JOINT_DECIMALS)
