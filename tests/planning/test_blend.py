"""Corner blends with continuous curvature (issue 39, ``spline_path(..., blend="g2")``,
``TimingOptions(corner_blend="g2")``): the path leaves the polyline ``r`` before a blended corner,
rejoins it ``r`` after (along the polyline), passes the corner closer than ``r``, and
keeps every other waypoint exactly."""

from __future__ import annotations

import numpy as np
import pytest

from safepath.timing import spline_path


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    lam = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + lam[:, None] * ab), axis=1)


@pytest.mark.parametrize("seed", range(20))
def test_a_blend_leaves_and_rejoins_the_polyline_r_from_the_corner(seed: int) -> None:
    rng = np.random.default_rng(seed)
    dof = int(rng.integers(2, 8))
    waypoints = [rng.normal(size=dof) * 1.5 for _ in range(4)]
    legs = [float(np.linalg.norm(b - a)) for a, b in zip(waypoints[:-1], waypoints[1:],
                                                         strict=True)]
    radius = float(rng.uniform(0.05, 0.6))
    r = [min(radius, 0.4 * legs[k - 1], 0.4 * legs[k]) for k in (1, 2)]
    path, s_way, _ = spline_path(waypoints, 0.06, corners=[(1, r[0]), (2, r[1])],
                                   blend="g2")
    s = np.linspace(0.0, float(path.x[-1]), 20001)
    q = path(s)  # type: ignore[operator]
    assert np.all(np.diff(s_way) > 0) and s_way[0] == 0.0 and s_way[-1] == path.x[-1]
    np.testing.assert_allclose(q[0], waypoints[0], atol=1e-12)
    np.testing.assert_allclose(q[-1], waypoints[-1], atol=1e-9)
    for k in (1, 2):
        corner = waypoints[k]
        gap = np.linalg.norm(q - corner, axis=1)
        # The corner itself is cut, by less than the radius.
        assert 1e-6 < gap.min() < r[k - 1]
        # Outside the blend (farther than r along the path from its middle, with a
        # spacing's slack for the spline), the path lies on the polyline's segments.
        far = np.abs(s - s_way[k]) > r[k - 1] * 1.2 + 0.06
        near_k = np.abs(s - s_way[k]) < 1.5 * max(r) + 0.5 * min(legs)
        on = np.minimum(_distance_to_segment(q, waypoints[k - 1], corner),
                        _distance_to_segment(q, corner, waypoints[k + 1]))
        assert on[far & near_k].max(initial=0.0) < 1e-3
    # The corner's path parameter is the blend's middle, the nearest point to it.
    for k in (1, 2):
        nearest = s[np.argmin(np.linalg.norm(q - waypoints[k], axis=1))]
        assert abs(nearest - s_way[k]) < 0.25 * r[k - 1] + 0.01


def test_radius_zero_passes_through_the_corner() -> None:
    waypoints = [np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0])]
    path, s_way, _ = spline_path(waypoints, 0.06, corners=[(1, 0.0)], blend="g2")
    np.testing.assert_allclose(path(s_way[1]), waypoints[1], atol=1e-12)  # type: ignore[operator]


def test_blends_that_meet_do_not_repeat_a_point() -> None:
    """Radii larger than half the way between two corners are reduced to it: the two
    blends meet at the middle of the segment between them, and the spline is valid."""
    waypoints = [np.zeros(2), np.array([1.0, 0.0]), np.array([1.0, 1.0]), np.array([2.0, 1.0])]
    path, s_way, knots = spline_path(waypoints, 0.06, corners=[(1, 5.0), (2, 5.0)],
                                       blend="g2")
    assert np.all(np.diff(knots) > 0) and np.all(np.diff(s_way) > 0)
    # The blends meet in the middle of the segment between the corners, on it.
    s = np.linspace(0.0, float(path.x[-1]), 2001)
    q = path(s)  # type: ignore[operator]
    assert np.linalg.norm(q - np.array([1.0, 0.5]), axis=1).min() < 1e-3


def test_the_planner_blends_as_its_options_say(bundled_cell) -> None:  # noqa: ANN001
    """``TimingOptions(corner_blend="g2")`` reaches the planner's splines: the route's
    blended chunk differs from the default's, and both keep every limit as executed."""
    from safepath import PlanOptions, TimingOptions, plan_cell
    from safepath.model.execution import check_executed

    routes = bundled_cell.route_table()
    robot = bundled_cell.robot
    plans = {blend: plan_cell(bundled_cell, PlanOptions(timing=TimingOptions(
        corner_blend=blend)), routes={"phase1": routes["phase1"]})["phase1"]
        for blend in ("gap", "g2")}
    assert plans["gap"].q.shape != plans["g2"].q.shape or \
        not np.array_equal(plans["gap"].q, plans["g2"].q)
    for traj in plans.values():
        check_executed(traj.t, traj.q, traj.qd, traj.qdd,
                       velocity_limits=robot.velocity_limits,
                       acceleration_limits=robot.acceleration_limits,
                       jerk_limits=robot.jerk_limits)


@pytest.mark.parametrize("seed", range(10))
def test_blends_are_exact_with_the_smallest_rate_of_curvature(seed: int) -> None:
    """Every via point blended: the path is the polyline averaged around each corner by
    a triangle of width ``2 r`` (curvature continuous, its rate ``|d_b - d_a| / r^2``
    and no more): a spline through points sampled along a curve would have a third
    derivative many times the curve's, and the jerk limits cap the speed by it."""
    rng = np.random.default_rng(100 + seed)
    dof = int(rng.integers(2, 8))
    waypoints = [rng.normal(size=dof) * 1.5 for _ in range(int(rng.integers(3, 6)))]
    legs = [float(np.linalg.norm(b - a)) for a, b in zip(waypoints[:-1], waypoints[1:],
                                                         strict=True)]
    corners = [(k, min(float(rng.uniform(0.05, 0.6)), 0.4 * legs[k - 1], 0.4 * legs[k]))
               for k in range(1, len(waypoints) - 1)]
    path, s_way, _ = spline_path(waypoints, 0.06, corners=corners, blend="g2")
    d = [(b - a) / np.linalg.norm(b - a) for a, b in zip(waypoints[:-1], waypoints[1:],
                                                         strict=True)]
    s = np.linspace(0.0, float(path.x[-1]), 40001)
    rate = np.abs(path(s, 3))  # type: ignore[operator]
    for k, r in corners:
        near = np.abs(s - s_way[k]) < r
        bound = np.abs(d[k] - d[k - 1]) / r ** 2
        assert np.all(rate[near] <= bound * (1 + 1e-9) + 1e-9)
        # The blend's middle: the polyline's corner moved by (d_b - d_a) r / 6.
        np.testing.assert_allclose(path(s_way[k]), waypoints[k] + (d[k] - d[k - 1]) * r / 6,
                                   atol=1e-12)
    straight = np.all([np.abs(s - s_way[k]) > r for k, r in corners], axis=0)
    assert rate[straight].max() < 1e-9
    # Continuous up to the second derivative across every breakpoint.
    inner = path.x[1:-1]
    for nu in (0, 1, 2):
        np.testing.assert_allclose(path(inner - 1e-12, nu), path(inner, nu), atol=1e-9)  # type: ignore[operator]
    np.testing.assert_allclose(path(s_way[-1]), waypoints[-1], atol=1e-12)  # type: ignore[operator]


def test_topp_ra_grid_is_coarser_only_on_straight_pieces() -> None:
    """TOPP-RA's gridpoints lie ``grid_step`` apart on the blends and up to
    ``STRAIGHT_STEPS`` times that on the straight pieces (where the limits hold between
    gridpoints wherever they hold at them)."""
    from safepath.timing._path_limits import STRAIGHT_STEPS, gridpoints, straight_pieces

    waypoints = [np.zeros(3), np.array([2.0, 0.0, 0.0]), np.array([2.0, 2.0, 1.0])]
    path, s_way, _ = spline_path(waypoints, 0.06, corners=[(1, 0.3)], blend="g2")
    straight = straight_pieces(path)
    assert straight is not None and straight.tolist() == [True, False, False, True]
    grid = gridpoints(path.x, s_way, 0.005, straight)
    gaps = np.diff(grid)
    piece = np.searchsorted(path.x, grid[:-1], side="right") - 1
    assert gaps[~straight[piece]].max() <= 0.005 + 1e-12
    assert 0.005 < gaps[straight[piece]].min()
    assert gaps[straight[piece]].max() <= STRAIGHT_STEPS * 0.005 + 1e-12
