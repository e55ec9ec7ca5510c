"""Planning for the review session, away from the page's process.

Planning holds the GIL for seconds (OMPL callbacks, TOPPRA, the verifier), which
would freeze the page's websocket and playback threads. The session therefore plans
through a :class:`PlanBackend`: by default ``safepath.runtime.RuntimePlanner`` (its
workers keep the cell loaded), or a one-worker process pool started with ``spawn``.
Both answer with a ``Future`` of trajectories by route name, or of the typed
``safepath`` error the planner raised (errors pickle with their evidence).
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np

from ..cell import Cell
from ..errors import InputError
from ..files._io import check_names
from ..model.trajectory import Trajectory

__all__ = ["PlanBackend", "ProcessPlanBackend", "RuntimePlanBackend", "make_backend",
           "plan_in_worker"]



BackendKind = Literal["auto", "process", "runtime"]


class PlanBackend(Protocol):
    """Plans routes of one cell (a folder, or a cell built in Python) with given poses,
    outside the caller's process."""

    def plan(self, poses: Mapping[str, np.ndarray], routes: Sequence[str] | None = None
             ) -> Future[dict[str, Trajectory]]:
        """Plan ``routes`` (None: all) with ``poses``; the future raises a SafepathError."""
        ...

    def close(self) -> None:
        """Release the worker."""
        ...


def plan_in_worker(source: str | Cell, poses: dict[str, list[float]],
                   routes: list[str] | None, seed: int) -> dict[str, Trajectory]:
    """Load the cell (a folder; a cell arrives unpickled), override its poses, plan
    ``routes`` and the routes they follow.

    Runs in the worker process; its errors reach the caller's future as they were
    raised (typed, with their evidence).

    Raises:
        InputError: An unknown route (lists the known ones).
        SafepathError: Whatever loading or planning raised.
    """
    from ..cell import load_cell
    from ..cell.routes import after_chain
    from ..planning import PlannerOptions, PlanOptions, plan_cell

    cell = source if isinstance(source, Cell) else load_cell(source)
    for name, q in poses.items():
        cell.poses[name] = cell.robot.as_joint_vector(q, name=f"poses.{name}",
                                                      path=cell.poses_path)
    all_routes = cell.route_table()
    asked = list(all_routes if routes is None else routes)
    check_names(asked, all_routes, path=None, key="route", what="route", error=InputError)
    keep = {r for name in asked for r in after_chain(all_routes, name)}
    chosen = {k: v for k, v in all_routes.items() if k in keep}
    options = PlanOptions(planner=PlannerOptions(seed=seed))
    return plan_cell(cell, options, routes=chosen)


def _ignore_sigint() -> None:
    # Ctrl-C in the terminal reaches the whole process group; the session stops the
    # worker itself, so the worker must not die with a traceback of its own.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class ProcessPlanBackend:
    """Plans in one spawned worker process (started on first use, then kept warm).

    Args:
        source: The scene folder, or a cell built in Python (its robot from
            :func:`~safepath.load_robot`: it is sent to the worker).
        seed: Planner seed.
    """

    def __init__(self, source: str | Path | Cell, *, seed: int = 0) -> None:
        self.source = source if isinstance(source, Cell) else str(Path(source).resolve())
        self.seed = seed
        self._executor: ProcessPoolExecutor | None = None

    def plan(self, poses: Mapping[str, np.ndarray], routes: Sequence[str] | None = None
             ) -> Future[dict[str, Trajectory]]:
        """See :class:`PlanBackend`."""
        if self._executor is None:
            self._executor = ProcessPoolExecutor(
                max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                initializer=_ignore_sigint)
        payload = {k: [float(v) for v in q] for k, q in poses.items()}
        # The worker is spawned on submit; it inherits this signal mask, so a Ctrl-C
        # during its start-up (before its initializer ignores SIGINT) cannot kill it
        # with a traceback. The parent gets a deferred Ctrl-C as usual.
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            return self._executor.submit(plan_in_worker, self.source, payload,
                                         None if routes is None else list(routes), self.seed)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)

    def close(self) -> None:
        """Stop the worker (a running job is abandoned)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None


class RuntimePlanBackend:
    """Adapter to ``safepath.runtime.RuntimePlanner`` (which plans in its own worker)."""

    def __init__(self, source: str | Path | Cell, *, seed: int = 0) -> None:
        from ..runtime import RuntimePlanner

        self.seed = seed
        self._planner: Any = RuntimePlanner(source)

    def plan(self, poses: Mapping[str, np.ndarray], routes: Sequence[str] | None = None
             ) -> Future[dict[str, Trajectory]]:
        """See :class:`PlanBackend` (it plans every route: the runtime has no subset)."""
        out: Future[dict[str, Trajectory]] = Future()

        def planned(done: Future) -> None:
            try:
                out.set_result(dict(done.result()))
            except BaseException as exc:  # handed over to the caller's future
                out.set_exception(exc)

        def updated(done: Future) -> None:
            try:
                done.result()
                self._planner.plan_cell(seed=self.seed).add_done_callback(planned)
            except BaseException as exc:
                out.set_exception(exc)

        self._planner.update_poses(dict(poses)).add_done_callback(updated)
        return out

    def close(self) -> None:
        """Stop the runtime planner."""
        close = getattr(self._planner, "close", None)
        if callable(close):
            close()


def make_backend(source: str | Path | Cell, *, kind: BackendKind = "auto", seed: int = 0
                 ) -> PlanBackend:
    """The planning backend of a scene folder or a cell: the runtime planner (``auto``,
    ``runtime``) or a process pool (``process``)."""
    if kind == "process":
        return ProcessPlanBackend(source, seed=seed)
    return RuntimePlanBackend(source, seed=seed)
