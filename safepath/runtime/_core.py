"""The shared state of a runtime planner: its request queue, pose updates and counters.

It never refers to the :class:`~safepath.runtime.RuntimePlanner` itself, so that the
planner can be garbage-collected while the worker threads run (they then finish the
requests already queued and stop).

Pose updates are numbered in the order they were asked for; every request remembers
how many came before it, and plans with exactly those applied (the successful ones),
whichever worker takes it and whenever.
"""

from __future__ import annotations

import atexit
import itertools
import multiprocessing
import multiprocessing.util  # noqa: F401 - its exit hook must be registered before ours
import queue
import threading
import weakref
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..cell import Cell
from ..planning import PlanOptions
from ._slot import KEEP_POSES, Job, Slot
from ._transport import WorkerError

__all__ = ["Core", "RuntimeStats", "CLOSE_JOIN_TIMEOUT"]

#: Time close() waits for each worker thread [s] (a worker is terminated well before).
CLOSE_JOIN_TIMEOUT = 10.0


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
        skipped: Requests cancelled before they reached a worker (never computed).
        killed: Workers stopped because their request was cancelled or timed out.
        crashed: Workers that died on their own.
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


class Core:
    """State shared by a planner and its worker threads.

    Args:
        scene: The scene folder.
        options: Planning options.
        workers: Number of worker processes.
        start_method: Multiprocessing start method (``spawn`` or ``forkserver``).
    """

    def __init__(self, scene: Path | Cell, options: PlanOptions, workers: int,
                 start_method: str) -> None:
        self.cond = threading.Condition()
        self.closing = False
        self._released = False
        self._jobs: queue.SimpleQueue[Job | None] = queue.SimpleQueue()
        self._ids = itertools.count(1)
        self._counts = dict.fromkeys(("started", "sent", "completed", "skipped", "killed",
                                      "crashed"), 0)
        self._outstanding: dict[int, Job] = {}
        # Pose updates: update k (1-based) holds validated poses, or None (no effect).
        self._seq = 0
        self._floor = 0  # every update <= floor is resolved and folded into _floor_state
        self._floor_state: tuple[int, dict[str, np.ndarray]] = (0, {})
        self._resolved: dict[int, dict[str, np.ndarray] | None] = {}
        context = multiprocessing.get_context(start_method)
        self.slots = [Slot(self, i, context, scene, options)  # type: ignore[arg-type]
                      for i in range(workers)]
        for slot in self.slots:
            slot.thread.start()
        _LIVE.add(self)

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
                      describe=describe, on_finish=self._finished)
            self._outstanding[job.id] = job
            self._jobs.put(job)  # under the lock: queue order is update order
        return job.future

    def next_job(self) -> Job | None:
        """The next request for a worker thread (None: stop)."""
        return self._jobs.get()

    def poses_for(self, job: Job) -> tuple[int, dict[str, np.ndarray]] | None:
        """(version, poses overlay) ``job`` must plan with, once every pose update asked
        for before it is resolved; None if the planner closes meanwhile."""
        if job.kind == "validate":
            return KEEP_POSES, {}  # validation plans nothing
        with self.cond:
            while not self.closing and any(
                    s not in self._resolved for s in range(self._floor + 1, job.poses_seq + 1)):
                self.cond.wait()
            if self.closing:
                return None
            version, overlay = self._floor_state
            for s in range(self._floor + 1, job.poses_seq + 1):
                poses = self._resolved[s]
                if poses is not None:
                    version, overlay = s, {**overlay, **poses}
            return version, overlay

    def _finished(self, job: Job, value: Any) -> None:
        """A job ended (answered or cancelled); ``value`` is None unless it succeeded."""
        with self.cond:
            self._outstanding.pop(job.id, None)
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
                            queued=max(0, queued - busy), **counts)

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
