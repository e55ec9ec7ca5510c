"""Continuous (unbounded) joints end to end (issue 36, point 1), on example-robot-data's
Kinova Jaco (``kinova``: six planned joints, ``j2s6s200_joint_1``, ``_4`` and ``_6``
continuous): loaded without refusal, the collision geometry and the release check's the
same a turn away, the short way round across +-pi, straight TCP lines and OMPL across
the wrap, joint values continuous in the released trajectory, its ROS 2 goal and bag, the
twin's hinges free; and on the bundled Kinova Gen3 (``robots/gen3``, 7 DoF, four
continuous joints).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import safepath
from safepath import CollisionChecker, PoseError, Scene, SceneObject, Shape, placement
from safepath.errors import TrajectoryError, VerificationError
from safepath.ros import check_start, follow_joint_trajectory_goal
from safepath.verify import FclVerifier

TURN = 2.0 * np.pi
WRAPS = (True, False, False, True, False, True)
# A pose of the arm reaching up and out, base joint near +pi [rad].
Q_UP = np.array([2.9, 3.5, 2.0, 0.3, 2.5, 3.0])
FLOOR = SceneObject("floor", Shape("box", (2.0, 2.0, 0.02)), placement((0.0, 0.0, -0.011)))


@pytest.fixture(scope="module")
def kinova() -> safepath.Robot:
    return safepath.load_robot("kinova")


def _floor() -> Scene:
    return Scene(name="floor", robot="kinova", objects=[FLOOR])


def _continuous_in_time(traj: safepath.Trajectory) -> float:
    """The largest change [rad] of any joint between two samples 2 ms apart (a jump of a
    turn would show as ~6.28)."""
    q, _, _ = traj.sample(np.arange(0.0, float(traj.t[-1]), 0.002))
    return float(np.max(np.abs(np.diff(q, axis=0))))


def test_the_jaco_loads_with_its_continuous_joints(kinova: safepath.Robot) -> None:
    assert kinova.dof == 6 and kinova.continuous == WRAPS
    wraps = np.array(WRAPS)
    assert np.all(np.isneginf(kinova.lower[wraps])) and np.all(np.isposinf(kinova.upper[wraps]))
    assert np.all(np.isfinite(kinova.lower[~wraps])) and np.all(np.isfinite(kinova.upper[~wraps]))
    # Any angle of a continuous joint is a pose; a bounded joint's limits still hold.
    assert kinova.limit_violation(Q_UP + 5 * TURN * wraps) is None
    kinova.as_joint_vector(Q_UP + np.array([40.0, 0, 0, -40.0, 0, 17.0]))
    with pytest.raises(PoseError, match="j2s6s200_joint_2"):
        kinova.as_joint_vector(Q_UP + np.array([0.0, TURN, 0, 0, 0, 0]))
    assert kinova.tcp_frame == "j2s6s200_end_effector"


def test_limits_given_to_a_continuous_joint_bound_it() -> None:
    robot = safepath.load_robot("kinova")
    q_far = Q_UP.copy()
    q_far[0] = -2.9
    assert robot.nearest_turn(q_far, Q_UP)[0] == pytest.approx(-2.9 + TURN)
    robot.lower[0], robot.upper[0] = -3.0, 3.0
    assert robot.continuous == (False, *WRAPS[1:])
    assert robot.nearest_turn(q_far, Q_UP)[0] == -2.9  # the long way: the limits say so
    assert "j2s6s200_joint_1" in str(robot.limit_violation(Q_UP + np.array([TURN, 0, 0, 0, 0, 0])))


def test_the_rebuilt_joints_place_the_links_as_pinocchio_does(kinova: safepath.Robot) -> None:
    """The revolute joint of one angle places every frame where Pinocchio's own
    continuous joint (cos, sin) does."""
    import pinocchio as pin
    from example_robot_data.robots_loader import ROBOTS

    original = ROBOTS["kinova"]().robot.model
    data, data_ours = original.createData(), kinova.model.createData()
    rng = np.random.default_rng(36)
    for _ in range(5):
        q = rng.uniform(np.where(WRAPS, -10.0, kinova.lower), np.where(WRAPS, 10.0, kinova.upper))
        q_pin = np.concatenate([[math.cos(q[0]), math.sin(q[0])], q[1:3],
                                [math.cos(q[3]), math.sin(q[3])], q[4:5],
                                [math.cos(q[5]), math.sin(q[5])]])
        pin.framesForwardKinematics(original, data, q_pin)
        pin.framesForwardKinematics(kinova.model, data_ours, q)
        for a, b in zip(data.oMf, data_ours.oMf, strict=True):
            np.testing.assert_allclose(a.homogeneous, b.homogeneous, atol=1e-12)


def test_checks_are_the_same_a_turn_away(kinova: safepath.Robot) -> None:
    """The planner's checker (sphere layer and coal) and the release check's FCL answer
    alike at q and at q moved by whole turns of the continuous joints."""
    post = SceneObject("post", Shape("box", (0.1, 0.1, 0.8)), placement((-0.3, 0.35, 0.4)))
    scene = Scene(name="post", robot="kinova", objects=[FLOOR, post])
    checker = CollisionChecker(kinova, scene)
    verifier = FclVerifier(kinova, scene)
    rng = np.random.default_rng(7)
    turns = np.array(WRAPS, dtype=float) * TURN
    answers = set()
    for _ in range(40):
        q = rng.uniform(np.where(WRAPS, -np.pi, kinova.lower), np.where(WRAPS, np.pi, kinova.upper))
        here = checker.check(q)
        answers.add(here.valid)
        for k in (-3, 1, 7):
            there = checker.check(q + k * turns)
            assert there.valid == here.valid and checker.is_valid(q + k * turns) == here.valid
            # coal's GJK on the convex hulls stops within its tolerance: 10 um.
            assert there.clearance == pytest.approx(here.clearance, abs=1e-5)
            np.testing.assert_allclose(verifier.bounds_at(q + k * turns).T_world_geom,
                                       verifier.bounds_at(q).T_world_geom, atol=1e-9)
            # Its bounds come out of iterations that stop within their tolerance: 1 um.
            np.testing.assert_allclose(verifier.bounds_at(q + k * turns).bounds,
                                       verifier.bounds_at(q).bounds, rtol=0.0, atol=1e-6)
            assert _released(verifier, q + k * turns) == _released(verifier, q)
    assert answers == {True, False}  # both kinds of state were met


def _released(verifier: FclVerifier, q: np.ndarray) -> bool:
    """Whether the release check passes the arm at rest at ``q`` for 0.1 s."""
    try:
        verifier.verify(np.array([0.0, 0.1]), np.array([q, q]), np.zeros((2, len(q))))
    except VerificationError:
        return False
    return True


def test_a_motion_across_pi_goes_the_short_way(kinova: safepath.Robot) -> None:
    q_goal = Q_UP.copy()
    q_goal[0] = -2.9  # 5.8 rad the long way, 0.48 rad across +-pi
    traj = safepath.plan(kinova, _floor(), Q_UP, q_goal)
    travel = np.abs(np.diff(traj.q, axis=0)).sum(axis=0)
    assert travel[0] == pytest.approx(TURN - 5.8, abs=1e-6)
    assert traj.q[:, 0].max() > np.pi  # it crossed +pi, unwrapped
    np.testing.assert_allclose(traj.q[-1], kinova.nearest_turn(q_goal, Q_UP), atol=1e-9)
    np.testing.assert_allclose(kinova.frame_pose(traj.q[-1]).homogeneous,
                               kinova.frame_pose(q_goal).homogeneous, atol=1e-9)
    assert _continuous_in_time(traj) < 0.01


def test_300_degrees_away_is_60_degrees_the_other_way(kinova: safepath.Robot) -> None:
    q_goal = Q_UP.copy()
    q_goal[3] += math.radians(300.0)  # the wrist's goal, as taught
    q_goal[5] -= math.radians(300.0)
    traj = safepath.plan(kinova, _floor(), Q_UP, q_goal)
    travel = np.abs(np.diff(traj.q, axis=0)).sum(axis=0)
    assert travel[3] < np.pi and travel[5] < np.pi
    assert travel[3] == pytest.approx(math.radians(60.0), abs=1e-6)
    assert travel[5] == pytest.approx(math.radians(60.0), abs=1e-6)
    assert _continuous_in_time(traj) < 0.01


def test_a_straight_tcp_line_across_pi(kinova: safepath.Robot) -> None:
    q_goal = Q_UP.copy()
    q_goal[0] = -2.9
    traj = safepath.plan(kinova, _floor(), Q_UP, q_goal, kind="line")
    assert traj.q[:, 0].max() > np.pi and traj.q[-1, 0] == pytest.approx(-2.9 + TURN)
    assert np.abs(np.diff(traj.q[:, 0])).sum() < 0.5
    assert _continuous_in_time(traj) < 0.01
    # The TCP stays on the chord between its two ends.
    p0, p1 = kinova.tcp_position(Q_UP), kinova.tcp_position(q_goal)
    q, _, _ = traj.sample(np.linspace(0.0, float(traj.t[-1]), 50))
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    for p in kinova.tcp_positions(q):
        off = (p - p0) - ((p - p0) @ d) * d
        assert np.linalg.norm(off) < 2e-3


def test_ompl_plans_around_a_wall_across_the_wrap(kinova: safepath.Robot) -> None:
    """The direct way across +-pi is blocked: OMPL, sampling a window of the continuous
    joints around start and goal, finds a way; the result is verified and continuous."""
    wall = SceneObject("wall", Shape("box", (0.02, 0.8, 1.2)), placement((0.0, 0.6, 0.8)))
    scene = Scene(name="wall", robot="kinova", objects=[FLOOR, wall])
    q_start, q_goal = Q_UP.copy(), Q_UP.copy()
    q_start[0], q_goal[0] = 2.7, -2.7
    checker = CollisionChecker(kinova, scene)
    assert not checker.segment_is_valid(q_start, kinova.nearest_turn(q_goal, q_start))
    traj = safepath.plan(kinova, scene, q_start, q_goal)
    np.testing.assert_allclose(kinova.frame_pose(traj.q[-1]).homogeneous,
                               kinova.frame_pose(q_goal).homogeneous, atol=1e-9)
    assert traj.info["clearance_bound"] >= 0.0
    assert _continuous_in_time(traj) < 0.01
    low, high = min(2.7, -2.7 + TURN) - np.pi, max(2.7, -2.7 + TURN) + np.pi
    assert low <= traj.q[:, 0].min() and traj.q[:, 0].max() <= high


def test_the_goal_carries_unwrapped_continuous_positions(kinova: safepath.Robot) -> None:
    q_goal = Q_UP.copy()
    q_goal[0] = -2.9
    traj = safepath.plan(kinova, _floor(), Q_UP, q_goal)
    goal = follow_joint_trajectory_goal(traj, controller=kinova.controller)
    positions = np.array([list(p.positions) for p in goal.trajectory.points])
    assert np.max(np.abs(np.diff(positions, axis=0))) < 0.1  # no jump of a turn
    assert positions[-1, 0] == pytest.approx(-2.9 + TURN)
    # /joint_states may report the base a turn away: the same start for a continuous joint.
    measured = dict(zip(kinova.joint_names, traj.q[0] - TURN * np.array(WRAPS), strict=True))
    names = [n for n, c in zip(kinova.joint_names, kinova.continuous, strict=True) if c]
    check_start(traj, measured, continuous=names)
    with pytest.raises(TrajectoryError, match="j2s6s200_joint_1"):
        check_start(traj, measured)


def test_the_bag_carries_unwrapped_continuous_positions(kinova: safepath.Robot,
                                                        tmp_path: Path) -> None:
    from safepath.ros import read_bag, write_bag

    q_goal = Q_UP.copy()
    q_goal[0] = -2.9
    traj = safepath.plan(kinova, _floor(), Q_UP, q_goal)
    bag = write_bag(tmp_path / "jaco", [traj])
    states = read_bag(bag).on("/joint_states")
    base = np.array([m.msg.position[m.msg.name.index("j2s6s200_joint_1")] for m in states])
    assert base[0] == pytest.approx(2.9) and base[-1] == pytest.approx(-2.9 + TURN)
    assert np.max(np.abs(np.diff(base))) < 0.05  # 50 Hz, no jump of a turn


def test_the_twin_leaves_continuous_hinges_free(kinova: safepath.Robot) -> None:
    pytest.importorskip("mujoco")
    from safepath.sim.model import build_robot_model

    model = build_robot_model(kinova)
    for name, wraps in zip(kinova.joint_names, WRAPS, strict=True):
        j = model.model.joint(name)
        assert bool(model.model.jnt_limited[j.id]) is (not wraps)


# Kinova's "Home" of the Gen3 (ros2_kortex's gen3.srdf, see robots/gen3/README.md) [rad].
GEN3_HOME = np.array([0.0, 0.26, 3.14, -2.27, 0.0, 0.96, 1.57])


def test_the_gen3_turns_its_base_and_wrist_the_short_way() -> None:
    gen3 = safepath.load_robot("gen3")
    assert gen3.dof == 7 and gen3.continuous == (True, False, True, False, True, False, True)
    scene = Scene(name="floor", robot="gen3", objects=[FLOOR])
    assert CollisionChecker(gen3, scene).check(GEN3_HOME).valid
    q_start, q_goal = GEN3_HOME.copy(), GEN3_HOME.copy()
    q_start[0], q_goal[0] = 3.0, -3.0  # across +-pi: 0.28 rad, not 6
    q_goal[6] += math.radians(300.0)  # the bracelet: 60 degrees the other way
    traj = safepath.plan(gen3, scene, q_start, q_goal)
    travel = np.abs(np.diff(traj.q, axis=0)).sum(axis=0)
    assert travel[0] == pytest.approx(TURN - 6.0, abs=1e-6)
    assert travel[6] == pytest.approx(math.radians(60.0), abs=1e-6)
    np.testing.assert_allclose(gen3.frame_pose(traj.q[-1]).homogeneous,
                               gen3.frame_pose(q_goal).homogeneous, atol=1e-9)
    assert _continuous_in_time(traj) < 0.01
