"""TOPP-RA's grid along a spline path, and the joint and TCP limits there.

Each route step (input segment) has its own speed scale and optional TCP speed limit, so
the limits vary along the path. The grid follows the spline: each spline piece is cut
evenly (the path's curvature is linear on a piece; across a spline knot it bends, which is
where knots between gridpoints would otherwise exceed a limit), plus the segment
boundaries, where the smaller limits of the two segments hold. The limits are also imposed
at :data:`INTERIOR` points of each grid interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..robot import Robot
from . import _topp

__all__ = ["INTERIOR", "PathSpline", "PathLimits", "Points", "path_limits", "row_max"]

#: Where inside each grid interval the limits are imposed too (fractions of the interval).
INTERIOR: tuple[float, ...] = (0.5,)


class PathSpline(Protocol):
    """A joint path ``q(s)``: ``path(s)``, and its derivatives ``path(s, 1)``, ``path(s, 2)``.

    Attributes:
        x: The spline's breakpoints (path parameters of its pieces' ends), from 0.
    """

    x: np.ndarray

    def __call__(self, s: np.ndarray | float, nu: int = 0) -> np.ndarray:
        """Positions [rad] (or their ``nu``-th derivative) at path parameters ``s``."""
        ...


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
        inside: The same at :data:`INTERIOR` points of each grid interval.
        s_way: Path parameter of the segment boundaries.
        vmax_seg: Velocity limits of each segment (segments, dof) [rad/s].
        amax_seg: Acceleration limits of each segment (segments, dof) [rad/s^2].
    """

    grid: np.ndarray
    at_grid: Points
    inside: tuple[Points, ...]
    s_way: np.ndarray
    vmax_seg: np.ndarray
    amax_seg: np.ndarray

    def rows(self, factor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """TOPP-RA's rows ``|a u + b x| <= c`` of each interval, with the limits at each
        gridpoint scaled by ``factor`` (inside an interval: the smaller of its ends')."""
        grid, at = self.grid, self.at_grid
        rows = [_topp.acceleration_rows(grid, at.dq, at.ddq, at.alim * factor[:, None])]
        f_in = np.minimum(factor[:-1], factor[1:])
        for theta, inside in zip(INTERIOR, self.inside, strict=True):
            rows.append(_topp.interior_rows(grid, theta, inside.dq, inside.ddq,
                                            inside.alim * f_in[:, None],
                                            inside.xmax * f_in ** 2))
        a, b, c = (np.hstack(part) for part in zip(*rows, strict=True))
        return a, b, c


def path_limits(robot: Robot, path: PathSpline, s_way: np.ndarray, scales: Sequence[float],
                tcp_speeds: Sequence[float | None], *, speed_scale: float, grid_step: float
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
    """
    grid = _grid(path.x, s_way, grid_step)
    seg_scales = np.asarray(scales, dtype=float) * speed_scale
    last = len(seg_scales) - 1
    seg_of_grid = np.clip(np.searchsorted(s_way, grid, side="right") - 1, 0, last)
    # A gridpoint on a segment boundary ends one segment and starts the next: the
    # smaller limits of the two hold there.
    seg_before = np.clip(np.searchsorted(s_way, grid, side="left") - 1, 0, last)
    scale_grid = np.minimum(seg_scales[seg_of_grid], seg_scales[seg_before])
    at_grid = _points(robot, path, grid, scale_grid)
    delta = np.diff(grid)
    inside = tuple(_points(robot, path, grid[:-1] + theta * delta, seg_scales[seg_of_grid[:-1]])
                   for theta in INTERIOR)
    if any(v is not None for v in tcp_speeds):
        # TCP speed: sdot <= v_tcp / |dp/ds|, |dp/ds| by finite differences on the grid
        # (linear between gridpoints).
        p = np.array([robot.tcp_position(q) for q in path(grid)])
        tcp_rate = np.linalg.norm(np.gradient(p, grid, axis=0), axis=1)
        v_seg = np.array([np.inf if v is None else v for v in tcp_speeds])
        v_grid = np.minimum(v_seg[seg_of_grid], v_seg[seg_before])
        _limit_tcp(at_grid.xmax, v_grid, tcp_rate)
        for theta, points in zip(INTERIOR, inside, strict=True):
            _limit_tcp(points.xmax, v_seg[seg_of_grid[:-1]],
                       (1 - theta) * tcp_rate[:-1] + theta * tcp_rate[1:])
    return PathLimits(grid, at_grid, inside, s_way,
                      seg_scales[:, None] * robot.velocity_limits,
                      seg_scales[:, None] * robot.acceleration_limits)


def _limit_tcp(xmax: np.ndarray, v_tcp: np.ndarray, tcp_rate: np.ndarray) -> None:
    """Lower ``xmax`` (in place) to keep the TCP at most ``v_tcp`` [m/s] fast."""
    limited = np.isfinite(v_tcp) & (tcp_rate >= 1e-9)
    xmax[limited] = np.minimum(xmax[limited], (v_tcp[limited] / tcp_rate[limited]) ** 2)


def _grid(breaks: np.ndarray, s_way: np.ndarray, step: float) -> np.ndarray:
    """TOPP-RA's gridpoints: each spline piece cut evenly into pieces of at most ``step``
    (at least 19 in all), and the segment boundaries.

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
    return np.union1d(grid, s_way[~on])


def _points(robot: Robot, path: PathSpline, s: np.ndarray, scale: np.ndarray) -> Points:
    """The path at ``s`` and the joint limits there, scaled by ``scale`` (per point)."""
    dq, ddq = path(s, 1), path(s, 2)
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
