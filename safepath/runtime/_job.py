"""A request's life: the future the caller holds, and the deadline that ends it.

A :class:`Job` owns the ``concurrent.futures.Future`` handed to the caller. The future
stays *pending* until the answer is in, so ``future.cancel()`` succeeds at any time
before that: before the job reaches a worker it simply never runs; while a worker plans
it, the worker is stopped and replaced. Results are set by the thread that has them
(a slot, the deadline thread), which wakes ``result()`` at once; done-callbacks run on
short-lived threads of their own, so that one that blocks (even one that waits for
another future of the same planner) never stalls the planner.

A job with a timeout has a deadline counted from the request. :class:`Deadlines` is
one thread that fails every job whose deadline passed with ``PlannerTimeout``, wherever
the job is (queued, waiting for pose updates or a worker, or planning); a thread waiting
in ``result()`` at the deadline fails it itself, one scheduler wake-up sooner. The slot
that plans it then stops its worker.
"""

from __future__ import annotations

import heapq
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, wait
from typing import Any, Protocol

from ..errors import PlannerTimeout

__all__ = ["Job", "Deadlines", "RequestFuture", "WAITER_GRACE"]

#: How long after a deadline the deadline thread leaves a request that a thread waits
#: for to that thread [s] (the waiter, woken at the deadline, fails it first).
WAITER_GRACE = 0.02

log = logging.getLogger(__name__)


class _Interruptible(Protocol):
    def interrupt(self) -> None: ...


class RequestFuture(Future[Any]):
    """The future of a request: its done-callbacks each run on a short-lived thread of
    their own, so that the thread that answers (the deadline thread, a slot) sets the
    result at once, waking ``result()`` directly, and a callback that blocks (even one
    that waits for another future of the same planner) never stalls it. A callback added
    once the future is done runs at once in the caller's thread, as for any future.

    A thread waiting in :meth:`result` or :meth:`exception` when the request's deadline
    passes times the request out itself: it wakes at the deadline on its own, instead of
    waiting for the deadline thread to wake and then wake it (two scheduler wake-ups in
    a row, each up to tens of milliseconds on a loaded machine).
    """

    _deadline: float | None = None
    _expire: Callable[[], object] | None = None
    #: Threads waiting in :meth:`result` or :meth:`exception` for the deadline.
    waiting = 0

    def expire_at(self, deadline: float, expire: Callable[[], object]) -> None:
        """Call ``expire`` in a waiting thread that reaches ``deadline``
        (``time.monotonic()``) before the answer."""
        self._deadline, self._expire = deadline, expire

    def result(self, timeout: float | None = None) -> Any:
        return super().result(self._await_deadline(timeout))

    def exception(self, timeout: float | None = None) -> BaseException | None:
        return super().exception(self._await_deadline(timeout))

    def _await_deadline(self, timeout: float | None) -> float | None:
        """Wait up to the deadline (if it comes before ``timeout`` [s]) and expire the
        request there; the part of ``timeout`` left."""
        start = time.monotonic()
        deadline, expire = self._deadline, self._expire
        if deadline is None or expire is None or self.done() or (
                timeout is not None and start + timeout < deadline):
            return timeout
        self.waiting += 1  # only ever read as "any": a lost update is harmless
        try:
            done = wait([self], timeout=max(0.0, deadline - start)).done
        finally:
            self.waiting -= 1
        if not done:
            expire()
        return None if timeout is None else max(0.0, timeout - (time.monotonic() - start))

    def add_done_callback(self, fn: Callable[[Future[Any]], object]) -> None:
        if self.done():
            super().add_done_callback(fn)
            return

        def dispatch(future: Future[Any]) -> None:
            try:
                threading.Thread(target=_call, args=(fn, future), daemon=True,
                                 name="safepath-runtime-callback").start()
            except RuntimeError:  # no new threads at interpreter shutdown
                _call(fn, future)

        super().add_done_callback(dispatch)


def _call(fn: Callable[[Future[Any]], object], future: Future[Any]) -> None:
    try:
        fn(future)
    except Exception:  # as Future's own callbacks: logged, never raised into the planner
        log.exception("exception calling callback for %r", future)


class Job:
    """One request: what to do, and the future that gets its answer.

    Attributes:
        id: Unique id (the worker echoes it).
        kind: ``route``, ``cell``, ``replan`` or ``validate``.
        payload: Arguments for the worker.
        timeout: Time budget from the request [s], or None.
        deadline: ``time.monotonic()`` when the budget runs out, or None.
        poses_seq: Number of pose updates requested before this job.
        describe: What the job does, for messages (``route 'phase1'``).
        cache_key: Key of the answer in the planner's result cache (without the poses
            version), or None for answers that are not cached.
        future: The caller's future.
    """

    def __init__(self, job_id: int, kind: str, payload: dict[str, Any], *,
                 timeout: float | None, poses_seq: int, describe: str,
                 on_finish: Callable[[Job, Any, bool], None],
                 cache_key: tuple[Any, ...] | None = None) -> None:
        self.id = job_id
        self.kind = kind
        self.payload = payload
        self.timeout = timeout
        self.deadline = None if timeout is None else time.monotonic() + timeout
        self.poses_seq = poses_seq
        self.describe = describe
        self.cache_key = cache_key
        self.future: RequestFuture = RequestFuture()
        self._on_finish = on_finish
        self._lock = threading.Lock()
        self._finished = False
        self._slot: _Interruptible | None = None
        # In the thread that cancels (not dispatched): the slot is interrupted at once.
        Future.add_done_callback(self.future, self._on_done)
        if self.deadline is not None:
            self.future.expire_at(self.deadline, self.expire)

    @property
    def finished(self) -> bool:
        """Whether the job has its answer, was cancelled or timed out."""
        return self._finished

    def claim(self, slot: _Interruptible) -> bool:
        """Mark the job as taken by ``slot``; False if it ended meanwhile."""
        with self._lock:
            if self._finished:
                return False
            self._slot = slot
            return True

    def release(self) -> None:
        """The slot is done with the job."""
        with self._lock:
            self._slot = None

    def finish(self, ok: bool, value: Any, *, timed_out: bool = False) -> bool:
        """Hand an answer (a result, or an exception if not ``ok``) to the future; False
        if the job had ended already (cancelled, timed out, answered)."""
        with self._lock:
            if self._finished:
                return False
            self._finished = True
            running = self.future.set_running_or_notify_cancel()
        self._on_finish(self, value if ok and running else None, timed_out and running)
        if running:  # wakes result() now; the callbacks get threads of their own
            if ok:
                self.future.set_result(value)
            else:
                self.future.set_exception(value)
        return True

    def expire(self) -> bool:
        """The deadline passed: fail with ``PlannerTimeout`` unless answered already, and
        make the slot that plans the job (if any) stop its worker; False if the job had
        ended already."""
        assert self.timeout is not None
        with self._lock:
            slot = self._slot
        expired = self.finish(False, PlannerTimeout(
            f"{self.describe} not planned within the {self.timeout:g} s timeout",
            status="timeout"), timed_out=True)
        if expired and slot is not None:
            slot.interrupt()
        return expired

    def _on_done(self, future: Future[Any]) -> None:
        if not future.cancelled():
            return
        with self._lock:
            if self._finished:
                return
            self._finished = True
            future.set_running_or_notify_cancel()  # wakes wait() and as_completed()
            slot = self._slot
        self._on_finish(self, None, False)
        if slot is not None:
            slot.interrupt()


class Deadlines:
    """The thread that times out jobs at their deadlines (started on first use)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._heap: list[tuple[float, int, Job]] = []
        self._thread: threading.Thread | None = None
        self._stopped = False

    def add(self, job: Job) -> None:
        """Time out ``job`` at ``job.deadline``."""
        assert job.deadline is not None
        with self._cond:
            if self._stopped:
                return
            heapq.heappush(self._heap, (job.deadline, job.id, job))
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, daemon=True,
                                                name="safepath-runtime-deadlines")
                self._thread.start()
            self._cond.notify()

    def stop(self) -> None:
        """End the thread (jobs still pending never time out: the planner is closed)."""
        with self._cond:
            self._stopped = True
            self._heap.clear()
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while True:
                    while self._heap and self._heap[0][2].finished:
                        heapq.heappop(self._heap)
                    if self._stopped:
                        return
                    if not self._heap:
                        self._cond.wait()
                        continue
                    now = time.monotonic()
                    delay = self._heap[0][0] - now
                    if delay <= 0:
                        due, _, job = heapq.heappop(self._heap)
                        if job.future.waiting and due == job.deadline:
                            # A thread waits for it and expires it itself: waking now too
                            # would take the interpreter lock from it at its deadline.
                            heapq.heappush(self._heap, (due + WAITER_GRACE, job.id, job))
                            continue
                        break
                    self._cond.wait(delay)
            job.expire()
