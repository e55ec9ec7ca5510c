"""The routes a review session shows: read from ``safepath plan``'s files, or planned in
the background (a worker process, so the page never freezes), and whether they are
stale (planned with poses other than the saved ones).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import CancelledError, Future
from pathlib import Path
from typing import Any

import numpy as np

from ..cell import Cell, Route
from ..errors import SafepathError
from ..model.trajectory import Trajectory
from .analysis import affected_routes, analyse_routes, load_plans
from .backend import PlanBackend, make_backend
from .options import ViewOptions
from .timeline import Timeline

__all__ = ["Plans"]

log = logging.getLogger(__name__)


class Plans:
    """Loads, plans and shows the routes (see the module docstring).

    Args:
        cell: The cell (its ``poses`` are the saved poses).
        routes: The cell's routes.
        options: Sample period, planner seed and backend.
        timeline: Shows the routes.
        lock: The session's lock (held while the timeline is changed).
        say: Reports a line to every page (``error=True`` for failures).
        changed: Called when the shown plans change (for the stale notice).
    """

    def __init__(self, cell: Cell, routes: Mapping[str, Route], options: ViewOptions,
                 timeline: Timeline, lock: Any, *, say: Callable[..., None],
                 changed: Callable[[], None]) -> None:
        self.cell = cell
        self.routes = routes
        self.options = options
        self.timeline = timeline
        self.poses = {k: q.copy() for k, q in cell.poses.items()}
        self.ready = threading.Event()
        self._lock = lock
        self._say = say
        self._changed = changed
        self._job: Future[dict[str, Trajectory]] | None = None
        self._backend: PlanBackend | None = None
        self._closed = threading.Event()

    @property
    def running(self) -> bool:
        """Whether planning runs."""
        return self._job is not None and not self._job.done()

    def load(self, source: str | Path) -> list[str]:
        """Show the trajectories written by ``safepath plan`` instead of the shown ones.

        Raises:
            TrajectoryError: Unreadable, or made for another robot.
        """
        trajectories = load_plans(self.cell, source)
        self.show(trajectories, replace=True)
        with self._lock:
            self.poses = {k: q.copy() for k, q in self.cell.poses.items()}
        self._changed()
        return list(trajectories)

    def show(self, trajectories: Mapping[str, Trajectory], *,
             poses: Mapping[str, np.ndarray] | None = None, replace: bool = False) -> None:
        """Show ``trajectories`` (added to, or with ``replace`` instead of, the shown ones).

        Raises:
            TrajectoryError: A trajectory made for another robot.
        """
        with self._lock:
            merged = {} if replace else {k: r.trajectory
                                         for k, r in self.timeline.reviews.items()}
        merged.update(trajectories)
        reviews = analyse_routes(self.cell, merged, poses=poses, routes=self.routes,
                                 period=self.options.sample_period)
        if reviews:
            with self._lock:
                self.timeline.set_reviews(reviews)

    def stale(self) -> list[str]:
        """Poses the shown routes were planned with that differ from the saved ones."""
        saved = self.cell.poses
        return [n for n in {**saved, **self.poses} if n not in saved or n not in self.poses
                or not np.array_equal(saved[n], self.poses[n])]

    def replan(self, poses: Mapping[str, np.ndarray], *, everything: bool = False
               ) -> Future[dict[str, Trajectory]]:
        """Re-plan the routes that use a pose that differs from the shown plans' (all
        with ``everything``) with ``poses``, in the background.

        Raises:
            SafepathError: Planning already runs, or no route uses a changed pose.
        """
        with self._lock:
            if self.running:
                raise SafepathError("planning is already running")
            poses = {k: np.array(q) for k, q in poses.items()}
            changed = [n for n, q in poses.items() if n not in self.poses
                       or not np.array_equal(q, self.poses[n])]
            routes = None if everything or not self.timeline.reviews or not changed else \
                affected_routes(self.routes, changed)
            if routes == []:
                raise SafepathError(f"no route uses {', '.join(changed)}: nothing to re-plan")
            if self._backend is None:
                source = self.cell if self.cell.folder is None else self.cell.folder
                self._backend = make_backend(source, kind=self.options.backend,
                                             seed=self.options.seed)
            self._say(f"planning {'every route' if routes is None else ', '.join(routes)}...")
            self.ready.clear()
            try:
                job = self._backend.plan(poses, routes)
            except BaseException:
                self.ready.set()
                raise
            self._job = job
        started = time.perf_counter()
        job.add_done_callback(lambda f: threading.Thread(
            target=self._planned, args=(f, poses, started), daemon=True).start())
        return job

    def close(self) -> None:
        """Stop the planning worker."""
        self._closed.set()
        if self._backend is not None:
            self._backend.close()

    def _planned(self, job: Future[dict[str, Trajectory]], poses: dict[str, np.ndarray],
                 started: float) -> None:
        try:
            result = job.result()
            self.show(result, poses=poses)
            with self._lock:
                self.poses = poses
            self._say(f"planned {', '.join(result)} in {time.perf_counter() - started:.1f} s")
        except CancelledError:
            if not self._closed.is_set():
                self._say("planning cancelled")
        except SafepathError as exc:
            self._say(f"planning failed: {type(exc).__name__}: {exc}", error=True)
        except Exception as exc:  # the page must not die with the worker
            log.debug("planning job failed", exc_info=True)
            self._say(f"planning failed: {type(exc).__name__}: {exc}", error=True)
        finally:
            self.ready.set()
            if not self._closed.is_set():
                self._changed()
