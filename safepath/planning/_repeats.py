"""What a plan computes again, bit for bit, when the same cell is planned again.

A cell's node or quality-check cycle plans the same routes from the same poses in the
same world cycle after cycle: the same IK goals, the same straight TCP lines checked by
the same checker, the same seeded joint moves, the same blended splines through the same
points, checked at the same samples. Each of these is a pure function of its inputs, so
it is kept here, per process, by the exact bits of those inputs (the robot and checker
by identity: they are built once per cell; an IK goal also by the robot's kinematic
model and joint limits), and a second ask gets the first's answer (the same bits: plans
stay deterministic). Only successes are kept: a failure is computed again and raises with the
asker's own step name. The timed pieces and the independent release check are not kept:
every trajectory that leaves the library is re-checked (:mod:`safepath.verify`).

:func:`counts` says how many asks were answered from here (``hits``) and how many
computed (``misses``), so that a benchmark reports the first plan's cost apart.
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from typing import TypeVar

import numpy as np

from ..collision import CollisionChecker
from ..kinematics.ik import LineOptions
from ..model.robot import Robot

__all__ = ["ik_goal", "checked_line", "joint_path", "spline", "spline_free", "counts", "clear"]

T = TypeVar("T")
S = TypeVar("S")

#: Answers kept per robot or checker (the oldest dropped first): a cell's routes need a few
#: dozen; the bound keeps a long-running node that plans ever new goals from growing.
KEEP = 512

_LOCK = threading.Lock()
_KEPT: weakref.WeakKeyDictionary[object, OrderedDict[Hashable, object]] = \
    weakref.WeakKeyDictionary()
_COUNTS = {"hits": 0, "misses": 0}


def _kept(owner: object, key: Hashable, compute: Callable[[], T]) -> T:
    """The answer kept for ``key`` under ``owner``, else ``compute()``'s (then kept)."""
    with _LOCK:
        table = _KEPT.get(owner)
        if table is not None and key in table:
            table.move_to_end(key)
            _COUNTS["hits"] += 1
            return table[key]  # type: ignore[return-value]
    value = compute()  # outside the lock: a failure raises and keeps nothing
    with _LOCK:
        table = _KEPT.setdefault(owner, OrderedDict())
        table[key] = value
        while len(table) > KEEP:
            table.popitem(last=False)
        _COUNTS["misses"] += 1
    return value


def _bits(*arrays: np.ndarray) -> tuple[bytes, ...]:
    """The exact bits (float64, with the shape) of each array, as a key."""
    out: list[bytes] = []
    for a in arrays:
        b = np.ascontiguousarray(a, dtype=float)
        out += [str(b.shape).encode(), b.tobytes()]
    return tuple(out)


def ik_goal(robot: Robot, T_world_tcp: np.ndarray, q_init: np.ndarray, options: LineOptions,
            solve: Callable[[], np.ndarray]) -> np.ndarray:
    """The IK solution ``solve()`` finds for the TCP pose ``T_world_tcp`` (4x4) from
    ``q_init`` [rad] under ``options``: kept per robot, its kinematic model and joint
    limits (a robot whose limits change in place asks again; a copy is returned)."""
    key = ("ik", id(robot.model), *_bits(T_world_tcp, q_init, robot.lower, robot.upper),
           options)
    return _kept(robot, key, lambda: np.array(solve(), dtype=float)).copy()


def checked_line(checker: CollisionChecker, q: np.ndarray, goal: np.ndarray,
                 options: LineOptions, compute: Callable[[], list[np.ndarray]]
                 ) -> list[np.ndarray]:
    """The waypoints ``compute()`` gives (the straight TCP line from ``q`` to ``goal``
    [rad] under ``options``, found free by ``checker``): kept per checker (copies are
    returned)."""
    key = ("line", *_bits(q, goal), options)
    kept = _kept(checker, key, lambda: np.array(compute(), dtype=float))
    return list(kept.copy())


def joint_path(checker: CollisionChecker, q: np.ndarray, goal: np.ndarray,
               options: Hashable, compute: Callable[[], list[np.ndarray]]
               ) -> list[np.ndarray]:
    """The joint path ``compute()`` gives from ``q`` to ``goal`` [rad] in ``checker``'s
    world under the planner ``options`` (seeded: the same path every time): kept per
    checker (copies are returned)."""
    key = ("move", *_bits(q, goal), options)
    kept = _kept(checker, key, lambda: np.array(compute(), dtype=float))
    return list(kept.copy())


def spline(robot: Robot, waypoints: Sequence[np.ndarray], settings: Hashable,
           compute: Callable[[], S]) -> S:
    """The blended spline ``compute()`` makes through ``waypoints`` [rad] (with the
    corners and spline settings ``settings``): kept per robot whose paths it joins (the
    path object is shared: a path is read, never changed; its arrays are copies)."""
    key = ("spline", *_bits(np.asarray(waypoints, dtype=float)), settings)
    return _arrays_copied(_kept(robot, key, compute))


def _arrays_copied(value: S) -> S:
    """``value`` with its arrays (the items of a tuple) copied: a plan may write into
    what it is given, never into what later plans get (the kernels take writable
    arrays only, so kept ones cannot be made read-only)."""
    if not isinstance(value, tuple):
        return value
    return type(value)(v.copy() if isinstance(v, np.ndarray) else v  # type: ignore[return-value]
                       for v in value)


def spline_free(checker: CollisionChecker, samples: np.ndarray,
                check: Callable[[], bool]) -> bool:
    """Whether ``checker`` finds the polyline through ``samples`` [rad] free: ``check()``,
    kept per checker when it is (a blocked one is checked again on the next ask)."""
    key = ("spline free", *_bits(samples))
    try:
        return _kept(checker, key, lambda: True if check() else _raise_blocked())
    except _Blocked:
        return False


class _Blocked(Exception):
    """A check that found its path blocked (not kept)."""


def _raise_blocked() -> bool:
    raise _Blocked


def counts() -> dict[str, int]:
    """How many asks were answered from what was kept (``hits``) and how many were
    computed (``misses``), in this process (a copy)."""
    with _LOCK:
        return dict(_COUNTS)


def clear() -> None:
    """Forget every kept answer (a benchmark's cold start); the counts stay."""
    with _LOCK:
        _KEPT.clear()
