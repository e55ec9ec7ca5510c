"""TOPPRA timing on the Ned3 Pro: limits kept, durations optimal, scales and TCP speed.

Timing is checked against closed forms (the rest-to-rest trapezoid of a straight
joint move) and against finite differences of the timed result (TCP speed).
"""

from __future__ import annotations

import numpy as np
import pytest

from safepath import (
    ConfigError,
    PlanOptions,
    Route,
    Step,
    Target,
    TimingOptions,
    plan_route,
)
from safepath.cell import Cell
from safepath.planning.timing import TimedPiece, rest_to_rest_time, spline_path, time_path
from safepath.robot import Robot

from .conftest import LIMIT_TOL, Plans, dense_times

PAIRS = [("high1", "high2"), ("high2", "safe"), ("safe", "unsafe"), ("grip", "low1")]


def _assert_within(piece: TimedPiece, robot: Robot, scales: np.ndarray) -> None:
    scale = scales[piece.segment][:, None]
    v = np.abs(piece.qd) / (robot.velocity_limits * scale)
    a = np.abs(piece.qdd) / (robot.acceleration_limits * scale)
    assert v.max() <= 1 + LIMIT_TOL, f"velocity at {v.max():.5f} of its limit"
    assert a.max() <= 1 + LIMIT_TOL, f"acceleration at {a.max():.5f} of its limit"


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4, 5, 6, 29])
def test_random_polylines_keep_the_limits(bundled_cell: Cell, seed: int) -> None:
    robot = bundled_cell.robot
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5))
    lo, hi = robot.lower * 0.8, robot.upper * 0.8
    waypoints = [lo + rng.random(robot.dof) * (hi - lo) for _ in range(n + 1)]
    scales = rng.uniform(0.3, 1.0, size=n)
    path, s_way, _ = spline_path(waypoints, 0.06)
    piece = time_path(robot, path, s_way, scales=list(scales), tcp_speeds=[None] * n)
    _assert_within(piece, robot, scales)
    assert np.all(np.diff(piece.t) > 0) and piece.t[0] == 0.0
    assert not np.any(piece.qd[0]) and not np.any(piece.qd[-1])
    np.testing.assert_allclose(piece.q[0], waypoints[0], atol=1e-9)
    np.testing.assert_allclose(piece.q[-1], waypoints[-1], atol=1e-6)
    # The spline passes through every waypoint (no corner cut without corners).
    for w, s in zip(waypoints, s_way, strict=True):
        np.testing.assert_allclose(path(s), w, atol=1e-9)  # type: ignore[operator, arg-type]
    assert sorted(set(piece.segment.tolist())) == list(range(n))


@pytest.mark.parametrize(("a", "b"), PAIRS)
def test_straight_move_matches_the_trapezoid(bundled_cell: Cell, a: str, b: str) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose(a), bundled_cell.pose(b)
    expected = rest_to_rest_time(q1 - q0, robot.velocity_limits, robot.acceleration_limits)
    path, s_way, _ = spline_path([q0, q1], 0.06)
    piece = time_path(robot, path, s_way, scales=[1.0], tcp_speeds=[None])
    assert float(piece.t[-1]) == pytest.approx(expected, rel=0.01)
    assert float(piece.t[-1]) >= expected * (1 - 1e-6)  # nothing beats the optimum
    _assert_within(piece, robot, np.ones(1))


def test_the_trapezoid_itself() -> None:
    vmax, amax = np.array([1.0, 2.0]), np.array([2.0, 2.0])
    # Joint 0 limits: 1 rad at v 1, a 2: 0.5 s accelerating, 0.5 rad cruising -> 1.5 s.
    assert rest_to_rest_time(np.array([1.0, 0.0]), vmax, amax) == pytest.approx(1.5)
    # Short move: triangle, 2 * sqrt(d / a).
    assert rest_to_rest_time(np.array([0.1, 0.0]), vmax, amax) == pytest.approx(
        2 * np.sqrt(0.1 / 2.0))
    assert rest_to_rest_time(np.zeros(2), vmax, amax) == 0.0


def _move(cell: Cell, a: str, b: str, speed: float = 1.0,
          options: PlanOptions | None = None) -> tuple[float, float]:
    """Duration and peak velocity ratio of a free joint move a -> b planned as a route."""
    route = Route("t", a, (Step("move", Target(b), speed=speed),))
    traj = plan_route(cell, route, options)
    return traj.duration, float(np.max(np.abs(traj.qd) / cell.robot.velocity_limits))


def test_route_move_is_time_optimal(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose("high2"), bundled_cell.pose("high1")
    duration, peak = _move(bundled_cell, "high2", "high1")
    assert duration == pytest.approx(
        rest_to_rest_time(q1 - q0, robot.velocity_limits, robot.acceleration_limits), rel=0.01)
    assert peak == pytest.approx(1.0, abs=LIMIT_TOL)  # it cruises at the limit


def test_step_speed_halves_velocities(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose("high2"), bundled_cell.pose("high1")
    _, full = _move(bundled_cell, "high2", "high1")
    duration, half = _move(bundled_cell, "high2", "high1", speed=0.5)
    assert half == pytest.approx(full / 2, rel=0.005)
    assert duration == pytest.approx(rest_to_rest_time(
        q1 - q0, 0.5 * robot.velocity_limits, 0.5 * robot.acceleration_limits), rel=0.01)
    # The global speed scale does the same.
    options = PlanOptions(timing=TimingOptions(speed_scale=0.5))
    duration_g, half_g = _move(bundled_cell, "high2", "high1", options=options)
    assert half_g == pytest.approx(half, rel=1e-3)
    assert duration_g == pytest.approx(duration, rel=1e-3)


def _tcp_speed(cell: Cell, q: np.ndarray, period: float) -> np.ndarray:
    p = np.array([cell.robot.tcp_position(qk) for qk in q])
    return np.linalg.norm(np.diff(p, axis=0), axis=1) / period


@pytest.mark.parametrize("name", ["phase1", "phase2_safe"])
def test_tcp_speed_limit_on_the_routes_lines(bundled: Plans, name: str) -> None:
    cell, route, traj = bundled.cell, bundled.routes[name], bundled.trajectories[name]
    period = 0.001
    times = dense_times(traj, period)[:-1]
    times = times[times <= traj.duration - period]
    q, _, _ = traj.sample(np.concatenate([times, times + period]))
    p = np.array([cell.robot.tcp_position(qk) for qk in q])
    speed = np.linalg.norm(p[len(times):] - p[:len(times)], axis=1) / period
    step_of = traj.step_index[np.searchsorted(traj.t, times, side="right") - 1]
    limited = 0
    for k, step in enumerate(route.steps):
        if step.tcp_speed is None:
            continue
        sel = step_of == k
        assert speed[sel].max() <= step.tcp_speed * 1.01, traj.steps[k]
        limited += 1
    assert limited >= 2


def test_a_binding_tcp_speed_limit_is_reached_not_exceeded(bundled_cell: Cell) -> None:
    limit = 0.05  # [m/s], far below what the joints allow on this 21 cm line
    route = Route("t", "high1", (Step("line", Target("grip"), tcp_speed=limit),))
    traj = plan_route(bundled_cell, route)
    period = 0.002
    q, _, _ = traj.sample(dense_times(traj, period))
    speed = _tcp_speed(bundled_cell, q, period)
    assert speed.max() <= limit * 1.01
    assert speed.max() >= limit * 0.97
    length = np.linalg.norm(bundled_cell.robot.tcp_position(bundled_cell.pose("grip"))
                            - bundled_cell.robot.tcp_position(bundled_cell.pose("high1")))
    assert traj.duration >= length / limit


def test_timing_options_are_validated() -> None:
    with pytest.raises(ConfigError, match="speed_scale"):
        TimingOptions(speed_scale=1.5)
    with pytest.raises(ConfigError, match="speed_scale"):
        TimingOptions(speed_scale=0.0)
    with pytest.raises(ConfigError, match="knot_period"):
        TimingOptions(knot_period=0.0)
