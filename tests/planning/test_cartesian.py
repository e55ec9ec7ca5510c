"""Straight TCP lines by inverse kinematics: on the segment, orientation kept, no jumps;
the numba kernel that runs them agrees with Pinocchio."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from safepath import IKError, Robot, load_robot
from safepath.cell import Cell
from safepath.kinematics import LineOptions, solve_ik
from safepath.kinematics import _ik_kernel as kernel
from safepath.planning import cartesian_line
from safepath.planning.cartesian import line_chain

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
    with pytest.raises(IKError, match="no inverse-kinematics solution") as info:
        solve_ik(robot, far, target_q, step="reach")
    assert info.value.step == "reach" and info.value.fraction is None  # a target, no line
    assert "of the line" not in str(info.value)
    np.testing.assert_allclose(info.value.position, far.translation)


# -- the numba line kernel against Pinocchio ----------------------------------------------
def _screw_robot() -> Robot:
    """A 7-joint arm, built in code, with every joint kind the line kernel follows:
    revolute about a frame axis and about a skew axis, prismatic along a frame axis and
    a skew axis, and helical; the TCP hangs off the sixth joint, so the seventh is off
    the chain (its Jacobian column must be zero)."""
    rng = np.random.default_rng(11)
    model = pin.Model()
    kinds = [pin.JointModelRZ(), pin.JointModelPrismaticUnaligned(np.array([0.6, 0.0, 0.8])),
             pin.JointModelRevoluteUnaligned(np.array([0.0, 0.6, 0.8])),
             pin.JointModelHelicalUnaligned(np.array([0.48, 0.6, 0.64]), 0.05),
             pin.JointModelRY(), pin.JointModelPX(), pin.JointModelRX()]
    parent = 0
    ids = []
    for i, kind in enumerate(kinds):
        placement = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.1)
        lower, upper = (-0.3, 0.3) if kind.shortname().startswith(("JointModelP",)) else (-3, 3)
        ids.append(model.addJoint(ids[-2] if i == 6 else parent, kind, placement, f"j{i}",
                                  np.array([10.0]), np.array([1.0]), np.array([lower]),
                                  np.array([upper])))
        parent = ids[-1]
    model.addFrame(pin.Frame("tcp", ids[5], pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.1])),
                                                    np.array([0.05, 0.0, 0.12])),
                             pin.FrameType.OP_FRAME))
    return Robot(name="screws", model=model, collision_model=pin.GeometryModel(),
                 visual_model=None, velocity_limits=np.ones(7), acceleration_limits=np.ones(7),
                 tcp_frame="tcp")


@pytest.fixture(scope="module", params=["ned3pro", "ur5", "panda", "screws"])
def any_robot(request: pytest.FixtureRequest) -> Robot:
    return _screw_robot() if request.param == "screws" else load_robot(request.param)


def _random_q(robot: Robot, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(np.maximum(robot.lower, -3.0), np.minimum(robot.upper, 3.0))


def test_kernel_kinematics_match_pinocchio(any_robot: Robot) -> None:
    robot = any_robot
    chain = line_chain(robot)
    rng = np.random.default_rng(0)
    data = robot.model.createData()
    for _ in range(20):
        q = _random_q(robot, rng)
        R, p, J = np.empty((3, 3)), np.empty(3), np.empty((6, robot.dof))
        kernel.tcp_pose(chain.joint_f, chain.joint_i, chain.frame_f, q, R, p)
        kernel.tcp_jacobian(chain.joint_f, chain.joint_i, chain.frame_f, q, J)
        T = robot.frame_pose(q)
        np.testing.assert_allclose(R, T.rotation, atol=1e-12)
        np.testing.assert_allclose(p, T.translation, atol=1e-12)
        J_pin = pin.computeFrameJacobian(robot.model, data, q, robot.tcp_frame_id, pin.LOCAL)
        np.testing.assert_allclose(J, J_pin, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-6, 1e-4, 0.3, 2.0, 2.8, np.pi - 1e-3, np.pi])
def test_kernel_log6_and_jlog6_match_pinocchio(angle: float) -> None:
    rng = np.random.default_rng(1)
    for _ in range(10):
        axis = rng.normal(size=3)
        M = pin.SE3(pin.exp3(angle * axis / np.linalg.norm(axis)), rng.normal(size=3) * 0.2)
        R, p = np.ascontiguousarray(M.rotation), np.ascontiguousarray(M.translation)
        out, jac = np.empty(6), np.empty((6, 6))
        kernel.log6(R, p, out)
        np.testing.assert_allclose(out, pin.log6(M).vector, atol=1e-9)
        if angle < np.pi - 1e-6:  # Jlog6 is singular at pi
            kernel.jlog6(R, p, jac)
            np.testing.assert_allclose(jac, pin.Jlog6(M), atol=1e-7)


def test_kernel_solve_takes_the_steps_of_solve_ik(any_robot: Robot) -> None:
    """Same algorithm: from the same seed, the same solution (to rounding), or none."""
    robot = any_robot
    chain = line_chain(robot)
    options = LineOptions()
    params = np.array([options.position_tolerance, options.orientation_tolerance,
                       options.max_joint_step, 1e-6])
    rng = np.random.default_rng(2)
    solved = 0
    for trial in range(12):
        q_target = _random_q(robot, rng)
        seed = np.clip(q_target + rng.normal(size=robot.dof) * 0.2, robot.lower, robot.upper)
        T = robot.frame_pose(q_target)
        if trial == 0:  # out of reach
            T = pin.SE3(T.rotation, T.translation + np.array([5.0, 0.0, 0.0]))
        try:
            expected: np.ndarray | None = solve_ik(robot, T, seed, options=options)
        except IKError:
            expected = None
        q = seed.copy()
        steps = kernel.solve(chain.joint_f, chain.joint_i, chain.frame_f,
                             np.ascontiguousarray(T.rotation), np.ascontiguousarray(T.translation),
                             q, robot.lower, robot.upper, params, options.max_iterations)
        if expected is None:
            assert steps == -1
            continue
        assert steps >= 0
        solved += 1
        np.testing.assert_allclose(q, expected, atol=1e-7)
    assert solved >= 8


def test_screw_robot_line() -> None:
    """A line on an arm of prismatic, skew-axis and helical joints: on its targets."""
    robot = _screw_robot()
    q0 = np.array([0.3, 0.05, -0.4, 0.6, 0.5, -0.1, 0.0])
    q_goal_guess = q0 + np.array([0.05, 0.02, 0.04, -0.03, 0.02, 0.01, 0.0])
    path = cartesian_line(robot, q0, q_goal_guess)
    _assert_on_targets(robot, path, LineOptions())


def _assert_on_targets(robot: Robot, path: list[np.ndarray], options: LineOptions) -> None:
    """Every waypoint but the last (snapped to the goal) is at its target, waypoint k of
    n at s = k/n, within the IK tolerances, measured by Pinocchio."""
    T0, T1 = robot.frame_pose(path[0]), robot.frame_pose(path[-1])
    w = pin.log3(T0.rotation.T @ T1.rotation)
    n = len(path) - 1
    for k, q in enumerate(path[:-1]):
        s = k / n
        T = robot.frame_pose(q)
        target = (1 - s) * T0.translation + s * T1.translation
        assert np.linalg.norm(T.translation - target) < options.position_tolerance
        R_target = T0.rotation @ pin.exp3(s * w)
        assert np.linalg.norm(pin.log3(T.rotation.T @ R_target)) < options.orientation_tolerance


@pytest.mark.parametrize(("a", "b"), LINES)
def test_line_waypoints_are_on_their_targets(bundled_cell: Cell, a: str, b: str) -> None:
    robot = bundled_cell.robot
    options = LineOptions()
    path = cartesian_line(robot, bundled_cell.pose(a), bundled_cell.pose(b), options=options)
    _assert_on_targets(robot, path, options)
    again = cartesian_line(robot, bundled_cell.pose(a), bundled_cell.pose(b), options=options)
    assert all(np.array_equal(x, y) for x, y in zip(path, again, strict=True))


def test_joint_jump_is_reported_where_it_happens(bundled_cell: Cell) -> None:
    robot = bundled_cell.robot
    q0, q1 = bundled_cell.pose("low1"), bundled_cell.pose("high2")
    p0, p1 = robot.tcp_position(q0), robot.tcp_position(q1)
    options = LineOptions(max_joint_step=0.004)  # a 4 mm TCP step moves a joint more
    with pytest.raises(IKError, match="joint jump of") as info:
        cartesian_line(robot, q0, q1, options=options, step_name="2 line up")
    err = info.value
    assert err.step == "2 line up" and 0.0 < err.fraction < 1.0
    np.testing.assert_allclose(err.position, p0 + err.fraction * (p1 - p0), atol=1e-9)
    # At a waypoint: k/n of the line, n the number of 4 mm steps.
    n = int(np.ceil(np.linalg.norm(p1 - p0) / options.step))
    assert err.fraction * n == pytest.approx(round(err.fraction * n), abs=1e-9)


def test_joint_motion_reads_every_joint_kind_of_the_screw_robot() -> None:
    """One place reads joint types (collision weights, the sphere layer's bounds and the
    verifier all ask it): aligned and unaligned, revolute and prismatic; helical is none."""
    from safepath.model.robot import is_prismatic, joint_motion

    model = _screw_robot().model
    found = [joint_motion(model, j) for j in range(1, model.njoints)]
    assert [None if f is None else f[0] for f in found] == [
        "revolute", "prismatic", "revolute", None, "revolute", "prismatic", "revolute"]
    assert found[1] is not None and np.allclose(found[1][1], [0.6, 0.0, 0.8])
    assert found[5] is not None and found[5][1] == (1.0, 0.0, 0.0)
    assert [is_prismatic(model, j) for j in range(1, model.njoints)] == [
        False, True, False, False, False, True, False]


def test_interval_index_is_the_one_knot_lookup() -> None:
    from safepath.model._knots import interval_index

    t = np.array([0.0, 0.5, 1.0, 2.0])
    assert interval_index(t, [-1.0, 0.0, 0.49, 0.5, 1.99, 2.0, 9.0], t.size - 1).tolist() == [
        0, 0, 0, 1, 2, 2, 2]
    assert interval_index(t, [2.0, 9.0], t.size).tolist() == [3, 3]
    assert int(interval_index(t, 0.75, t.size)) == 1
