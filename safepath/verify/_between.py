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

The finer check, where that figure is negative: the verifier's walk holds every clearance
pair to at least the resolution plus the stray (:attr:`Strays.above`), so that it
certifies every sample whose distance exceeds that (and so does its own bound at a
sample it leaves, where that is higher), and every interval between two such samples
keeps half the resolution; for the samples left, FCL measures both ends of every
interval they bound, and an interval whose bound is still negative is halved (FCL
measures the middle) until each part's bound is not negative: all the intervals at
once, one halving after the other. An interval of states ``a`` to ``b`` whose distances
FCL measured as ``d_a``, ``d_b``, over which the body's points move at most ``m`` (the
verifier's motion weights times the joints' motion), keeps at least
``max((d_a + d_b - m) / 2, max(d_a, d_b) - m)`` minus the stray: every state of it is
within ``x m`` of ``a`` and ``(1 - x) m`` of ``b``. An interval that cannot be made
non-negative (an end closer than the stray, or halved down to :data:`FINEST` of motion, or
the check's budget of FCL distances spent) makes the trajectory unprovable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..errors import UnprovenClearance
from ._bounds import Grid

__all__ = ["FINEST", "BUDGET", "Between", "Probe", "Strays", "bound_between",
           "clearance_bound", "interval_bound", "unproven"]

#: An interval is halved no finer than this much motion of the body's points [m].
FINEST = 1e-5
#: FCL distances the finer check may measure in one verification.
BUDGET = 20_000
#: Room above a threshold, as in the verifier's walk [m].
_SLACK = 1e-5


class Probe(Protocol):
    """What the finer check reads from one verification (the verifier's run)."""

    def distances(self, p: int, samples: np.ndarray) -> np.ndarray:
        """FCL's distances of pair ``p`` at the grid samples ``samples`` [m]."""
        ...

    def distances_at(self, p: int, states: np.ndarray) -> np.ndarray:
        """FCL's distances of pair ``p`` at the joint positions ``states`` [m] (states x
        dof [rad])."""
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


def interval_bound(d_a: np.ndarray, d_b: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Lower bounds on pairs' distances at every state of straight joint segments [m],
    from their distances at the ends ``d_a``, ``d_b`` [m] and bounds ``motion`` [m] on
    how far the bodies' points move along them (each state is ``x motion`` from one end
    and ``(1 - x) motion`` from the other); one per segment."""
    return np.maximum((d_a + d_b - motion) / 2.0, np.maximum(d_a, d_b) - motion)


@dataclass(frozen=True)
class Strays:
    """How far each pair's moving body may stray from the straight joint segments between
    the knots (``amax_j h^2 / 8`` in joint ``j`` for knots ``h`` apart, weighted), and what
    the walk must prove of a clearance pair's samples for the finer check.

    Attributes:
        move: Per pair, its moving body's motion weights (pairs x dof) [m/rad].
        rate: Per pair, those times the joints' acceleration limits, over 8 [m/s^2].
        squares: Per knot, the square of the interval ending at it (0 at the first)
            [s^2].
        above: Per pair, the resolution plus its largest stray (plus slack) [m]: every
            interval between two samples whose distances exceed it keeps half the
            resolution.
    """

    move: np.ndarray
    rate: np.ndarray
    squares: np.ndarray
    above: np.ndarray

    @staticmethod
    def of(t: np.ndarray, move: np.ndarray, amax: np.ndarray, resolution: float) -> Strays:
        """The strays of knots at times ``t`` [s], for pairs whose bodies' motion weights
        are ``move`` [m/rad], with acceleration limits ``amax`` [rad/s^2], on a grid of
        ``resolution`` [m]."""
        rate = move @ np.asarray(amax, dtype=float) / 8.0
        h = np.diff(np.asarray(t, dtype=float), prepend=float(t[0]))
        squares = h * h
        return Strays(move, rate, squares, resolution + rate * squares.max() + _SLACK)

    def at(self, pairs: np.ndarray, knots: np.ndarray) -> np.ndarray:
        """The strays of pairs ``pairs`` on the intervals ending at knots ``knots`` [m]."""
        return self.rate[pairs] * self.squares[knots]  # type: ignore[no-any-return]


def clearance_bound(probe: Probe, grid: Grid, knots: tuple[np.ndarray, np.ndarray],
                    entries: tuple[np.ndarray, ...], left: tuple[np.ndarray, ...],
                    strays: Strays, smallest: float, resolution: float) -> Between:
    """The certified clearance bound of a verification: the grid's figure if it is not
    negative, else the finer check's (:func:`bound_between`).

    The grid's figure: every sample is no closer than ``smallest`` minus half the
    resolution (the verifier measures its clearance to within that), every instant of
    the straight joint segments within half the resolution of a sample, and the
    executed motion within the stray of those (largest body weight times acceleration
    limits, largest knot interval).

    Args:
        probe: The verification's FCL distances.
        grid: Its grid.
        knots: Its knot times [s] and positions [rad].
        entries: The clearance pairs and their stretches (see :func:`bound_between`).
        left: The couples its walk left (see :func:`bound_between`).
        strays: Its :class:`Strays`.
        smallest: The smallest clearance the verification found (or was given) [m].
        resolution: The grid's resolution [m].
    """
    t, q = knots
    if not len(entries[0]):
        return Between(float("inf"))
    h = float(np.max(np.diff(t))) if t.size > 1 else 0.0
    figure = smallest - resolution - float(strays.rate[entries[0]].max()) * h * h
    if figure >= 0.0:
        return Between(figure)
    return bound_between(probe, grid, q, entries, left, strays, resolution)


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
                  left: tuple[np.ndarray, ...], strays: Strays, resolution: float) -> Between:
    """The finer check: a lower bound on the clearance pairs' distances at every instant.

    Args:
        probe: The verification's FCL distances.
        grid: Its grid.
        q: Its knots [rad] (knots x dof).
        entries: The clearance pairs to check and their stretches of samples: (pairs,
            first sample, the one after the last).
        left: The couples (pairs, samples, bounds [m]) the verification's walk did not
            certify; it held each clearance pair to at least ``strays.above``: every
            other sample's distance exceeds that, and so does that of a couple whose
            bound (the walk's lower bound at its sample) does.
        strays: The verification's :class:`Strays`.
        resolution: The grid's resolution [m].

    Returns:
        The smallest bound and its interval; or, if an interval could not be made
        non-negative, the first such interval (in time) found at the halving where one
        was found, with its smallest part's bound.
    """
    todo, first, stop = (np.asarray(a, dtype=np.int64) for a in entries)
    if not todo.size:
        return Between(float("inf"))
    pairs, samples, bounds = left
    checked = np.zeros(len(strays.move), dtype=bool)
    checked[todo] = True
    keep = checked[pairs] & ~(bounds > strays.above[pairs])  # (a NaN bound is kept)
    pairs, samples = pairs[keep], samples[keep]
    pair, start = _intervals(pairs, samples, (todo, first, stop), len(strays.move))
    (d_a, d_b), measured = _end_distances(probe, pair, start)
    parts = _Parts(np.arange(pair.size), pair, grid.states(q, start),
                   grid.states(q, start + 1), d_a, d_b,
                   strays.at(pair, grid.knot_of[start + 1]))
    found, failed, checks = _refine(probe, parts, strays.move)
    checks += measured
    if failed >= 0:
        return Between(float(found[failed]), int(pair[failed]), int(start[failed]), checks)
    # Every interval between two certified samples keeps at least half the resolution.
    k = int(np.argmin(found)) if found.size else -1
    if k < 0 or found[k] >= resolution / 2.0:
        return Between(resolution / 2.0, checks=checks)
    return Between(float(found[k]), int(pair[k]), int(start[k]), checks)


def _intervals(pairs: np.ndarray, samples: np.ndarray, entries: tuple[np.ndarray, ...],
               count: int) -> tuple[np.ndarray, np.ndarray]:
    """The intervals (pairs, first samples) next to the uncertified couples (``pairs``,
    ``samples``), inside the stretch each was walked on (``entries``: pairs, first
    sample, the one after the last), in time order (then by pair, of ``count``)."""
    todo, first, stop = entries
    keys = [np.empty(0, dtype=np.int64)]
    for p in np.unique(pairs).tolist():
        s = samples[pairs == p]
        for f, e in zip(first[todo == p].tolist(), stop[todo == p].tolist(), strict=True):
            inside = s[(f <= s) & (s < e)]
            a = np.concatenate([inside - 1, inside])
            keys.append(a[(f <= a) & (a + 1 < e)] * count + p)
    key = np.unique(np.concatenate(keys))
    return key % count, key // count


def _end_distances(probe: Probe, pair: np.ndarray, start: np.ndarray
                   ) -> tuple[tuple[np.ndarray, np.ndarray], int]:
    """FCL's distances of each interval's pair at its two ends [m] (each sample of a
    pair measured once), and how many were measured."""
    d_a, d_b = np.empty(pair.size), np.empty(pair.size)
    measured = 0
    for p in np.unique(pair).tolist():
        at = np.flatnonzero(pair == p)
        ends = np.union1d(start[at], start[at] + 1)
        d = probe.distances(p, ends)
        i = np.searchsorted(ends, start[at])  # and the sample after is the next end
        d_a[at], d_b[at] = d[i], d[i + 1]
        measured += ends.size
    return (d_a, d_b), measured


@dataclass(frozen=True)
class _Parts:
    """Straight joint segments of the intervals, each with its pair's FCL distances at
    its ends.

    Attributes:
        interval: The interval each is part of.
        pair: Its pair.
        q_a, q_b: Its ends [rad] (parts x dof).
        d_a, d_b: The pair's FCL distances there [m].
        stray: How far its pair's body may stray from it [m].
    """

    interval: np.ndarray
    pair: np.ndarray
    q_a: np.ndarray
    q_b: np.ndarray
    d_a: np.ndarray
    d_b: np.ndarray
    stray: np.ndarray

    def halves(self, rows: np.ndarray, d_m: np.ndarray) -> _Parts:
        """Parts ``rows`` halved, FCL's distances at their middles being ``d_m``."""
        q_m = self.middles(rows)
        return _Parts(np.tile(self.interval[rows], 2), np.tile(self.pair[rows], 2),
                      np.concatenate([self.q_a[rows], q_m]),
                      np.concatenate([q_m, self.q_b[rows]]),
                      np.concatenate([self.d_a[rows], d_m]),
                      np.concatenate([d_m, self.d_b[rows]]), np.tile(self.stray[rows], 2))

    def middles(self, rows: np.ndarray) -> np.ndarray:
        """The middles of parts ``rows`` [rad]."""
        return 0.5 * (self.q_a[rows] + self.q_b[rows])  # type: ignore[no-any-return]


def _refine(probe: Probe, parts: _Parts, move: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The intervals' bounds [m], halving every part whose bound is negative (FCL
    measures its middle) until each part's is not, all intervals together, one halving
    after the other; the first interval (in time) found that cannot be made
    non-negative (a part closer than its stray at an end, or of no more than
    :data:`FINEST` motion, or the budget spent; -1: none, its bound is its smallest
    part's); and the FCL distances measured."""
    found = np.full(int(parts.interval.max(initial=-1)) + 1, np.inf)
    checks = 0
    while parts.pair.size:
        motion = np.einsum("ij,ij->i", move[parts.pair], np.abs(parts.q_b - parts.q_a))
        bound = interval_bound(parts.d_a, parts.d_b, motion) - parts.stray
        done = bound >= 0.0
        np.minimum.at(found, parts.interval[done], bound[done])
        split = np.flatnonzero(~done)
        stuck = split[(np.minimum(parts.d_a[split], parts.d_b[split]) <= parts.stray[split])
                      | (motion[split] <= FINEST)]
        if stuck.size or checks + split.size > BUDGET:
            first = int(parts.interval[stuck if stuck.size else split].min())
            found[first] = bound[split][parts.interval[split] == first].min()
            return found, first, checks
        d_m = np.empty(split.size)
        for p in np.unique(parts.pair[split]).tolist():
            rows = np.flatnonzero(parts.pair[split] == p)
            d_m[rows] = probe.distances_at(p, parts.middles(split[rows]))
        checks += split.size
        parts = parts.halves(split, d_m)
    return found, -1, checks
