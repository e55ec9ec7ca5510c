"""Releasing a timed run: the knots stretched in time until their join is within every
limit as executed, and checked (:mod:`safepath.timing.path_timing` times the runs).

A uniform stretch in time scales the join exactly (speeds by ``1/k``, accelerations by
``1/k^2``, jerks by ``1/k^3``); the knots stay a whole number of nanoseconds apart, as a
goal carries them. Knots timed several knot periods apart are released as they are:
their join is the motion checked, and a goal adds points of that join where its
controller wants them closer (:func:`safepath.ros.joint_trajectory`: a quintic matched at
both ends of a part of a quintic is that part, so the motion stays the same).
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import TimingError
from ..model.execution import CHECK_RATE
from . import _smooth
from ._path_limits import PathLimits
from ._tcp_check import TcpLimits

__all__ = ["TimedPiece", "Run", "release", "interval_ratios", "stretch_knots", "stretch",
           "ns_grid", "RETIME_ABOVE"]

log = logging.getLogger("safepath.timing.path_timing")

#: Time stretch (relative, above 1) that the knots' excess over the limits would need,
#: above which the path is re-timed with locally tightened limits; a smaller excess is
#: removed by the uniform time stretch, which costs at most that fraction of the motion
#: time (a jerk excess ``e`` needs a stretch of ``e^(1/3)``, an acceleration excess
#: ``e^(1/2)``).
RETIME_ABOVE = 1e-2
#: Margin the final stretch leaves below every limit (relative), so that the released
#: ratios stay <= 1.0 however they are rounded.
_SLACK = 1e-6
#: The knots' ratios below this are only bounded (``Interpolation.ratios``' ``exact_from``):
#: the timing reads them only where they are over ``1 - _SLACK`` (to stretch, to
#: tighten, to release), so that it comes out the same as from the exact ones.
_EXACT_FROM = 0.999
_NS = 1_000_000_000


@dataclass(frozen=True)
class TimedPiece:
    """A rest-to-rest timed piece of path.

    Attributes:
        t: Knot times from 0 [s].
        q: Positions [rad] (N, dof).
        qd: Velocities [rad/s].
        qdd: Accelerations [rad/s^2].
        s: Path parameter of each knot.
        segment: Index of the input polyline segment of each knot.
        runs: TOPP-RA runs its timing took (1 when the first run's knots needed no more
            than a small time stretch; 0 for a closed-form straight move or a piece not
            timed by :func:`time_path`).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    s: np.ndarray
    segment: np.ndarray
    runs: int = 0


@dataclass(frozen=True)
class Run:
    """One timing: TOPP-RA, smoothed, sampled at the knots, and its executed peaks.

    Attributes:
        t: Knot times [s].
        s: Path parameter of each knot.
        sd: Path speed at each knot [1/s].
        q: Positions [rad].
        qd: Velocities [rad/s].
        qdd: Accelerations [rad/s^2].
        segment: Input segment of each knot.
        ratios: Per interval between knots, the largest speed, acceleration and jerk
            ratio of the quintic join (3, knots - 1).
        smoothed: The smoothed profile (maps knot times back to the profile's path);
            None for a closed-form straight motion.
    """

    t: np.ndarray
    s: np.ndarray
    sd: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    segment: np.ndarray
    ratios: np.ndarray
    smoothed: _smooth.Smoothed | None

    @functools.cached_property
    def stretch(self) -> float:
        """The time stretch that brings every ratio to just below 1 (at least 1)."""
        v, a, j = (float(r.max()) if r.size else 0.0 for r in self.ratios)
        return stretch(v, a, j)

    @property
    def stretched(self) -> float:
        """Its duration once stretched to meet every limit [s]."""
        return float(self.t[-1]) * self.stretch


def interval_ratios(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                     segment: np.ndarray, limits: PathLimits, at: np.ndarray | None = None
                     ) -> np.ndarray:
    """Per knot interval (those in ``at``, else all), the knots' join's largest speed,
    acceleration and jerk ratio (limits of the smaller-scaled of its two knots'
    segments), (3, intervals)."""
    if at is None:
        seg = _slower(segment[:-1], segment[1:], limits)
    else:  # the rows of the intervals read only
        seg = np.zeros(t.size - 1, dtype=np.int64)
        seg[at] = _slower(segment[at], segment[at + 1], limits)
    return limits.interpolation.ratios(t, q, qd, qdd, CHECK_RATE, seg, limits.vmax_seg,
                                       limits.amax_seg, limits.jmax_seg,
                                       exact_from=_EXACT_FROM, at=at)


def _slower(a: np.ndarray, b: np.ndarray, limits: PathLimits) -> np.ndarray:
    """Of segments ``a`` and ``b`` (element by element), the one with the smaller speed
    scale."""
    return np.where(limits.vmax_seg[a, 0] <= limits.vmax_seg[b, 0], a, b)


def _stretched_ratios(ratios: np.ndarray, k: float, t: np.ndarray, q: np.ndarray,
                      qd: np.ndarray, qdd: np.ndarray, segment: np.ndarray,
                      limits: PathLimits) -> np.ndarray:
    """The interval ratios (3, intervals) of knots ``(t, q, qd, qdd)`` that are knots of
    ``ratios`` stretched in time by ``k`` (:func:`stretch_knots`), in place of ``ratios``:
    computed again where ``ratios`` scaled by the stretch reach :data:`_EXACT_FROM` (or
    are NaN), elsewhere those scaled.

    A uniform stretch scales the join exactly (its speeds by ``1/k``, accelerations by
    ``1/k^2``, jerks by ``1/k^3``), so a bound of the unstretched join's peak, scaled, is
    a bound of the stretched one's; the knots' rounding moves a peak by ~1e-11 of it, far
    inside the 1e-3 below :data:`_EXACT_FROM`, and every ratio of :data:`_EXACT_FROM` or
    more is computed from the stretched knots themselves."""
    for row, power in zip(ratios, (k, k * k, k * k * k), strict=True):
        np.divide(row, power, out=row)
    at = _near_limit(ratios)
    if at.size:
        ratios[:, at] = interval_ratios(t, q, qd, qdd, segment, limits, at=at)
    return ratios


def _near_limit(ratios: np.ndarray) -> np.ndarray:
    """The intervals whose ratios (3, intervals) reach :data:`_EXACT_FROM` or are NaN:
    those whose ratios are only bounds below it are left out."""
    return np.flatnonzero(~(ratios.max(axis=0) < _EXACT_FROM))


def stretch_knots(t: np.ndarray, qd: np.ndarray, qdd: np.ndarray, k: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Evenly spaced knots slowed down by at least ``k`` >= 1: times times ``k'``, speeds
    over ``k'``, accelerations over ``k'^2`` (their quintic join's jerks over ``k'^3``),
    where ``k'`` is ``k`` rounded up so that the knots stay a whole number of nanoseconds
    apart. Returns the new ``t, qd, qdd`` and ``k'``."""
    stretched_ns, k = _rounded_stretch(t, k)
    return ns_grid(t.size, stretched_ns), qd / k, qdd / (k * k), k


def _rounded_stretch(t: np.ndarray, k: float) -> tuple[int, float]:
    """The knot step [ns] of evenly spaced knots ``t`` stretched by at least ``k``, and
    the stretch that gives it (``k`` rounded up to a whole ns of step)."""
    step_ns = _step_ns(t)
    stretched_ns = int(np.ceil(step_ns * k))
    return stretched_ns, stretched_ns / step_ns


def _step_ns(t: np.ndarray) -> int:
    """The step of evenly spaced knot times ``t`` [ns] (1 for a single knot)."""
    return round(float(t[1] - t[0]) * _NS) if t.size > 1 else 1


def _stretch_in_place(t: np.ndarray, qd: np.ndarray, qdd: np.ndarray, k: float) -> float:
    """:func:`stretch_knots` into the knots' own arrays (the release's: the large arrays of
    a long path are not allocated again); returns ``k'``."""
    stretched_ns, k = _rounded_stretch(t, k)
    np.divide(np.arange(t.size, dtype=np.int64) * stretched_ns, _NS, out=t)
    np.divide(qd, k, out=qd)
    np.divide(qdd, k * k, out=qdd)
    return k


def ns_grid(n: int, step_ns: int) -> np.ndarray:
    """``n`` times [s] from 0, ``step_ns`` nanoseconds apart (exact in nanoseconds)."""
    return np.arange(n, dtype=np.int64) * step_ns / _NS


def stretch(v_peak: float, a_peak: float, j_peak: float = 0.0) -> float:
    """The time stretch that brings the peak ratios to just below 1 (at least 1)."""
    return max(1.0, v_peak / (1.0 - _SLACK), float(np.sqrt(a_peak / (1.0 - _SLACK))),
               float(np.cbrt(j_peak / (1.0 - _SLACK))))


def _worst(ratios: np.ndarray, v_tcp: float) -> float:
    """The largest of the interval ratios (3, intervals) and the TCP's ratio; NaN if any
    is NaN."""
    return float(np.max(ratios, initial=v_tcp)) if ratios.size else v_tcp


def release(run: Run, limits: PathLimits, where: str, tcp: TcpLimits | None = None
            ) -> TimedPiece:
    """The run stretched in time just enough that its knots' join is within every
    limit (the TCP's speed limits too, ``tcp``), and checked. The run's knots and ratios
    are stretched in place: it is not used after its release."""
    t, qd, qdd, ratios = run.t, run.qd, run.qdd, run.ratios
    duration = float(t[-1])

    def tcp_ratio() -> float:
        if tcp is None:
            return 0.0
        sd = run.sd * (duration / float(t[-1])) if t[-1] > 0 else run.sd
        return tcp.ratio(t, run.q, qd, qdd, run.segment, run.s, sd)

    # Unstretched, the released knots are the run's own: their ratios are known already.
    v_tcp = tcp_ratio()
    k = max(run.stretch, stretch(v_tcp, 0.0))
    if k > 1.0:
        log.debug("timing up to %.4f %% over a limit; stretching time by %.6f",
                  (max(float(ratios.max()), v_tcp) - 1) * 100, k)
        k = _stretch_in_place(t, qd, qdd, k)
        ratios = _stretched_ratios(ratios, k, t, run.q, qd, qdd, run.segment, limits)
        v_tcp = tcp_ratio()
    ratios, v_tcp = _settle(t, run.q, qd, qdd, run.segment, ratios, v_tcp, limits,
                            tcp_ratio)
    worst = _worst(ratios, v_tcp)
    if not worst <= 1.0:  # also NaN
        raise TimingError(f"the {limits.interpolation} join of the timed knots is at "
                          f"{worst!r} of a limit" + where)
    return TimedPiece(t, run.q, qd, qdd, run.s, run.segment)


def _settle(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
            segment: np.ndarray, ratios: np.ndarray, v_tcp: float, limits: PathLimits,
            tcp_ratio: Callable[[], float]) -> tuple[np.ndarray, float]:
    """The knots stretched in place by the little more that rounding may still need (a
    stretch rounded to whole nanoseconds of step, a speed bound's sample count): up to
    three times, while the worst ratio lies in ``(1, 1 + RETIME_ABOVE)``; returns their
    ratios and TCP ratio."""
    worst = _worst(ratios, v_tcp)
    for _ in range(3):
        # The speed bound samples each interval at >= 1 kHz: a stretched interval may get
        # one more sample, which moves the bound by ~1e-7; stretch that much more.
        if worst <= 1.0 or not worst < 1.0 + RETIME_ABOVE:
            break
        v, a, j = (float(r.max()) if r.size else 0.0 for r in ratios)
        more = _stretch_in_place(t, qd, qdd, stretch(max(v, v_tcp), a, j))
        ratios = _stretched_ratios(ratios, more, t, q, qd, qdd, segment, limits)
        v_tcp = tcp_ratio()
        worst = _worst(ratios, v_tcp)
    return ratios, v_tcp

