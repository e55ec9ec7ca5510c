"""Playback of the review session: the shown routes, route choice, time, play / pause /
speed / scrub, and the readouts.

A :class:`Timeline` draws the selected route at the current time on the shared
:class:`~safepath.view.stage.Stage` (every page sees it) while it is ``active``; the
session makes it inactive while its own pose editor uses that stage. It does no
locking: the session calls it under its lock; :meth:`Timeline.run`, the playback
thread, takes that lock for each tick.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..cell import Cell
from ..errors import InputError, SafepathError
from ..files._io import check_names
from ..planning import initial_world
from .analysis import CLEAR_ENOUGH, RouteReview, StepCheckers
from .panel import Panel, clearance_plot_data, speed_plot_data
from .scene_nodes import draw_path
from .stage import Stage

__all__ = ["Timeline"]

log = logging.getLogger(__name__)

#: Readout refresh period [s]; the robot itself moves at the playback rate.
_TEXT_PERIOD = 0.1
#: Period of the ``watch`` call of the playback thread [s].
_WATCH_PERIOD = 1.0


class Timeline:
    """Playback state and drawing (see the module docstring).

    Args:
        cell: The cell.
        server: The viser server (the TCP path is drawn for every page).
        stage: The shared stage.
        panel: The shared panel (route dropdown, time slider, plots, loop).
        idle_pose: Pose shown while no route is planned.
    """

    def __init__(self, cell: Cell, server: Any, stage: Stage, panel: Panel, *,
                 idle_pose: str) -> None:
        self.cell = cell
        self.server = server
        self.stage = stage
        self.panel = panel
        self.idle_pose = idle_pose
        self.reviews: dict[str, RouteReview] = {}
        self.checkers: dict[str, StepCheckers] = {}
        self.route: str | None = None
        self.t = 0.0
        self.playing = False
        self.speed = 1.0
        self.active = True
        self.path: Any = None
        self._idle_checker = cell.checker(held=False, at=idle_pose)

    @property
    def data(self) -> RouteReview | None:
        """What the review shows about the selected route."""
        return self.reviews.get(self.route) if self.route else None

    @property
    def duration(self) -> float:
        """Duration of the selected route [s] (0 when none)."""
        data = self.data
        return data.duration if data else 0.0

    def set_reviews(self, reviews: dict[str, RouteReview]) -> None:
        """Show ``reviews`` instead of the routes shown so far; keep the selected route
        (and its time) when it is still there."""
        self.reviews = reviews
        self.checkers = {k: StepCheckers(self.cell, r.worlds, r.allowed)
                         for k, r in reviews.items()}
        keep = self.route in reviews
        route = self.route if keep and self.route else next(iter(reviews))
        self.panel.route.options = list(reviews)
        self.select(route, restart=not keep)

    def select(self, name: str, *, restart: bool) -> None:
        """Make ``name`` the selected route: path, plots, time.

        Raises:
            InputError: No such planned route (lists them).
        """
        check_names([name], self.reviews, path=None, key="route", what="route",
                    error=InputError)
        self.route, data = name, self.reviews[name]
        panel = self.panel
        panel.route.value = name
        panel.time.max = max(round(data.duration, 2), 0.01)
        panel.clearance_plot.data = clearance_plot_data(data.times, data.clearance,
                                                        self.cell.scene.margin, CLEAR_ENOUGH)
        panel.speed_plot.data = speed_plot_data(data.times, data.velocity_ratio)
        self.path = draw_path(self.server, "/path", data.tcp, data.level,
                              visible=bool(panel.show_path.value))
        self.t = 0.0 if restart else min(self.t, data.duration)
        self.draw()

    def play(self) -> None:
        """Play from the current time (from the start at the end).

        Raises:
            SafepathError: No route is planned yet.
        """
        if self.route is None:
            raise SafepathError("nothing to play yet: no route is planned")
        if self.t >= self.duration - 1e-9:
            self.t = 0.0
        self.playing = True

    def seek(self, t: float) -> None:
        """Show the selected route at time ``t`` [s] (clamped to its duration)."""
        if self.route is None:
            raise SafepathError("nothing to show yet: no route is planned")
        self.t = float(np.clip(t, 0.0, self.duration))
        self.draw()

    def set_speed(self, speed: float) -> None:
        """Playback speed, 1 = real time.

        Raises:
            InputError: Not in (0, 10].
        """
        if not (np.isfinite(speed) and 0 < speed <= 10):
            raise InputError(f"speed must be in (0, 10], got {speed}", key="speed")
        self.speed = float(speed)

    def advance(self, dt: float) -> None:
        """Move the time on by ``dt`` [s] of wall time (at the playback speed)."""
        if not self.playing or self.route is None:
            return
        duration = self.duration
        t = self.t + dt * self.speed
        if t >= duration:
            if self.panel.loop.value and duration > 0:
                t = t % duration
            else:
                t, self.playing = duration, False
        self.t = t
        self.draw()

    def draw(self) -> None:
        """Draw the selected route at the current time (the idle pose when none), if
        the timeline is active."""
        if not self.active:
            return
        data = self.data
        if data is None:
            self.stage.show(self.cell.pose(self.idle_pose), initial_world(self.cell),
                            self._idle_checker)
            return
        traj = data.trajectory
        t = traj.t[0] + self.t
        q = traj.sample([t])[0][0]
        step = data.step_index_at(t)
        self.stage.show(q, data.worlds[step], self.checkers[data.name](step))
        self.panel.time.value = float(round(self.t, 2))

    def set_path_visible(self, visible: bool) -> None:
        """Show or hide the TCP path."""
        if self.path is not None:
            self.path.visible = visible

    def readouts(self, editing: str | None) -> tuple[str, str]:
        """The time readout and the safety readout of the shared stage; ``editing``
        names the pose shown instead of the route, if any."""
        if editing is not None:
            head = f"editing pose **{editing}**"
        elif self.route is None:
            head = "no route planned yet"
        else:
            data = self.reviews[self.route]
            step = data.trajectory.steps[data.step_index_at(data.trajectory.t[0] + self.t)]
            state = "playing" if self.playing else "paused"
            head = (f"**{self.route}** · t = {self.t:.2f} / {data.duration:.2f} s · "
                    f"{state}\n\nstep `{step}`")
        shown, checker = self.stage.shown, self.stage.checker
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
        data_sel = self.data
        if data_sel is not None and editing is None:
            i = int(np.argmin(data_sel.clearance))
            pair = data_sel.closest[i]
            state += (f"\n\nroute minimum {data_sel.clearance[i] * 1000:.1f} mm at "
                      f"t = {data_sel.times[i]:.2f} s ({' / '.join(pair) if pair else '-'})")
        return head, state

    def run(self, stop: threading.Event, lock: Any, *, rate: float,
            editing: Callable[[], str | None], watch: Callable[[], None]) -> None:
        """The playback thread: advance at ``rate`` [Hz], refresh the readouts (10 Hz),
        call ``watch`` once a second, each under ``lock``, until ``stop`` is set."""
        period = 1.0 / rate
        last = time.monotonic()
        next_text = next_watch = 0.0
        shown_text: tuple[str, str] = ("", "")
        while not stop.wait(period):
            now = time.monotonic()
            dt, last = now - last, now
            try:
                with lock:
                    self.advance(dt)
                    if now >= next_text:
                        next_text = now + _TEXT_PERIOD
                        text = self.readouts(editing())
                        if text != shown_text:
                            self.panel.readout.content, self.panel.state.content = text
                            shown_text = text
                    if now >= next_watch:
                        next_watch = now + _WATCH_PERIOD
                        watch()
            except Exception:  # keep playing; say it in the log
                log.debug("playback tick failed", exc_info=True)
