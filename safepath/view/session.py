"""The browser review session: play, check and fix a cell's motions (viser).

A :class:`ReviewSession` serves one cell on a viser server: the robot's geometry, the
cell's objects, the taught poses as TCP frames and, per planned route, the TCP path
coloured by clearance, with a timeline driven by a 30 Hz server thread that samples the
real trajectory timing. Every page watches the same playback; each page edits on its
own (joint sliders or a TCP gizmo, checked live), re-plans in a worker process (the
page never freezes), and saves back atomically. Every GUI callback is guarded: a
failure shows as one line in the page, never as a traceback.

Who may edit: see :mod:`safepath.view.access` (a session bound beyond loopback is
read-only until a page is unlocked with the token). No edit is lost: see
:mod:`safepath.view.sync` and :mod:`safepath.view.store` (saves over the version
loaded only, conflicts named pose by pose, every save logged in ``poses.log``).

Parts, each with explicit inputs, one lock for all: ``stage`` (what every page sees),
``timeline`` (playback), ``plans`` (routes), ``poses`` (saved poses), ``pages`` (a
:class:`~safepath.view.clients.ClientEditor` per page), ``editor`` (edits from Python).
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import viser

from ..cell import Cell, load_cell
from ..errors import SafepathError
from ..model.trajectory import Trajectory
from ._ports import choose_port, is_loopback
from .access import Access, new_token
from .analysis import CLEAR_ENOUGH, RouteReview, load_plans, routes_of
from .clients import ClientEditor, guard
from .editor import PoseEditor
from .edits import PoseEdits, PoseStatus
from .options import ViewOptions
from .pages import Pages
from .panel import NO_ROUTE, Panel, build_panel
from .plans import Plans
from .scene_nodes import CellNodes, PoseFrames, RobotNodes, cell_framing, configure_lighting
from .stage import ShownState, Stage
from .store import PosesStore
from .sync import SharedPoses
from .timeline import Timeline

__all__ = ["ViewOptions", "ShownState", "ReviewSession"]

log = logging.getLogger(__name__)

#: Who saves through the Python API (the save log's ``client``).
PYTHON_CLIENT = "python"


class ReviewSession:
    """A browser session to review, edit and re-plan one cell.

    Args:
        scene: The scene folder, or a :class:`~safepath.cell._cell.Cell` built in Python
            (the session works on a copy: the cell's poses change only through a save).
            Edits of such a cell are saved to its ``poses_path`` (created by the first
            save if it does not exist); without one, saving is refused with a
            ``ConfigError``. Planning sends the cell to a worker process, so its robot
            must come from :func:`~safepath.load_robot`.
        plans: Trajectories written by ``safepath plan`` (folder or file); None plans
            the cell at start-up, in the background.
        options: Host, port, access, rate, planning.

    Raises:
        SafepathError: Unknown scene, unreadable plan, plan for another robot.
        ConfigError: A cell built in Python whose existing ``poses_path`` holds other
            poses than the cell's.
    """

    def __init__(self, scene: str | Path | Cell, *, plans: str | Path | None = None,
                 options: ViewOptions | None = None) -> None:
        self.options = opts = options or ViewOptions()
        if isinstance(scene, Cell):
            self.cell = replace(scene, poses=dict(scene.poses))  # its own checkers
        else:
            self.cell = load_cell(scene)
        self.routes = routes_of(self.cell)
        self._given = load_plans(self.cell, plans) if plans is not None else None
        self.poses = SharedPoses(self.cell, PosesStore(self.cell))
        self.edits = self.poses.new_editor()
        needs_token = not opts.allow_anonymous_edit and (
            opts.token is not None or not is_loopback(opts.host))
        #: The token that unlocks editing (None: editing is open to every page).
        self.token = (opts.token or new_token()) if needs_token else None
        self.access = Access(self.token, given=opts.token is not None,
                             attempts=opts.token_attempts,
                             host_attempts=opts.token_host_attempts)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._server: viser.ViserServer | None = None
        self._port = 0
        self.messages: list[str] = []
        self.startup_time: float | None = None

    # -- lifecycle --------------------------------------------------------------------------
    def start(self) -> ReviewSession:
        """Start the server, draw the cell, start playback (and planning if needed).

        Raises:
            InputError: The host cannot be listened on, or ``strict_port`` and the
                port is taken.
        """
        if self._server is not None:
            raise SafepathError("the review session is already running")
        t0 = time.perf_counter()
        opts = self.options
        port = choose_port(opts.host, opts.port, strict=opts.strict_port)
        server = viser.ViserServer(host=opts.host, port=port, verbose=False,
                                   label=f"safepath · {self.cell.scene.name}")
        self._server, self._port = server, server.get_port()
        try:
            self._build(server)
        except BaseException:
            self.stop()
            raise
        self.startup_time = time.perf_counter() - t0
        log.info("review session of %s at %s (%.2f s)", self.cell.scene.name, self.url,
                 self.startup_time)
        return self

    def _build(self, server: viser.ViserServer) -> None:
        cell = self.cell
        eye, centre = cell_framing(cell)  # the whole cell, robot and objects
        server.initial_camera.position = eye
        server.initial_camera.look_at = centre
        idle = next(iter(self.routes.values())).start if self.routes else next(iter(cell.poses))
        with self._lock, server.atomic():
            configure_lighting(server)
            self.stage = Stage(server, cell)
            self.pose_frames = PoseFrames(server, cell.robot, cell.poses)
            self.panel: Panel = build_panel(server, cell.robot, title=self._title(),
                                            poses=list(cell.poses), margin=cell.scene.margin,
                                            clear_enough=CLEAR_ENOUGH)
            self.timeline = Timeline(cell, server, self.stage, self.panel, idle_pose=idle)
            self.plans = Plans(cell, self.routes, self.options, self.timeline, self._lock,
                               say=self._say, changed=lambda: self.pages.plans_changed())
            self.editor = PoseEditor(cell, self.edits, stage=lambda: self.stage,
                                     frames=self.pose_frames)
            self.pages = Pages(cell, self.poses, self.access, self._lock,
                               frames=self.pose_frames, local=self.editor, plans=self.plans,
                               notice=self.panel.notice, say=self._say,
                               replan=lambda poses: self.replan(poses=poses),
                               replan_on_save=self.options.replan_on_save)
            self._wire()
            self.timeline.draw()
        server.on_client_connect(lambda client: self.pages.connected(server, client))
        server.on_client_disconnect(self.pages.disconnected)
        if self._given is not None:
            self.plans.show(self._given)
            self.plans.ready.set()
        elif self.options.plan_on_start:
            self.replan(everything=True)
        self._thread = threading.Thread(
            target=self.timeline.run, name="safepath-view-playback", daemon=True,
            args=(self._stop, self._lock),
            kwargs={"rate": self.options.rate, "editing": lambda: self.editor.pose,
                    "watch": self._watch})
        self._thread.start()

    def stop(self) -> None:
        """Stop playback, planning and the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._server is not None:
            self.pages.close()
            self.plans.close()
            self._server.stop()
            self._server = None

    def __enter__(self) -> ReviewSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def server(self) -> viser.ViserServer:
        """The viser server (raises before :meth:`start`)."""
        if self._server is None:
            raise SafepathError("the review session is not running")
        return self._server

    @property
    def port(self) -> int:
        """The port actually listened on."""
        return self._port

    @property
    def port_changed(self) -> bool:
        """Whether the requested port was taken and another one is used."""
        return self.options.port != 0 and self._port != self.options.port

    @property
    def url(self) -> str:
        """The page's address."""
        host = self.options.host
        host = "localhost" if host in ("0.0.0.0", "::") else host
        return f"http://[{host}]:{self._port}" if ":" in host else f"http://{host}:{self._port}"

    @property
    def robot_nodes(self) -> RobotNodes:
        """The shared robot's nodes."""
        return self.stage.robot_nodes

    @property
    def cell_nodes(self) -> CellNodes:
        """The shared cell objects' nodes."""
        return self.stage.cell_nodes

    @property
    def shown(self) -> ShownState | None:
        """The state every page shows (the playback, or the pose edited from Python)."""
        return self.stage.shown

    @property
    def mode(self) -> str:
        """``review`` (routes) or ``edit`` (a pose, edited from Python)."""
        return "edit" if self.editor.editing else "review"

    # -- playback ---------------------------------------------------------------------------
    @property
    def route_names(self) -> list[str]:
        """Routes that can be played."""
        return list(self.timeline.reviews)

    @property
    def route(self) -> str | None:
        """The selected route."""
        return self.timeline.route

    @property
    def review_data(self) -> RouteReview | None:
        """What the review shows about the selected route."""
        return self.timeline.data

    @property
    def time(self) -> float:
        """Time within the selected route [s]."""
        return self.timeline.t

    @property
    def duration(self) -> float:
        """Duration of the selected route [s] (0 when none)."""
        return self.timeline.duration

    @property
    def playing(self) -> bool:
        """Whether playback runs."""
        return self.timeline.playing

    @property
    def speed(self) -> float:
        """Playback speed (1 = real time)."""
        return self.timeline.speed

    @contextlib.contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the session's lock for the block: no page's callback, playback tick or
        plan result changes the session meanwhile, so that edits made from Python
        through several calls (a page's, or the session's own methods: the lock is
        re-entrant) land as one, as a page's callbacks do (they run under it)."""
        with self._lock:
            yield

    def select_route(self, name: str) -> None:
        """Show route ``name`` from its start (ends a pose edit from Python).

        Raises:
            InputError: No such planned route (lists them).
        """
        with self._lock:
            self._end_edit()
            self.timeline.select(name, restart=name != self.timeline.route)

    def play(self) -> None:
        """Play the selected route from the current time (from the start at the end).

        Raises:
            SafepathError: No route is planned yet.
        """
        with self._lock:
            self._end_edit()
            self.timeline.play()

    def pause(self) -> None:
        """Stop playback where it is."""
        with self._lock:
            self.timeline.playing = False

    def seek(self, t: float) -> None:
        """Show the selected route at time ``t`` [s] (clamped to its duration)."""
        with self._lock:
            self._end_edit()
            self.timeline.seek(t)

    def set_speed(self, speed: float) -> None:
        """Playback speed, 1 = real time.

        Raises:
            InputError: Not in (0, 10].
        """
        with self._lock:
            self.timeline.set_speed(speed)

    # -- pose editing from Python (trusted; shown to every page) ----------------------------
    def edit_pose(self, name: str) -> PoseStatus:
        """Show pose ``name`` (as edited) for editing; playback pauses.

        Raises:
            PoseError: Unknown pose.
        """
        with self._lock:
            self.edits.status(name)  # an unknown pose changes nothing
            self.timeline.playing = False
            self.timeline.active = False
            return self.editor.edit_pose(name)

    def set_joints(self, q: np.ndarray) -> PoseStatus:
        """Edit the selected pose to ``q`` [rad] and check it live."""
        with self._lock:
            return self.editor.set_joints(q)

    def move_tcp(self, T_world_tcp: pin.SE3) -> PoseStatus:
        """Edit the selected pose so that its TCP is at ``T_world_tcp`` (IK).

        Raises:
            IKError: No solution near the pose (it is left as it was).
        """
        with self._lock:
            return self.editor.move_tcp(T_world_tcp)

    def reset_pose(self) -> PoseStatus:
        """Drop the edit of the selected pose."""
        with self._lock:
            return self.editor.reset_pose()

    def save_poses(self, *, insist: bool = False) -> Path:
        """Save the edits made from Python (see :meth:`save_edits`)."""
        return self.save_edits(self.edits, PYTHON_CLIENT, insist)

    def review(self) -> None:
        """Leave pose editing; show the selected route."""
        with self._lock:
            self._end_edit()

    def _end_edit(self) -> None:
        if self.editor.editing:
            self.editor.leave()
            self.timeline.active = True
            self.timeline.draw()

    # -- saved poses ------------------------------------------------------------------------
    def save_edits(self, edits: PoseEdits, client: str, insist: bool = False) -> Path:
        """Save one editor's edits to ``poses.yaml`` (atomically, the previous file kept
        as ``poses.yaml~``, a line added to ``poses.log``); every page then shows the
        new poses, and the routes are re-planned (``replan_on_save``) or marked stale.

        Raises:
            SafepathError: Nothing is edited.
            PosesChanged: The file changed since it was loaded, or another save changed a
                pose edited here (names the poses; nothing is written).
            CollisionError: An edited pose collides and ``insist`` is false.
        """
        return self.pages.save(edits, client, insist)

    def reload_poses(self, client: str = PYTHON_CLIENT) -> None:
        """Read ``poses.yaml`` again (after a change outside the session): every page shows
        it; edits of poses changed there become conflicts, the others are kept.

        Raises:
            PoseError: The file is malformed (nothing changes).
        """
        self.pages.reload(client)

    @property
    def clients(self) -> dict[int, ClientEditor]:
        """The connected pages' editors, by viser client id."""
        return self.pages.clients

    # -- plans ------------------------------------------------------------------------------
    def wait_for_plans(self, timeout: float | None = None) -> bool:
        """Wait for start-up planning or a re-plan; whether routes are shown."""
        self.plans.ready.wait(timeout)
        return bool(self.timeline.reviews)

    def replan(self, *, everything: bool = False,
               poses: Mapping[str, np.ndarray] | None = None
               ) -> Future[dict[str, Trajectory]]:
        """Re-plan the routes that use changed poses (all with ``everything``) in the
        background, with ``poses`` (default: the saved poses with the edits made from
        Python); every page shows the result when it arrives.

        Raises:
            SafepathError: Planning already runs, or no route uses a changed pose.
        """
        with self._lock:
            return self.plans.replan(self.edits.poses() if poses is None else poses,
                                     everything=everything)

    # -- wiring -----------------------------------------------------------------------------
    def _wire(self) -> None:
        """Connect the shared panel's callbacks, each guarded (errors show in the page)."""
        p, timeline = self.panel, self.timeline

        def on(handle: Any, fn: Callable[[Any], object]) -> None:
            handle.on_update(self.guarded(fn))

        on(p.route, lambda ev: self.select_route(ev.target.value)
           if ev.target.value != NO_ROUTE else None)
        on(p.time, lambda ev: self.seek(float(ev.target.value)))
        p.play.on_click(self.guarded(lambda ev: self.play()))
        p.pause.on_click(self.guarded(lambda ev: self.pause()))
        on(p.speed, lambda ev: self.set_speed(float(ev.target.value)))
        on(p.visual_style, lambda ev: self._locked(
            self.stage.robot_nodes.set_style, "visual" if ev.target.value else "collision"))
        on(p.show_poses, lambda ev: self._locked(self.pose_frames.set_visible,
                                                 bool(ev.target.value)))
        on(p.show_path, lambda ev: self._locked(timeline.set_path_visible,
                                                bool(ev.target.value)))

    def _watch(self) -> None:
        """Once a second: has ``poses.yaml`` changed behind the session? (holds the lock)"""
        if self.poses.watch():
            self.pages.update_notice()

    def _locked(self, fn: Callable[..., object], *args: Any) -> None:
        with self._lock:
            fn(*args)

    def _title(self) -> str:
        c = self.cell
        return (f"**{c.scene.name}** · {c.robot.name} · {len(c.poses)} poses · "
                f"margin {c.scene.margin * 1000:.0f} mm")

    def _say(self, text: str, *, error: bool = False, notify: bool = False) -> None:
        """Show a status line to every page (and, for an error or with ``notify``, a
        notification)."""
        self.messages.append(text)
        if error:
            log.warning("%s", text)
        server = self._server
        if server is None:
            return
        self.panel.status.content = f"**error:** {text}" if error else text
        if error or notify:
            for client in server.get_clients().values():
                client.add_notification("safepath", text, color="red" if error else "blue",
                                        auto_close_seconds=10.0)

    def guarded(self, fn: Callable[..., object]) -> Callable[[Any], None]:
        """``fn`` as a GUI callback (it takes viser's event) for a widget on the
        session's server that shows a failure instead of raising: a
        :class:`~safepath.SafepathError`'s message, or any other exception's type and
        message, goes to every page's status line, a notification and
        :attr:`messages`. Events the server made itself (no client) are ignored."""
        return guard(fn, lambda text: self._say(text, error=True))
