"""TOPP-RA's grid along a spline path, and the joint and TCP limits there.

Each route step (input segment) has its own speed scale and optional TCP speed limit, so
the limits vary along the path. The grid follows the spline: each spline piece is cut
evenly (the path's curvature is linear on a piece; across a spline knot it bends, which is
where knots between gridpoints would otherwise exceed a limit), plus the segment
boundaries, where the smaller limits of the two segments hold.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np

from ..model._knots import interval_index
from ..model.interpolation import Interpolation
from ..model.robot import Robot
from . import _topp

__all__ = ["AHEAD_MARGIN", "STRAIGHT_STEPS", "TCP_STEP", "PathSpline", "PathLimits", "Points",
           "ahead_of_steps", "gridpoints", "jet", "path_limits", "row_max", "sliding_min",
           "straight_pieces", "tcp_limits"]

#: Spacing of the points where the TCP's speed per path speed is computed [rad].
TCP_STEP = 0.015
#: Margin of the reach of :func:`ahead_of_steps` over half the averages' width at the
#: speed bound.
AHEAD_MARGIN = 1.2
#: How many times coarser TOPP-RA's grid is on a straight piece of the path
#: (:func:`gridpoints`).
STRAIGHT_STEPS = 8
#: Share of each joint's jerk limit left to the path's third derivative
#: (``|q'''(s)| sdot^3``); the rest is for the changes of the path acceleration (the
#: averages; where they exceed, the re-timing). Half held the speed lower than needed:
#: with 0.65 the Ned3 Pro's and the UR5's random via-point paths came 0.5-0.8 % closer to
#: the jerk-free optimum on median and 1 % at p95, the quality-check cycle's motion 4 %
#: shorter, with fewer re-timings (``benchmarks/timing_quality.py``,
#: ``benchmarks/plan_cycle.py``); the other arms' paths did not change.
JERK_SPEED_SHARE = 0.65


class PathSpline(Protocol):
    """A joint path ``q(s)``: ``path(s)``, and its derivatives ``path(s, 1)``, ``path(s, 2)``.

    Attributes:
        x: The spline's breakpoints (path parameters of its pieces' ends), from 0.
    """

    x: np.ndarray

    def __call__(self, s: np.ndarray | float, nu: int = 0) -> np.ndarray:
        """Positions [rad] (or their ``nu``-th derivative) at path parameters ``s``."""
        ...


def jet(path: PathSpline, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``path(s), path(s, 1), path(s, 2)``: with one piece lookup where the path offers
    it (:meth:`~safepath.timing.CubicPath.jet`)."""
    fast = getattr(path, "jet", None)
    if fast is not None:
        return fast(s)  # type: ignore[no-any-return]
    return path(s), path(s, 1), path(s, 2)


@dataclass(frozen=True)
class Points:
    """The path and its limits at some points along it.

    Attributes:
        dq: Path tangent ``q'(s)`` (points, dof).
        ddq: Path curvature ``q''(s)`` (points, dof).
        alim: Acceleration limits (points, dof) [rad/s^2].
        xmax: Bound on the squared path speed (points,) [1/s^2] (velocity, TCP speed).
    """

    dq: np.ndarray
    ddq: np.ndarray
    alim: np.ndarray
    xmax: np.ndarray


@dataclass(frozen=True)
class PathLimits:
    """The limits along TOPP-RA's grid, and those each knot is checked against.

    Attributes:
        grid: Gridpoints along the path (N+1,).
        at_grid: The path and limits at the gridpoints.
        s_way: Path parameter of the segment boundaries.
        vmax_seg: Velocity limits of each segment (segments, dof) [rad/s].
        amax_seg: Acceleration limits of each segment (segments, dof) [rad/s^2].
        jmax_seg: Jerk limits of each segment (segments, dof) [rad/s^3].
        interpolation: How the robot's controller joins the knots (they are checked so).
        tcp_rate: The TCP's speed per path speed ``|dp/ds|`` at the gridpoints [m/rad]
            (an estimate, :func:`_tcp_rate`), where a segment limits the TCP's speed.
    """

    grid: np.ndarray
    at_grid: Points
    s_way: np.ndarray
    vmax_seg: np.ndarray
    amax_seg: np.ndarray
    jmax_seg: np.ndarray
    interpolation: Interpolation
    tcp_rate: np.ndarray | None = None

    @cached_property
    def rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """TOPP-RA's rows ``|a u + b x| <= c`` of each interval, the acceleration limits as
        they are (the same in every run; :func:`~safepath.timing._topp.solve` scales
        them by a factor per gridpoint)."""
        at = self.at_grid
        return _topp.acceleration_rows(self.grid, at.dq, at.ddq, at.alim)


def path_limits(robot: Robot, path: PathSpline, s_way: np.ndarray, scales: Sequence[float],
                tcp_speeds: Sequence[float | None], *, speed_scale: float, grid_step: float,
                jerk_scale: float = 1.0, ahead: float = 0.0, scales_ahead: bool = True
                ) -> PathLimits:
    """TOPP-RA's grid along ``path`` and the limits there.

    Args:
        robot: Limits and kinematics.
        path: The spline.
        s_way: Path parameter of the segment boundaries.
        scales: Speed scale of each segment, in (0, 1].
        tcp_speeds: TCP speed limit of each segment [m/s], or None.
        speed_scale: Global speed scale, in (0, 1].
        grid_step: Largest spacing of the gridpoints [rad].
        jerk_scale: Fraction of the jerk limits (on top of the speed scales), in (0, 1].
        ahead: Time [s] over which the timing averages the profile (the moving averages'
            total width): a segment's speed scale and TCP speed limit hold on TOPP-RA's
            grid from as far before the segment's start and after its end as the path
            covers in half that time (:func:`ahead_of_steps`), so that the averages
            carry no speed or acceleration of a faster segment into a slower one. The
            limits the knots are checked against (``*_seg``) stay the segments' own.
        scales_ahead: Whether the speed scales hold ahead too, or only the TCP speed
            limits (the joint limits are checked on the knots' executed motion, where a
            scale carried into a slower segment costs a time stretch; nothing else checks
            the TCP's speed that way before release but :func:`~safepath.timing.time_path`'s
            release, where a stretch costs the whole piece).
    """
    grid = gridpoints(path.x, s_way, grid_step, straight_pieces(path))
    seg_scales = np.asarray(scales, dtype=float) * speed_scale
    last = len(seg_scales) - 1
    seg_of_grid = interval_index(s_way, grid, last + 1)
    # A gridpoint on a segment boundary ends one segment and starts the next: the
    # smaller limits of the two hold there.
    seg_before = np.minimum(np.maximum(np.searchsorted(s_way, grid, side="left") - 1, 0), last)
    scale_grid = np.minimum(seg_scales[seg_of_grid], seg_scales[seg_before])
    v_seg = tcp_limits(tcp_speeds)
    v_grid = np.minimum(v_seg[seg_of_grid], v_seg[seg_before])
    _, dq, ddq = jet(path, grid)
    bound = _Bounds(robot, path, s_way, grid, dq, jerk_scale, np.isfinite(v_seg).any())
    if ahead > 0.0 and ((scales_ahead and np.ptp(seg_scales) > 0.0)
                        or bool(np.any(v_seg != v_seg[0]))):
        near_scale, v_grid = ahead_of_steps(grid, bound, ahead, scale_grid, v_grid)
        if scales_ahead:
            scale_grid = near_scale
    at_grid = Points(dq, ddq, scale_grid[:, None] * robot.acceleration_limits,
                     bound(scale_grid, v_grid))
    return PathLimits(grid, at_grid, s_way, seg_scales[:, None] * robot.velocity_limits,
                      seg_scales[:, None] * robot.acceleration_limits,
                      (seg_scales * jerk_scale)[:, None] * robot.jerk_limits,
                      robot.controller.interpolation, bound.rate)


class _Bounds:
    """The bound on ``x = sdot^2`` at the gridpoints for given speed scales and TCP speed
    limits there (the path's derivatives and the TCP's rate computed once).

    Args:
        robot: Limits and kinematics.
        path: The spline.
        s_way: Path parameter of the segment boundaries.
        grid: The gridpoints.
        dq: The path's tangent at the gridpoints.
        jerk_scale: Fraction of the jerk limits.
        tcp: Whether any segment limits the TCP's speed.
    """

    def __init__(self, robot: Robot, path: PathSpline, s_way: np.ndarray, grid: np.ndarray,
                 dq: np.ndarray, jerk_scale: float, tcp: bool) -> None:
        # Per gridpoint, the largest joint speed per path speed over its limit, and the
        # largest q''' over its share of the jerk limit: the bounds scale them (computed
        # once, whatever the scales).
        jden = JERK_SPEED_SHARE * jerk_scale * robot.jerk_limits
        coef = getattr(path, "coefficients", None)
        if coef is None:
            self._v_peak = row_max(np.abs(dq) / robot.velocity_limits)
            self._j_peak = row_max(_third_derivative(path, grid) / jden)
        else:
            self._v_peak, self._j_peak = np.empty(grid.size), np.empty(grid.size)
            # (The robot's limits are read-only: a writable copy, as the kernel's
            # signature takes.)
            _topp.compiled_kernels()["grid_peaks"](
                *(np.ascontiguousarray(x, dtype=np.float64)
                  for x in (grid, path.x, coef, dq)),
                np.array(robot.velocity_limits, dtype=np.float64), jden,
                self._v_peak, self._j_peak)
        self._joint: tuple[np.ndarray, np.ndarray] | None = None  # (scale, its bound)
        self.rate = _tcp_rate(robot, path, s_way, grid) if tcp else None

    def joint(self, scale: np.ndarray) -> np.ndarray:
        """The bound [1/s^2] that the joint velocity limits and the path's
        third-derivative term of the jerk (``|q'''_j(s)| sdot^3`` within
        :data:`JERK_SPEED_SHARE` of each joint's jerk limit) give under the speed
        ``scale`` at each gridpoint (the last scale's bound is kept)."""
        kept = self._joint
        if kept is not None and np.array_equal(kept[0], scale):
            return kept[1]
        cap = np.sqrt(_topp.X_CAP)
        with np.errstate(divide="ignore"):
            sd_v = np.where(self._v_peak > 1e-12, scale / np.maximum(self._v_peak, 1e-300), cap)
            sd_j = np.where(self._j_peak > 1e-12,
                            np.cbrt(scale / np.maximum(self._j_peak, 1e-300)), cap)
        bound = np.minimum(np.minimum(sd_v, sd_j), cap) ** 2
        self._joint = (scale.copy(), bound)
        return bound

    def __call__(self, scale: np.ndarray, v_tcp: np.ndarray) -> np.ndarray:
        """The bound [1/s^2] under the speed ``scale`` and TCP speed limits ``v_tcp``
        [m/s] (inf: none) at each gridpoint: joint velocities, the path's
        third-derivative term of the jerk (:meth:`joint`), the TCP's speed."""
        xmax = self.joint(scale)
        if self.rate is None:
            return xmax
        with np.errstate(divide="ignore"):
            tcp = np.where(np.isfinite(v_tcp) & (self.rate >= 1e-9),
                           (v_tcp / np.maximum(self.rate, 1e-9)) ** 2, np.inf)
        return np.minimum(xmax, tcp)


def _third_derivative(path: PathSpline, grid: np.ndarray) -> np.ndarray:
    """``|q'''|`` at the gridpoints (points, dof) of a path that does not offer its pieces'
    coefficients (a :class:`~safepath.timing.CubicPath`'s are read off by the kernel
    ``grid_peaks``): the larger of the values just before and at each gridpoint."""
    eps = 1e-9 * max(1.0, float(grid[-1]))
    return np.maximum(np.abs(path(grid, 3)), np.abs(path(np.maximum(grid - eps, 0.0), 3)))


def tcp_limits(tcp_speeds: Sequence[float | None]) -> np.ndarray:
    """Each segment's TCP speed limit [m/s] as an array, inf where it has none."""
    return np.array([np.inf if v is None else v for v in tcp_speeds], dtype=float)


def straight_pieces(path: PathSpline) -> np.ndarray | None:
    """Which pieces of the path are straight (no second or third derivative), where the
    path offers its pieces' coefficients (:class:`~safepath.timing.CubicPath`)."""
    coef = getattr(path, "coefficients", None)
    if coef is None:
        return None
    return np.all(coef[:, 2:, :] == 0.0, axis=(1, 2))


def _tcp_rate(robot: Robot, path: PathSpline, s_way: np.ndarray, grid: np.ndarray
              ) -> np.ndarray:
    """The TCP's speed per path speed ``|dp/ds|`` at ``grid`` [m/rad], from finite
    differences of the TCP position on a grid of its own, :data:`TCP_STEP` apart
    (forward kinematics is the costly part; the rate varies slowly), linear in between.
    The TCP is at most ``v_tcp`` [m/s] fast where ``sdot <= v_tcp / |dp/ds|``."""
    samples = gridpoints(path.x, s_way, TCP_STEP)
    p = robot.tcp_positions(path(samples))
    return np.interp(grid, samples, np.linalg.norm(np.gradient(p, samples, axis=0), axis=1))


def gridpoints(breaks: np.ndarray, s_way: np.ndarray, step: float,
               straight: np.ndarray | None = None) -> np.ndarray:
    """TOPP-RA's gridpoints [rad] (path parameter): each spline piece (between
    ``breaks``) cut evenly into pieces of at most ``step`` [rad] (at least 19 in all),
    and the segment boundaries ``s_way``; a straight piece (``straight``, per piece)
    into pieces of at most :data:`STRAIGHT_STEPS` times that.

    On a spline piece the path's curvature is linear in ``s``; across a spline knot it
    bends, which is where the limits would otherwise be exceeded between gridpoints. On a
    straight piece the path's tangent is constant and it has no curvature: the limits
    hold between gridpoints where they hold at them (the path acceleration is constant
    between gridpoints and the squared speed linear), and a finer grid only places
    TOPP-RA's switches between full acceleration and the speed limit more exactly.
    """
    length = float(breaks[-1])
    step = min(step, length / 19)
    pieces = np.diff(breaks)
    steps = step if straight is None else np.where(straight, STRAIGHT_STEPS * step, step)
    counts = np.maximum(1, np.ceil(pieces / steps - 1e-9).astype(np.int64))
    grid = np.empty(int(counts.sum()) + 1)
    _topp.compiled_kernels()["fill_grid"](np.ascontiguousarray(breaks, dtype=np.float64),
                                          counts, grid)
    grid[-1] = length
    # A segment boundary replaces a gridpoint it (almost) falls on, or is added.
    near = 1e-9 * max(1.0, length)
    after = np.minimum(np.maximum(np.searchsorted(grid, s_way), 1), grid.size - 1)
    nearest = np.where(grid[after] - s_way < s_way - grid[after - 1], after, after - 1)
    on = np.abs(grid[nearest] - s_way) <= near
    grid[nearest[on]] = s_way[on]
    if on.all():
        return grid
    return np.insert(grid, np.searchsorted(grid, s_way[~on]), s_way[~on])


def ahead_of_steps(grid: np.ndarray, bound: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   ahead: float, scale: np.ndarray, v_tcp: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The speed scales and TCP speed limits at the gridpoints, each the smallest within
    reach of the gridpoint.

    The two moving averages give the motion at time ``t`` the mean speed of the profile
    over ``[t - ahead, t]``, at about the profile's place at ``t - ahead / 2``: the
    speeds averaged into a gridpoint come from no farther along the path than the
    profile covers in ``ahead / 2`` [s] around it. The reach is that time at the speed
    the limits allow there (:data:`AHEAD_MARGIN` for the change of speed within it), once
    with the steps' own limits and again with those the first pass brought near a slower
    step, which the profile keeps to there.

    Args:
        grid: The gridpoints.
        bound: The bound on ``sdot^2`` at the gridpoints under given scales and TCP speed
            limits.
        ahead: The averages' total width [s].
        scale: The steps' speed scale at each gridpoint.
        v_tcp: The steps' TCP speed limit at each gridpoint [m/s] (inf: none).
    """
    near = (scale, v_tcp)
    for _ in range(2):
        reach = AHEAD_MARGIN * 0.5 * ahead * np.sqrt(bound(*near))
        lo = np.searchsorted(grid, grid - reach, side="left")
        hi = np.searchsorted(grid, grid + reach, side="right")
        near = (sliding_min(scale, lo, hi), sliding_min(v_tcp, lo, hi))
    return near


def sliding_min(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The smallest of ``values[lo[i]:hi[i]]`` for every ``i`` (each range non-empty),
    from a table of the minima over power-of-two spans (no loop over ``i``): row ``k``
    holds the minimum of the ``2^k`` values from each index (inf past the end)."""
    n = values.size
    levels = max(1, n.bit_length())
    table = np.full((levels, n), np.inf)
    table[0] = values
    span = 1
    for k in range(1, levels):
        m = n - 2 * span + 1  # the spans of 2^k that fit
        np.minimum(table[k - 1, :m], table[k - 1, span:span + m], out=table[k, :m])
        span *= 2
    level = np.floor(np.log2(np.maximum(hi - lo, 1))).astype(np.int64)
    return np.minimum(table[level, lo], table[level, hi - (1 << level)])


def row_max(values: np.ndarray) -> np.ndarray:
    """The largest value of each row of a (rows, dof) array."""
    # numpy reduces a short last axis slowly; across the long one it is ~10x faster.
    return np.max(np.ascontiguousarray(values.T), axis=0)
