"""Playback of the review session: route choice, time, play / pause / speed / scrub,
the 30 Hz playback thread, the readouts, and the wiring of the panel's callbacks.

A mixin of :class:`~safepath.view.session.ReviewSession`, kept apart so that each
file stays about one thing; it uses the session's state under the session's lock.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pinocchio as pin

from ..errors import InputError, SafepathError
from .analysis import CLEAR_ENOUGH, RouteReview, StepCheckers
from .panel import NO_POSE, NO_ROUTE, clearance_plot_data, speed_plot_data
from .scene_nodes import draw_path

if TYPE_CHECKING:
    from .session import ReviewSession

__all__ = ["Timeline"]

log = logging.getLogger(__name__)

#: Readout refresh period [s]; the robot itself moves at the playback rate.
_TEXT_PERIOD = 0.1


class Timeline:
    """Playback state and controls (see the module docstring)."""

    _lock: threading.RLock
    _reviews: dict[str, RouteReview]
    _checkers: dict[str, StepCheckers]
    _route: str | None
    _t: float
    _playing: bool
    _speed: float
    _stop: threading.Event
    panel: Any
    _path: Any

    # -- public controls --------------------------------------------------------------------
    @property
    def route_names(self) -> list[str]:
        """Routes that can be played."""
        return list(self._reviews)

    @property
    def route(self) -> str | None:
        """The selected route."""
        return self._route

    @property
    def review_data(self) -> RouteReview | None:
        """What the review shows about the selected route."""
        return self._reviews.get(self._route) if self._route else None

    @property
    def time(self) -> float:
        """Time within the selected route [s]."""
        return self._t

    @property
    def duration(self) -> float:
        """Duration of the selected route [s] (0 when none)."""
        data = self.review_data
        return data.duration if data else 0.0

    @property
    def playing(self) -> bool:
        """Whether playback runs."""
        return self._playing

    @property
    def speed(self) -> float:
        """Playback speed (1 = real time)."""
        return self._speed

    def select_route(self, name: str) -> None:
        """Show route ``name`` from its start.

        Raises:
            InputError: No such planned route (lists them).
        """
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            if name not in self._reviews:
                known = ", ".join(self._reviews) or "none planned yet"
                raise InputError(f"unknown route '{name}' (routes: {known})", key="route")
            if self._mode == "edit":
                self.review()
            self._select(name, restart=name != self._route)

    def _select(self, name: str, *, restart: bool) -> None:
        """Make ``name`` the selected route: path, plots, time (holds the lock); the
        robot shows it unless a pose is being edited."""
        self = cast("ReviewSession", self)  # the mixin's host
        self._route, data = name, self._reviews[name]
        panel = self.panel
        panel.route.value = name
        panel.time.max = max(round(data.duration, 2), 0.01)
        panel.clearance_plot.data = clearance_plot_data(data.times, data.clearance,
                                                        self.cell.scene.margin, CLEAR_ENOUGH)
        panel.speed_plot.data = speed_plot_data(data.times, data.velocity_ratio)
        self._path = draw_path(self.server, "/path", data.tcp, data.level,
                               visible=bool(panel.show_path.value))
        self._t = 0.0 if restart else min(self._t, data.duration)
        if self._mode == "review":
            self._show_time()

    def play(self) -> None:
        """Play the selected route from the current time (from the start at the end).

        Raises:
            SafepathError: No route is planned yet.
        """
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            if self._route is None:
                raise SafepathError("nothing to play yet: no route is planned")
            if self._mode == "edit":
                self.review()
            if self._t >= self.duration - 1e-9:
                self._t = 0.0
            self._playing = True

    def pause(self) -> None:
        """Stop playback where it is."""
        with self._lock:
            self._playing = False

    def seek(self, t: float) -> None:
        """Show the selected route at time ``t`` [s] (clamped to its duration)."""
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            if self._route is None:
                raise SafepathError("nothing to show yet: no route is planned")
            if self._mode == "edit":
                self.review()
            self._t = float(np.clip(t, 0.0, self.duration))
            self._show_time()

    def set_speed(self, speed: float) -> None:
        """Playback speed, 1 = real time.

        Raises:
            InputError: Not in (0, 10].
        """
        if not (np.isfinite(speed) and 0 < speed <= 10):
            raise InputError(f"speed must be in (0, 10], got {speed}", key="speed")
        with self._lock:
            self._speed = float(speed)

    # -- drawing ----------------------------------------------------------------------------
    def _show_time(self) -> None:
        """Draw the selected route at the current time (holds the lock)."""
        self = cast("ReviewSession", self)  # the mixin's host
        data = self._reviews[self._route or ""]
        traj = data.trajectory
        t = traj.t[0] + self._t
        q = traj.sample([t])[0][0]
        step = data.step_index_at(t)
        self._show(q, data.worlds[step], self._checkers[data.name](step))
        self.panel.time.value = float(round(self._t, 2))

    def _readouts(self) -> tuple[str, str]:
        """The time readout and the safety readout (holds the lock)."""
        self = cast("ReviewSession", self)  # the mixin's host
        shown, checker = self._shown, self._shown_checker
        if self._mode == "edit":
            head = f"editing pose **{self._pose}**"
        elif self._route is None:
            head = "no route planned yet"
        else:
            data = self._reviews[self._route]
            step = data.trajectory.steps[data.step_index_at(data.trajectory.t[0] + self._t)]
            state = "playing" if self._playing else "paused"
            head = (f"**{self._route}** · t = {self._t:.2f} / {data.duration:.2f} s · "
                    f"{state}\n\nstep `{step}`")
        if shown is None or checker is None:
            return head, ""
        if not shown.valid:
            pairs = ", ".join(f"{a} / {b}" for a, b in shown.collisions)
            limit = self.cell.robot.limit_violation(shown.q)
            state = f"**COLLISION**: {pairs}" if pairs else f"**outside limits**: {limit}"
        else:
            clearance, pair = checker.clearance(shown.q)
            where = " / ".join(pair) if pair else "-"
            state = f"valid · clearance **{clearance * 1000:.1f} mm** ({where})"
        data_sel = self.review_data
        if data_sel is not None and self._mode == "review":
            i = int(np.argmin(data_sel.clearance))
            pair = data_sel.closest[i]
            state += (f"\n\nroute minimum {data_sel.clearance[i] * 1000:.1f} mm at "
                      f"t = {data_sel.times[i]:.2f} s ({' / '.join(pair) if pair else '-'})")
        return head, state

    # -- the playback thread ----------------------------------------------------------------
    def _run(self) -> None:
        self = cast("ReviewSession", self)  # the mixin's host
        period = 1.0 / self.options.rate
        last = time.monotonic()
        next_text = 0.0
        shown_text: tuple[str, str] = ("", "")
        while not self._stop.wait(period):
            now = time.monotonic()
            dt, last = now - last, now
            try:
                with self._lock:
                    if self._playing and self._route is not None:
                        self._advance(dt)
                    if now >= next_text:
                        next_text = now + _TEXT_PERIOD
                        text = self._readouts()
                        if text != shown_text:
                            self.panel.readout.content, self.panel.state.content = text
                            shown_text = text
            except Exception:  # keep playing; say it once in the log
                log.debug("playback tick failed", exc_info=True)

    def _advance(self, dt: float) -> None:
        self = cast("ReviewSession", self)  # the mixin's host
        duration = self.duration
        t = self._t + dt * self._speed
        if t >= duration:
            if self.panel.loop.value and duration > 0:
                t = t % duration
            else:
                t, self._playing = duration, False
        self._t = t
        self._show_time()

    # -- wiring -----------------------------------------------------------------------------
    def _wire(self) -> None:
        """Connect the panel's callbacks, each guarded (errors show in the page)."""
        self = cast("ReviewSession", self)  # the mixin's host
        p, g = self.panel, self._guard

        def on(handle: Any, fn: Callable[[Any], object]) -> None:
            handle.on_update(g(fn))

        on(p.route, lambda e: self.select_route(e.target.value)
           if e.target.value != NO_ROUTE else None)
        on(p.time, lambda e: self.seek(float(e.target.value)))
        p.play.on_click(g(lambda e: self.play()))
        p.pause.on_click(g(lambda e: self.pause()))
        on(p.speed, lambda e: self.set_speed(float(e.target.value)))
        on(p.pose, lambda e: self.review() if e.target.value == NO_POSE
           else self.edit_pose(e.target.value))
        for j, slider in enumerate(p.joints):
            on(slider, functools.partial(self._joint_moved, j))
        on(p.gizmo_enabled, lambda e: setattr(
            self._gizmo, "visible", bool(e.target.value) and self._mode == "edit"))
        p.reset.on_click(g(lambda e: self.reset_pose()))
        p.replan.on_click(g(lambda e: self.replan()))
        p.save.on_click(g(lambda e: self.save_poses(insist=bool(p.insist.value))))
        on(p.visual_style, lambda e: self._locked(
            self.robot_nodes.set_style, "visual" if e.target.value else "collision"))
        on(p.show_poses, lambda e: self._locked(self.pose_frames.set_visible,
                                                bool(e.target.value)))
        on(p.show_path, lambda e: self._locked(self._set_path_visible, bool(e.target.value)))
        self._gizmo.on_update(g(lambda e: self._drag_tcp(e.target.wxyz, e.target.position)))

    def _locked(self, fn: Callable[..., object], *args: Any) -> None:
        with self._lock:
            fn(*args)

    def _set_path_visible(self, visible: bool) -> None:
        if self._path is not None:
            self._path.visible = visible

    def _joint_moved(self, j: int, event: Any) -> None:
        self._set_joint(j, float(event.target.value))

    def _set_joint(self, j: int, value: float) -> None:
        self = cast("ReviewSession", self)  # the mixin's host
        with self._lock:
            q = self.editor.q(self._editing())
            q[j] = value
            self.set_joints(q)

    def _drag_tcp(self, wxyz: np.ndarray, position: np.ndarray) -> None:
        self = cast("ReviewSession", self)  # the mixin's host
        w, x, y, z = (float(v) for v in wxyz)
        rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
        self.move_tcp(pin.SE3(rotation, np.asarray(position, dtype=float)))
