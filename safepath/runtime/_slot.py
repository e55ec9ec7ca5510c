"""Caller side of one planner worker: the thread that feeds it jobs and replaces it.

A :class:`Slot` holds one loaded worker process (from the planner's
:class:`~safepath.runtime._launcher.Launcher`) and runs a thread that takes jobs from
the planner's queue, answers those the result cache holds, sends the others to its
worker and waits for the answer, a cancellation, a timeout or the worker's death. A
worker whose job was cancelled or timed out is stopped (a plan in native code cannot be
interrupted otherwise) and replaced by a warm spare.
"""

from __future__ import annotations

import logging
import pickle
import signal
import threading
from concurrent.futures import Future
from multiprocessing.connection import wait
from typing import Any, Protocol

import numpy as np

from ._job import Job
from ._launcher import Launcher, Loaded, emit, stop_worker
from ._transport import WorkerError, decode_error

__all__ = ["KEEP_POSES", "Slot", "SlotOwner"]

log = logging.getLogger(__name__)

#: Poses version of a job that plans nothing (the worker keeps its poses).
KEEP_POSES = -1


class SlotOwner(Protocol):
    """What a slot needs of the planner that owns it (``runtime._core.Core``): jobs, pose
    states, workers, the result cache and counters. The slot calls it back through
    these alone, so this module imports nothing of its owner."""

    closing: bool
    #: The multiprocessing context the workers run in.
    context: Any
    launcher: Launcher

    def next_job(self) -> Job | None:
        """The next job to send, or None once the planner closes."""

    def poses_for(self, job: Job) -> tuple[int, dict[str, np.ndarray]] | None:
        """The poses version and poses ``job`` is planned with (None: closing)."""

    def answer_from_cache(self, job: Job, version: int) -> bool:
        """Whether the result cache answered ``job`` (its future is then set)."""

    def remember(self, version: int, entries: dict[tuple[Any, ...], bytes]) -> None:
        """Keep a worker's results for poses ``version`` in the result cache."""

    def learn(self, cell: dict[str, Any]) -> None:
        """Keep what a loaded worker says of its cell (pose names, robot joints)."""

    def count(self, name: str) -> None:
        """Count one event ``name`` (sent, completed, killed, ...)."""

    def slot_exited(self) -> None:
        """Called by a slot's thread as it ends."""


class Slot:
    """One worker process, fed and replaced by its own thread.

    Args:
        core: Supplies jobs, pose states, workers, the result cache and counters.
        index: Slot number, for names.
    """

    def __init__(self, core: SlotOwner, index: int) -> None:
        self._core = core
        self.index = index
        self.worker: Loaded | None = None
        self._version = 0  # poses version the worker plans with
        self.job: Job | None = None  # the job the worker is computing
        self.loaded: Future[None] = Future()
        self._wake_r, self._wake_w = core.context.Pipe(duplex=False)
        self._wake_lock = threading.Lock()
        self.thread = threading.Thread(target=self._main, name=f"safepath-runtime-{index}",
                                       daemon=True)

    @property
    def pid(self) -> int | None:
        """Process id of the running worker, or None."""
        worker = self.worker
        return None if worker is None else worker.proc.pid

    def interrupt(self) -> None:
        """Make the slot's thread look at cancellations, time-outs and closing now."""
        with self._wake_lock:
            try:
                self._wake_w.send_bytes(b"!")
            except (OSError, ValueError):
                pass

    # -- the slot's thread -----------------------------------------------------------------
    def _main(self) -> None:
        try:
            if not self._core.closing:
                self._acquire()
            while (job := self._core.next_job()) is not None:
                if not job.claim(self):
                    self._core.count("skipped")
                    continue
                try:
                    self._serve(job)
                except Exception as exc:  # noqa: BLE001 - a bug here must not hang futures
                    log.exception("planner slot %d failed on %s", self.index, job.describe)
                    self._stop(graceful=False)
                    job.finish(False, WorkerError(f"internal error of the runtime planner "
                                                  f"during {job.describe}: {exc!r}"))
                finally:
                    job.release()
        finally:
            self._stop(graceful=True)
            if not self.loaded.done():
                self.loaded.set_exception(WorkerError("the runtime planner is closed"))
            with self._wake_lock:
                self._wake_w.close()
            self._wake_r.close()
            self._core.slot_exited()

    def _serve(self, job: Job) -> None:
        state = self._core.poses_for(job)
        if state is None or self._core.closing:
            job.future.cancel()
            return
        version, overlay = state
        if job.finished:  # cancelled or timed out while it waited
            self._core.count("skipped")
            return
        if self._core.answer_from_cache(job, version):
            return
        if self.worker is None or not self.worker.proc.is_alive():
            self._stop(graceful=False)
            error = self._acquire()
            if error is not None:
                if self._core.closing:
                    job.future.cancel()
                else:
                    job.finish(False, error)
                return
        if job.finished:
            self._core.count("skipped")
            return
        assert self.worker is not None
        conn = self.worker.conn
        try:
            if version not in (KEEP_POSES, self._version):
                conn.send(("poses", version, overlay))
                self._version = version
            conn.send(("job", job.id, job.kind, job.payload))
        except (OSError, EOFError):
            self._crashed(job)
            self._replace()
            return
        except Exception as exc:  # noqa: BLE001 - e.g. a payload that does not pickle
            job.finish(False, exc)
            return
        self._core.count("sent")
        self.job = job
        try:
            replace = self._wait(job, version)
        finally:
            self.job = None
        if replace:
            self._replace()

    def _drain_wake(self) -> None:
        while self._wake_r.poll():
            self._wake_r.recv_bytes()

    def _wait(self, job: Job, version: int) -> bool:
        """Wait for the answer, a cancellation, a timeout or the worker's death; whether
        the worker must be replaced."""
        assert self.worker is not None
        conn, sentinel = self.worker.conn, self.worker.proc.sentinel
        while True:
            ready = wait([conn, sentinel, self._wake_r])
            if self._wake_r in ready:
                self._drain_wake()
            if self._core.closing:
                log.info("%s cancelled while planning: stopping worker %s", job.describe,
                         self.pid)
                self._core.count("killed")
                self._stop(graceful=False)
                job.future.cancel()  # closing: the job ends cancelled too
                return False
            if conn in ready or conn.poll():
                try:
                    kind, job_id, payload = conn.recv()
                except (EOFError, OSError):
                    self._crashed(job)
                    return True
                if kind == "log":
                    emit(payload)
                    continue
                if job_id != job.id:
                    log.warning("ignoring a stale answer for job %d", job_id)
                    continue
                self._core.count("completed")
                if kind == "ok":
                    answer, entries = payload
                    self._core.remember(version, entries)
                    job.finish(True, pickle.loads(answer))  # no-op if it timed out meanwhile
                else:
                    job.finish(False, decode_error(payload))
                return False
            if job.finished:  # cancelled or timed out while the worker plans it
                how = "cancelled" if job.future.cancelled() else "timed out"
                log.info("%s %s while planning: replacing worker %s", job.describe, how,
                         self.pid)
                self._core.count("killed")
                return True
            if sentinel in ready:
                self._crashed(job)
                return True

    def _crashed(self, job: Job) -> None:
        worker = self.worker
        pid = None if worker is None else worker.proc.pid
        code = None
        if worker is not None:
            worker.proc.join(timeout=2.0)
            code = worker.proc.exitcode
        how = "died" if code is None else f"exited with code {code}"
        if code is not None and code < 0:
            try:
                how = f"was killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"was killed by signal {-code}"
        log.warning("planner worker %s %s during %s", pid, how, job.describe)
        self._core.count("crashed")
        job.finish(False, WorkerError(
            f"the planner worker (pid {pid}) {how} during {job.describe}; it is replaced",
            pid=pid, exitcode=code))

    def _replace(self) -> None:
        """Stop the worker and take another (a warm spare when one is ready)."""
        self._stop(graceful=False)
        if not self._core.closing:
            self._acquire()

    # -- process life ----------------------------------------------------------------------
    def _acquire(self) -> BaseException | None:
        """Take a loaded worker from the launcher; the error if none could load."""
        if self.loaded.done():  # a replacement: ready() waits for this one now
            self.loaded = Future()
        loaded = self.loaded
        result = self._core.launcher.acquire()
        if isinstance(result, Loaded) and self._core.closing:
            stop_worker(result, graceful=True)
            result = WorkerError("the runtime planner is closed")
        if isinstance(result, BaseException):
            loaded.set_exception(result)
            return result
        self.worker, self._version = result, 0
        self._core.remember(0, result.entries)  # its warm-up plan, with the loaded poses
        self._core.learn(result.cell)
        loaded.set_result(None)
        return None

    def _stop(self, *, graceful: bool) -> None:
        """Stop the worker (asking first if ``graceful``) and reap it."""
        worker, self.worker = self.worker, None
        if worker is not None:
            stop_worker(worker, graceful=graceful)
