"""The robot's MuJoCo model and its simulated trajectory controller, on real MuJoCo."""

from __future__ import annotations

import numpy as np
import pytest
from quintic_join import quintic_peaks

from safepath import Trajectory
from safepath.cell import Cell
from safepath.errors import InputError
from safepath.ros import follow_joint_trajectory_goal, split_at_gripper_events, tool_goal
from safepath.sim.arm import CANCELED, INVALID_JOINTS, SUCCESSFUL, ArmResult
from safepath.sim.model import ServoGains, build_robot_model
from safepath.sim.twin import RobotTwin


def test_model_carries_the_robots_masses_and_shapes(cell: Cell) -> None:
    import mujoco

    robot = cell.robot
    rm = build_robot_model(robot, cell.scene)
    assert rm.model.opt.timestep == pytest.approx(0.001)
    masses = [robot.model.inertias[j].mass for j in range(1, robot.model.njoints)]
    assert float(np.sum(rm.model.body_mass)) == pytest.approx(sum(masses), rel=1e-6)
    robot_geoms = sum(1 for g in range(rm.model.ngeom)
                      if mujoco.mj_id2name(rm.model, mujoco.mjtObj.mjOBJ_GEOM, g)
                      .startswith("robot/"))
    assert robot_geoms == len(robot.collision_model.geometryObjects)
    assert rm.scene_geoms == sum(1 for o in cell.scene.objects.values() if not o.movable)
    # kp = m w^2 and kd = 2 zeta m w: their ratio is the servo's stated frequency.
    assert np.allclose(rm.kp / rm.kd, ServoGains().omega / 2.0)


def test_bad_timestep_and_gains_are_typed_errors(cell: Cell) -> None:
    with pytest.raises(InputError, match="timestep"):
        build_robot_model(cell.robot, timestep=0.01)
    with pytest.raises(InputError, match="bandwidth"):
        ServoGains(bandwidth=-1.0)


def _run(twin: RobotTwin, goal_id: int, horizon: float = 20.0) -> ArmResult:
    end = twin.now + horizon
    while twin.now < end:
        for result in twin.advance(twin.now + 0.01):
            if isinstance(result, ArmResult) and result.goal_id == goal_id:
                return result
    raise AssertionError(f"goal {goal_id} gave no result")


def test_a_goal_is_executed_within_its_tolerances(cell: Cell,
                                                  routes: dict[str, Trajectory]) -> None:
    parts = split_at_gripper_events(routes["phase1"])
    motion = next(p for p in parts if isinstance(p, Trajectory))
    twin = RobotTwin(cell.robot, cell.scene, motion.q[0])
    goal = follow_joint_trajectory_goal(motion, controller=cell.robot.controller,
                                        backend="rosbags")
    assert twin.send_arm_goal(goal, 1) is None
    result = _run(twin, 1)
    assert result.error_code == SUCCESSFUL
    # The result comes once the trajectory's time is over, within a check period.
    assert motion.duration <= result.time <= motion.duration + 0.011
    tol = np.asarray(cell.robot.controller.goal_tolerance)
    assert np.all(np.abs(twin.q - motion.q[-1]) <= tol)
    # What is commanded (the quintic join of the goal's points, as the message carries
    # them) keeps the speed limits; the servos follow it closely, but not perfectly: a
    # physics model's position servo tracking it may overshoot its speed a little (seen:
    # 1.026 of joint 1's limit from 0.971 commanded), which is not the commanded motion.
    points = goal.trajectory.points
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in points])
    P, V, A = (np.array([list(getattr(p, f)) for p in points])  # noqa: N806
               for f in ("positions", "velocities", "accelerations"))
    commanded = quintic_peaks(t, P, V, A)[0] / cell.robot.velocity_limits
    assert commanded.max() <= 1.0
    assert 0 < twin.recording.tracking.max() < 0.02
    assert np.all(twin.recording.speed_ratio <= commanded + 0.1)
    assert twin.recording.contact_steps == 0


def test_a_goal_with_a_past_stamp_joins_from_now(cell: Cell,
                                                routes: dict[str, Trajectory]) -> None:
    motion = next(p for p in split_at_gripper_events(routes["phase1"])
                  if isinstance(p, Trajectory))
    twin = RobotTwin(cell.robot, cell.scene, motion.q[0])
    spec = cell.robot.controller
    twin.send_arm_goal(follow_joint_trajectory_goal(motion, controller=spec,
                                                    backend="rosbags"), 1)
    twin.advance(1.0)
    # The same motion again, stamped 0.6 s ago: the controller is 0.4 s into it now.
    replacement = follow_joint_trajectory_goal(motion, controller=spec, backend="rosbags",
                                               stamp_ns=400_000_000)
    assert twin.send_arm_goal(replacement, 2) is None
    assert twin.arm.results[-1].goal_id == 1 and twin.arm.results[-1].error_code == CANCELED
    twin.advance(1.5)
    expected = motion.sample([1.1])[0][0]
    assert np.allclose(twin.arm.reference_at(twin.step), expected, atol=1e-4)


def test_a_goal_for_other_joints_is_rejected_and_a_tool_goal_takes_its_time(
        cell: Cell, routes: dict[str, Trajectory]) -> None:
    motion = next(p for p in split_at_gripper_events(routes["phase1"])
                  if isinstance(p, Trajectory))
    twin = RobotTwin(cell.robot, cell.scene, motion.q[0])
    goal = follow_joint_trajectory_goal(motion, controller=cell.robot.controller,
                                        backend="rosbags")
    goal.trajectory.joint_names[0] = "elbow"
    rejected = twin.send_arm_goal(goal, 1)
    assert rejected is not None and rejected.error_code == INVALID_JOINTS
    assert twin.send_gripper_goal(tool_goal("close", backend="rosbags"), 2) is None
    results = twin.advance(twin.options.gripper_time + 0.01)
    assert [(r.goal_id, r.action) for r in results] == [(2, "close")]  # type: ignore[union-attr]
