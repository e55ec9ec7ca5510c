"""Planning in worker processes, answered through ``concurrent.futures.Future``.

OMPL, Pinocchio, coal and TOPPRA hold the interpreter lock while they compute, so a plan
run on a thread of the caller's process delays every other thread of it (a ROS 2
executor, a viser server): by the interpreter's switch interval at each hand-over, and
by the whole call during a long native call (``benchmarks/runtime_heartbeat.py``
measures it). :class:`RuntimePlanner` plans in worker processes instead: each loads the
cell and its routes once and keeps them loaded; the caller's threads only send requests
and unpickle answers (about 1 ms for the three routes of the bundled cell).

Lifecycle: the workers start in the background as soon as the planner is built (about
1 s: imports, loading, warm-up), so the first plan is answered sooner. Then one more,
a warm spare, loads: a request that is cancelled or times out while it plans stops its
worker (native code cannot be interrupted otherwise), and the spare takes its place at
once while a new spare loads. ``ready()`` tells when the workers and the spare are
loaded (until the spare is, a stopped worker's replacement has to load first).
Results are cached in this process (per poses, seed and world), so stopping a worker
loses none, and a request the cache holds is answered without a worker. ``close()`` (or
leaving a ``with`` block) cancels what is queued or running and stops the workers. A
planner that is garbage-collected without ``close()`` finishes the work already asked
for, then stops its workers; at interpreter exit every worker is stopped and reaped.

Like any ``spawn`` multiprocessing, the worker imports the caller's main module: a
script must keep its entry point under ``if __name__ == "__main__":``.
"""

from __future__ import annotations

import math
import operator
import threading
import weakref
from collections.abc import Mapping
from concurrent.futures import Future
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import numpy as np

from ..cell import Cell
from ..errors import ConfigError, InputError, PoseError
from ..model.trajectory import Trajectory
from ..planning import PlanOptions, WorldState
from ._core import Core, RuntimeStats

__all__ = ["RuntimePlanner", "RuntimeStats"]


class RuntimePlanner:
    """Plans a cell's routes in worker processes; every request returns a Future.

    Thread-safe: any thread may call any method. Results equal those of
    :func:`safepath.plan_cell` in the caller's process for the same seed, array for
    array. Done-callbacks of the returned futures run on a short-lived thread of the
    planner; they may block, and may even wait for other requests of the same planner.

    ``future.cancel()`` succeeds until the answer is in (``future.running()`` stays False
    meanwhile): a request not yet started is dropped, a running one stops its worker,
    which a warm spare replaces at once.

    Args:
        scene: The scene folder (``scene.yaml``, ``poses.yaml``, ``routes.yaml``), or a
            :class:`~safepath.cell._cell.Cell` with its routes (built in Python; its robot must
            come from :func:`~safepath.load_robot`, which the workers call again; its
            locked joints and any limits, TCP frame, tool or controller changed since
            travel with it, see :data:`safepath.description.robot_folder.CARRIED`).
        options: Planning options (default: ``PlanOptions()``).
        workers: Worker processes; requests are spread over them, each runs one at a time.
        start_method: ``spawn`` (default) or ``forkserver``; never ``fork``, which is
            unsafe in a process with threads (rclpy, viser).
        spare: Keep one more worker loaded, to replace at once a worker stopped by a
            cancelled or timed-out request (it costs the memory of one worker process;
            without it the next request waits one to three seconds for a new worker).

    Raises:
        ConfigError: The scene folder does not exist, or the cell's robot was built in
            Python (it cannot be sent to a worker process).
        InputError: ``workers`` or ``start_method`` is invalid.

    Example::

        planner = RuntimePlanner("scenes/quality_check_cell")   # workers start now
        future = planner.plan_route("phase1", timeout=10.0)
        future.add_done_callback(on_planned)                     # never blocks the caller
        ...
        planner.close()                                          # at shutdown
    """

    def __init__(self, scene: str | Path | Cell, *, options: PlanOptions | None = None,
                 workers: int = 1,
                 start_method: Literal["spawn", "forkserver"] = "spawn",
                 spare: bool = True) -> None:
        source: Path | Cell
        if isinstance(scene, Cell):
            import pickle

            pickle.dumps(scene)  # a robot built in Python cannot reach the workers: say so now
            source = scene
        else:
            source = Path(scene).expanduser().resolve()
            if not source.is_dir():
                raise ConfigError("scene folder not found", path=source)
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise InputError(f"workers must be an integer >= 1, got {workers!r}", key="workers")
        if start_method not in ("spawn", "forkserver"):
            raise InputError(f"start_method must be 'spawn' or 'forkserver', got "
                             f"{start_method!r}", key="start_method")
        if not isinstance(spare, bool):
            raise InputError(f"spare must be True or False, got {spare!r}", key="spare")
        if options is not None and not isinstance(options, PlanOptions):
            raise InputError(f"options must be PlanOptions, got {type(options).__name__}",
                             key="options")
        self.scene = source
        self.options = options or PlanOptions()
        self._core = Core(source, self.options, workers, start_method, spares=int(spare))
        self._finalizer = weakref.finalize(self, self._core.release)
        self._finalizer.atexit = False  # _close_all stops the workers at exit

    # -- requests --------------------------------------------------------------------------
    def plan_route(self, name: str, *, seed: int | None = None, timeout: float | None = None,
                   world: WorldState | None = None) -> Future[Trajectory]:
        """Plan, time and verify one route.

        Without ``world`` the route starts in the world its ``after`` chain leaves (the
        routes it follows are planned too, and cached), exactly as in
        :func:`safepath.plan_cell`. Results are cached in this process per poses, seed and
        world: asking again is answered at once (about a millisecond to unpickle), also
        after a cancelled or timed-out request.

        Args:
            name: Route name in ``routes.yaml``.
            seed: Planner seed (default: the options' seed).
            timeout: Time budget [s] counted from this call: when it runs out the future
                fails with ``PlannerTimeout`` (within a few milliseconds), wherever the
                request is (queued, waiting for a worker, or planning: then its worker
                is stopped and replaced); None: no limit.
            world: World state at the start, instead of the ``after`` chain's.

        Returns:
            A future of the trajectory. It fails with the library's typed errors
            (``ConfigError`` for an unknown route, ``PlanningError``, ``TimingError``,
            ``VerificationError``), ``PlannerTimeout`` when ``timeout`` runs out, or
            :class:`WorkerError` when the worker dies.
        """
        if world is not None and not isinstance(world, WorldState):
            raise InputError(f"world must be a WorldState, got {type(world).__name__}",
                             key="world")
        payload = {"name": str(name), "seed": _seed(seed), "world": world}
        return self._core.submit("route", payload, _timeout(timeout), f"route '{name}'")

    def replan(self, route: str, request: Any, *, held: str | None, margin: float,
               world: WorldState | None = None, seed: int | None = None,
               timeout: float | None = None) -> Future[Trajectory]:
        """Plan around an extra obstacle: from a monitor's re-plan request (rest state,
        obstacle box) back to route ``route``, as :func:`safepath.monitor.replan.replan`
        does in this process, on a warm worker. Not cached (every request is new).

        Args:
            route: Route name in ``routes.yaml`` (a re-planned route's name is understood
                as its original's).
            request: A :class:`~safepath.monitor.ReplanRequest`.
            held: Object held at the rest state, or None.
            margin: Clearance the new path keeps from the obstacle box [m].
            world: World state at the rest state (default: the scene's, with ``held``).
            seed: Planner seed (default: the options' seed).
            timeout: Time budget from this call [s], as in :meth:`plan_route`.

        Returns:
            A future of the trajectory; it fails with ``PlanningError`` saying why no way
            was found (every way tried), or as :meth:`plan_route`'s.

        Raises:
            InputError: ``request`` is not a ReplanRequest, or ``world`` not a WorldState.
        """
        from ..monitor import ReplanRequest

        if not isinstance(request, ReplanRequest):
            raise InputError(f"request must be a ReplanRequest, got {type(request).__name__}",
                             key="request")
        if world is not None and not isinstance(world, WorldState):
            raise InputError(f"world must be a WorldState, got {type(world).__name__}",
                             key="world")
        payload = {"name": str(route), "seed": _seed(seed), "world": world,
                   "request": request, "held": held, "margin": float(margin)}
        return self._core.submit("replan", payload, _timeout(timeout),
                                 f"re-plan of route '{route}'")

    def plan_cell(self, *, seed: int | None = None, timeout: float | None = None
                  ) -> Future[dict[str, Trajectory]]:
        """Plan every route of the cell, like :func:`safepath.plan_cell`.

        Args:
            seed: Planner seed (default: the options' seed).
            timeout: Time budget from this call [s], as in :meth:`plan_route`; None: no
                limit.

        Returns:
            A future of the trajectories by route name (failures as in :meth:`plan_route`).
        """
        return self._core.submit("cell", {"seed": _seed(seed)}, _timeout(timeout),
                                 "the cell's routes")

    def update_poses(self, poses: Mapping[str, Any]) -> Future[None]:
        """Replace taught poses for every later request (an edit in the browser).

        The given poses replace those of the same name; the others are kept. Each is
        validated like a taught pose (known name, joint count, finite, inside the limits)
        and checked collision-free as ``safepath check`` checks it, in a worker. A
        failed or cancelled update changes nothing. Requests made after
        this call plan with the new poses; requests made before it do not.

        Args:
            poses: Joint vectors by pose name [rad].

        Returns:
            A future that fails with ``PoseError`` (naming the pose, and the colliding
            pair for a pose in collision) if a pose is invalid.

        Raises:
            PoseError: ``poses`` is not a mapping.
        """
        if not isinstance(poses, Mapping):
            raise PoseError(f"expected a mapping of pose names to joint vectors, got "
                            f"{type(poses).__name__}")
        copied = {name: _copy(q) for name, q in poses.items()}
        try:  # a bad name, length or value is answered at once, whatever the workers do
            self._core.precheck(copied)
        except PoseError as exc:
            refused: Future[None] = Future()
            refused.set_exception(exc)
            return refused
        return self._core.submit("validate", {"poses": copied}, None, "the pose update")

    def ready(self) -> Future[None]:
        """A future that is done when every worker has loaded the cell and so has the
        warm spare (with ``spare=True``), so that a request cancelled from then on is
        replaced at once; or when a worker failed to load: then it carries the load
        error, e.g. a ``ConfigError`` naming the file. After a cancelled or timed-out
        request, ``ready()`` waits again for the new spare."""
        out: Future[None] = Future()
        loaded = [slot.loaded for slot in self._core.slots]
        lock = threading.Lock()
        left = [len(loaded)]

        def one_done(_: Future[None]) -> None:
            with lock:
                left[0] -= 1
                if left[0]:
                    return
            for f in loaded:
                if f.exception() is not None:
                    out.set_exception(f.exception())  # type: ignore[arg-type]
                    return
            # The spare loads after the workers (not competing with them for the CPUs).
            self._core.launcher.warm().add_done_callback(lambda _: out.set_result(None))

        for f in loaded:
            f.add_done_callback(one_done)
        return out

    def stats(self) -> RuntimeStats:
        """Counters and worker process ids (a snapshot)."""
        return self._core.stats()

    # -- lifecycle -------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._core.closing

    def close(self) -> None:
        """Cancel queued and running requests, stop the workers and reap them.

        Idempotent. Waits for the worker threads (a running plan is terminated, not
        awaited), so no worker process is left behind when it returns.
        """
        self._finalizer.detach()
        self._core.close()

    def __enter__(self) -> RuntimePlanner:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"{len(self._core.slots)} worker(s)"
        return f"RuntimePlanner({str(self.scene)!r}, {state})"


def _seed(seed: int | None) -> int | None:
    if seed is None:
        return None
    try:
        return operator.index(seed)
    except TypeError:
        raise InputError(f"seed must be an integer, got {seed!r}", key="seed") from None


def _timeout(timeout: float | None) -> float | None:
    if timeout is None:
        return None
    try:
        value = float(timeout)
    except (TypeError, ValueError):
        value = float("nan")
    if not value > 0:
        raise InputError(f"timeout must be > 0 [s], got {timeout!r}", key="timeout")
    return None if math.isinf(value) else value


def _copy(q: Any) -> Any:
    """A private copy of a joint vector, so that later edits by the caller do not leak in
    (anything that is not numeric goes as is: the worker reports it as a PoseError)."""
    try:
        return np.array(q, dtype=float)
    except (TypeError, ValueError):
        return q
