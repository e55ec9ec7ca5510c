"""Property test: timed random paths, sent as goals, stay within every limit as executed.

Random joint polylines on four robots are timed (:func:`safepath.timing.time_path`),
turned into ``JointTrajectory`` messages (rosbags' message types), and the messages' own
numbers are joined as ros2_control's joint_trajectory_controller joins them (a quintic
per joint through position, velocity and acceleration), sampled at 1 kHz by an
implementation written here (not safepath's), and compared with the robots' velocity,
acceleration and jerk limits.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from quintic_join import quintic_peaks as _quintic_peaks

import safepath
from safepath.errors import ExecutedLimitError
from safepath.model.trajectory import Trajectory
from safepath.ros import joint_trajectory
from safepath.timing import TimingOptions, spline_path, time_path

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = ("ned3pro", "gen3_lite", "panda", "ur5")
PATHS_PER_ROBOT = 100  # 400 in all (seeded per robot)


@pytest.fixture(scope="module")
def robots() -> dict[str, safepath.Robot]:
    return {name: safepath.load_robot(name) for name in ROBOTS}


def _message_arrays(msg) -> tuple[np.ndarray, ...]:  # noqa: ANN001
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])
    P, V, A = (np.array([list(getattr(p, f)) for p in msg.points])  # noqa: N806
               for f in ("positions", "velocities", "accelerations"))
    return t, P, V, A


def _random_path(robot: safepath.Robot, rng: np.random.Generator) -> list[np.ndarray]:
    mid = (robot.lower + robot.upper) / 2
    # Moves of a few seconds on every robot (the Gen3 Lite's joints turn at 0.5 rad/s).
    half = np.minimum(np.minimum((robot.upper - robot.lower) / 2, np.pi),
                      1.5 * robot.velocity_limits) * 0.5
    n = int(rng.integers(2, 6))
    return [mid + half * rng.uniform(-1, 1, robot.dof) for _ in range(n)]


@pytest.mark.parametrize("name", ROBOTS)
def test_random_paths_within_limits_as_executed(robots: dict[str, safepath.Robot], name: str
                                                ) -> None:
    robot = robots[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    vmax, amax, jmax = robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits
    worst = np.zeros(3)
    for _ in range(PATHS_PER_ROBOT):
        pts = _random_path(robot, rng)
        corners = [(k, float(rng.choice([0.0, 0.1, 0.3]))) for k in range(1, len(pts) - 1)]
        path, s_way, _ = spline_path(pts, 0.06, corners=corners)
        scales = rng.uniform(0.2, 1.0, len(pts) - 1).tolist()
        piece = time_path(robot, path, s_way, scales=scales, tcp_speeds=[None] * len(scales),
                          options=TimingOptions())
        # The released path is the spline: every knot lies on it, or, where the timing
        # subdivided the join of knots further apart, within that join's few micro-radians.
        assert np.allclose(piece.q, path(piece.s), atol=1e-5)
        traj = Trajectory(robot.joint_names, piece.t, piece.q, piece.qd, piece.qdd,
                          np.zeros(piece.t.size, dtype=int), ("move",), robot=robot.name,
                          limits=robot.motion_limits)
        msg = joint_trajectory(traj, controller=robot.controller, backend="rosbags")
        t, P, V, A = _message_arrays(msg)  # noqa: N806
        assert np.array_equal(P[0], pts[0]) and np.allclose(P[-1], pts[-1], atol=1e-12)
        assert not V[0].any() and not V[-1].any()
        v, a, j = _quintic_peaks(t, P, V, A)
        ratios = np.array([np.max(v / vmax), np.max(a / amax), np.max(j / jmax)])
        worst = np.maximum(worst, ratios)
    assert np.all(worst <= 1.0 + 1e-9), f"{name}: executed v/a/j ratios {worst}"
    # Not a vacuous bound: the timing uses the limits (near-time-optimal somewhere).
    assert worst[0] > 0.9 or worst[1] > 0.9


def test_goal_over_a_limit_is_refused(robots: dict[str, safepath.Robot]) -> None:
    """A trajectory whose knots carry a bang-bang acceleration switch (what TOPP-RA alone
    gives) is refused when turned into a goal, naming the quantity."""
    robot = robots["ned3pro"]
    t = np.arange(0, 11) * 0.004
    acc = np.where(t < 0.02, 1.0, -1.0) * robot.acceleration_limits[0]
    qd = np.zeros((t.size, robot.dof))
    qdd = np.zeros((t.size, robot.dof))
    qdd[:, 0] = acc
    qd[1:, 0] = np.cumsum(acc[:-1] * 0.004)
    q = np.zeros((t.size, robot.dof))
    q[1:, 0] = np.cumsum(qd[:-1, 0] * 0.004 + acc[:-1] * 0.004 ** 2 / 2)
    qd[-1] = qdd[0] = qdd[-1] = 0.0
    anonymous = Trajectory(robot.joint_names, t, q, qd, qdd, np.zeros(t.size, dtype=int),
                           ("move",))
    with pytest.raises(safepath.errors.TrajectoryError, match="limits"):
        joint_trajectory(anonymous, backend="rosbags")  # no limits recorded, none given
    with pytest.raises(ExecutedLimitError) as info:
        joint_trajectory(anonymous, limits=robot, backend="rosbags")
    assert info.value.key in ("acceleration", "jerk") and info.value.ratio > 1.0
    # Naming a bundled robot gives no limits (they are never re-loaded by name): the
    # limits a trajectory carries are those it is checked against.
    named = Trajectory(robot.joint_names, t, q, qd, qdd, np.zeros(t.size, dtype=int),
                       ("move",), robot=robot.name)
    with pytest.raises(safepath.errors.TrajectoryError, match="limits"):
        joint_trajectory(named, backend="rosbags")
    carried = dataclasses.replace(named, limits=robot.motion_limits)
    with pytest.raises(ExecutedLimitError):
        joint_trajectory(carried, backend="rosbags")


def test_clearance_bound_holds_at_every_instant_as_executed() -> None:
    """``info['clearance_bound']`` is below the clearance (coal, the planner's checker) of
    the executed motion sampled every 2 ms, and close to it."""
    cell = safepath.load_cell(ROOT / "scenes" / "quality_check_cell")
    traj = safepath.plan(cell.robot, cell.scene, cell.pose("high1"), cell.pose("unsafe"))
    bound = traj.info["clearance_bound"]
    assert 0.0 < traj.info["knot_deviation"] < 1e-3
    assert bound <= traj.info["min_clearance"] - traj.info["resolution"]
    times = np.arange(0.0, traj.duration, 0.002)
    q, _, _ = traj.sample(times)
    checker = cell.checker()
    clearance = np.array([checker.check(qk).clearance for qk in q])
    assert clearance.min() >= bound
    assert clearance.min() - bound < 0.005  # a bound, not a wild guess
