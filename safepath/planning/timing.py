"""Time-optimal timing of a joint path with TOPPRA, under the robot's limits.

The path (a polyline of joint waypoints) is interpolated by a cubic spline through
evenly spaced points, which rounds the corners a little (the caller re-checks the
spline for collisions and falls back to stopping at corners). TOPPRA then finds the
fastest timing under joint velocity and acceleration limits that vary along the path
(each route step has its own speed scale and an optional TCP speed limit), with the
``ParametrizeConstAccel`` parametrizer, which respects the limits. The output is
sampled and checked: no sample may exceed a limit by more than ``tolerance``; if one
does, the limits are tightened by the excess and the timing is redone.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import TimingError
from ..robot import Robot

__all__ = ["TimingOptions", "TimedPiece", "spline_path", "time_path", "rest_to_rest_time"]

log = logging.getLogger(__name__)
logging.getLogger("toppra").setLevel(logging.WARNING)


@dataclass(frozen=True)
class TimingOptions:
    """Options of the time parameterisation.

    Attributes:
        speed_scale: Global fraction of the velocity and acceleration limits, in (0, 1].
        knot_period: Period of the output knots [s].
        spacing: Spacing of the spline's interpolation points along the path [rad].
        grid_step: Spacing of TOPPRA's grid along the path [rad].
        tolerance: Allowed relative excess of a limit on a sample (0.001 = 0.1 %).
        retries: TOPPRA runs with locally tightened limits before time is stretched.
        blend_radii: Blend radii tried at via points, largest first [rad]; 0 passes
            through the via pose exactly.
    """

    speed_scale: float = 1.0
    knot_period: float = 0.004
    spacing: float = 0.06
    grid_step: float = 0.015
    tolerance: float = 0.001
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
                ) -> tuple[object, np.ndarray, np.ndarray]:
    """A cubic spline through a polyline resampled every ``spacing`` [rad].

    Args:
        waypoints: The polyline.
        spacing: Largest distance between interpolation points [rad].
        corners: Interior waypoints the spline may cut (via points), each with its
            blend radius [rad]: interpolation points closer than that to the corner
            (and the corner itself) are left out, so the spline rounds the corner
            instead of passing through it.

    Returns:
        The toppra spline, the path parameter of each input waypoint (its closest
        point for cut corners), and the spline's interpolation parameters.
    """
    import toppra as ta

    W = np.asarray(waypoints, dtype=float)
    seg = np.linalg.norm(np.diff(W, axis=0), axis=1)
    s_way = np.concatenate([[0.0], np.cumsum(seg)])
    pts, ss = [W[0]], [0.0]
    for k in range(len(W) - 1):
        m = max(1, int(np.ceil(seg[k] / spacing)))
        for j in range(1, m + 1):
            pts.append(W[k] + (j / m) * (W[k + 1] - W[k]))
            ss.append(s_way[k] + (j / m) * seg[k])
    P, S = np.asarray(pts), np.asarray(ss)
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
    path = ta.SplineInterpolator(S, P, bc_type="not-a-knot")
    return path, s_way, S


def time_path(robot: Robot, path: object, s_way: np.ndarray, *, scales: Sequence[float],
              tcp_speeds: Sequence[float | None], options: TimingOptions = TimingOptions(),
              step: str | None = None) -> TimedPiece:
    """Time a spline path rest to rest.

    Args:
        robot: Limits and kinematics.
        path: Spline from :func:`spline_path`.
        s_way: Path parameter of the input waypoints (segment boundaries).
        scales: Speed scale of each input segment, in (0, 1].
        tcp_speeds: TCP speed limit of each input segment [m/s], or None.
        options: Timing options.
        step: Step name for errors.

    Raises:
        TimingError: TOPPRA found no feasible timing.
    """
    length = float(s_way[-1])
    n_grid = max(20, int(np.ceil(length / options.grid_step)) + 1)
    grid = np.union1d(np.linspace(0.0, length, n_grid), s_way)
    seg_of_grid = np.clip(np.searchsorted(s_way, grid, side="right") - 1, 0, len(scales) - 1)
    scale_grid = np.asarray(scales, dtype=float)[seg_of_grid] * options.speed_scale
    vmax = robot.velocity_limits
    amax = robot.acceleration_limits
    # TCP speed: sdot <= v_tcp / |dp/ds|, expressed as per-joint velocity bounds.
    dq = path(grid, 1)  # type: ignore[operator]
    vlim_grid = scale_grid[:, None] * vmax[None, :]
    if any(v is not None for v in tcp_speeds):
        q_grid = path(grid)  # type: ignore[operator]
        p = np.array([robot.tcp_position(q) for q in q_grid])
        dp = np.gradient(p, grid, axis=0)
        speed = np.linalg.norm(dp, axis=1)
        for g, seg in enumerate(seg_of_grid):
            v = tcp_speeds[seg]
            if v is None or speed[g] < 1e-9:
                continue
            sd_max = v / speed[g]
            vlim_grid[g] = np.minimum(vlim_grid[g], np.maximum(np.abs(dq[g]) * sd_max, 1e-9))
    # TOPPRA enforces the limits at grid points; between them, and where the spline
    # bends sharply, a sample may exceed a limit a little. Tighten the limits only around
    # the offending samples and time again; as a last resort stretch time uniformly,
    # which scales velocities by 1/k and accelerations by 1/k^2 and so meets the limits.
    seg_scales = np.asarray(scales, dtype=float) * options.speed_scale
    factor = np.ones(len(grid))
    ratio = float("inf")
    piece: TimedPiece | None = None
    for attempt in range(options.retries):
        piece = _toppra(path, grid, vlim_grid * factor[:, None],
                        scale_grid[:, None] * amax[None, :] * factor[:, None], options, step)
        seg_index = np.clip(np.searchsorted(s_way, piece.s, side="right") - 1, 0,
                            len(scales) - 1)
        piece = TimedPiece(piece.t, piece.q, piece.qd, piece.qdd, piece.s, seg_index)
        v_ratio, a_ratio = _knot_ratios(piece, robot, seg_scales)
        per_knot = np.maximum(v_ratio, a_ratio)
        previous, ratio = ratio, float(per_knot.max())
        if ratio <= 1.0 + options.tolerance:
            return piece
        if ratio >= previous - 1e-6:
            break  # tightening no longer helps: stretch time below
        log.debug("timing attempt %d exceeds limits by %.3f %%; tightening locally", attempt,
                  (ratio - 1) * 100)
        over = per_knot > 1.0 + options.tolerance / 2
        g_of_knot = np.clip(np.searchsorted(grid, piece.s[over]), 0, len(grid) - 1)
        for g, r in zip(g_of_knot, per_knot[over], strict=True):
            lo, hi = max(g - 2, 0), min(g + 3, len(grid))
            factor[lo:hi] = np.minimum(factor[lo:hi], 1.0 / (r * (1 + options.tolerance / 4)))
    if piece is None:
        raise TimingError("no timing attempt was made (retries must be >= 1)")
    v_ratio, a_ratio = _knot_ratios(piece, robot, seg_scales)
    k = max(1.0, float(v_ratio.max()), float(np.sqrt(a_ratio.max()))) * (1.0 + 1e-9)
    log.debug("timing still %.3f %% over; stretching time by %.4f", (ratio - 1) * 100, k)
    return TimedPiece(piece.t * k, piece.q, piece.qd / k, piece.qdd / (k * k), piece.s,
                      piece.segment)


def _knot_ratios(piece: TimedPiece, robot: Robot, seg_scales: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per knot, the largest |qd|/vmax and the largest |qdd|/amax (scaled limits)."""
    scale = seg_scales[piece.segment][:, None]
    v = np.max(np.abs(piece.qd) / (robot.velocity_limits[None, :] * scale), axis=1)
    a = np.max(np.abs(piece.qdd) / (robot.acceleration_limits[None, :] * scale), axis=1)
    return v, a


def _toppra(path: object, grid: np.ndarray, vlim_grid: np.ndarray, alim_grid: np.ndarray,
            options: TimingOptions, step: str | None) -> TimedPiece:
    import toppra.algorithm as algo

    from ._constraints import VaryingAcceleration, VaryingVelocity

    pc_vel = VaryingVelocity(vlim_grid)
    pc_acc = VaryingAcceleration(alim_grid)
    instance = algo.TOPPRA([pc_vel, pc_acc], path, gridpoints=grid,
                           parametrizer="ParametrizeConstAccel")
    traj = instance.compute_trajectory(0.0, 0.0)
    if traj is None:
        raise TimingError("TOPPRA found no feasible timing" + (f" (step '{step}')" if step
                                                                 else ""))
    duration = float(traj.duration)
    n = max(2, int(np.ceil(duration / options.knot_period)) + 1)
    t = np.linspace(0.0, duration, n)
    # One evaluation of s(t), s'(t), s''(t) for all knots (toppra's public calls would
    # repeat it for q, qd and qdd); s(t) also tells which route step each knot is in.
    evaluate = getattr(traj, "_eval_params", None)
    if evaluate is None:  # pragma: no cover - another toppra version
        raise TimingError("this toppra's ParametrizeConstAccel has no _eval_params; "
                          "safepath needs toppra 0.6")
    s, sd, sdd = evaluate(t)
    ps, pss = path(s, 1), path(s, 2)  # type: ignore[operator]
    q = path(s)  # type: ignore[operator]
    qd = ps * sd[:, None]
    qdd = pss * (sd ** 2)[:, None] + ps * sdd[:, None]
    qd[0] = qd[-1] = 0.0
    return TimedPiece(t, np.asarray(q), np.asarray(qd), np.asarray(qdd), np.asarray(s),
                      np.zeros(n, dtype=int))


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
