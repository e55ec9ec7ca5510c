"""Route steps with different limits timed in one pass (issue 39,
``TimingOptions(limits_ahead=True)``): a step's speed scale and TCP speed limit hold on
TOPP-RA's grid as far around the step as the jerk smoothing's moving averages reach, so
the first run's knots already keep the slower step's limits as executed (their quintic
join), with no re-timing.

On the four bundled robots, each a two-step straight path (the step boundary in the
middle); the executed limits are each interval's smaller-scaled step's, at 0 tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

from safepath.description.robot_folder import load_robot
from safepath.model.execution import interval_ratios
from safepath.timing import TimingOptions, _path_limits, spline_path, time_path

ROBOTS = ("gen3_lite", "ned3pro", "panda", "ur5")
#: (speed scales, TCP speed limits [m/s]) of the two steps.
STEPS = (((1.0, 0.3), (None, None)), ((0.3, 1.0), (None, None)),
         ((1.0, 0.5), (None, 0.25)))


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize(("scales", "tcp"), STEPS)
def test_a_slower_step_is_timed_in_one_run_within_its_limits(
        name: str, scales: tuple[float, float], tcp: tuple[float | None, float | None]
) -> None:
    robot = load_robot(name)
    rng = np.random.default_rng(7)
    lo, hi = robot.lower * 0.6, robot.upper * 0.6
    a, b = (lo + rng.random(robot.dof) * (hi - lo) for _ in range(2))
    path, s_way, _ = spline_path([a, 0.5 * (a + b), b], 0.06)
    piece = time_path(robot, path, s_way, scales=list(scales), tcp_speeds=list(tcp),
                      options=TimingOptions(limits_ahead=True))
    assert piece.runs == 1
    step_scale = np.asarray(scales)[piece.segment]
    interval = np.minimum(step_scale[:-1], step_scale[1:])[:, None]
    ratios = interval_ratios(piece.t, piece.q, piece.qd, piece.qdd,
                             vmax=interval * robot.velocity_limits,
                             amax=interval * robot.acceleration_limits,
                             jmax=interval * robot.jerk_limits)
    worst = max(float(r.max()) for r in ratios)
    assert worst <= 1.0
    # Near the limits, not stopped short of them by the tightening.
    assert worst > 0.9


def test_the_sliding_minimum_is_the_minimum_of_each_range() -> None:
    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 64, 1000):
        values = rng.random(n)
        lo = rng.integers(0, n, n)
        hi = np.minimum(lo + 1 + rng.integers(0, n, n), n)
        expected = np.array([values[a:b].min() for a, b in zip(lo, hi, strict=True)])
        assert np.array_equal(_path_limits.sliding_min(values, lo, hi), expected)


def test_a_step_limit_holds_ahead_only_as_far_as_the_averages_reach() -> None:
    robot = load_robot("ur5")
    a = np.zeros(robot.dof)
    b = np.full(robot.dof, 1.0)
    path, s_way, _ = spline_path([a, 0.5 * (a + b), b], 0.06)
    kwargs = {"speed_scale": 1.0, "grid_step": 0.005}
    own = _path_limits.path_limits(robot, path, s_way, [1.0, 0.4], [None, None], **kwargs)
    ahead = _path_limits.path_limits(robot, path, s_way, [1.0, 0.4], [None, None],
                                     ahead=0.2, **kwargs)
    slower = ahead.at_grid.alim[:, 0] < own.at_grid.alim[:, 0]
    assert slower.any()
    # Only before the slower step (which keeps its own limits), and not from the start.
    assert np.all(ahead.grid[slower] < s_way[1])
    assert not slower[0]
    np.testing.assert_array_equal(ahead.at_grid.alim[slower, 0],
                                  own.at_grid.alim[-1, 0])
    # The limits the knots are checked against are the steps' own.
    np.testing.assert_array_equal(ahead.amax_seg, own.amax_seg)


def _tcp_speed_ratio(robot, piece, tcp: tuple[float, float]) -> float:  # noqa: ANN001
    """The TCP's largest speed over its step's limit in the knots' quintic join, sampled
    every 0.25 ms (speeds from positions 10 us apart: independent of the timing's own
    check, which uses velocities)."""
    from safepath.model.execution import join

    times = np.arange(0.0, float(piece.t[-1]), 2.5e-4)
    h = 1e-5
    p = [join(piece.t, piece.q, piece.qd, piece.qdd, times + d)[0] for d in (-h, h)]
    speed = np.linalg.norm(robot.tcp_positions(p[1]) - robot.tcp_positions(p[0]),
                           axis=1) / (2 * h)
    k = np.clip(np.searchsorted(piece.t, times, side="right") - 1, 0, piece.t.size - 2)
    limit = np.asarray(tcp)[np.minimum(piece.segment[k], piece.segment[k + 1])]
    # The interval's smaller limit: both steps' limits where it straddles the boundary.
    limit = np.minimum(limit, np.asarray(tcp)[np.maximum(piece.segment[k],
                                                         piece.segment[k + 1])])
    inside = (times > h) & (times < piece.t[-1] - h)
    return float(np.max(speed[inside] / limit[inside]))


@pytest.mark.parametrize("name", ("panda", "ur5", "gen3_lite"))
@pytest.mark.parametrize("tcp_ahead", (True, False))
@pytest.mark.parametrize("tcp", ((0.4, 0.12), (0.12, 0.4)))
@pytest.mark.parametrize("knots", ((0.004, 3.0), (0.006, 2.0)))
def test_the_tcp_speed_holds_as_executed_across_steps(name: str, tcp_ahead: bool,
                                                      tcp: tuple[float, float],
                                                      knots: tuple[float, float]) -> None:
    """Two steps with different TCP speed limits, blended at the via point between them:
    the TCP's speed in the motion the controller executes stays within each step's limit
    (the smaller of both across their boundary), with or without the limits held ahead,
    with the default knots or 6 ms apart (``knots``: knot period [s], jerk smoothing; on
    the Panda with the 0.12 m/s step first, the peak lies between the check's 1 kHz
    samples, 2e-6 over the limit, unless the samples near the peak are refined); it comes
    near the limit (not slowed far below it)."""
    robot = load_robot(name)
    rng = np.random.default_rng(11)
    lo, hi = robot.lower * 0.5, robot.upper * 0.5
    a, via, b = (lo + rng.random(robot.dof) * (hi - lo) for _ in range(3))
    path, s_way, _ = spline_path([a, via, b], 0.06, corners=[(1, 0.3)], blend="g2")
    piece = time_path(robot, path, s_way, scales=[1.0, 1.0], tcp_speeds=list(tcp),
                      options=TimingOptions(tcp_ahead=tcp_ahead, knot_period=knots[0],
                                            jerk_smoothing=knots[1]))
    ratio = _tcp_speed_ratio(robot, piece, tcp)
    assert 0.95 < ratio <= 1.0 + 1e-6
