"""TOPP-RA's grid along a spline path, and the joint and TCP limits there.

Each route step (input segment) has its own speed scale and optional TCP speed limit, so
the limits vary along the path. The grid follows the spline: each spline piece is cut
evenly (the path's curvature is linear on a piece; across a spline knot it bends, which is
where knots between gridpoints would otherwise exceed a limit), plus the segment
boundaries, where the smaller limits of the two segments hold.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np

from ..model._knots import interval_index
from ..model.robot import Robot
from . import _topp

__all__ = ["TCP_STEP", "PathSpline", "PathLimits", "Points", "gridpoints", "jet",
           "path_limits", "row_max"]

#: Spacing of the points where the TCP's speed per path speed is computed [rad].
TCP_STEP = 0.015
#: Share of each joint's jerk limit left to the path's third derivative
#: (``|q'''(s)| sdot^3``); the rest is for the changes of the path acceleration.
JERK_SPEED_SHARE = 0.5


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
    """

    grid: np.ndarray
    at_grid: Points
    s_way: np.ndarray
    vmax_seg: np.ndarray
    amax_seg: np.ndarray
    jmax_seg: np.ndarray

    @cached_property
    def _unit_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows with the limits as they are (the path's part is the same in every
        run; only the limits' factor changes)."""
        at = self.at_grid
        return _topp.acceleration_rows(self.grid, at.dq, at.ddq, at.alim)

    def rows(self, factor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """TOPP-RA's rows ``|a u + b x| <= c`` of each interval, with the acceleration
        limits at each gridpoint scaled by ``factor``."""
        a, b, c = self._unit_rows
        if np.all(factor == 1.0):
            return a, b, c
        half = c.shape[1] // 2  # the limits at s_i, then at s_{i+1}
        return a, b, c * np.repeat(np.stack([factor[:-1], factor[1:]], axis=1), half, axis=1)


def path_limits(robot: Robot, path: PathSpline, s_way: np.ndarray, scales: Sequence[float],
                tcp_speeds: Sequence[float | None], *, speed_scale: float, grid_step: float,
                jerk_scale: float = 1.0) -> PathLimits:
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
    """
    grid = gridpoints(path.x, s_way, grid_step)
    seg_scales = np.asarray(scales, dtype=float) * speed_scale
    last = len(seg_scales) - 1
    seg_of_grid = interval_index(s_way, grid, last + 1)
    # A gridpoint on a segment boundary ends one segment and starts the next: the
    # smaller limits of the two hold there.
    seg_before = np.clip(np.searchsorted(s_way, grid, side="left") - 1, 0, last)
    scale_grid = np.minimum(seg_scales[seg_of_grid], seg_scales[seg_before])
    at_grid = _points(robot, path, grid, scale_grid)
    at_grid = dataclasses.replace(at_grid, xmax=np.minimum(
        at_grid.xmax, _jerk_xmax(robot, path, grid, scale_grid * jerk_scale)))
    if any(v is not None for v in tcp_speeds):
        v_seg = np.array([np.inf if v is None else v for v in tcp_speeds])
        v_grid = np.minimum(v_seg[seg_of_grid], v_seg[seg_before])
        at_grid = dataclasses.replace(at_grid, xmax=np.minimum(
            at_grid.xmax, _tcp_xmax(robot, path, s_way, grid, v_grid)))
    return PathLimits(grid, at_grid, s_way, seg_scales[:, None] * robot.velocity_limits,
                      seg_scales[:, None] * robot.acceleration_limits,
                      (seg_scales * jerk_scale)[:, None] * robot.jerk_limits)


def _jerk_xmax(robot: Robot, path: PathSpline, grid: np.ndarray, scale: np.ndarray
               ) -> np.ndarray:
    """Bound on ``x`` at ``grid`` that keeps the path's third-derivative term of every
    joint's jerk, ``|q'''_j(s)| sdot^3``, within :data:`JERK_SPEED_SHARE` of its limit
    (``q'''`` of the pieces on both sides of a gridpoint)."""
    eps = 1e-9 * max(1.0, float(grid[-1]))
    d3 = np.maximum(np.abs(path(grid, 3)), np.abs(path(np.maximum(grid - eps, 0.0), 3)))
    jmax = JERK_SPEED_SHARE * scale[:, None] * robot.jerk_limits
    with np.errstate(divide="ignore", over="ignore"):
        sd = np.min(np.where(d3 > 1e-12, (jmax / np.maximum(d3, 1e-300)) ** (1.0 / 3.0),
                             np.inf), axis=1)
    return np.minimum(sd, np.sqrt(_topp.X_CAP)) ** 2


def _tcp_xmax(robot: Robot, path: PathSpline, s_way: np.ndarray, grid: np.ndarray,
              v_tcp: np.ndarray) -> np.ndarray:
    """Bound on ``x`` at ``grid`` that keeps the TCP at most ``v_tcp`` [m/s] fast (inf
    where there is no limit): ``sdot <= v_tcp / |dp/ds|``.

    ``|dp/ds|`` comes from finite differences of the TCP position on a grid of its own,
    :data:`TCP_STEP` apart (forward kinematics is the costly part; the rate varies
    slowly), linear in between.
    """
    samples = gridpoints(path.x, s_way, TCP_STEP)
    p = robot.tcp_positions(path(samples))
    rate = np.interp(grid, samples, np.linalg.norm(np.gradient(p, samples, axis=0), axis=1))
    with np.errstate(divide="ignore"):
        return np.where(np.isfinite(v_tcp) & (rate >= 1e-9),
                        (v_tcp / np.maximum(rate, 1e-9)) ** 2, np.inf)


def gridpoints(breaks: np.ndarray, s_way: np.ndarray, step: float) -> np.ndarray:
    """TOPP-RA's gridpoints [rad] (path parameter): each spline piece (between
    ``breaks``) cut evenly into pieces of at most ``step`` [rad] (at least 19 in all),
    and the segment boundaries ``s_way``.

    On a spline piece the path's curvature is linear in ``s``; across a spline knot it
    bends, which is where the limits would otherwise be exceeded between gridpoints.
    """
    length = float(breaks[-1])
    step = min(step, length / 19)
    pieces = np.diff(breaks)
    counts = np.maximum(1, np.ceil(pieces / step - 1e-9).astype(int))
    piece = np.repeat(np.arange(pieces.size), counts)
    j = np.arange(piece.size) - np.repeat(np.cumsum(counts) - counts, counts)
    grid = np.append(breaks[piece] + pieces[piece] * (j / counts[piece]), length)
    # A segment boundary replaces a gridpoint it (almost) falls on, or is added.
    near = 1e-9 * max(1.0, length)
    after = np.clip(np.searchsorted(grid, s_way), 1, grid.size - 1)
    nearest = np.where(grid[after] - s_way < s_way - grid[after - 1], after, after - 1)
    on = np.abs(grid[nearest] - s_way) <= near
    grid[nearest[on]] = s_way[on]
    if on.all():
        return grid
    return np.insert(grid, np.searchsorted(grid, s_way[~on]), s_way[~on])


def _points(robot: Robot, path: PathSpline, s: np.ndarray, scale: np.ndarray) -> Points:
    """The path at ``s`` and the joint limits there, scaled by ``scale`` (per point)."""
    _, dq, ddq = jet(path, s)
    # sdot <= scale vmax_j / |q'_j| for every joint j.
    peak = row_max(np.abs(dq) / robot.velocity_limits)
    with np.errstate(divide="ignore"):
        sd_max = np.where(peak > 1e-12, scale / np.maximum(peak, 1e-300), np.inf)
    xmax = np.minimum(sd_max, np.sqrt(_topp.X_CAP)) ** 2
    return Points(dq, ddq, scale[:, None] * robot.acceleration_limits, xmax)


def row_max(values: np.ndarray) -> np.ndarray:
    """The largest value of each row of a (rows, dof) array."""
    # numpy reduces a short last axis slowly; across the long one it is ~10x faster.
    return np.max(np.ascontiguousarray(values.T), axis=0)
