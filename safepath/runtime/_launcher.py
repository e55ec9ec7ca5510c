"""Starting planner workers, and the warm spare that replaces a stopped one at once.

A worker takes one to a few seconds to start (imports, loading the cell, warm-up). A
cancelled or timed-out request stops its worker (a plan in native code cannot be
interrupted otherwise); without a spare, the next request would wait for a new one to
load. The :class:`Launcher` keeps ``spares`` loaded workers ready: a slot that stopped
its worker takes a spare at once, and a new spare loads in the background.

Workers load on short-lived threads of the launcher; a slot asks for one with
:meth:`Launcher.acquire` and waits only if none is ready.
"""

from __future__ import annotations

import itertools
import logging
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from ..cell import Cell
from ..planning import PlanOptions
from . import _worker
from ._transport import WorkerError, decode_error

if TYPE_CHECKING:
    from multiprocessing.context import ForkServerContext, SpawnContext

    Context = SpawnContext | ForkServerContext

__all__ = ["Launcher", "Loaded", "stop_worker", "emit", "START_TIMEOUT", "STOP_GRACE"]

log = logging.getLogger(__name__)

#: How long a worker may take to load the cell [s] before it counts as failed.
START_TIMEOUT = 120.0
#: How long a worker asked to stop may take before it is terminated [s].
STOP_GRACE = 2.0


class Loaded(NamedTuple):
    """A worker process that has loaded the cell, this end of its pipe, and the results
    of its warm-up plan (pickled, by cache key, for the poses it loaded)."""

    proc: BaseProcess
    conn: Connection
    entries: dict[tuple[Any, ...], bytes] = {}
    #: The loaded cell's taught pose names and its robot's joints (names, lower and
    #: upper limits), for checks the caller makes without a worker.
    cell: dict[str, Any] = {}


def emit(record: logging.LogRecord) -> None:
    """Re-emit a worker's log record through the caller's logger of the same name."""
    logger = logging.getLogger(record.name)
    if logger.isEnabledFor(record.levelno):
        logger.handle(record)


def stop_worker(worker: Loaded, *, graceful: bool) -> None:
    """Stop a worker (asking first if ``graceful``) and reap it."""
    proc, conn = worker.proc, worker.conn
    if graceful and proc.is_alive():
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
    conn.close()
    proc.close()


class Launcher:
    """Starts workers for the slots of one planner and keeps warm spares.

    Args:
        context: Multiprocessing context (spawn or forkserver).
        scene: What the workers load (the scene folder, or a cell).
        options: Planning options.
        spares: Loaded workers to keep ready beyond those in use. They start after the
            first worker has loaded (not competing with it), and only while workers
            load successfully.
        count: Adds one to a counter of the planner's statistics (``started``).
    """

    def __init__(self, context: Context, scene: Path | Cell, options: PlanOptions, *,
                 spares: int,
                 count: Callable[[str], None]) -> None:
        self._ctx = context
        self._scene = scene
        self._options = options
        self._spares = spares
        self._count = count
        self._cond = threading.Condition()
        self._ready: list[Loaded] = []
        self._waiters: list[Future[Loaded]] = []
        self._warm_waiters: list[Future[None]] = []
        self._loading = 0
        self._healthy = False  # the last load succeeded: spares may be loaded
        self._closed = False
        self._names = itertools.count()
        self._threads: set[threading.Thread] = set()
        # Written once, by close(): wakes every load that waits for its worker.
        self._stop_r, self._stop_w = context.Pipe(duplex=False)

    def spare_pids(self) -> tuple[int, ...]:
        """Process ids of the loaded workers waiting to be used."""
        with self._cond:
            return tuple(w.proc.pid for w in self._ready if w.proc.pid is not None)

    def warm(self) -> Future[None]:
        """A future done once the spares are loaded (at once if they are), or once no
        more will load: the last load failed, or the launcher is closed."""
        future: Future[None] = Future()
        with self._cond:
            if not self._is_warm():
                self._warm_waiters.append(future)
                return future
        future.set_result(None)
        return future

    def _is_warm(self) -> bool:
        """Whether the spares are loaded or none will be (under _cond)."""
        return self._closed or not self._healthy or len(self._ready) >= self._spares

    def _take_warm_waiters(self) -> list[Future[None]]:
        """The warm waiters to answer now, if the spares are warm (under _cond)."""
        if not self._is_warm():
            return []
        waiters, self._warm_waiters = self._warm_waiters, []
        return waiters

    def acquire(self) -> Loaded | BaseException:
        """A loaded worker (a spare if one is ready), or the error that stopped one from
        loading (``WorkerError`` once closed). Blocks while none is ready."""
        with self._cond:
            if self._closed:
                return WorkerError("the runtime planner is closed")
            if self._ready:
                worker = self._ready.pop(0)
                self._fill()
                return worker
            ticket: Future[Loaded] = Future()
            self._waiters.append(ticket)
            self._fill()
        try:
            return ticket.result()
        except BaseException as exc:  # noqa: BLE001 - the load error is the answer
            return exc

    def close(self, timeout: float) -> None:
        """Stop the spares, interrupt the loads and wait for them (``timeout`` [s])."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            spares, self._ready = self._ready, []
            waiters, self._waiters = self._waiters, []
            warm = self._take_warm_waiters()
            threads = list(self._threads)
        for ticket in waiters:
            ticket.set_exception(WorkerError("the runtime planner is closed"))
        for future in warm:
            future.set_result(None)
        try:
            self._stop_w.send_bytes(b"!")
        except (OSError, ValueError):
            pass
        for worker in spares:
            stop_worker(worker, graceful=True)
        for thread in threads:
            thread.join(timeout)
        self._stop_w.close()
        self._stop_r.close()

    # -- loading ---------------------------------------------------------------------------
    def _fill(self) -> None:
        """Start loads until every waiter has one, or, when none waits, until the spares
        are loaded or loading (under _cond). Spares wait for the waiters: on two cores,
        two workers loading at once both take twice as long."""
        if self._waiters:
            wanted = len(self._waiters)
        else:
            wanted = self._spares - len(self._ready) if self._healthy else 0
        while self._loading < wanted:
            self._loading += 1
            thread = threading.Thread(target=self._load, daemon=True,
                                      name="safepath-runtime-launcher")
            self._threads.add(thread)
            thread.start()

    def _load(self) -> None:
        # Workers inherit this thread's signal mask: with SIGINT blocked, a Ctrl-C in the
        # terminal cannot kill a worker that is still importing (before it ignores SIGINT);
        # the caller's main thread gets it as usual and decides. The resource tracker is
        # started first because starting it unblocks SIGINT in the calling thread.
        if hasattr(signal, "pthread_sigmask"):
            resource_tracker.ensure_running()
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        result = self._start()
        with self._cond:
            self._loading -= 1
            self._threads.discard(threading.current_thread())
            if self._closed:
                ticket = None
            else:
                self._healthy = not isinstance(result, BaseException)
                ticket = self._waiters.pop(0) if self._waiters else None
                if ticket is None and isinstance(result, Loaded):
                    self._ready.append(result)
                self._fill()
            warm = self._take_warm_waiters()
        for future in warm:
            future.set_result(None)
        if self._closed and isinstance(result, Loaded):
            stop_worker(result, graceful=True)
        elif ticket is not None:
            if isinstance(result, Loaded):
                ticket.set_result(result)
            else:
                ticket.set_exception(result)

    def _start(self) -> Loaded | BaseException:
        """Start a worker and wait until it has loaded the cell; the error if it could not."""
        t_start = time.perf_counter()
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(
            target=_worker.serve, name=f"safepath-runtime-worker-{next(self._names)}",
            daemon=True, args=(child, self._scene, self._options,
                               logging.getLogger("safepath").getEffectiveLevel()))
        try:
            proc.start()
        except Exception as exc:  # noqa: BLE001 - e.g. no more processes
            parent.close()
            return WorkerError(f"could not start the planner worker: {exc}")
        finally:
            child.close()
        self._count("started")
        info = self._await_ready(proc, parent)
        if isinstance(info, dict):
            log.info("planner worker %d ready in %.2f s", proc.pid,
                     time.perf_counter() - t_start)
            return Loaded(proc, parent, info.get("entries", {}),
                          {k: info[k] for k in ("poses", "joints") if k in info})
        error = info
        if not self._closed:
            log.warning("planner worker for %s could not start: %s", self._scene, error)
        stop_worker(Loaded(proc, parent), graceful=False)
        return error

    def _await_ready(self, proc: BaseProcess, conn: Connection
                     ) -> dict[str, Any] | BaseException:
        """The worker's ``ready`` information, or why it did not load."""
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            remaining = max(0.0, deadline - time.monotonic())
            ready: list[Any] = wait([conn, proc.sentinel, self._stop_r], remaining)
            if self._closed:
                return WorkerError("the runtime planner was closed while its worker started")
            closed = False
            if conn in ready or conn.poll():
                try:
                    kind, _, payload = conn.recv()
                except (EOFError, OSError):
                    closed = True  # the worker is gone: its exit code tells why
                else:
                    if kind == "log":
                        emit(payload)
                        continue
                    if kind == "ready":
                        return payload  # type: ignore[no-any-return]
                    return decode_error(payload)
            if closed or proc.sentinel in ready:
                proc.join(timeout=STOP_GRACE)
                return WorkerError(f"the planner worker (pid {proc.pid}) exited with code "
                                   f"{proc.exitcode} while loading {self._scene}",
                                   pid=proc.pid, exitcode=proc.exitcode)
            if time.monotonic() >= deadline:
                return WorkerError(f"the planner worker (pid {proc.pid}) did not load "
                                   f"{self._scene} within {START_TIMEOUT:g} s", pid=proc.pid)
