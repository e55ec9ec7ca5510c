"""Caller side of one planner worker: a job's life, and the thread that drives a process.

A :class:`Job` owns the ``concurrent.futures.Future`` handed to the caller. The future
stays *pending* until the worker's answer is in, so ``future.cancel()`` succeeds at any
time before that: before the job reaches a worker it simply never runs; while a worker
plans it, the worker is terminated and a fresh one started. Results are set from a
short-lived thread, so that a done-callback that blocks (even one that waits for another
future of the same planner) never stalls the planner.

A :class:`Slot` is one worker process and the thread that feeds it jobs, waits for the
answer (or the deadline, a cancellation, the process's death) and restarts it.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection, wait
from multiprocessing.context import SpawnContext
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..cell import Cell
from ..errors import PlannerTimeout
from ..planning import PlanOptions
from . import _worker
from ._transport import WorkerError, decode_error

if TYPE_CHECKING:
    from multiprocessing.context import ForkServerContext

    Context = SpawnContext | ForkServerContext

__all__ = ["KEEP_POSES", "Job", "Slot"]

log = logging.getLogger(__name__)

#: How long a worker may take to load the cell [s] before it counts as failed.
START_TIMEOUT = 120.0
#: Poses version of a job that plans nothing (the worker keeps its poses).
KEEP_POSES = -1
#: How long a worker asked to stop may take before it is terminated [s].
STOP_GRACE = 2.0


def _settle(future: Future[Any], ok: bool, value: Any) -> None:
    if ok:
        future.set_result(value)
    else:
        future.set_exception(value)


class Job:
    """One request: what to do, and the future that gets its answer.

    Attributes:
        id: Unique id (the worker echoes it).
        kind: ``route``, ``cell`` or ``validate``.
        payload: Arguments for the worker.
        timeout: Time budget once the worker has it [s], or None.
        poses_seq: Number of pose updates requested before this job.
        describe: What the job does, for messages (``route 'phase1'``).
        future: The caller's future.
    """

    def __init__(self, job_id: int, kind: str, payload: dict[str, Any], *,
                 timeout: float | None, poses_seq: int, describe: str,
                 on_finish: Callable[[Job, Any], None]) -> None:
        self.id = job_id
        self.kind = kind
        self.payload = payload
        self.timeout = timeout
        self.poses_seq = poses_seq
        self.describe = describe
        self.future: Future[Any] = Future()
        self._on_finish = on_finish
        self._lock = threading.Lock()
        self._finished = False
        self._slot: Slot | None = None
        self.future.add_done_callback(self._on_done)

    def claim(self, slot: Slot) -> bool:
        """Mark the job as taken by ``slot``; False if it was cancelled meanwhile."""
        with self._lock:
            if self._finished:
                return False
            self._slot = slot
            return True

    def release(self) -> None:
        """The slot is done with the job."""
        with self._lock:
            self._slot = None

    def finish(self, ok: bool, value: Any) -> None:
        """Hand the worker's answer (a result, or an exception if not ``ok``) to the future."""
        with self._lock:
            if self._finished:
                return  # cancelled first
            self._finished = True
            running = self.future.set_running_or_notify_cancel()
        self._on_finish(self, value if ok and running else None)
        if not running:
            return
        try:
            threading.Thread(target=_settle, args=(self.future, ok, value), daemon=True,
                             name=f"safepath-runtime-done-{self.id}").start()
        except RuntimeError:  # no new threads at interpreter shutdown
            _settle(self.future, ok, value)

    def _on_done(self, future: Future[Any]) -> None:
        if not future.cancelled():
            return
        with self._lock:
            if self._finished:
                return
            self._finished = True
            future.set_running_or_notify_cancel()  # wakes wait() and as_completed()
            slot = self._slot
        self._on_finish(self, None)
        if slot is not None:
            slot.interrupt()


class Slot:
    """One worker process, started and restarted by its own thread.

    Args:
        core: Supplies jobs, pose states and counters (see ``planner._Core``).
        index: Slot number, for names.
        context: Multiprocessing context (spawn or forkserver).
        scene: Scene folder.
        options: Planning options.
    """

    def __init__(self, core: Any, index: int, context: Context, scene: Path | Cell,
                 options: PlanOptions) -> None:
        self._core = core
        self.index = index
        self._ctx = context
        self._scene = scene
        self._options = options
        self.proc: BaseProcess | None = None
        self._conn: Connection | None = None
        self._version = 0  # poses version the worker plans with
        self.job: Job | None = None  # the job the worker is computing
        self.loaded: Future[None] = Future()
        self._wake_r, self._wake_w = context.Pipe(duplex=False)
        self._wake_lock = threading.Lock()
        self.thread = threading.Thread(target=self._main, name=f"safepath-runtime-{index}",
                                       daemon=True)

    @property
    def pid(self) -> int | None:
        """Process id of the running worker, or None."""
        proc = self.proc
        return None if proc is None else proc.pid

    def interrupt(self) -> None:
        """Make the slot's thread look at cancellations and the closing flag now."""
        with self._wake_lock:
            try:
                self._wake_w.send_bytes(b"!")
            except (OSError, ValueError):
                pass

    # -- the slot's thread -----------------------------------------------------------------
    def _main(self) -> None:
        # Workers inherit this thread's signal mask: with SIGINT blocked, a Ctrl-C in the
        # terminal cannot kill a worker that is still importing (before it ignores SIGINT);
        # the caller's main thread gets it as usual and decides. The resource tracker is
        # started first because starting it unblocks SIGINT in the calling thread.
        if hasattr(signal, "pthread_sigmask"):
            resource_tracker.ensure_running()
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            if not self._core.closing:
                self._start()
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

    def _serve(self, job: Job) -> None:
        state = self._core.poses_for(job)
        if state is None or self._core.closing:
            job.future.cancel()
            return
        if self.proc is None or not self.proc.is_alive():
            self._stop(graceful=False)
            error = self._start()
            if error is not None:
                if self._core.closing:
                    job.future.cancel()
                else:
                    job.finish(False, error)
                return
        if job.future.cancelled():
            self._core.count("skipped")
            return
        version, overlay = state
        assert self._conn is not None
        try:
            if version not in (KEEP_POSES, self._version):
                self._conn.send(("poses", version, overlay))
                self._version = version
            self._conn.send(("job", job.id, job.kind, job.payload))
        except (OSError, EOFError):
            self._crashed(job)
            return
        except Exception as exc:  # noqa: BLE001 - e.g. a payload that does not pickle
            job.finish(False, exc)
            return
        self._core.count("sent")
        self.job = job
        try:
            self._wait(job)
        finally:
            self.job = None

    def _drain_wake(self) -> None:
        while self._wake_r.poll():
            self._wake_r.recv_bytes()

    def _wait(self, job: Job) -> None:
        assert self.proc is not None and self._conn is not None
        conn, sentinel = self._conn, self.proc.sentinel
        deadline = None if job.timeout is None else time.monotonic() + job.timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready = wait([conn, sentinel, self._wake_r], remaining)
            if self._wake_r in ready:
                self._drain_wake()
            if job.future.cancelled() or self._core.closing:
                log.info("%s cancelled while planning: stopping worker %s", job.describe,
                         self.pid)
                self._core.count("killed")
                self._stop(graceful=False)
                job.future.cancel()  # closing: the job ends cancelled too
                self._restart()
                return
            if conn in ready or conn.poll():
                try:
                    kind, job_id, payload = conn.recv()
                except (EOFError, OSError):
                    self._crashed(job)
                    return
                if kind == "log":
                    _emit(payload)
                    continue
                if job_id != job.id:
                    log.warning("ignoring a stale answer for job %d", job_id)
                    continue
                self._core.count("completed")
                if kind == "ok":
                    job.finish(True, payload)
                else:
                    job.finish(False, decode_error(payload))
                return
            if sentinel in ready:
                self._crashed(job)
                return
            if deadline is not None and time.monotonic() >= deadline:
                assert job.timeout is not None
                log.info("%s timed out after %g s: stopping worker %s", job.describe,
                         job.timeout, self.pid)
                self._core.count("killed")
                self._stop(graceful=False)
                job.finish(False, PlannerTimeout(
                    f"{job.describe} not planned within the {job.timeout:g} s timeout; "
                    "the worker was stopped and restarts", status="timeout"))
                self._restart()
                return

    def _crashed(self, job: Job) -> None:
        proc = self.proc
        pid = None if proc is None else proc.pid
        code = None
        if proc is not None:
            proc.join(timeout=STOP_GRACE)
            code = proc.exitcode
        how = "died" if code is None else f"exited with code {code}"
        if code is not None and code < 0:
            try:
                how = f"was killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"was killed by signal {-code}"
        log.warning("planner worker %s %s during %s", pid, how, job.describe)
        self._core.count("crashed")
        self._stop(graceful=False)
        job.finish(False, WorkerError(
            f"the planner worker (pid {pid}) {how} during {job.describe}; it restarts",
            pid=pid, exitcode=code))
        self._restart()

    def _restart(self) -> None:
        if not self._core.closing:
            self._start()

    # -- process life ----------------------------------------------------------------------
    def _start(self) -> BaseException | None:
        """Start a worker and wait until it has loaded the cell; the error if it could not."""
        if self.loaded.done():  # a restart: ready() waits for this start now
            self.loaded = Future()
        loaded = self.loaded
        t_start = time.perf_counter()
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(
            target=_worker.serve, name=f"safepath-runtime-worker-{self.index}", daemon=True,
            args=(child, self._scene, self._options,
                  logging.getLogger("safepath").getEffectiveLevel()))
        try:
            proc.start()
        except Exception as exc:  # noqa: BLE001 - e.g. no more processes
            parent.close()
            failed = WorkerError(f"could not start the planner worker: {exc}")
            loaded.set_exception(failed)
            return failed
        finally:
            child.close()
        self.proc, self._conn, self._version = proc, parent, 0
        self._core.count("started")
        error = self._await_ready(proc, parent)
        if error is None:
            log.info("planner worker %d ready in %.2f s", proc.pid,
                     time.perf_counter() - t_start)
            loaded.set_result(None)
        else:
            log.warning("planner worker for %s could not start: %s", self._scene, error)
            self._stop(graceful=False)
            loaded.set_exception(error)
        return error

    def _await_ready(self, proc: BaseProcess, conn: Connection) -> BaseException | None:
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            remaining = max(0.0, deadline - time.monotonic())
            ready = wait([conn, proc.sentinel, self._wake_r], remaining)
            if self._wake_r in ready:
                self._drain_wake()
            if self._core.closing:
                return WorkerError("the runtime planner was closed while its worker started")
            closed = False
            if conn in ready or conn.poll():
                try:
                    kind, _, payload = conn.recv()
                except (EOFError, OSError):
                    closed = True  # the worker is gone: its exit code tells why
                else:
                    if kind == "log":
                        _emit(payload)
                        continue
                    if kind == "ready":
                        return None
                    return decode_error(payload)
            if closed or proc.sentinel in ready:
                proc.join(timeout=STOP_GRACE)
                return WorkerError(f"the planner worker (pid {proc.pid}) exited with code "
                                   f"{proc.exitcode} while loading {self._scene}",
                                   pid=proc.pid, exitcode=proc.exitcode)
            if time.monotonic() >= deadline:
                return WorkerError(f"the planner worker (pid {proc.pid}) did not load "
                                   f"{self._scene} within {START_TIMEOUT:g} s", pid=proc.pid)

    def _stop(self, *, graceful: bool) -> None:
        """Stop the worker (asking first if ``graceful``) and reap it."""
        proc, conn = self.proc, self._conn
        self.proc, self._conn = None, None
        if proc is None:
            return
        if graceful and conn is not None and proc.is_alive():
            try:
                conn.send(("stop",))
            except (OSError, ValueError):
                pass
            proc.join(timeout=STOP_GRACE)
        if proc.is_alive():
            proc.terminate()
            proc.join(timeout=STOP_GRACE)
        if proc.is_alive():
            proc.kill()
            proc.join()
        if conn is not None:
            conn.close()
        proc.close()


def _emit(record: logging.LogRecord) -> None:
    """Re-emit a worker's log record through the caller's logger of the same name."""
    logger = logging.getLogger(record.name)
    if logger.isEnabledFor(record.levelno):
        logger.handle(record)
