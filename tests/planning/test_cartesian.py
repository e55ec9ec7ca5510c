"""Straight TCP lines by inverse kinematics: on the segment, orientation kept, no jumps."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from safepath import IKError
from safepath.cell import Cell
from safepath.planning import LineOptions, cartesian_line, solve_ik

LINES = [("grip", "high1"), ("high2", "low1"), ("low1", "high2")]


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    s = float(np.clip((p - a) @ d / (d @ d), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + s * d)))


@pytest.mark.parametrize(("a", "b"), LINES)
def test_line_stays_on_the_segment(bundled_cell: Cell, a: str, b: str) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose(a), bundled_cell.pose(b)
    options = LineOptions()
    path = cartesian_line(robot, q0, q1, options=options)
    np.testing.assert_array_equal(path[0], q0)
    np.testing.assert_array_equal(path[-1], q1)
    T0, T1 = robot.frame_pose(q0), robot.frame_pose(q1)
    p0, p1 = T0.translation, T1.translation
    length = float(np.linalg.norm(p1 - p0))
    assert length > 0.15
    deviation = max(_distance_to_segment(robot.tcp_position(q), p0, p1) for q in path)
    assert deviation < 5e-4, f"TCP {deviation * 1000:.2f} mm off the line"
    # Waypoints advance monotonically, at most `step` apart (the last one may snap
    # to the taught pose, which lies on the line within the IK tolerance).
    along = np.array([(robot.tcp_position(q) - p0) @ (p1 - p0) / length for q in path])
    assert np.all(np.diff(along) > 0)
    assert np.diff(along).max() <= options.step + 1e-4
    # No joint jumps.
    jumps = np.abs(np.diff(np.asarray(path), axis=0)).max()
    assert jumps <= options.max_joint_step


@pytest.mark.parametrize(("a", "b"), LINES)
def test_line_keeps_orientation(bundled_cell: Cell, a: str, b: str) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose(a), bundled_cell.pose(b)
    path = cartesian_line(robot, q0, q1)
    R0, R1 = robot.frame_pose(q0).rotation, robot.frame_pose(q1).rotation
    turn = float(np.linalg.norm(pin.log3(R0.T @ R1)))
    assert turn < np.radians(10)  # taught poses of a vertical move: a few degrees apart
    for q in path[1:-1]:
        R = robot.frame_pose(q).rotation
        # Never farther from the start orientation than the goal is, and on the way
        # between the two (geodesic), within the IK tolerance.
        assert np.linalg.norm(pin.log3(R0.T @ R)) <= turn + 1e-3
        assert (np.linalg.norm(pin.log3(R0.T @ R)) + np.linalg.norm(pin.log3(R.T @ R1))
                <= turn + 2e-3)


def test_line_through_the_base_axis_is_unreachable(bundled_cell: Cell) -> None:
    """From high1 to its mirror image across the base: the line passes the base axis."""
    robot = bundled_cell.robot
    q0 = bundled_cell.pose("high1")
    q1 = q0.copy()
    q1[0] = 2.9  # joint_1 turned by about 170 deg
    p0, p1 = robot.tcp_position(q0), robot.tcp_position(q1)
    with pytest.raises(IKError) as info:
        cartesian_line(robot, q0, q1, step_name="3 line mirror")
    err = info.value
    assert 0.0 < err.fraction < 1.0
    assert err.step == "3 line mirror"
    position = np.asarray(err.position)
    assert position.shape == (3,)
    assert _distance_to_segment(position, p0, p1) < 1e-9
    expected = p0 + err.fraction * (p1 - p0)
    np.testing.assert_allclose(position, expected, atol=1e-9)
    assert f"{err.fraction:.0%}" in str(err)


def test_solve_ik_round_trip_and_failure(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    target_q = bundled_cell.pose("low1")
    T = robot.frame_pose(target_q)
    q = solve_ik(robot, T, bundled_cell.pose("high2"))
    assert q is not None
    np.testing.assert_allclose(robot.tcp_position(q), T.translation, atol=1e-5)
    assert np.linalg.norm(pin.log3(robot.frame_pose(q).rotation.T @ T.rotation)) < 1e-4
    assert robot.within_limits(q)
    far = pin.SE3(T.rotation, T.translation + np.array([1.0, 0.0, 0.0]))
    assert solve_ik(robot, far, target_q) is None
