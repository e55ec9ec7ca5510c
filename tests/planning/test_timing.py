"""TOPP-RA timing on the Ned3 Pro: limits kept, durations optimal, scales and TCP speed.

Timing is checked against closed forms (the rest-to-rest trapezoid of a straight
joint move), against finite differences of the timed result (TCP speed), and our
TOPP-RA kernel against the ``toppra`` library on the same grids.
"""

from __future__ import annotations

import os
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from quintic_join import quintic_peaks as _quintic_peaks
from s_curve import s_curve_time

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
from safepath.errors import TimingError
from safepath.model.robot import Robot
from safepath.timing import (
    PathSpline,
    TimedPiece,
    _path_limits,
    _release,
    _smooth,
    _topp,
    rest_to_rest_time,
    spline_path,
    time_path,
)
from safepath.timing import path_timing as timing

from .conftest import LIMIT_TOL, ROOT, Plans, dense_times

PAIRS = [("high1", "high2"), ("high2", "safe"), ("safe", "unsafe"), ("grip", "low1")]


def _assert_within(piece: TimedPiece, robot: Robot, scales: np.ndarray) -> None:
    scale = scales[piece.segment][:, None]
    v = np.abs(piece.qd) / (robot.velocity_limits * scale)
    a = np.abs(piece.qdd) / (robot.acceleration_limits * scale)
    assert v.max() <= 1 + LIMIT_TOL, f"velocity at {v.max()!r} of its limit"
    assert a.max() <= 1 + LIMIT_TOL, f"acceleration at {a.max()!r} of its limit"
    # Rounded the other way round (as test_plan_cell divides), still not over.
    assert (np.abs(piece.qd) / robot.velocity_limits / scale).max() <= 1 + LIMIT_TOL
    assert (np.abs(piece.qdd) / robot.acceleration_limits / scale).max() <= 1 + LIMIT_TOL
    # As a controller executes the knots (their quintic join, sampled at 1 kHz), jerk too.
    peaks = _quintic_peaks(piece.t, piece.q, piece.qd, piece.qdd)
    for peak, limit in zip(peaks, (robot.velocity_limits, robot.acceleration_limits,
                                   robot.jerk_limits), strict=True):
        assert np.max(peak / limit) <= 1 + LIMIT_TOL


def _random_polyline(robot: Robot, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    lo, hi = robot.lower * 0.8, robot.upper * 0.8
    return [lo + rng.random(robot.dof) * (hi - lo) for _ in range(n + 1)]


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
def test_straight_move_matches_the_s_curve(bundled_cell: Cell, a: str, b: str) -> None:
    """A straight joint move takes within 1 % of the time-optimal jerk-limited move (the
    S-curve of the joint that limits it, computed here), never less: it is that S-curve
    (timing._scurve), its phases lengthened to whole knot periods."""
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose(a), bundled_cell.pose(b)
    expected = s_curve_time(q1 - q0, robot.velocity_limits, robot.acceleration_limits,
                            robot.jerk_limits)
    path, s_way, _ = spline_path([q0, q1], 0.06)
    piece = time_path(robot, path, s_way, scales=[1.0], tcp_speeds=[None])
    assert expected * (1 - 1e-6) <= float(piece.t[-1]) <= expected * 1.01
    # ... and at least the jerk-free optimum (the trapezoid).
    assert float(piece.t[-1]) > rest_to_rest_time(q1 - q0, robot.velocity_limits,
                                                  robot.acceleration_limits)
    _assert_within(piece, robot, np.ones(1))


@pytest.mark.parametrize("seed", range(30))
def test_a_straight_move_is_its_s_curve_as_executed(bundled_cell: Cell, seed: int) -> None:
    """The knots of a straight move sample its S-curve at every jerk switch, so their
    quintic join is the S-curve: its jerk reaches the projected jerk limit (within the
    lengthening to whole knot periods) and never exceeds a limit, at any scale."""
    robot = bundled_cell.robot
    rng = np.random.default_rng(seed)
    q0, q1 = _random_polyline(robot, rng, 1)
    q1 = q0 + (q1 - q0) * float(rng.choice([1e-3, 0.05, 0.3, 1.0]))  # short to long
    scale = float(rng.uniform(0.2, 1.0))
    path, s_way, _ = spline_path([q0, q1], 0.06)
    piece = time_path(robot, path, s_way, scales=[scale], tcp_speeds=[None])
    limits = [lim * scale for lim in (robot.velocity_limits, robot.acceleration_limits,
                                      robot.jerk_limits)]
    peaks = _quintic_peaks(piece.t, piece.q, piece.qd, piece.qdd)
    ratios = [float(np.max(p / lim)) for p, lim in zip(peaks, limits, strict=True)]
    assert max(ratios) <= 1.0
    expected = s_curve_time(q1 - q0, *limits)
    assert expected * (1 - 1e-6) <= float(piece.t[-1]) <= expected * 1.01 + 0.004
    # The jerk of the knots' join is the S-curve's: a constant +-j on whole intervals.
    assert ratios[2] > 0.9
    np.testing.assert_allclose(piece.q[-1], q1, atol=1e-9)


def test_the_s_curve_itself() -> None:
    # v 1, a 2, j 4: ramp to 1 rad/s in 1/2 + 1/2 = 1 s (covering 1 rad); 3 rad -> 4 s.
    assert s_curve_time(np.array([3.0]), np.array([1.0]), np.array([2.0]),
                        np.array([4.0])) == pytest.approx(4.0)
    # Short: peak p with ramp 2 sqrt(p / j) (a not reached): 0.1 rad at j 4.
    peak = (0.1 / 2 * np.sqrt(4.0)) ** (2 / 3)
    assert s_curve_time(np.array([0.1]), np.array([1.0]), np.array([2.0]),
                        np.array([4.0])) == pytest.approx(4 * np.sqrt(peak / 4.0))


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
    expected = s_curve_time(q1 - q0, robot.velocity_limits, robot.acceleration_limits,
                            robot.jerk_limits)
    assert expected * (1 - 1e-6) <= duration <= expected * 1.01
    assert 1.0 - 1e-3 <= peak <= 1.0  # it cruises at the limit, not above


def test_step_speed_halves_velocities(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose("high2"), bundled_cell.pose("high1")
    _, full = _move(bundled_cell, "high2", "high1")
    duration, half = _move(bundled_cell, "high2", "high1", speed=0.5)
    assert half == pytest.approx(full / 2, rel=0.005)
    expected = s_curve_time(q1 - q0, 0.5 * robot.velocity_limits,
                            0.5 * robot.acceleration_limits, 0.5 * robot.jerk_limits)
    assert expected * (1 - 1e-6) <= duration <= expected * 1.07
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
    for bad in (0, 2.0, "4"):
        with pytest.raises(ConfigError, match="max_knot_spacing") as info:
            TimingOptions(max_knot_spacing=bad)  # type: ignore[arg-type]
        assert info.value.key == "max_knot_spacing"


@pytest.mark.parametrize("seed", range(4))
def test_knots_timed_further_apart_are_released_as_timed_and_a_goal_joins_them_alike(
        bundled_cell: Cell, seed: int) -> None:
    """The Ned3 Pro's moving averages span 64 ms or more, so a run is timed on knots four
    knot periods apart and released as timed: every knot on the spline, their join within
    every limit. A goal for a controller that wants points one knot period apart gets
    points of that join between them: its own join is the same motion (to rounding).
    With ``max_knot_spacing=1`` the knots lie one period apart."""
    from quintic_join import quintic_state

    from safepath.model.trajectory import Trajectory
    from safepath.ros import joint_trajectory

    robot = bundled_cell.robot
    period = TimingOptions().knot_period
    rng = np.random.default_rng(700 + seed)
    n = int(rng.integers(2, 5))
    path, s_way, _ = spline_path(_random_polyline(robot, rng, n), 0.06,
                                 corners=[(k, 0.3) for k in range(1, n)], blend="g2")
    timed = {m: time_path(robot, path, s_way, scales=[1.0] * n, tcp_speeds=[None] * n,
                          options=TimingOptions(max_knot_spacing=m)) for m in (1, 4)}
    one, four = timed[1], timed[4]
    for piece, m in ((one, 1), (four, 4)):
        assert np.allclose(piece.q, path(piece.s), rtol=0, atol=1e-12)
        step = np.diff(piece.t)  # evenly spaced, m periods apart (longer by a stretch)
        assert np.allclose(step, step[0], rtol=0, atol=1e-12)
        assert m * period <= step[0] < 1.05 * m * period
        v, a, j = _quintic_peaks(piece.t, piece.q, piece.qd, piece.qdd)
        assert max(np.max(v / robot.velocity_limits), np.max(a / robot.acceleration_limits),
                   np.max(j / robot.jerk_limits)) <= 1.0 + 1e-9
    traj = Trajectory(robot.joint_names, four.t, four.q, four.qd, four.qdd,
                      np.zeros(four.t.size, dtype=int), ("move",), robot=robot.name,
                      limits=robot.motion_limits)
    msg = joint_trajectory(traj, period=period, controller=robot.controller,
                           backend="rosbags")
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                  for p in msg.points])
    P, V, A = (np.array([list(getattr(p, f)) for p in msg.points])  # noqa: N806
               for f in ("positions", "velocities", "accelerations"))
    parts = int(np.ceil(float(four.t[1]) / period - 1e-9))  # 5: 16 ms stretched a bit
    assert t.size == parts * (four.t.size - 1) + 1 and np.max(np.diff(t)) <= period + 1e-9
    assert np.array_equal(P[::parts], four.q)
    for at in np.linspace(0.0, float(four.t[-1]), 801):
        for mine, theirs in zip(quintic_state(t, P, V, A, at),
                                quintic_state(four.t, four.q, four.qd, four.qdd, at),
                                strict=True):
            assert np.allclose(mine, theirs, rtol=0, atol=1e-8)
    # Both near the optimum: the coarser timing costs little motion time.
    assert four.t[-1] <= one.t[-1] * 1.02


# -- strict limits --------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(12))
def test_released_knots_never_exceed_a_limit(bundled_cell: Cell, seed: int) -> None:
    """Random polylines, blended corners, step scales, TCP limits and a global scale:
    every released knot is at most at its limit (ratio <= 1.0, no tolerance)."""
    robot = bundled_cell.robot
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 6))
    waypoints = _random_polyline(robot, rng, n)
    corners = [(k, float(rng.choice([0.1, 0.3, 0.6]))) for k in range(1, n)]
    scales = rng.uniform(0.2, 1.0, size=n)
    tcp = [float(rng.uniform(0.05, 0.5)) if rng.random() < 0.3 else None for _ in range(n)]
    speed_scale = float(rng.choice([1.0, 0.7]))
    path, s_way, _ = spline_path(waypoints, 0.06, corners=corners)
    piece = time_path(robot, path, s_way, scales=list(scales), tcp_speeds=tcp,
                      options=TimingOptions(speed_scale=speed_scale))
    _assert_within(piece, robot, scales * speed_scale)
    v = np.abs(piece.qd) / (robot.velocity_limits * (scales * speed_scale)[piece.segment][:, None])
    assert v.max() > 0.5  # the limits are used, not just kept


def test_a_knot_over_a_limit_is_never_released(bundled_cell: Cell,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the final stretch, a coarse grid leaves knots over a limit: time_path
    must raise rather than release them."""
    robot = bundled_cell.robot
    waypoints = _random_polyline(robot, np.random.default_rng(7), 3)
    path, s_way, _ = spline_path(waypoints, 0.06, corners=[(1, 0.3), (2, 0.3)])
    coarse = TimingOptions(grid_step=0.1, retries=1)
    time_path(robot, path, s_way, scales=[1.0] * 3, tcp_speeds=[None] * 3, options=coarse)
    monkeypatch.setattr(_release, "stretch", lambda *peaks: 1.0)
    with pytest.raises(TimingError, match=r"of a limit \(step 'corner'\)"):
        time_path(robot, path, s_way, scales=[1.0] * 3, tcp_speeds=[None] * 3, options=coarse,
                  step="corner")


def test_a_path_that_cannot_move_raises(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    path, s_way, _ = spline_path([bundled_cell.pose("high1"), bundled_cell.pose("high2")], 0.06)
    with pytest.raises(TimingError, match="no feasible timing.*'stuck'"):
        time_path(robot, path, s_way, scales=[0.0], tcp_speeds=[None], step="stuck")


def test_timing_is_deterministic(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    waypoints = _random_polyline(robot, np.random.default_rng(3), 3)
    runs = []
    for _ in range(2):
        path, s_way, _ = spline_path(waypoints, 0.06, corners=[(1, 0.3)])
        runs.append(time_path(robot, path, s_way, scales=[1.0, 0.5, 0.8],
                              tcp_speeds=[None, 0.2, None]))
    for name in ("t", "q", "qd", "qdd", "s", "segment"):
        assert getattr(runs[0], name).tobytes() == getattr(runs[1], name).tobytes(), name


@pytest.mark.parametrize("seed", [0, 1, 3])  # paths that the default timing re-times
@pytest.mark.parametrize("retries", [1, 3])
def test_bounded_ratios_time_as_the_exact_ones(bundled_cell: Cell, seed: int, retries: int,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Timing reads the knots' ratios only where they reach ``_EXACT_FROM``, so bounds
    below it change nothing: the same paths (blended, re-timed or, with one run, stretched
    a lot at release, where only the ratios near a limit are computed again) come out bit
    for bit as with every ratio exact."""
    robot = bundled_cell.robot
    rng = np.random.default_rng(500 + seed)
    n = int(rng.integers(2, 5))
    path, s_way, _ = spline_path(_random_polyline(robot, rng, n), 0.06,
                                 corners=[(k, 0.3) for k in range(1, n)], blend="g2")
    options = TimingOptions(retries=retries)
    pieces = [time_path(robot, path, s_way, scales=[1.0] * n, tcp_speeds=[None] * n,
                        options=options)]
    monkeypatch.setattr(_release, "_EXACT_FROM", 0.0)
    pieces.append(time_path(robot, path, s_way, scales=[1.0] * n, tcp_speeds=[None] * n,
                            options=options))
    if retries > 1:
        assert pieces[0].runs > 1  # re-timed: tightened where the knots were over a limit
    else:  # stretched at release by more than a re-timing would have let through
        step = pieces[0].t[1] - pieces[0].t[0]
        assert step > (1 + timing.RETIME_ABOVE) * TimingOptions().knot_period
    for name in ("t", "q", "qd", "qdd", "s", "segment"):
        assert getattr(pieces[0], name).tobytes() == getattr(pieces[1], name).tobytes(), name


def test_a_retry_averages_at_least_as_wide_as_the_run_before(
        bundled_cell: Cell, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run timed again with tightened limits measures its own profile's swings: its
    first moving average is as wide as they need and never narrower than the run
    before's (a tightened profile with wider swings kept the first run's width, and its
    jerk went up). Over random blended paths: the widths never shrink from run to run,
    and some retry widens them."""
    robot = bundled_cell.robot
    smooth = _smooth.smooth
    widths: list[float] = []

    def spy(profile: Any, tau_a: float, tau_b: float) -> Any:
        widths.append(tau_a)
        return smooth(profile, tau_a, tau_b)

    monkeypatch.setattr(_smooth, "smooth", spy)
    grew = 0
    for seed in range(24):
        rng = np.random.default_rng(900 + seed)
        n = int(rng.integers(2, 5))
        path, s_way, _ = spline_path(_random_polyline(robot, rng, n), 0.06,
                                     corners=[(k, 0.3) for k in range(1, n)], blend="g2")
        widths.clear()
        piece = time_path(robot, path, s_way, scales=[1.0] * n, tcp_speeds=[None] * n)
        assert len(widths) == piece.runs
        assert all(b >= a for a, b in zip(widths, widths[1:], strict=False)), widths
        grew += any(b > a for a, b in zip(widths, widths[1:], strict=False))
    assert grew > 0


def test_the_tightening_kernel_takes_the_smallest_factor_of_the_windows_over_each_point(
        ) -> None:
    """Each gridpoint's factors are scaled by the smallest of the windows over it (1 where
    none): as ``np.minimum.at`` over every point of every window, bit for bit; empty
    windows (``hi <= lo``) scale nothing."""
    rng = np.random.default_rng(3)
    n = 500
    for trial in range(20):
        lo = rng.integers(0, n, 30)
        hi = np.minimum(lo + rng.integers(-3, 80, 30), n)
        acc, xs = rng.uniform(0.3, 1.0, 30), rng.uniform(0.3, 1.0, 30)
        f_acc, f_x = rng.uniform(0.5, 1.0, n), rng.uniform(0.5, 1.0, n)
        want_acc, want_x = np.ones(n), np.ones(n)
        for w in range(30):
            np.minimum.at(want_acc, np.arange(lo[w], max(hi[w], lo[w])), acc[w])
            np.minimum.at(want_x, np.arange(lo[w], max(hi[w], lo[w])), xs[w])
        want_acc *= f_acc
        want_x *= f_x
        _topp.compiled_kernels()["tighten"](lo, hi, acc, xs, np.ones(n), np.ones(n), f_acc, f_x)
        assert np.array_equal(f_acc, want_acc) and np.array_equal(f_x, want_x), trial


def test_the_profile_is_evaluated_as_numpy_evaluates_it() -> None:
    """The compiled evaluation of a TOPP-RA profile gives numpy's sums bit for bit: inside,
    at the gridpoints' times, before the start and after the end (clamped), with the last
    time at or past the end taken as the end at rest; the times in order or not."""
    rng = np.random.default_rng(8)
    for trial in range(10):
        grid = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.01, 300))])
        x = np.concatenate([[0.0], rng.uniform(0.01, 4.0, 299), [0.0]])
        profile = _topp.parametrize(grid, x)
        end = profile.duration
        t = np.sort(np.concatenate([rng.uniform(-0.1, end + 0.1, 500), profile.t]))
        if trial % 2:
            t = t[t < end]
        k = np.minimum(np.maximum(np.searchsorted(profile.t, t, side="right") - 1, 0),
                       profile.u.size - 1)
        dt = t - profile.t[k]
        want_s = np.minimum(np.maximum(profile.grid[k] + dt * profile.sd[k]
                                       + 0.5 * dt * dt * profile.u[k], grid[0]), grid[-1])
        want_sd = np.maximum(profile.sd[k] + dt * profile.u[k], 0.0)
        if t[-1] >= profile.t[-1]:
            want_s[-1], want_sd[-1] = grid[-1], 0.0
        s, sd, u = _topp.evaluate(profile, t)
        for got, want in ((s, want_s), (sd, want_sd), (u, profile.u[k])):
            assert got.tobytes() == want.tobytes(), trial
        mixed = rng.permutation(t.size - 1)  # in any order (the last one stays last)
        s, sd, u = _topp.evaluate(profile, np.append(t[mixed], t[-1]))
        for got, want in ((s, want_s), (sd, want_sd), (u, profile.u[k])):
            assert got.tobytes() == np.append(want[mixed], want[-1]).tobytes(), trial


def test_the_grid_follows_the_spline_pieces() -> None:
    """Gridpoints: strictly increasing, at most ``step`` apart, on every spline knot and
    exactly on every segment boundary (so each knot knows its segment's limits)."""
    rng = np.random.default_rng(5)
    for _ in range(300):
        breaks = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.2, rng.integers(2, 30)))])
        s_way = np.unique(np.concatenate([
            [0.0, breaks[-1]], rng.choice(breaks, rng.integers(0, breaks.size)),
            rng.uniform(0.0, breaks[-1], rng.integers(0, 4))]))
        step = float(rng.choice([0.005, 0.015, 0.05]))
        grid = _path_limits.gridpoints(breaks, s_way, step)
        assert grid[0] == 0.0 and grid[-1] == breaks[-1]
        assert np.all(np.diff(grid) > 0)
        assert np.diff(grid).max() <= step * (1 + 1e-9)
        assert np.all(np.isin(s_way, grid))
        assert np.abs(grid[:, None] - breaks[None, :]).min(axis=0).max() <= 1e-9


# -- our TOPP-RA against the toppra library ---------------------------------------------------

def _toppra_duration(path: PathSpline, grid: np.ndarray, vlim: np.ndarray, alim: np.ndarray
                     ) -> tuple[float, np.ndarray]:
    """toppra's TOPPRA (seidel solver, ParametrizeConstAccel) with per-gridpoint limits,
    acceleration in the interpolation discretisation; duration [s] and path speeds."""
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint
    from toppra.constraint.linear_constraint import canlinear_colloc_to_interpolate

    class Velocity(constraint.LinearConstraint):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.dof = vlim.shape[1]

        def compute_constraint_params(self, p: Any, gridpoints: np.ndarray, *args: object,
                                      **kwargs: object) -> tuple:
            qs = np.abs(p(gridpoints, 1))
            with np.errstate(divide="ignore"):
                sd = np.where(qs > 1e-12, vlim / np.maximum(qs, 1e-300), np.inf)
            xmax = np.minimum(np.min(sd, axis=1) ** 2, _topp.X_CAP)
            return None, None, None, None, None, None, np.stack([0 * xmax, xmax], axis=1)

    class Acceleration(constraint.LinearConstraint):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.dof = alim.shape[1]
            self.identical = False
            self.set_discretization_type(constraint.DiscretizationType.Interpolation)

        def compute_constraint_params(self, p: Any, gridpoints: np.ndarray, *args: object,
                                      **kwargs: object) -> tuple:
            ps, pss = p(gridpoints, 1), p(gridpoints, 2)
            n, dof = ps.shape
            F = np.concatenate([np.eye(dof), -np.eye(dof)])[None].repeat(n, axis=0)
            g = np.hstack([alim, alim])
            return canlinear_colloc_to_interpolate(ps, pss, np.zeros_like(ps), F, g, None,
                                                   None, gridpoints, identical=False)

    spline = ta.SplineInterpolator(path.x, path(path.x))
    instance = algo.TOPPRA([Velocity(), Acceleration()], spline, gridpoints=grid,
                           parametrizer="ParametrizeConstAccel")
    traj = instance.compute_trajectory(0.0, 0.0)
    assert traj is not None
    return float(traj.duration), np.asarray(instance.problem_data.sd_vec)


@pytest.mark.parametrize("seed", range(8))
def test_our_topp_ra_agrees_with_toppra(bundled_cell: Cell, seed: int) -> None:
    """Same path, grid and limits (varying along the path): same durations and path
    speeds as toppra, to far better than 1 %."""
    robot = bundled_cell.robot
    rng = np.random.default_rng(200 + seed)
    n = int(rng.integers(1, 5))
    path, s_way, _ = spline_path(_random_polyline(robot, rng, n), 0.06,
                                 corners=[(k, 0.3) for k in range(1, n)])
    grid = np.linspace(0.0, float(s_way[-1]), int(rng.integers(40, 400)))
    # A speed scale that changes along the path, as route steps do.
    scale = np.interp(grid, [0.0, grid[-1]], rng.uniform(0.3, 1.0, size=2))[:, None]
    vlim, alim = scale * robot.velocity_limits, scale * robot.acceleration_limits
    expected, sd_expected = _toppra_duration(path, grid, vlim, alim)

    dq, ddq = path(grid, 1), path(grid, 2)
    with np.errstate(divide="ignore"):
        xmax = np.minimum(np.min(vlim / np.abs(dq), axis=1) ** 2, _topp.X_CAP)
    x = _topp.solve(grid, xmax, *_topp.acceleration_rows(grid, dq, ddq, alim))
    assert x is not None
    profile = _topp.parametrize(grid, x)
    assert profile.duration == pytest.approx(expected, rel=1e-4)
    np.testing.assert_allclose(profile.sd, sd_expected, rtol=0, atol=1e-4 * sd_expected.max())


def test_the_kernel_reports_what_it_cannot_time() -> None:
    grid = np.linspace(0.0, 1.0, 11)
    ones = np.ones((10, 2))
    assert _topp.solve(grid, np.ones(11), ones, ones, ones) is not None
    for bad in (np.nan, np.inf, -np.inf):  # in any row, its limit or their factor
        for which in range(3):
            rows = [ones.copy(), ones.copy(), ones.copy()]
            rows[which][4, 1] = bad
            assert _topp.solve(grid, np.ones(11), *rows) is None, (bad, which)
        factor = np.ones(11)
        factor[5] = bad
        assert _topp.solve(grid, np.ones(11), ones, ones, ones, factor) is None, bad
    assert _topp.solve(grid, np.where(grid == 0.5, np.nan, 1.0), ones, ones, ones) is None
    with pytest.raises(ValueError, match="one per gridpoint"):
        _topp.solve(grid, np.ones(11), ones, ones, ones, np.ones(10))
    # No acceleration at all: the path cannot start.
    assert _topp.solve(grid, np.ones(11), ones, ones, 0 * ones) is None


def test_timing_needs_neither_toppra_nor_numba_at_import() -> None:
    """numba is imported on the first timing unless the kernels are compiled ahead of
    time (safepath._aot), toppra never."""
    from safepath import _aot

    script = (
        "import sys\n"
        "import safepath.timing as timing\n"
        "print('numba' in sys.modules, 'scipy' in sys.modules)\n"
        "from safepath import load_cell\n"
        f"cell = load_cell({str(ROOT / 'scenes' / 'quality_check_cell')!r})\n"
        "path, s_way, _ = timing.spline_path([cell.pose('high1'), cell.pose('grip')], 0.06)\n"
        "timing.time_path(cell.robot, path, s_way, scales=[1.0], tcp_speeds=[None])\n"
        "print('numba' in sys.modules, 'toppra' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=120).stdout.split()
    jit = _aot.find()[0] is None or os.environ.get("SAFEPATH_AOT") == "0"
    assert out == ["False", "False", str(jit), "False"]


def test_a_segment_takes_the_quick_way_only_when_no_point_repeats_the_one_before() -> None:
    """time_segments keeps every waypoint of a segment at once only when none lies within
    1e-10 (in every joint) of the one before it, the last kept one before the first;
    otherwise it drops the repeats one by one."""
    from safepath.planning._chunks import apart

    a = np.array([0.1, 0.2, 0.3])
    b = a + [0.0, 0.0, 1e-9]
    c = a + [0.0, 0.0, 5e-11]
    assert apart(None, [a, b])
    assert apart(a - 1.0, [a, b])
    assert not apart(None, [a, c])  # c repeats a
    assert not apart(c, [a, b])  # a repeats the last kept point
    assert not apart(None, [a, b, b.copy()])


def _shift_reference(f: np.ndarray, dt: float) -> int:
    """The fewest rows ``m >= 1`` over which no column of ``f`` changes by more than
    ``m dt`` (a plain search over every ``m``)."""
    for m in range(1, f.shape[0]):
        if float(np.abs(f[m:] - f[:-m]).max()) <= m * dt:
            return m
    return f.shape[0]


@pytest.mark.parametrize("seed", range(12))
def test_the_jerk_window_kernel_finds_the_fewest_rows(seed: int) -> None:
    """The compiled search for the jerk smoothing's window equals a plain search over
    every width, on random accelerations (steps, ramps and noise)."""
    from safepath.timing._topp import compiled_kernels

    rng = np.random.default_rng(seed)
    n, dof = int(rng.integers(3, 300)), int(rng.integers(1, 8))
    f = np.cumsum(rng.normal(0.0, 0.02, (n, dof)), axis=0)
    f[rng.integers(0, n):] += rng.normal(0.0, 1.0, dof)  # a switch
    f = np.vstack([np.zeros((1, dof)), f, np.zeros((1, dof))])
    dt = float(rng.uniform(0.001, 0.05))
    assert compiled_kernels()["jerk_shift"](np.ascontiguousarray(f.T), dt) == \
        _shift_reference(f, dt)


#: A path the Panda planner produced on a fresh problem set (benchmarks/peers, seed 96001,
#: p19): five via points, the last leg 6 mrad long, so its blend is cut to 2.5 mrad.
_NEARLY_AT_REST = np.array([
    [2.551501, 0.357605, -2.742295, -2.69757,
     2.247519, 3.367837, 1.709813],
    [1.181827375878846, 0.26083754946817805, -1.4701365438864564, -2.748239305796226,
     1.740653873043366, 3.4178140862072706, 0.7108158882478782],
    [-0.2542669406923108, 0.10269100781843699, 0.1845382964802827, -2.7596697686992986,
     1.3839061943360176, 3.341456507286333, -0.23389601297837206],
    [-0.3063935058269199, 0.004742662702841016, 0.7664623213737446, -2.692260629530598,
     1.6551253449937775, 3.12924263081167, -0.10108210587466204],
    [-0.28669690387996766, -0.028240068244388218, 0.9041974927530745, -2.572861183220206,
     1.408397342420852, 3.0172344178535475, -0.1673172294227387],
    [1.9008889070839958, 0.6026199406469228, -1.4748226115172418, -1.5455439963245825,
     -0.3872564301197149, 2.677239476897539, -1.5752784689835828],
    [1.901688, 0.600838, -1.478253, -1.546525,
     -0.382863, 2.676792, -1.576735]])


def test_a_timing_that_would_take_forever_is_refused_not_made() -> None:
    """TOPP-RA's grid cannot resolve a 2.5 mrad blend: its profile passes it almost at
    rest and lasts 1.3e6 s; its knots (and the jerk window's samples, 4.7 GB) were
    being made until the process was killed. Anything over ``max_duration`` is refused
    with a TimingError first (the planner then tries a smaller blend)."""
    from safepath.description.robot_folder import load_robot

    robot = load_robot("panda")
    corners = [(1, 0.1), (2, 0.1), (3, 0.1), (4, 0.1), (5, 0.002471201868041414)]
    path, s_way, _ = spline_path(list(_NEARLY_AT_REST), 0.06, corners=corners, blend="g2")
    with pytest.raises(TimingError, match="over max_duration 3600 s: the path is passed "
                                          "almost at rest"):
        time_path(robot, path, s_way, scales=[1.0] * 5, tcp_speeds=[None] * 5)
    # Below the bound, the same check on an ordinary path.
    path, s_way, _ = spline_path(list(_NEARLY_AT_REST[:3]), 0.06, corners=[(1, 0.3)])
    piece = time_path(robot, path, s_way, scales=[1.0] * 2, tcp_speeds=[None] * 2)
    with pytest.raises(TimingError, match="max_duration 0.5 s"):
        time_path(robot, path, s_way, scales=[1.0] * 2, tcp_speeds=[None] * 2,
                  options=TimingOptions(max_duration=0.5))
    assert piece.t[-1] > 0.5
    with pytest.raises(ConfigError, match="max_duration"):
        TimingOptions(max_duration=0.0)


@pytest.mark.parametrize("blend", ["g2", "gap"])
def test_the_gridpoints_peaks_are_numpys_bit_for_bit(blend: str) -> None:
    """The compiled per-gridpoint peaks of the path limits (``grid_peaks``): the largest
    ``|q'| / v_max`` and the largest ``|q'''| / j`` over the joints, ``|q'''|`` the larger
    of the cubic pieces' on both sides of a gridpoint (one on a breakpoint ends the piece
    before it too), give numpy's values bit for bit, on TOPP-RA's own grids."""
    rng = np.random.default_rng(21)
    kernel = _topp.compiled_kernels()["grid_peaks"]
    for trial in range(12):
        dof = int(rng.integers(2, 8))
        points = rng.uniform(-2.0, 2.0, (int(rng.integers(2, 6)), dof))
        corners = [(k, 0.2) for k in range(1, len(points) - 1)]
        path, s_way, _ = spline_path(points, 0.06, corners=corners, blend=blend)
        grid = _path_limits.gridpoints(path.x, s_way, 0.005,
                                       _path_limits.straight_pieces(path))
        dq = path(grid, 1)
        vmax, jden = rng.uniform(0.5, 3.0, dof), rng.uniform(10.0, 500.0, dof)
        coef = path.coefficients
        last = coef.shape[0] - 1
        after = np.minimum(np.maximum(np.searchsorted(path.x, grid, side="right") - 1, 0),
                           last)
        before = np.minimum(np.maximum(np.searchsorted(path.x, grid, side="left") - 1, 0),
                            last)
        c3 = np.abs(coef[:, 3, :])
        want_v = np.max(np.abs(dq) / vmax, axis=1)
        want_j = np.max(6.0 * np.maximum(c3[after], c3[before]) / jden, axis=1)
        assert np.isin(path.x, grid).all()  # breakpoints among the gridpoints
        v, j = np.empty(grid.size), np.empty(grid.size)
        kernel(grid, path.x, np.ascontiguousarray(coef), np.ascontiguousarray(dq), vmax, jden,
               v, j)
        assert v.tobytes() == want_v.tobytes() and j.tobytes() == want_j.tobytes(), trial


def test_topp_ras_rows_are_the_limits_at_both_ends_of_each_interval() -> None:
    """``acceleration_rows``: on interval ``i``, the limits at ``s_i`` then those at
    ``s_{i+1}`` with ``x_{i+1} = x_i + 2 delta u_i`` expanded, bit for bit the stacked
    numpy sums."""
    rng = np.random.default_rng(5)
    n, dof = 400, 6
    grid = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.005, n - 1))])
    dq, ddq, alim = (rng.normal(0.0, 1.0, (n, dof)) for _ in range(3))
    a, b, c = _topp.acceleration_rows(grid, dq, ddq, alim)
    delta = np.diff(grid)[:, None]
    for got, want in ((a, np.hstack([dq[:-1], dq[1:] + 2.0 * delta * ddq[1:]])),
                      (b, np.hstack([ddq[:-1], ddq[1:]])), (c, np.hstack([alim[:-1], alim[1:]]))):
        assert got.shape == (n - 1, 2 * dof) and got.tobytes() == want.tobytes()
