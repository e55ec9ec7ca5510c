"""The release criterion between samples: a certified lower bound on every clearance
pair's distance at every instant of the motion a controller executes, which must not be
negative.

Part of the verifier's independent geometry (:mod:`safepath.verify`): it reads the
verifier's own walk, its FCL distances and its own motion weights, nothing of the
planner's.

Why samples are not enough: the verifier judges the grid's samples, and a body moves at
most the resolution between two of them; the controller's join of the knots strays from
the straight joint segments the samples lie on by at most ``amax_j h^2 / 8`` in joint ``j``
for knots ``h`` apart (the join keeps ``|q''| <= amax``, which is checked before release).
So at every instant a pair's distance is at least the smaller of its two samples' minus
half the resolution and that stray. A pair kept a margin of 10 mm passes that with room
to spare; a pair whose object has no margin may come within a resolution of it at a
sample, and then the figure is negative: contact between the samples is not ruled out.

The finer check, where that figure is negative: the walk certifies every sample of every
clearance pair whose distance exceeds the resolution plus the stray (so that every
interval between two certified samples keeps half the resolution); for the samples it
leaves, FCL measures both ends of every interval they bound, and an interval whose bound
is still negative is halved (FCL measures the middle) until each part's bound is not
negative. An interval of states ``a`` to ``b`` whose distances FCL measured as ``d_a``,
``d_b``, over which the body's points move at most ``m`` (the verifier's motion weights
times the joints' motion), keeps at least
``max((d_a + d_b - m) / 2, max(d_a, d_b) - m)`` minus the stray: every state of it is
within ``x m`` of ``a`` and ``(1 - x) m`` of ``b``. An interval that cannot be made
non-negative (an end closer than the stray, or halved down to :data:`FINEST` of motion, or
the check's budget of FCL distances spent) makes the trajectory unprovable.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..errors import UnprovenClearance
from ._bounds import Grid

__all__ = ["FINEST", "BUDGET", "Between", "Probe", "bound_between", "clearance_bound",
           "interval_bound", "stray_of", "unproven"]

#: An interval is halved no finer than this much motion of the body's points [m].
FINEST = 1e-5
#: FCL distances the finer check may measure in one verification.
BUDGET = 20_000
#: Room above a threshold, as in the verifier's walk [m].
_SLACK = 1e-5


class Probe(Protocol):
    """What the finer check reads from one verification (the verifier's run)."""

    def walk(self, todo: np.ndarray, theta: np.ndarray,
             stretches: tuple[np.ndarray, np.ndarray]
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The conservative layer's walk of pairs ``todo`` against ``theta`` [m]: the
        couples (pairs, samples, bounds) it does not certify."""
        ...

    def distance(self, p: int, s: int) -> float:
        """FCL's distance of pair ``p`` at grid sample ``s`` [m]."""
        ...

    def distance_at(self, p: int, q: np.ndarray) -> float:
        """FCL's distance of pair ``p`` at the joint positions ``q`` [m]."""
        ...


@dataclass(frozen=True)
class Between:
    """The smallest certified bound between samples.

    Attributes:
        bound: A lower bound on every checked pair's distance at every instant [m]
            (inf: no clearance pair); negative where the finer check failed.
        pair: The pair of the smallest bound found (-1: none).
        sample: The grid sample its interval starts at (-1: none).
        checks: FCL distances the finer check measured.
        proven: Whether the bound is not negative.
    """

    bound: float
    pair: int = -1
    sample: int = -1
    checks: int = 0

    @property
    def proven(self) -> bool:
        """Whether contact between samples is ruled out."""
        return self.bound >= 0.0


def interval_bound(d_a: float, d_b: float, motion: float) -> float:
    """A lower bound on a pair's distance at every state of a straight joint segment [m],
    from its distances at the ends ``d_a``, ``d_b`` [m] and a bound ``motion`` [m] on how
    far the body's points move along it (each state is ``x motion`` from one end and
    ``(1 - x) motion`` from the other)."""
    return max((d_a + d_b - motion) / 2.0, max(d_a, d_b) - motion)


def stray_of(t: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """How far [m] each pair's moving body may stray, on each knot interval, from the
    straight joint segment between the knots: (pairs, knots); column ``k`` is the
    interval ending at knot ``k`` (column 0: the first knot, nothing).

    Args:
        t: Knot times [s].
        rate: Per pair, its body's motion weights times the joints' acceleration limits,
            over 8 [m/s^2].
    """
    h = np.diff(np.asarray(t, dtype=float), prepend=float(t[0]))
    return np.outer(rate, h * h)


def clearance_bound(probe: Probe, grid: Grid, knots: tuple[np.ndarray, np.ndarray],
                    entries: tuple[np.ndarray, ...], move: np.ndarray, amax: np.ndarray,
                    smallest: float, resolution: float) -> Between:
    """The certified clearance bound of a verification: the grid's figure if it is not
    negative, else the finer check's (:func:`bound_between`).

    The grid's figure: every sample is no closer than ``smallest`` minus half the
    resolution (the verifier measures its clearance to within that), every instant of
    the straight joint segments within half the resolution of a sample, and the
    executed motion within the stray of those (largest body weight times acceleration
    limits, largest knot interval).

    Args:
        probe: The verification's walk and FCL distances.
        grid: Its grid.
        knots: Its knot times [s] and positions [rad].
        entries: The clearance pairs and their stretches (see :func:`bound_between`).
        move: Per pair, its moving body's motion weights (pairs x dof) [m/rad].
        amax: The joints' acceleration limits [rad/s^2].
        smallest: The smallest clearance the verification found (or was given) [m].
        resolution: The grid's resolution [m].
    """
    t, q = knots
    if not len(entries[0]):
        return Between(float("inf"))
    rate = move @ np.asarray(amax, dtype=float) / 8.0
    h = float(np.max(np.diff(t))) if t.size > 1 else 0.0
    figure = smallest - resolution - float(rate[entries[0]].max()) * h * h
    if figure >= 0.0:
        return Between(figure)
    return bound_between(probe, grid, q, entries, move, stray_of(t, rate), resolution)


def unproven(between: Between, names: tuple[str, str], grid: Grid,
             knots: tuple[np.ndarray, np.ndarray], step: str | None) -> UnprovenClearance:
    """The error for a pair whose certified bound :func:`bound_between` could not make
    non-negative: its names, the bound, where its interval starts (knot times [s] and
    positions [rad] ``knots``) and the step."""
    t, q = knots
    s = between.sample
    k = int(grid.knot_of[s])
    time = float(t[k - 1] + grid.frac[s] * (t[k] - t[k - 1])) if k else float(t[0])
    return UnprovenClearance(
        f"certified clearance bound {between.bound * 1000:.4f} mm between {names[0]} / "
        f"{names[1]}: contact between two samples is not ruled out (the finer check "
        f"measured {between.checks} FCL distances, halving down to {FINEST * 1000:.2f} mm "
        "of motion)", pair=names, bound=between.bound, time=time, q=grid.state(q, s),
        step=step)


def bound_between(probe: Probe, grid: Grid, q: np.ndarray, entries: tuple[np.ndarray, ...],
                  move: np.ndarray, stray: np.ndarray, resolution: float) -> Between:
    """The finer check: a lower bound on the clearance pairs' distances at every instant.

    Args:
        probe: The verification's walk and FCL distances.
        grid: Its grid.
        q: Its knots [rad] (knots x dof).
        entries: The clearance pairs to check and their stretches of samples: (pairs,
            first sample, the one after the last).
        move: Per pair, its moving body's motion weights (pairs x dof) [m/rad].
        stray: :func:`stray_of` the knots, per pair (pairs x knots) [m].
        resolution: The grid's resolution [m].

    Returns:
        The smallest bound; the first interval (in time) that could not be made
        non-negative, if any.
    """
    todo, first, stop = (np.asarray(a, dtype=np.int64) for a in entries)
    if not todo.size:
        return Between(float("inf"))
    most = stray.max(axis=1)
    theta = np.full(len(move), np.inf)
    theta[todo] = resolution + most[todo] + _SLACK
    pairs, samples, _ = probe.walk(todo, theta, (first, stop))
    # Every interval between two certified samples keeps at least half the resolution.
    best = Between(resolution / 2.0)
    checks, measured = 0, dict[tuple[int, int], float]()

    def distance(p: int, s: int) -> float:
        if (p, s) not in measured:
            measured[p, s] = probe.distance(p, s)
        return measured[p, s]

    for p, a in _intervals(pairs, samples, todo, first, stop):
        k = int(grid.knot_of[a + 1])
        found, used = _refine(probe, p, (grid.state(q, a), grid.state(q, a + 1)),
                              (distance(p, a), distance(p, a + 1)), move[p],
                              float(stray[p, k]), BUDGET - checks)
        checks += used
        if found < best.bound:
            best = Between(found, p, a, checks)
        if found < 0.0:
            break
    return Between(best.bound, best.pair, best.sample, checks + len(measured))


def _intervals(pairs: np.ndarray, samples: np.ndarray, todo: np.ndarray, first: np.ndarray,
               stop: np.ndarray) -> list[tuple[int, int]]:
    """The intervals (pair, first sample) next to an uncertified couple, inside the
    stretch it was walked on, in time order."""
    stretches = defaultdict(list)
    for p, f, e in zip(todo.tolist(), first.tolist(), stop.tolist(), strict=True):
        stretches[p].append((f, e))
    out: set[tuple[int, int]] = set()
    for p, s in zip(pairs.tolist(), samples.tolist(), strict=True):
        for f, e in stretches[p]:
            if f <= s < e:
                out.update((p, a) for a in (s - 1, s) if f <= a and a + 1 < e)
    return sorted(out, key=lambda c: (c[1], c[0]))


def _refine(probe: Probe, p: int, ends: tuple[np.ndarray, np.ndarray],
            distances: tuple[float, float], weights: np.ndarray, stray: float,
            budget: int) -> tuple[float, int]:
    """Pair ``p``'s bound on the straight joint segment between the states ``ends``
    (their FCL distances ``distances``) [m], halving it until every part's is not
    negative; and the FCL distances measured. A negative bound: a part that cannot be
    made non-negative (the first found)."""
    stack = [(*ends, *distances)]
    worst, checks = float("inf"), 0
    while stack:
        q_a, q_b, d_a, d_b = stack.pop()
        motion = float(weights @ np.abs(q_b - q_a))
        bound = interval_bound(d_a, d_b, motion) - stray
        if bound >= 0.0:
            worst = min(worst, bound)
            continue
        if min(d_a, d_b) <= stray or motion <= FINEST or checks >= budget:
            return bound, checks
        q_m = 0.5 * (q_a + q_b)
        d_m = probe.distance_at(p, q_m)
        checks += 1
        stack += [(q_m, q_b, d_m, d_b), (q_a, q_m, d_a, d_m)]
    return worst, checks
