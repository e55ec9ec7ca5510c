"""A newcomer's UR5 and Panda: cells built in Python and in YAML plan, export to ROS 2 and
write bags, from the API and from the command line, with the robots' own controller
settings (``robots/<name>/controller.yaml``), never the Ned3 Pro's."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

import safepath
from safepath import (
    Cell,
    PoseError,
    Route,
    Scene,
    SceneObject,
    Shape,
    Step,
    Target,
    placement,
)
from safepath.cli import main
from safepath.ros import follow_joint_trajectory_goal, joint_trajectory, read_bag, write_bag
from safepath.ros.messages import deserialize, serialize

ROOT = Path(__file__).resolve().parents[1]
CELLS = ROOT / "examples" / "cells"
UR5_JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
              "wrist_2_joint", "wrist_3_joint"]
PANDA_JOINTS = [f"panda_joint{i}" for i in range(1, 8)]


def ur5_cell_in_python() -> Cell:
    """The UR5 cell of examples/cells/ur5_cell, written in Python instead of YAML."""
    ur5 = safepath.load_robot("ur5")
    scene = Scene(name="ur5_cell", robot="ur5", objects=[
        SceneObject("table", Shape("box", (1.2, 1.2, 0.04)), placement((0.3, 0.0, -0.02))),
        SceneObject("wall", Shape("box", (0.04, 0.5, 0.5)), placement((0.45, 0.25, 0.25)),
                    margin=0.005),
        SceneObject("left_bin", Shape("box", (0.2, 0.2, 0.08)), placement((0.55, -0.3, 0.04))),
    ])
    poses = {"above_bin": [-0.6, -1.2, 1.6, -1.97, -1.57, 0.0],
             "beside_wall": [1.4, -1.2, 1.6, -1.97, -1.57, 0.0]}
    routes = {
        "over_the_wall": Route("over_the_wall", "above_bin", (
            Step("line", Target("above_bin", (0.0, 0.0, -0.05)), speed=0.5, tcp_speed=0.1),
            Step("line", Target(None, (0.0, 0.0, 0.05)), speed=0.5),
            Step("move", Target("beside_wall")),
        )),
        "back": Route("back", "beside_wall", (Step("move", Target("above_bin"), speed=0.5),),
                      after="over_the_wall"),
    }
    return Cell(ur5, scene, poses, routes=routes)


@pytest.fixture(scope="module")
def ur5_plans() -> dict[str, safepath.Trajectory]:
    return safepath.plan_cell(ur5_cell_in_python())


@pytest.fixture(scope="module")
def panda_plans() -> dict[str, safepath.Trajectory]:
    return safepath.plan_cell(safepath.load_cell(CELLS / "panda_cell"))


def test_python_and_yaml_ur5_cells_are_the_same_cell(ur5_plans: dict) -> None:
    yaml_cell = safepath.load_cell(CELLS / "ur5_cell")
    py_cell = ur5_cell_in_python()
    assert yaml_cell.route_table() == py_cell.route_table()
    assert yaml_cell.poses.keys() == py_cell.poses.keys()
    for name in py_cell.poses:
        assert np.array_equal(yaml_cell.poses[name], py_cell.poses[name])
    for name, obj in py_cell.scene.objects.items():
        other = yaml_cell.scene.objects[name]
        assert (other.shape, other.margin) == (obj.shape, obj.margin)
        assert np.allclose(other.T_world_object, obj.T_world_object)
    # Same seed, same cell: the YAML cell plans the very same trajectories.
    from_yaml = safepath.plan_cell(yaml_cell)
    for name, traj in ur5_plans.items():
        assert np.array_equal(from_yaml[name].q, traj.q)


def test_ur5_trajectories_export_with_the_ur5_controller(ur5_plans: dict, tmp_path: Path
                                                         ) -> None:
    traj = ur5_plans["over_the_wall"]
    assert traj.robot == "ur5" and list(traj.joint_names) == UR5_JOINTS
    assert traj.info["min_clearance"] >= 0.005 - 1e-9
    msg = joint_trajectory(traj, backend="rosbags")
    assert msg.joint_names == UR5_JOINTS
    ns = np.array([p.time_from_start.sec * 10**9 + p.time_from_start.nanosec
                   for p in msg.points])
    # Every knot (about 4 ms apart), at most the controller's period (robots/ur5/
    # controller.yaml: 8 ms, its 125 Hz cycle) apart.
    assert len(msg.points) == traj.t.size and np.all(np.diff(ns) <= 8_000_000)
    goal = follow_joint_trajectory_goal(traj, backend="rosbags")
    assert goal.goal_tolerance == []  # the driver's own, never the Ned's six values
    again = deserialize(serialize(goal, "control_msgs/action/FollowJointTrajectory_Goal"),
                        "control_msgs/action/FollowJointTrajectory_Goal")
    assert again.trajectory.joint_names == UR5_JOINTS
    assert len(again.trajectory.points) == len(msg.points)
    robot = safepath.load_robot("ur5")
    assert robot.controller.follow_joint_trajectory_action == (
        "/scaled_joint_trajectory_controller/follow_joint_trajectory")
    bag = write_bag(tmp_path / "ur5", [ur5_plans["over_the_wall"], ur5_plans["back"]])
    contents = read_bag(bag)
    states = contents.on("/joint_states")
    assert states[0].msg.name == UR5_JOINTS
    stamps = np.array([m.timestamp for m in states])
    assert np.allclose(np.diff(stamps)[:-1], 1e9 / 125.0)
    assert [json.loads(m.msg.data)["robot"] for m in contents.on("/safepath/route")] == [
        "ur5", "ur5"]


def test_panda_yaml_cell_plans_and_writes_a_bag(panda_plans: dict, tmp_path: Path) -> None:
    traj = panda_plans["left_to_right"]
    assert list(traj.joint_names) == PANDA_JOINTS
    goal = follow_joint_trajectory_goal(traj, backend="rosbags")
    assert goal.trajectory.joint_names == PANDA_JOINTS and goal.goal_tolerance == []
    # An explicit tolerance still works, in the controller's joint order.
    tight = follow_joint_trajectory_goal(traj, goal_tolerance=[0.001] * 7, backend="rosbags")
    assert [t.name for t in tight.goal_tolerance] == PANDA_JOINTS
    contents = read_bag(write_bag(tmp_path / "panda", [traj]))
    (sent,) = contents.on("/safepath/trajectory")
    assert sent.msg.joint_names == PANDA_JOINTS
    assert np.allclose(sent.msg.points[-1].positions, traj.q[-1])


@pytest.mark.parametrize("cell", ["ur5_cell", "panda_cell"])
def test_cli_plans_the_yaml_cells_and_writes_a_bag(cell: str, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out, bag = tmp_path / "out", tmp_path / "bag"
    assert main(["plan", str(CELLS / cell), "--out", str(out), "--bag", str(bag)]) == 0
    assert "wrote a ROS 2 bag" in capsys.readouterr().out
    contents = read_bag(bag)
    names = UR5_JOINTS if cell == "ur5_cell" else PANDA_JOINTS
    assert all(m.msg.joint_names == names for m in contents.on("/safepath/trajectory"))
    assert (out / "summary.json").exists()


def test_cli_bag_gives_the_locked_fingers_their_value_and_names_a_via(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``plan --bag`` of the Panda cell with its fingers locked at 2 cm: ``/joint_states``
    holds both finger joints (the second mimics the first) at 0.02 m, so RViz draws the
    hand; summary.json names the route's ``via: ready`` as a via."""
    cell = tmp_path / "panda_cell"
    shutil.copytree(CELLS / "panda_cell", cell)
    with (cell / "scene.yaml").open("a") as f:
        f.write("\nlocked_joints: {panda_finger_joint1: 0.02}\n")
    out, bag = tmp_path / "out", tmp_path / "bag"
    assert main(["plan", str(cell), "--out", str(out), "--bag", str(bag)]) == 0
    states = read_bag(bag).on("/joint_states")
    fingers = ["panda_finger_joint1", "panda_finger_joint2"]
    assert states and all(m.msg.name == [*PANDA_JOINTS, *fingers] for m in states)
    assert all(np.array_equal(m.msg.position[7:], [0.02, 0.02]) for m in states)
    assert all(np.array_equal(m.msg.velocity[7:], [0.0, 0.0]) for m in states)
    steps = json.loads((out / "summary.json").read_text())["left_to_right"]["step_durations"]
    assert list(steps)[3:] == ["3 move right", "4 via ready"]


def test_plan_between_two_configurations() -> None:
    panda = safepath.load_robot("panda")
    cell = safepath.load_cell(CELLS / "panda_cell")
    traj = safepath.plan(panda, cell.scene, cell.pose("left"), cell.pose("right"))
    assert traj.route == "plan" and traj.robot == "panda"
    assert np.array_equal(traj.q[0], cell.pose("left"))
    assert np.allclose(traj.q[-1], cell.pose("right"))
    # The direct joint path hits the post: the planner went around it, and kept margins.
    assert not cell.checker().check_path([cell.pose("left"), cell.pose("right")]).valid
    assert traj.info["min_clearance"] >= 0.010 - 1e-9
    with pytest.raises(PoseError, match="expected 7 joint values, got 6") as info:
        safepath.plan(panda, cell.scene, cell.pose("left"), cell.pose("right")[:6])
    assert info.value.key == "q_goal"
    with pytest.raises(PoseError, match="outside its limits") as info:
        safepath.plan(panda, cell.scene, cell.pose("left") + 5.0, cell.pose("right"))
    assert info.value.key == "q_start"
    with pytest.raises(safepath.ConfigError) as info:
        safepath.plan(panda, cell.scene, cell.pose("left"), cell.pose("right"), speed=0)
    assert info.value.key == "speed"


def test_runtime_planner_takes_a_cell_built_in_python(ur5_plans: dict) -> None:
    from safepath.runtime import RuntimePlanner

    cell = ur5_cell_in_python()
    with RuntimePlanner(cell) as planner:
        traj = planner.plan_route("over_the_wall", timeout=120.0).result(timeout=180.0)
    assert np.array_equal(traj.q, ur5_plans["over_the_wall"].q)  # same seed, same answer
    # A robot built in Python cannot reach a worker process: refused up front.
    bare = safepath.Robot(name="ur5", model=cell.robot.model,
                          collision_model=cell.robot.collision_model, visual_model=None,
                          velocity_limits=cell.robot.velocity_limits,
                          acceleration_limits=cell.robot.acceleration_limits,
                          tcp_frame=cell.robot.tcp_frame)
    with pytest.raises(safepath.ConfigError, match="built in Python"):
        pickle.dumps(bare)
    with pytest.raises(safepath.ConfigError, match="built in Python"):
        RuntimePlanner(Cell(bare, cell.scene, cell.poses, routes=cell.routes))



def test_plan_refuses_a_start_in_collision_naming_the_pairs() -> None:
    cell = safepath.load_cell(CELLS / "ur5_cell")
    q = cell.pose("above_bin").copy()
    q[1] = -0.2  # the forearm down in the table
    assert not cell.checker().check(q).valid
    with pytest.raises(safepath.PlanningError, match="start state is invalid") as info:
        safepath.plan(cell.robot, cell.scene, q, cell.pose("beside_wall"))
    assert "forearm_link / table" in str(info.value)


def test_a_robot_keeps_its_locked_joints_and_changed_limits_in_a_worker() -> None:
    """A robot sends its changes with it: a worker that loads it again by name plans
    exactly as this process does (before, only the acceleration limits and the locked
    joints travelled: halved velocity limits were lost, the plans differed)."""
    from safepath.description.robot_folder import CARRIED
    from safepath.runtime import RuntimePlanner

    robot = safepath.load_robot("panda", locked_joints={"panda_finger_joint1": 0.04})
    robot.velocity_limits = robot.velocity_limits * 0.5
    robot.acceleration_limits = robot.acceleration_limits * 0.7
    robot.lower = robot.lower.copy()
    robot.lower[0] = -1.5  # a narrower first joint, as a cell's fence would ask
    copy = pickle.loads(pickle.dumps(robot))
    for key in CARRIED:
        mine, theirs = getattr(robot, key), getattr(copy, key)
        assert np.array_equal(mine, theirs) if isinstance(mine, np.ndarray) \
            else mine == theirs, key
    assert [(j.name, j.value) for j in copy.locked_joints] == \
        [(j.name, j.value) for j in robot.locked_joints]
    yaml_cell = safepath.load_cell(CELLS / "panda_cell")
    cell = Cell(robot, yaml_cell.scene, yaml_cell.poses, routes=yaml_cell.route_table())
    expected = safepath.plan_cell(cell)
    with RuntimePlanner(cell, spare=False) as planner:
        got = planner.plan_cell(timeout=240.0).result(timeout=300.0)
    assert list(got) == list(expected)
    for name, traj in expected.items():
        assert np.array_equal(got[name].t, traj.t) and np.array_equal(got[name].q, traj.q)
    # The changes matter: the robot as loaded plans other motions.
    plain = Cell(safepath.load_robot("panda", locked_joints={"panda_finger_joint1": 0.04}),
                 yaml_cell.scene, yaml_cell.poses, routes=yaml_cell.route_table())
    other = safepath.plan_cell(plain)
    assert any(other[n].duration != t.duration for n, t in expected.items())
