"""The browser review session: play, check and fix a cell's motions (viser).

A :class:`ReviewSession` serves one cell on a local viser server: the robot's
geometry, the cell's objects, the taught poses as TCP frames and, per planned route,
the TCP path coloured by clearance, with a timeline driven by a 30 Hz server thread
that samples the real trajectory timing. Poses can be edited (joint sliders or a TCP
gizmo, checked live), routes re-planned in a worker process (the page never freezes),
and the poses saved back atomically. Every GUI callback is guarded: a failure shows
as one line in the panel, never as a traceback.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import CancelledError, Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import viser

from ..cell import load_cell
from ..collision import CollisionChecker
from ..errors import SafepathError
from ..planning import WorldState, initial_world
from ..trajectory import Trajectory
from ._ports import choose_port
from .analysis import (
    CLEAR_ENOUGH,
    RouteReview,
    StepCheckers,
    affected_routes,
    analyse_routes,
    load_plans,
    routes_of,
)
from .backend import PlanBackend, make_backend
from .editing import PoseEditing
from .editor import PoseEditor
from .options import ViewOptions
from .panel import build_panel
from .scene_nodes import CellNodes, PoseFrames, RobotNodes, configure_lighting
from .timeline import Timeline

__all__ = ["ViewOptions", "ShownState", "ReviewSession"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ShownState:
    """The state the page shows.

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


class ReviewSession(Timeline, PoseEditing):
    """A browser session to review, edit and re-plan one cell.

    Args:
        scene: The scene folder.
        plans: Trajectories written by ``safepath plan`` (folder or file); None plans
            the cell at start-up, in the background.
        options: Host, port, rate, planning.

    Raises:
        SafepathError: Unknown scene, unreadable plan, plan for another robot.
    """

    def __init__(self, scene: str | Path, *, plans: str | Path | None = None,
                 options: ViewOptions | None = None) -> None:
        self.options = options or ViewOptions()
        self.cell = load_cell(scene)
        self.routes = routes_of(self.cell)
        self._given = load_plans(self.cell, plans) if plans is not None else None
        self.editor = PoseEditor(self.cell)
        self._plan_poses = {k: q.copy() for k, q in self.cell.poses.items()}
        self._lock = threading.RLock()
        self._reviews: dict[str, RouteReview] = {}
        self._checkers: dict[str, StepCheckers] = {}
        self._route: str | None = None
        self._t = 0.0
        self._playing = False
        self._speed = 1.0
        self._mode: Literal["review", "edit"] = "review"
        self._pose: str | None = None
        self._shown: ShownState | None = None
        self._shown_checker: CollisionChecker | None = None
        self._job: Future[dict[str, Trajectory]] | None = None
        self._backend: PlanBackend | None = None
        self._plans_ready = threading.Event()
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
        opts, cell = self.options, self.cell
        server.initial_camera.position = (0.46, -0.54, 0.65)
        server.initial_camera.look_at = (-0.02, 0.2, 0.05)
        with self._lock, server.atomic():
            configure_lighting(server)
            self.robot_nodes = RobotNodes(server, cell.robot)
            self.cell_nodes = CellNodes(server, cell.scene)
            self.pose_frames = PoseFrames(server, cell.robot, cell.poses)
            self._gizmo = server.scene.add_transform_controls(
                "/edit/tcp", scale=0.12, depth_test=False, visible=False)
            self._path: Any = None
            self.panel = build_panel(server, cell.robot, title=self._title(),
                                     poses=list(cell.poses), margin=cell.scene.margin,
                                     clear_enough=CLEAR_ENOUGH)
            self._wire()
            self._show_idle()
        if self._given is not None:
            self.set_trajectories(self._given)
            self._plans_ready.set()
        elif opts.plan_on_start:
            self.replan(everything=True)
        self._thread = threading.Thread(target=self._run, name="safepath-view-playback",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop playback, planning and the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._backend is not None:
            self._backend.close()
        if self._server is not None:
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
    def shown(self) -> ShownState | None:
        """The state the page shows."""
        return self._shown

    @property
    def mode(self) -> str:
        """``review`` (routes) or ``edit`` (a pose)."""
        return self._mode

    # -- plans ------------------------------------------------------------------------------
    def load_plans(self, source: str | Path) -> list[str]:
        """Show the trajectories written by ``safepath plan``; returns the route names.

        Raises:
            TrajectoryError: Unreadable, or made for another robot.
        """
        trajectories = load_plans(self.cell, source)
        self.set_trajectories(trajectories, replace=True)
        self._plan_poses = {k: q.copy() for k, q in self.cell.poses.items()}
        return list(trajectories)

    def set_trajectories(self, trajectories: Mapping[str, Trajectory], *,
                         poses: Mapping[str, np.ndarray] | None = None,
                         replace: bool = False) -> None:
        """Show ``trajectories`` (added to, or with ``replace`` instead of, the shown ones).

        Raises:
            TrajectoryError: A trajectory made for another robot.
        """
        with self._lock:
            merged = {} if replace else {k: r.trajectory for k, r in self._reviews.items()}
        merged.update(trajectories)
        reviews = analyse_routes(self.cell, merged, poses=poses, routes=self.routes,
                                 period=self.options.sample_period)
        if not reviews:
            return
        with self._lock:
            self._reviews = reviews
            self._checkers = {k: StepCheckers(self.cell, r.worlds, r.allowed)
                              for k, r in reviews.items()}
            keep = self._route in reviews
            route = self._route if keep and self._route else next(iter(reviews))
            self.panel.route.options = list(reviews)
            self._select(route, restart=not keep)

    def wait_for_plans(self, timeout: float | None = None) -> bool:
        """Wait for start-up planning or a re-plan; whether routes are shown."""
        self._plans_ready.wait(timeout)
        return bool(self._reviews)

    def replan(self, *, everything: bool = False) -> Future[dict[str, Trajectory]]:
        """Re-plan the routes that use edited poses (all with ``everything``), in the
        background; the result is shown when it arrives."""
        with self._lock:
            if self._job is not None and not self._job.done():
                raise SafepathError("planning is already running")
            poses = self.editor.poses()
            planned = {k: r.trajectory for k, r in self._reviews.items()}
            # Poses that differ from those the shown plans were made with.
            changed = [n for n, q in poses.items() if n not in self._plan_poses
                       or not np.array_equal(q, self._plan_poses[n])]
            routes = None if everything or not planned or not changed else \
                affected_routes(self.routes, changed)
            if routes == []:
                raise SafepathError(f"no route uses {', '.join(changed)}: nothing to re-plan")
            if self._backend is None:
                self._backend = make_backend(self.cell.folder, kind=self.options.backend,
                                             seed=self.options.seed)
            what = "every route" if routes is None else ", ".join(routes)
            self._say(f"planning {what}...")
            self.panel.replan.disabled = True
            self._plans_ready.clear()
            try:
                job = self._backend.plan(poses, routes)
            except BaseException:
                self.panel.replan.disabled = False
                self._plans_ready.set()
                raise
            self._job = job
        started = time.perf_counter()
        job.add_done_callback(lambda f: threading.Thread(
            target=self._planned, args=(f, poses, started), daemon=True).start())
        return job

    def _planned(self, job: Future[dict[str, Trajectory]], poses: dict[str, np.ndarray],
                 started: float) -> None:
        try:
            result = job.result()
            self.set_trajectories(result, poses=poses)
            self._plan_poses = poses
            self._say(f"planned {', '.join(result)} in {time.perf_counter() - started:.1f} s")
        except CancelledError:
            if not self._stop.is_set():
                self._say("planning cancelled")
        except SafepathError as exc:
            self._say(f"planning failed: {exc}", error=True)
        except Exception as exc:  # the page must not die with the worker
            log.debug("planning job failed", exc_info=True)
            self._say(f"planning failed: {type(exc).__name__}: {exc}", error=True)
        finally:
            with self._lock:
                if self._server is not None:
                    self.panel.replan.disabled = False
            self._plans_ready.set()

    # -- drawing ----------------------------------------------------------------------------
    def _show(self, q: np.ndarray, world: WorldState, checker: CollisionChecker) -> None:
        """Draw the robot at ``q`` in ``world``; colliding geometry red (holds the lock)."""
        cell = self.cell
        grasp = cell.scene.grasp
        with self.server.atomic():
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
        self._shown = ShownState(np.array(q), valid, pairs, world.held)
        self._shown_checker = checker

    def _show_idle(self) -> None:
        cell = self.cell
        first = next(iter(self.routes.values())).start if self.routes else next(iter(cell.poses))
        self._show(cell.pose(first), initial_world(cell), self.editor.checker(first, False))

    def _title(self) -> str:
        c = self.cell
        return (f"**{c.scene.name}** · {c.robot.name} · {len(c.poses)} poses · "
                f"margin {c.scene.margin * 1000:.0f} mm")

    def _say(self, text: str, *, error: bool = False) -> None:
        """Show a status line (and, for an error, a notification)."""
        self.messages.append(text)
        if error:
            log.warning("%s", text)
        server = self._server
        if server is None:
            return
        self.panel.status.content = f"**error:** {text}" if error else text
        if error:
            for client in server.get_clients().values():
                client.add_notification("safepath", text, color="red", auto_close_seconds=10.0)

    def _guard(self, fn: Callable[..., object]) -> Callable[[Any], None]:
        """A GUI callback that shows failures in the page instead of raising."""
        @functools.wraps(fn)
        def callback(event: Any) -> None:
            if getattr(event, "client", None) is None:
                return  # the server changed the value itself
            try:
                fn(event)
            except SafepathError as exc:
                self._say(str(exc), error=True)
            except Exception as exc:
                log.debug("GUI callback %s failed", fn.__name__, exc_info=True)
                self._say(f"internal error: {type(exc).__name__}: {exc}", error=True)
        return callback
