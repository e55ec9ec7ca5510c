"""The shared state of a runtime planner: its request queue, pose updates, result cache,
deadlines and counters.

It never refers to the :class:`~safepath.runtime.RuntimePlanner` itself, so that the
planner can be garbage-collected while the worker threads run (they then finish the
requests already queued and stop).

Pose updates are numbered in the order they were asked for; every request remembers
how many came before it, and plans with exactly those applied (the successful ones),
whichever worker takes it and whenever.

Results are cached here, in the caller's process, as the pickled bytes the worker sent,
keyed by poses version, seed and world: a worker that is stopped (a cancelled or
timed-out request) takes no cached result with it, and a request the cache holds is
answered at once, without a worker.
"""

from __future__ import annotations

import atexit
import itertools
import multiprocessing
import multiprocessing.util  # noqa: F401 - its exit hook must be registered before ours
import pickle
import queue
import threading
import weakref
from collections import OrderedDict
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..cell import Cell
from ..planning import PlanOptions
from ._job import Deadlines, Job
from ._launcher import Launcher
from ._slot import KEEP_POSES, Slot
from ._transport import WorkerError

__all__ = ["Core", "RuntimeStats", "CLOSE_JOIN_TIMEOUT"]

#: Time close() waits for each worker thread [s] (a worker is terminated well before).
CLOSE_JOIN_TIMEOUT = 10.0
#: Planned results kept (a route, or the cell's routes together, per poses version,
#: seed and world).
CACHE_SIZE = 64


@dataclass(frozen=True)
class RuntimeStats:
    """What a :class:`RuntimePlanner` has done so far (for diagnostics).

    Attributes:
        pids: Process id of each worker, None where none runs (starting, or failed).
        busy: Workers that are planning now.
        queued: Requests waiting for a worker.
        started: Worker processes started, restarts included.
        sent: Requests handed to a worker.
        completed: Answers (results or errors) received from a worker.
        skipped: Requests cancelled or timed out before they reached a worker (never
            computed).
        killed: Workers stopped because their request was cancelled or timed out.
        crashed: Workers that died on their own.
        cached: Requests answered from the result cache (no worker involved).
        timed_out: Requests that ended with ``PlannerTimeout``.
        spares: Process ids of the loaded spare workers, ready to replace a stopped one.
    """

    pids: tuple[int | None, ...]
    busy: int
    queued: int
    started: int
    sent: int
    completed: int
    skipped: int
    killed: int
    crashed: int
    cached: int = 0
    timed_out: int = 0
    spares: tuple[int, ...] = ()


class Core:
    """State shared by a planner and its worker threads.

    Args:
        scene: The scene folder, or a cell.
        options: Planning options.
        workers: Number of worker processes.
        start_method: Multiprocessing start method (``spawn`` or ``forkserver``).
        spares: Loaded spare workers kept ready.
    """

    def __init__(self, scene: Path | Cell, options: PlanOptions, workers: int,
                 start_method: str, spares: int = 1) -> None:
        self.cond = threading.Condition()
        self.closing = False
        self._released = False
        self._jobs: queue.SimpleQueue[Job | None] = queue.SimpleQueue()
        self._ids = itertools.count(1)
        self._counts = dict.fromkeys(("started", "sent", "completed", "skipped", "killed",
                                      "crashed", "cached", "timed_out"), 0)
        self._outstanding: dict[int, Job] = {}
        # Pose updates: update k (1-based) holds validated poses, or None (no effect).
        self._seq = 0
        self._floor = 0  # every update <= floor is resolved and folded into _floor_state
        self._floor_state: tuple[int, dict[str, np.ndarray]] = (0, {})
        self._resolved: dict[int, dict[str, np.ndarray] | None] = {}
        self.options = options
        #: The cell's pose names and robot joints, once a worker has loaded it.
        self._cell: dict[str, Any] = {}
        self._cache: OrderedDict[tuple[Any, ...], bytes] = OrderedDict()
        self._deadlines = Deadlines()
        self.context = multiprocessing.get_context(start_method)
        self.launcher = Launcher(self.context, scene, options,  # type: ignore[arg-type]
                                 spares=spares, count=self.count)
        self._running = workers
        self.slots = [Slot(self, i) for i in range(workers)]
        for slot in self.slots:
            slot.thread.start()
        _LIVE.add(self)

    def learn(self, cell: dict[str, Any]) -> None:
        """What a loaded worker says of its cell (pose names, robot joints)."""
        if cell:
            with self.cond:
                self._cell = dict(cell)

    def precheck(self, poses: dict[str, Any]) -> None:
        """Check a pose update as far as no worker is needed (known names; joint count,
        finite, inside the limits), once a worker has told the cell's joints.

        Raises:
            PoseError: Naming the pose and why.
        """
        from ..errors import PoseError
        from ..files._io import check_names
        from ..model.robot import joint_vector

        with self.cond:
            cell = self._cell
        if "poses" not in cell or "joints" not in cell:
            return
        names, lower, upper = cell["joints"]
        for name, q in poses.items():
            check_names([name], cell["poses"], path=None, key=str(name), what="pose",
                        error=PoseError)
            joint_vector(q, names, np.asarray(lower), np.asarray(upper), name=str(name))

    # -- requests --------------------------------------------------------------------------
    def submit(self, kind: str, payload: dict[str, Any], timeout: float | None,
               describe: str) -> Future[Any]:
        """Queue a request; its future (failed with WorkerError if the planner is closed)."""
        with self.cond:
            if self.closing or self._released:
                future: Future[Any] = Future()
                future.set_exception(WorkerError(f"the runtime planner is closed: {describe} "
                                                  "was not planned"))
                return future
            if kind == "validate":
                self._seq += 1
                payload = {**payload, "seq": self._seq}
            job = Job(next(self._ids), kind, payload, timeout=timeout, poses_seq=self._seq,
                      describe=describe, on_finish=self._finished,
                      cache_key=self._cache_key(kind, payload))
            self._outstanding[job.id] = job
            state = self._state_now(job.poses_seq)
            if state is not None and self._cached(job, state[0]) is not None:
                cached = True
            else:
                cached = False
                self._jobs.put(job)  # under the lock: queue order is update order
        if cached:
            self.answer_from_cache(job, state[0])  # type: ignore[index]
        elif job.deadline is not None:
            self._deadlines.add(job)
        return job.future

    # -- the result cache ------------------------------------------------------------------
    def _cache_key(self, kind: str, payload: dict[str, Any]) -> tuple[Any, ...] | None:
        """The cache key of a request's answer, without the poses version (the worker
        makes the same keys for what it sends, see ``_worker.Worker.run``)."""
        if kind in ("validate", "replan"):
            return None
        seed = payload["seed"] if payload["seed"] is not None else self.options.planner.seed
        if kind == "cell":
            return ("cell", seed)
        world = payload["world"]
        return ("route", payload["name"], seed, None if world is None else world.key())

    def _cached(self, job: Job, version: int) -> bytes | None:
        if job.cache_key is None:
            return None
        with self.cond:
            return self._cache.get((version, *job.cache_key))

    def answer_from_cache(self, job: Job, version: int) -> bool:
        """Answer ``job`` from the cache if it holds the answer for ``version``."""
        data = self._cached(job, version)
        if data is None:
            return False
        if job.finish(True, pickle.loads(data)):
            self.count("cached")
        return True

    def remember(self, version: int, entries: dict[tuple[Any, ...], bytes]) -> None:
        """Keep what a worker planned with the poses of ``version`` (pickled answers by
        cache key), dropping the oldest beyond :data:`CACHE_SIZE`."""
        with self.cond:
            for key, data in entries.items():
                full = (version, *key)
                self._cache[full] = data
                self._cache.move_to_end(full)
            while len(self._cache) > CACHE_SIZE:
                self._cache.popitem(last=False)

    def next_job(self) -> Job | None:
        """The next request for a worker thread (None: stop)."""
        return self._jobs.get()

    def poses_for(self, job: Job) -> tuple[int, dict[str, np.ndarray]] | None:
        """(version, poses overlay) ``job`` must plan with, once every pose update asked
        for before it is resolved; None if the planner closes meanwhile."""
        if job.kind == "validate":
            return KEEP_POSES, {}  # validation plans nothing
        with self.cond:
            while not self.closing and (state := self._state_now(job.poses_seq)) is None:
                self.cond.wait()
            if self.closing:
                return None
            return state

    def _state_now(self, poses_seq: int) -> tuple[int, dict[str, np.ndarray]] | None:
        """(version, poses overlay) after the first ``poses_seq`` pose updates, or None
        while one of them is not resolved yet (under ``cond``)."""
        if any(s not in self._resolved for s in range(self._floor + 1, poses_seq + 1)):
            return None
        version, overlay = self._floor_state
        for s in range(self._floor + 1, poses_seq + 1):
            poses = self._resolved[s]
            if poses is not None:
                version, overlay = s, {**overlay, **poses}
        return version, overlay

    def _finished(self, job: Job, value: Any, timed_out: bool) -> None:
        """A job ended (answered, cancelled or ``timed_out``); ``value`` is None unless it
        succeeded."""
        with self.cond:
            self._outstanding.pop(job.id, None)
            if timed_out:
                self._counts["timed_out"] += 1
            if job.kind == "validate":
                self._resolved[job.payload["seq"]] = value
            # Fold the resolved updates no pending job still needs to see separately.
            limit = min((j.poses_seq for j in self._outstanding.values()
                         if j.kind != "validate"), default=self._seq)
            while self._floor < limit and self._floor + 1 in self._resolved:
                self._floor += 1
                poses = self._resolved.pop(self._floor)
                if poses is not None:
                    self._floor_state = (self._floor, {**self._floor_state[1], **poses})
            self.cond.notify_all()

    def count(self, name: str) -> None:
        """Add one to a counter of :class:`RuntimeStats`."""
        with self.cond:
            self._counts[name] += 1

    def stats(self) -> RuntimeStats:
        """A snapshot of the counters."""
        with self.cond:
            counts = dict(self._counts)
            queued = sum(1 for j in self._outstanding.values() if not j.future.done())
        busy = sum(1 for s in self.slots if s.job is not None)
        return RuntimeStats(pids=tuple(s.pid for s in self.slots), busy=busy,
                            queued=max(0, queued - busy), spares=self.launcher.spare_pids(),
                            **counts)

    def slot_exited(self) -> None:
        """A slot's thread ends; the last one stops the spares and the deadline thread."""
        with self.cond:
            self._running -= 1
            last = self._running == 0
        if last:
            self.launcher.close(CLOSE_JOIN_TIMEOUT)
            self._deadlines.stop()

    # -- shutting down ---------------------------------------------------------------------
    def release(self) -> None:
        """The planner is gone: finish the requests already queued, then stop."""
        with self.cond:
            if self._released or self.closing:
                return
            self._released = True
            for _ in self.slots:
                self._jobs.put(None)

    def close(self, timeout: float = CLOSE_JOIN_TIMEOUT) -> None:
        """Cancel queued and running requests, stop the workers and reap them."""
        with self.cond:
            first = not self.closing
            self.closing = True
            self.cond.notify_all()
        if first:
            pending = []
            while True:
                try:
                    item = self._jobs.get_nowait()
                except queue.Empty:
                    break
                if item is not None:
                    pending.append(item)
            for job in pending:
                job.future.cancel()
            for _ in self.slots:
                self._jobs.put(None)
            for slot in self.slots:
                slot.interrupt()
            self.launcher.close(timeout)  # slots waiting for a worker get an error now
            self._deadlines.stop()
        me = threading.current_thread()
        for slot in self.slots:
            if slot.thread is not me and slot.thread.is_alive():
                slot.thread.join(timeout)
        _LIVE.discard(self)


_LIVE: weakref.WeakSet[Core] = weakref.WeakSet()


@atexit.register
def _close_all() -> None:
    """At interpreter exit, stop every worker (before multiprocessing's own exit hook)."""
    for core in list(_LIVE):
        core.close(timeout=5.0)
