"""The planner worker: a child process that keeps one cell loaded and plans on request.

Protocol (pickled tuples over one duplex :class:`multiprocessing.connection.Connection`):

caller -> worker
    ``("poses", version, overlay)``: plan with these poses from now on (no reply);
    ``("job", job_id, kind, payload)``: ``kind`` is ``route``, ``cell``, ``replan`` or
    ``validate``;
    ``("stop",)``: exit.

worker -> caller
    ``("ready", 0, info)`` or ``("error", 0, ErrorRecord)`` once, after loading and
    warming up (``info["entries"]``: the pickled results of the warm-up plan, by cache
    key, planned with the loaded poses);
    ``("ok", job_id, (answer, entries))`` or ``("error", job_id, ErrorRecord)`` per job:
    ``answer`` is the pickled result, ``entries`` the pickled results the caller may
    cache, by cache key (a route plans the routes it follows too: each is an entry);
    ``("log", 0, LogRecord)`` any time (records of the ``safepath`` loggers).

The worker answers jobs one at a time, in order. It exits on ``stop``, when the caller
closes the pipe, or when the caller terminates it (a cancelled or timed-out job). It
keeps no results: the caller caches them, so that stopping a worker loses none.
"""

from __future__ import annotations

import dataclasses
import importlib
import logging
import os
import pickle
import signal
from collections.abc import Mapping
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from .._aot import PLANNING_MODULES
from ..cell import Cell, Route
from ..cell.routes import after_chain
from ..errors import PoseError
from ..files._io import check_names
from ..planning import PlanOptions, WorldState, plan_cell, plan_route
from ._transport import encode_error, picklable_record

__all__ = ["serve"]

#: Modules the planner imports lazily on its first plan; the worker imports them while
#: loading, so that the first plan runs as fast as the next ones. The kernel modules load
#: the kernels compiled ahead of time, or else numba (safepath._aot).
WARM_MODULES = ("ompl.base", "ompl.geometric", "ompl.util", *PLANNING_MODULES, "fcl",
                "coal", "scipy.spatial")

#: A result, and the results the caller may cache by key (see ``_core.Core._cache_key``).
Answer = tuple[Any, dict[tuple[Any, ...], Any]]


class _PipeHandler(logging.Handler):
    """Sends log records to the caller, which re-emits them through its own loggers."""

    def __init__(self, conn: Connection, level: int) -> None:
        super().__init__(level)
        self._conn = conn

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self._conn.send(("log", 0, picklable_record(record)))
        except Exception:  # noqa: BLE001 - a log record is never worth a failed plan
            pass


class _Worker:
    """The loaded cell and its routes."""

    def __init__(self, scene: Path | Cell, options: PlanOptions) -> None:
        from ..cell import load_cell

        self.cell = scene if isinstance(scene, Cell) else load_cell(scene)
        self.base_poses = dict(self.cell.poses)
        self.routes_path = self.cell.folder / "routes.yaml" if self.cell.folder else None
        self.routes: dict[str, Route] = self.cell.route_table()
        self.options = options
        self.version = 0
        for name in WARM_MODULES:
            try:
                importlib.import_module(name)
            except ImportError:
                pass

    # -- poses -----------------------------------------------------------------------------
    def set_poses(self, version: int, overlay: Mapping[str, np.ndarray]) -> None:
        """Plan with the loaded poses replaced by ``overlay`` (already validated)."""
        if version != self.version:
            self.cell.poses = {**self.base_poses, **overlay}
            self.version = version

    def validate(self, poses: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """The poses as joint vectors [rad], each checked like a taught pose, and
        collision-free as ``safepath check`` checks it (gripper empty, and holding the
        object where the scene says it may be held; the pose's allowed contacts apply)."""
        out: dict[str, np.ndarray] = {}
        for name, q in poses.items():
            check_names([name], self.base_poses, path=None, key=str(name), what="pose",
                        error=PoseError)
            out[name] = self.cell.robot.as_joint_vector(q, name=name)
            self._check_free(str(name), out[name])
        return out

    def _check_free(self, name: str, q: np.ndarray) -> None:
        grasp = self.cell.scene.grasp
        for held in (False, True) if grasp is not None and name in grasp.poses else (False,):
            report = self.cell.checker(held=held, at=name).check(q)
            if report.collisions:
                pairs = ", ".join(f"{a} / {b}" for a, b in report.collisions)
                holding = f" holding '{grasp.object}'" if held and grasp else ""
                raise PoseError(f"pose '{name}' is in collision{holding}: {pairs}", key=name)

    # -- planning --------------------------------------------------------------------------
    def _options(self, seed: int | None) -> PlanOptions:
        if seed is None:
            return self.options
        return dataclasses.replace(
            self.options, planner=dataclasses.replace(self.options.planner, seed=seed))

    def _route(self, name: str) -> Route:
        check_names([name], self.routes, path=self.routes_path, key="routes", what="route")
        return self.routes[name]

    def _chain(self, name: str) -> list[str]:
        """``name`` and the routes it follows (``after``), first one first."""
        self._route(name)  # an unknown name is refused naming the routes file
        return after_chain(self.routes, name)

    def plan_route(self, name: str, seed: int | None, world: WorldState | None) -> Answer:
        """One route, from ``world`` or from the end world of the routes it follows (all
        of them are entries)."""
        options = self._options(seed)
        seed_used = options.planner.seed
        if world is not None:
            traj = plan_route(self.cell, self._route(name), options, world=world)
            return traj, {("route", name, seed_used, world.key()): traj}
        chain = self._chain(name)
        planned = plan_cell(self.cell, options, routes={n: self.routes[n] for n in chain})
        return planned[name], {("route", n, seed_used, None): t for n, t in planned.items()}

    def plan_cell(self, seed: int | None) -> Answer:
        """Every route of the cell, in the order :func:`safepath.plan_cell` gives (the
        whole and each route are entries)."""
        options = self._options(seed)
        seed_used = options.planner.seed
        planned = plan_cell(self.cell, options, routes=self.routes)
        entries: dict[tuple[Any, ...], Any] = {
            ("route", n, seed_used, None): t for n, t in planned.items()}
        entries[("cell", seed_used)] = planned
        return planned, entries

    def replan(self, payload: dict[str, Any]) -> Any:
        """Around the request's obstacle back to the route (not cached: every obstacle
        is new)."""
        from ..monitor.replan import replan

        return replan(self.cell, payload["name"], payload["request"], held=payload["held"],
                      margin=payload["margin"], options=self._options(payload["seed"]),
                      world=payload["world"])

    def warm_up(self) -> dict[tuple[Any, ...], Any]:
        """Plan the cell once with the default seed, so that a worker is warm when it
        is first used (collision checkers and verifiers built, numba kernels loaded:
        a fresh worker's first plan takes seconds, the next ones tens of milliseconds).
        Returns the results as cache entries; none if the cell does not plan (the error
        comes back when a request asks for it)."""
        try:
            return self.plan_cell(None)[1]
        except Exception as exc:  # noqa: BLE001 - a request reports it, typed
            logging.getLogger(__name__).debug("warm-up plan failed: %s", exc)
            return {}

    def run(self, kind: str, payload: dict[str, Any]) -> Answer:
        """Carry out one job."""
        if kind == "route":
            return self.plan_route(payload["name"], payload["seed"], payload["world"])
        if kind == "cell":
            return self.plan_cell(payload["seed"])
        if kind == "replan":
            return self.replan(payload), {}
        if kind == "validate":
            return self.validate(payload["poses"]), {}
        raise ValueError(f"unknown job kind '{kind}'")


def _encode(answer: Answer) -> tuple[bytes, dict[tuple[Any, ...], bytes]]:
    """Pickle the result and the entries (an entry that is the result is pickled once)."""
    value, entries = answer
    pickled = {key: pickle.dumps(v, protocol=pickle.HIGHEST_PROTOCOL)
               for key, v in entries.items()}
    same = [pickled[key] for key, v in entries.items() if v is value]
    data = same[0] if same else pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    return data, pickled


def serve(conn: Connection, scene: Path | Cell, options: PlanOptions, log_level: int) -> None:
    """Entry point of the worker process: load the cell, then answer jobs until told to stop.

    Args:
        conn: This end of the pipe to the caller.
        scene: The scene folder, or a cell (unpickled here).
        options: Planning options (the seed of a job may override the planner's).
        log_level: Level of the caller's ``safepath`` logger; records at or above it are
            forwarded.
    """
    # Ctrl-C reaches the whole process group: the caller decides when the worker stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):  # blocked by the caller's slot thread
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    logger = logging.getLogger("safepath")
    logger.setLevel(log_level)
    logger.addHandler(_PipeHandler(conn, log_level))
    logger.propagate = False
    try:
        worker = _Worker(scene, options)
    except Exception as exc:  # noqa: BLE001 - every load failure goes back typed
        conn.send(("error", 0, encode_error(exc)))
        return
    entries = _encode((None, worker.warm_up()))[1]
    robot = worker.cell.robot
    conn.send(("ready", 0, {"pid": os.getpid(), "entries": entries,
                            "poses": list(worker.base_poses),
                            "routes": list(worker.routes),
                            "joints": (tuple(robot.joint_names), robot.lower.tolist(),
                                       robot.upper.tolist())}))
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the caller is gone
            return
        if message[0] == "stop":
            return
        if message[0] == "poses":
            worker.set_poses(message[1], message[2])
            continue
        _, job_id, kind, payload = message
        try:
            reply: tuple[str, int, Any] = ("ok", job_id, _encode(worker.run(kind, payload)))
        except Exception as exc:  # noqa: BLE001 - errors are results of the job
            reply = ("error", job_id, encode_error(exc))
        try:
            conn.send(reply)
        except (EOFError, OSError):
            return
        except Exception as exc:  # noqa: BLE001 - e.g. a result that does not pickle
            conn.send(("error", job_id, encode_error(exc)))
