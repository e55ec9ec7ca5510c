"""Property: a timed path stays within the robot's limits as the controller executes it.

Random joint paths (a start, 1 to 3 via points and a goal, anywhere in the limits) of
each bundled robot, with random blend radii at the via points, step speed scales and TCP
speed limits, are timed by the public timing API (:func:`safepath.timing.spline_path`,
then :func:`safepath.timing.time_path`). The motion a trajectory controller makes of the
released knots (their quintic join, :func:`safepath.model.execution.interval_ratios`)
exceeds no velocity, acceleration or jerk limit on any interval: every ratio is at most
1.0, with no tolerance. (Jerk limits raised fourfold inside ``time_path`` make it fail.)

A path that turns back exactly the way it came at a blended via point (found by this
property: the spline raised a ``ValueError`` there) is timed too; the example test below
keeps the case.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from safepath import Robot, load_robot
from safepath.model.execution import interval_ratios
from safepath.timing import spline_path, time_path

from .strategies import bounded, in_limits

ROBOTS = ["ned3pro", "gen3_lite", "panda", "ur5"]
#: Spacing of the spline's interpolation points [rad] (TimingOptions' default).
SPACING = 0.06
#: Consecutive waypoints at least this far apart in some joint [rad]: a path, not a stop.
MIN_STEP = 0.05


@cache
def _robot(name: str) -> Robot:
    return load_robot(name)


@st.composite
def _paths(draw: st.DrawFn, robot: Robot) -> tuple[list[np.ndarray], list, list, list]:
    """Waypoints, corners (via point, blend radius [rad]), step scales and TCP speed
    limits [m/s] of one random path."""
    vias = draw(st.integers(1, 3))
    waypoints = [draw(in_limits(robot)) for _ in range(vias + 2)]
    for a, b in zip(waypoints, waypoints[1:], strict=False):
        assume(np.max(np.abs(b - a)) >= MIN_STEP)
    radii = st.sampled_from([0.0, 0.1, 0.3, 0.6])
    corners = [(k, draw(radii)) for k in range(1, vias + 1)]
    scales = [draw(st.floats(0.2, 1.0)) for _ in range(vias + 1)]
    tcp = [draw(st.one_of(st.none(), st.floats(0.05, 0.5))) for _ in range(vias + 1)]
    return waypoints, corners, scales, tcp


@pytest.mark.parametrize("name", ROBOTS)
def test_timed_paths_keep_the_limits_as_executed(name: str) -> None:
    robot = _robot(name)

    @bounded(25)
    @given(_paths(robot))
    def within(drawn: tuple[list[np.ndarray], list, list, list]) -> None:
        waypoints, corners, scales, tcp = drawn
        path, s_way, _ = spline_path(waypoints, SPACING, corners=corners)
        piece = time_path(robot, path, s_way, scales=scales, tcp_speeds=tcp)
        ratios = interval_ratios(piece.t, piece.q, piece.qd, piece.qdd,
                                 vmax=robot.velocity_limits, amax=robot.acceleration_limits,
                                 jmax=robot.jerk_limits)
        for what, r in zip(("velocity", "acceleration", "jerk"), ratios, strict=True):
            assert np.max(r) <= 1.0, f"{what} at {np.max(r)!r} of its limit"

    within()


@pytest.mark.parametrize("blend", ["gap", "g2"])
def test_a_path_turning_back_at_a_blended_via_point_is_timed(blend: str) -> None:
    robot = _robot("ned3pro")
    a, b = np.zeros(robot.dof), np.zeros(robot.dof)
    a[1] = -1.0
    path, s_way, _ = spline_path([a, b, a], SPACING, corners=[(1, 0.1)], blend=blend)
    piece = time_path(robot, path, s_way, scales=[1.0, 1.0], tcp_speeds=[None, None])
    np.testing.assert_array_equal(piece.q[-1], a)
    ratios = interval_ratios(piece.t, piece.q, piece.qd, piece.qdd,
                             vmax=robot.velocity_limits, amax=robot.acceleration_limits,
                             jmax=robot.jerk_limits)
    assert max(float(np.max(r)) for r in ratios) <= 1.0
    if blend == "gap":  # not cut: the path passes through the via point
        np.testing.assert_allclose(path(s_way[1]), b, atol=1e-12)
