"""Joint-space planning with OMPL when the direct segment is blocked.

The planner (RRTConnect by default, any OMPL geometric planner by name) uses the
safepath checker for states and its own motion validator for edges, so every edge is
checked at the checker's guaranteed resolution (OMPL's default resolution is far too
coarse for arms). The path is then shortcut with our own seeded shortcutter, which
checks every new edge the same way.

Determinism: OMPL draws from one process-wide generator. Each call reseeds it from the
caller's seed under a lock, before any planner exists, and plans while holding that
lock, so a seed gives the same path in any process and any thread.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from ..collision import CollisionChecker
from ..errors import PlanningError
from . import _ompl
from .options import PLANNERS, PlannerOptions

__all__ = ["PlannerOptions", "plan_joint_path", "random_shortcuts", "shortcut", "default_range",
           "PLANNERS"]

log = logging.getLogger(__name__)

_OMPL_LOCK = threading.Lock()

#: Fraction of the joint-space diagonal that :func:`default_range` gives.
RANGE_FRACTION = 1.0 / 15.0
#: The fraction for RRTConnect, whose two trees grow towards each other (see
#: :func:`default_range`).
CONNECT_RANGE_FRACTION = 2.0 / 15.0


def default_range(lower: np.ndarray, upper: np.ndarray, planner: str = "RRT") -> float:
    """The extension range safepath's planners use unless told otherwise [rad].

    A fifteenth of the joint-space diagonal, each joint's span counted up to one turn
    (2π [rad]): a revolute joint that can turn twice round (the UR5's) reaches no new
    configuration of its link in the second turn, and OMPL's own rule (a fifth of the
    full diagonal, 5.8 rad for the UR5) makes the single-tree planners (RRT, RRTstar,
    ...) try edges so long that nearly all collide. This gives 0.73 rad for the Ned3
    Pro, 0.87 rad for the Panda and 1.03 rad for the UR5 (the fraction was chosen on a
    detour problem of each: ``tests/planning/test_planners.py``).

    RRTConnect gets twice that: its trees grow towards each other, and an edge that
    reaches further costs one longer check where two would be made. On the Panda set it
    plans, smooths and times faster with it, the motions as long, and three times the
    fifteenth went no faster (``benchmarks/panda_set.py --seeds 3`` measures it).

    Args:
        lower: Lower joint position limits [rad or m].
        upper: Upper joint position limits [rad or m].
        planner: The OMPL planner (see :data:`PLANNERS`).
    """
    span = np.minimum(np.asarray(upper, float) - np.asarray(lower, float), 2.0 * np.pi)
    fraction = CONNECT_RANGE_FRACTION if planner == "RRTConnect" else RANGE_FRACTION
    return float(fraction * np.linalg.norm(span))


def plan_joint_path(checker: CollisionChecker, q_start: np.ndarray, q_goal: np.ndarray, *,
                    options: PlannerOptions = PlannerOptions(),  # noqa: B008 (frozen)
                    step: str | None = None,
                    times: dict[str, float] | None = None) -> list[np.ndarray]:
    """A collision-free joint path from ``q_start`` to ``q_goal`` (a polyline).

    ``times``, if given, accumulates the seconds spent shortcutting under ``"shortcut"``
    (the rest is finding the path), and, when OMPL plans, the seconds to its first path
    under ``"first_path"`` and the trees it grew under ``"attempts"`` (a tree that finds
    no path within its iteration budget is dropped for a new one: see
    :mod:`safepath.planning._ompl`).

    Raises:
        PlanningError: Start or goal invalid (names the pair), or no path found.
        PlannerTimeout: The time budget ran out.
    """
    for label, q in (("start", q_start), ("goal", q_goal)):
        if not checker.is_valid(q):
            rep = checker.check(q)
            why = rep.limit_violation or "collision " + ", ".join(
                f"{a} / {b}" for a, b in rep.collisions)
            raise PlanningError(f"{label} state is invalid: {why}", step=step)
    if checker.segment_is_valid(q_start, q_goal):
        return [q_start.copy(), q_goal.copy()]
    extension = default_range(checker.robot.lower, checker.robot.upper, options.planner) \
        if options.range is None else options.range
    with _OMPL_LOCK:
        _seed_ompl(options.seed)
        found = _ompl.solve(checker, q_start, q_goal, options, extension, step)
    if times is not None:
        times["first_path"] = times.get("first_path", 0.0) + found.first_path_time
        times["attempts"] = times.get("attempts", 0.0) + found.attempts
    raw = found.path
    rng = np.random.default_rng(options.seed)
    t0 = time.perf_counter()
    path = shortcut(checker, raw, rng, iterations=options.shortcut_iterations,
                    min_gain=options.shortcut_min_gain)
    if times is not None:
        times["shortcut"] = times.get("shortcut", 0.0) + time.perf_counter() - t0
    return path


def _seed_ompl(seed: int) -> None:
    """Reseed OMPL's process-wide generator (before any planner of the call exists)."""
    from ompl import util as ou

    # Reseeding after the first time makes OMPL log an error it does not act on.
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)
    ou.setLogLevel(ou.LOG_ERROR)


def shortcut(checker: CollisionChecker, path: list[np.ndarray], rng: np.random.Generator, *,
             iterations: int = 100, min_gain: float = 0.02) -> list[np.ndarray]:
    """Shorten a valid polyline by random shortcuts, each checked at full resolution.

    First removes every vertex whose neighbours see each other (greedy, from the start),
    then tries ``iterations`` random shortcuts between points on two segments, checking
    only those that would shorten the path by at least ``min_gain`` of its length
    (joint-space Euclidean length).

    Every edge of the result is checked as it stands. A shortcut also keeps parts of the
    two segments it joins: new edges, whose grid states their segment's check did not
    cover (a state between two free grid states may collide). Most are cut again by
    later shortcuts, so the parts left at the end are checked then; should one fail, the
    shortcuts are made again from the same draws, each kept only if its parts pass.

    The draws of all iterations are made at once (four uniforms each: the two segments
    and the points on them), and the gains of all draws left are measured at once on the
    current path: Python steps only through the draws worth a check, and measures again
    after each accepted shortcut.
    """
    pts = [p.copy() for p in path]
    # Greedy vertex removal.
    i = 0
    while i < len(pts) - 2:
        if checker.segment_is_valid(pts[i], pts[i + 2], check_ends=False):
            del pts[i + 1]
        else:
            i += 1
    draws = rng.random((iterations, 4))
    out, checked = random_shortcuts(checker, pts, draws, min_gain, eager=False)
    if all(checked[i] or checker.segment_is_valid(out[i], out[i + 1], check_ends=False)
           for i in range(len(out) - 1)):
        return out
    return random_shortcuts(checker, pts, draws, min_gain, eager=True)[0]


def random_shortcuts(checker: CollisionChecker, pts: list[np.ndarray], draws: np.ndarray,
                     min_gain: float, eager: bool) -> tuple[list[np.ndarray], list[bool]]:
    """The random shortcuts :func:`shortcut` makes of the valid polyline ``pts`` [rad],
    and per edge of the result whether it was checked as it stands.

    Args:
        checker: The collision checker.
        pts: The polyline [rad].
        draws: One row per iteration: four uniforms in [0, 1) (the two segments, and
            the points on them).
        min_gain: Least share of the path's length a shortcut must save to be checked.
        eager: Keep a shortcut only if the kept parts of its two segments pass too.
    """
    checked = [True] * (len(pts) - 1)
    k, iterations = 0, len(draws)  # draws used
    while k < iterations and len(pts) >= 3:
        P = np.asarray(pts)  # noqa: N806
        lengths = _lengths(pts)
        ends = np.concatenate([[0.0], np.cumsum(lengths)])
        # Two different segments, the lower first, and a point on each.
        D = draws[k:]  # noqa: N806
        m = len(lengths)
        s1 = np.minimum((D[:, 0] * m).astype(np.int64), m - 1)
        s2 = np.minimum((D[:, 1] * (m - 1)).astype(np.int64), m - 2)
        s2 += s2 >= s1
        a, b = np.minimum(s1, s2), np.maximum(s1, s2)
        ta, tb = D[:, 2], D[:, 3]
        qa = P[a] + ta[:, None] * (P[a + 1] - P[a])
        qb = P[b] + tb[:, None] * (P[b + 1] - P[b])
        if min_gain > 0.0:
            replaced = (1.0 - ta) * lengths[a] + (ends[b] - ends[a + 1]) + tb * lengths[b]
            gain = replaced - np.linalg.norm(qb - qa, axis=1)
            worth = np.flatnonzero(gain >= min_gain * ends[-1])
        else:
            worth = np.arange(len(D))
        for j in worth.tolist():
            if not checker.segment_is_valid(qa[j], qb[j], check_ends=True):
                continue
            aj, bj = int(a[j]), int(b[j])
            if eager and not (
                    checker.segment_is_valid(pts[aj], qa[j], check_ends=False)
                    and checker.segment_is_valid(qb[j], pts[bj + 1], check_ends=False)):
                continue
            pts, checked = _without_repeats(
                pts[: aj + 1] + [qa[j].copy(), qb[j].copy()] + pts[bj + 1:],
                checked[:aj] + [eager, True, eager] + checked[bj + 1:])
            k += j + 1
            break
        else:
            break  # no draw left is worth a check, or none passed
    return pts, checked


def _lengths(pts: list[np.ndarray]) -> np.ndarray:
    """Joint-space length of every segment of a polyline [rad] (kept beside the path,
    recomputed only when a shortcut changes it)."""
    return np.linalg.norm(np.diff(np.asarray(pts), axis=0), axis=1)


def _without_repeats(pts: list[np.ndarray], checked: list[bool], tol: float = 1e-9
                     ) -> tuple[list[np.ndarray], list[bool]]:
    """The polyline without points closer than ``tol`` to the one before; the ends are
    kept exactly (a shortcut point that came within ``tol`` of the goal gives way to
    it: repeated shortcuts onto the last segment shrink it that far). ``checked`` (per
    edge) follows: an edge that a dropped point changed counts as not checked."""
    out, flags = [pts[0]], []
    for k in range(1, len(pts)):
        if np.max(np.abs(pts[k] - pts[k - 1])) > tol:
            # The edge from the point kept last: edge k - 1 itself if that is pts[k - 1].
            flags.append(checked[k - 1] and out[-1] is pts[k - 1])
            out.append(pts[k])
    if out[-1] is not pts[-1]:  # the goal was dropped for the point just before it
        if len(out) > 1:
            out[-1] = pts[-1]
            flags[-1] = False
        else:
            out.append(pts[-1])
            flags.append(False)
    return out, flags
