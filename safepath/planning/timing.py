"""Time-optimal timing of a joint path with TOPP-RA, under the robot's limits, strictly.

The path (a polyline of joint waypoints) is interpolated by a cubic spline through
evenly spaced points, which rounds the corners a little (the caller re-checks the
spline for collisions and falls back to stopping at corners). TOPP-RA (our numba kernel
in :mod:`._topp`) then finds the fastest timing under joint velocity and acceleration
limits that vary along the path (each route step has its own speed scale and an optional
TCP speed limit), with a constant path acceleration between gridpoints.

TOPP-RA enforces the limits at its gridpoints (which follow the spline's pieces, see
:mod:`._path_limits`); the output knots between them may still exceed a limit a little.
Knots over a limit by more than :data:`RETIME_ABOVE` get the limits tightened around them
and the path is timed again (``retries`` runs in all); what is left is removed by
stretching time uniformly, which divides velocities by ``k`` and accelerations by
``k^2``. No released knot exceeds a limit: the ratios of the released knots are checked,
and a :class:`~safepath.errors.TimingError` is raised rather than release one over 1.0.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._knots import interval_index
from ..errors import TimingError
from ..robot import Robot
from . import _topp
from ._path_limits import PathLimits, PathSpline, path_limits, row_max
from ._spline import CubicPath

__all__ = ["TimingOptions", "TimedPiece", "PathSpline", "spline_path", "time_path",
           "rest_to_rest_time", "RETIME_ABOVE"]

log = logging.getLogger(__name__)

#: Relative excess of a limit on a knot above which the path is re-timed with locally
#: tightened limits; a smaller excess is removed by the uniform time stretch, which costs
#: at most that fraction of the motion time.
RETIME_ABOVE = 1e-3
#: Margin the final stretch leaves below every limit (relative), so that the released
#: ratios stay <= 1.0 however they are rounded.
_SLACK = 1e-9


@dataclass(frozen=True)
class TimingOptions:
    """Options of the time parameterisation.

    Attributes:
        speed_scale: Global fraction of the velocity and acceleration limits, in (0, 1].
        knot_period: Period of the output knots [s] (longer by the final stretch, if any).
        spacing: Spacing of the spline's interpolation points along the path [rad].
        grid_step: Largest spacing of TOPP-RA's gridpoints along the path [rad] (each
            spline piece is cut evenly). A finer grid gives faster motions (the path
            acceleration is constant between gridpoints) at a little more computation.
        retries: TOPP-RA runs (the first included) with locally tightened limits before
            the remaining excess is removed by stretching time.
        blend_radii: Blend radii tried at via points, largest first [rad]; 0 passes
            through the via pose exactly.
    """

    speed_scale: float = 1.0
    knot_period: float = 0.004
    spacing: float = 0.06
    grid_step: float = 0.005
    retries: int = 2
    blend_radii: tuple[float, ...] = (0.6, 0.3, 0.1, 0.0)

    def __post_init__(self) -> None:
        from ..errors import ConfigError

        if not 0 < self.speed_scale <= 1:
            raise ConfigError(f"speed_scale must lie in (0, 1], got {self.speed_scale}",
                              key="speed_scale")
        if not self.knot_period > 0:
            raise ConfigError(f"knot_period must be > 0, got {self.knot_period}",
                              key="knot_period")
        if not self.grid_step > 0:
            raise ConfigError(f"grid_step must be > 0, got {self.grid_step}", key="grid_step")
        if self.retries < 1:
            raise ConfigError(f"retries must be >= 1, got {self.retries}", key="retries")


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
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    s: np.ndarray
    segment: np.ndarray


def spline_path(waypoints: Sequence[np.ndarray], spacing: float, *,
                corners: Sequence[tuple[int, float]] = ()
                ) -> tuple[PathSpline, np.ndarray, np.ndarray]:
    """A cubic spline through a polyline resampled every ``spacing`` [rad].

    Args:
        waypoints: The polyline.
        spacing: Largest distance between interpolation points [rad].
        corners: Interior waypoints the spline may cut (via points), each with its
            blend radius [rad]: interpolation points closer than that to the corner
            (and the corner itself) are left out, so the spline rounds the corner
            instead of passing through it.

    Returns:
        The spline (not-a-knot, :class:`~safepath.planning._spline.CubicPath`, scipy's
        ``CubicSpline`` without its import cost), the path parameter of each input
        waypoint (its closest point for cut corners), and the spline's interpolation
        parameters.
    """
    W = np.asarray(waypoints, dtype=float)
    seg = np.linalg.norm(np.diff(W, axis=0), axis=1)
    s_way = np.concatenate([[0.0], np.cumsum(seg)])
    # Segment k gets m_k points, at fractions j / m_k (j = 1..m_k) of it.
    m = np.maximum(1, np.ceil(seg / spacing).astype(int))
    k = np.repeat(np.arange(seg.size), m)
    frac = (np.arange(k.size) - np.repeat(np.cumsum(m) - m, m) + 1) / m[k]
    P = np.vstack([W[:1], W[k] + frac[:, None] * (W[k + 1] - W[k])])
    S = np.concatenate([[0.0], s_way[k] + frac * seg[k]])
    if any(r > 0 for _, r in corners):
        keep = np.ones(len(S), dtype=bool)
        for c, r in corners:
            if 0 < c < len(W) - 1 and r > 0:
                keep &= ~(np.abs(S - s_way[c]) < r)
        keep[0] = keep[-1] = True
        P = P[keep]
        # Re-parametrise the kept points by chord length, and map the waypoints.
        chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        s_way = np.interp(s_way, S[keep], chord)
        S = chord
    if len(P) == 2:  # a straight line: a linear "spline"
        P = np.vstack([P[0], 0.5 * (P[0] + P[1]), P[1]])
        S = np.array([0.0, S[-1] / 2, S[-1]])
    path: PathSpline = CubicPath(S, P)
    return path, s_way, S


@dataclass(frozen=True)
class _Run:
    """One TOPP-RA run sampled at the knots (positions left out until released).

    Attributes:
        t: Knot times [s].
        s: Path parameter of each knot.
        qd: Velocities [rad/s].
        qdd: Accelerations [rad/s^2].
        segment: Input segment of each knot.
        v_ratio: Per knot, the largest |qd| / vmax (of its segment).
        a_ratio: Per knot, the largest |qdd| / amax.
    """

    t: np.ndarray
    s: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    segment: np.ndarray
    v_ratio: np.ndarray
    a_ratio: np.ndarray

    @property
    def stretched(self) -> float:
        """Its duration once stretched to meet every limit [s]."""
        return float(self.t[-1]) * _stretch(float(self.v_ratio.max()),
                                            float(self.a_ratio.max()))


def time_path(robot: Robot, path: PathSpline, s_way: np.ndarray, *, scales: Sequence[float],
              tcp_speeds: Sequence[float | None], options: TimingOptions = TimingOptions(),
              step: str | None = None) -> TimedPiece:
    """Time a spline path rest to rest, every knot within the limits.

    Args:
        robot: Limits and kinematics.
        path: Spline from :func:`spline_path`.
        s_way: Path parameter of the input waypoints (segment boundaries).
        scales: Speed scale of each input segment, in (0, 1].
        tcp_speeds: TCP speed limit of each input segment [m/s], or None.
        options: Timing options.
        step: Step name for errors.

    Raises:
        TimingError: TOPP-RA found no feasible timing, or a knot would break a limit.
    """
    where = f" (step '{step}')" if step else ""
    limits = path_limits(robot, path, s_way, scales, tcp_speeds,
                         speed_scale=options.speed_scale, grid_step=options.grid_step)
    # Knots between gridpoints may still exceed a limit a little: tighten the limits only
    # around those knots and time again, and keep the run that is fastest once stretched
    # to meet every limit.
    factor = np.ones(limits.grid.size)
    best: _Run | None = None
    for attempt in range(options.retries):
        run = _time_once(path, limits, factor, options.knot_period, where)
        if best is None or run.stretched < best.stretched:
            best = run
        per_knot = np.maximum(run.v_ratio, run.a_ratio)
        ratio = float(per_knot.max())
        if ratio <= 1.0 + RETIME_ABOVE or attempt + 1 == options.retries:
            break
        log.debug("timing attempt %d exceeds limits by %.3f %%; tightening locally", attempt,
                  (ratio - 1) * 100)
        _tighten(factor, limits.grid, run.s, per_knot)
    assert best is not None  # options.retries >= 1
    return _release(best, path, limits, where)


def _time_once(path: PathSpline, limits: PathLimits, factor: np.ndarray, knot_period: float,
               where: str) -> _Run:
    """One TOPP-RA run with the limits scaled by ``factor`` per gridpoint, sampled at knots."""
    x = _topp.solve(limits.grid, limits.at_grid.xmax * factor ** 2, *limits.rows(factor))
    if x is None:
        raise TimingError("TOPP-RA found no feasible timing" + where)
    profile = _topp.parametrize(limits.grid, x)
    duration = profile.duration
    if not (np.isfinite(duration) and duration > 0):
        raise TimingError(f"TOPP-RA gave a duration of {duration} s" + where)
    n = max(2, int(np.ceil(duration / knot_period)) + 1)
    t = np.linspace(0.0, duration, n)
    s, sd, sdd = _topp.evaluate(profile, t)
    ps, pss = path(s, 1), path(s, 2)
    qd = ps * sd[:, None]
    qdd = pss * (sd ** 2)[:, None] + ps * sdd[:, None]
    qd[0] = qd[-1] = 0.0  # at rest (not -0.0)
    segment = interval_index(limits.s_way, s, limits.vmax_seg.shape[0])
    return _Run(t, s, qd, qdd, segment, *_knot_ratios(qd, qdd, segment, limits))


def _knot_ratios(qd: np.ndarray, qdd: np.ndarray, segment: np.ndarray, limits: PathLimits
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per knot, the largest |qd|/vmax and the largest |qdd|/amax (of its segment)."""
    return (row_max(np.abs(qd) / limits.vmax_seg[segment]),
            row_max(np.abs(qdd) / limits.amax_seg[segment]))


def _tighten(factor: np.ndarray, grid: np.ndarray, s: np.ndarray, per_knot: np.ndarray
             ) -> None:
    """Scale the limits down around every knot over a limit (in place), by its excess."""
    over = per_knot > 1.0
    g = np.searchsorted(grid, s[over])
    target = 1.0 / (per_knot[over] * (1.0 + RETIME_ABOVE / 4))
    for offset in range(-2, 3):
        np.minimum.at(factor, np.clip(g + offset, 0, grid.size - 1), target)


def _stretch(v_peak: float, a_peak: float) -> float:
    """The time stretch that brings the peak ratios to just below 1 (at least 1)."""
    return max(1.0, v_peak / (1.0 - _SLACK), float(np.sqrt(a_peak / (1.0 - _SLACK))))


def _release(run: _Run, path: PathSpline, limits: PathLimits, where: str) -> TimedPiece:
    """The run stretched in time just enough that every knot is within its limits, checked."""
    k = _stretch(float(run.v_ratio.max()), float(run.a_ratio.max()))
    t, qd, qdd = run.t, run.qd, run.qdd
    v_ratio, a_ratio = run.v_ratio, run.a_ratio
    if k > 1.0:
        log.debug("timing up to %.4f %% over a limit; stretching time by %.6f",
                  (max(float(v_ratio.max()), float(a_ratio.max())) - 1) * 100, k)
        t, qd, qdd = t * k, qd / k, qdd / (k * k)
        v_ratio, a_ratio = _knot_ratios(qd, qdd, run.segment, limits)
    worst = max(float(v_ratio.max()), float(a_ratio.max()))
    if not worst <= 1.0:  # also NaN
        raise TimingError(f"a timed knot is at {worst!r} of its limit" + where)
    return TimedPiece(t, path(run.s), qd, qdd, run.s, run.segment)


def rest_to_rest_time(delta: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> float:
    """Time-optimal rest-to-rest duration of a straight joint move [s] (trapezoid)."""
    d = np.abs(np.asarray(delta, dtype=float))
    moving = d > 1e-12
    if not np.any(moving):
        return 0.0
    # Along the line, path speed <= min v_i/d_i, path acceleration <= min a_i/d_i (s in [0,1]).
    v = float(np.min(vmax[moving] / d[moving]))
    a = float(np.min(amax[moving] / d[moving]))
    if v * v / a >= 1.0:  # triangle profile
        return 2.0 * np.sqrt(1.0 / a)
    return 1.0 / v + v / a
