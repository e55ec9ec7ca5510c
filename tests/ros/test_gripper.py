"""GripperCommand goals from the robot's controller.yaml (the Gen3 Lite under ros2_kortex),
the optional gripper section of the schema, and bags with the goals a node sends."""

from __future__ import annotations

import logging
import math
import shutil
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from safepath import load_robot
from safepath.description.robot_folder import ROBOTS_DIR
from safepath.errors import ConfigError, InputError
from safepath.model.controller_spec import GripperSpec
from safepath.model.limits import MotionLimits
from safepath.model.trajectory import GripperEvent, Trajectory
from safepath.ros.bag import (
    ARM_GOAL_TOPIC,
    GRIPPER_GOAL_TOPIC,
    GRIPPER_TOPIC,
    JOINT_STATES_TOPIC,
    TRAJECTORY_TOPIC,
    read_bag,
    write_bag,
)
from safepath.ros.goals import follow_joint_trajectory_goal, split_at_gripper_events
from safepath.ros.gripper import gripper_command_goal, gripper_command_goals, gripper_of
from safepath.ros.messages import deserialize, serialize

from .test_messages import assert_same, round_trip

GEN3 = tuple(f"joint_{i}" for i in range(1, 7))
GOAL = "control_msgs/action/GripperCommand_Goal"


def gen3_route(events: bool = True) -> Trajectory:
    """Two rest-to-rest quintic moves of the Gen3 Lite, closing at the middle stop (faster
    than the arm may move: the trajectory records limits 10x its own, for these message
    tests)."""
    tau = np.linspace(0.0, 1.0, 21)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = 30 * tau**2 - 60 * tau**3 + 30 * tau**4
    dds = 60 * tau - 180 * tau**2 + 120 * tau**3
    a, b, c = np.zeros(6), np.array([0.3, -0.2, 0.4, 0.1, -0.3, 0.2]), np.full(6, 0.1)
    q = np.vstack([a + np.outer(s, b - a), b + np.outer(s[1:], c - b)])
    qd = np.vstack([np.outer(ds, b - a), np.outer(ds[1:], c - b)])
    qdd = np.vstack([np.outer(dds, b - a), np.outer(dds[1:], c - b)])
    t = np.concatenate([tau, 1.0 + tau[1:]])
    evs = (GripperEvent(0.0, "open", "start"), GripperEvent(1.0, "close", "grasp", "cup")) \
        if events else ()
    robot = load_robot("gen3_lite")
    fast = MotionLimits(10 * robot.velocity_limits, 10 * robot.acceleration_limits,
                        10 * robot.jerk_limits)
    return Trajectory(GEN3, t, q, qd, qdd, np.repeat([0, 1], [21, 20]), ("to_b", "to_c"),
                      evs, "gen3_lite", "pick", limits=fast)


def test_gen3_lite_controllers_come_from_its_folder() -> None:
    robot = load_robot("gen3_lite")
    spec = robot.controller
    assert spec.source == ROBOTS_DIR / "gen3_lite" / "controller.yaml"
    assert spec.follow_joint_trajectory_action == \
        "/joint_trajectory_controller/follow_joint_trajectory"
    assert spec.joint_names == GEN3
    g = gripper_of(robot)
    assert (g.action, g.joint, g.unit) == ("/gen3_lite_2f_gripper_controller/gripper_cmd",
                                           "right_finger_bottom_joint", "rad")
    assert (g.open_position, g.closed_position, g.max_effort) == (0.0, 0.8, 100.0)
    # Within the URDF's 0 .. 0.85 rad, capped at the 0.81 rad that kortex_driver scales to 1.
    assert g.position_range == (0.0, 0.81)
    assert gripper_of("gen3_lite") == g
    # Robots without a GripperCommand gripper keep loading, with no gripper section.
    for name in ("ned3pro", "ur5", "panda"):
        assert load_robot(name).controller.gripper is None


def test_gripper_command_goal_cdr_bytes() -> None:
    goal = gripper_command_goal("gen3_lite", "close", backend="rosbags")
    assert goal.__msgtype__ == GOAL
    # CDR little endian: the 4-byte header, then position and max_effort as float64.
    assert serialize(goal) == b"\x00\x01\x00\x00" + struct.pack("<dd", 0.8, 100.0)
    back = round_trip(goal)
    assert (back.command.position, back.command.max_effort) == (0.8, 100.0)
    opened = gripper_command_goal(load_robot("gen3_lite"), "open", backend="rosbags")
    assert opened.command.position == 0.0
    half = gripper_command_goal("gen3_lite", 0.4, max_effort=20.0, backend="rosbags")
    assert deserialize(serialize(half), GOAL).command.position == 0.4
    assert half.command.max_effort == 20.0
    # The result and feedback types round-trip too (what a node reads back).
    result = deserialize(b"\x00\x01\x00\x00" + struct.pack("<dd", 0.79, 1.5) + b"\x01\x00",
                         "control_msgs/action/GripperCommand_Result")
    assert (result.position, result.effort, result.stalled, result.reached_goal) == (
        0.79, 1.5, True, False)


@pytest.mark.parametrize(("robot", "position", "key", "words"), [
    ("ned3pro", 0.1, "robot", "no 'gripper' section"),
    ("ur5", "open", "robot", "robot 'ur5' has no GripperCommand gripper"),
    ("talos", "open", "robot", "no bundled robot 'talos' with a controller.yaml"),
    ("gen3_lite", 0.9, "position", "0.9 rad is outside the range of "
                                   "'right_finger_bottom_joint' \\[0, 0.81\\]"),
    ("gen3_lite", -0.01, "position", "outside the range"),
    ("gen3_lite", math.nan, "position", "finite number"),
    ("gen3_lite", "shut", "position", "unknown gripper position 'shut'"),
    (42, 0.1, "robot", "expected a Robot"),
])
def test_bad_gripper_goals_are_typed(robot: Any, position: Any, key: str, words: str) -> None:
    with pytest.raises(InputError, match=words) as info:
        gripper_command_goal(robot, position, backend="rosbags")
    assert info.value.key == key


def test_bad_max_effort_and_loaded_robot_without_gripper() -> None:
    with pytest.raises(InputError, match=">= 0") as info:
        gripper_command_goal("gen3_lite", "open", max_effort=-1.0, backend="rosbags")
    assert info.value.key == "max_effort"
    with pytest.raises(InputError, match="robot 'panda' has no GripperCommand gripper"):
        gripper_command_goal(load_robot("panda"), "open", backend="rosbags")


def test_gripper_controller_constructor_checks_its_values() -> None:
    good: dict[str, Any] = dict(action="/g/gripper_cmd", joint="finger", unit="m",
                                position_range=(0.0, 0.04), open_position=0.04,
                                closed_position=0.0, max_effort=20.0)
    GripperSpec(**good)
    for change, key in [({"action": "g/gripper_cmd"}, "gripper.action"),
                        ({"unit": "deg"}, "gripper.unit"),
                        ({"position_range": (0.04, 0.0)}, "gripper.position_range"),
                        ({"open_position": 0.05}, "gripper.open_position"),
                        ({"closed_position": 0.04}, "gripper.closed_position"),
                        ({"max_effort": -1.0}, "gripper.max_effort"),
                        ({"joint": ""}, "gripper.joint")]:
        with pytest.raises(ConfigError) as info:
            GripperSpec(**{**good, **change})
        assert info.value.key == key, change


@pytest.fixture()
def gen3_copy(tmp_path: Path) -> Path:
    folder = tmp_path / "gen3"
    shutil.copytree(ROBOTS_DIR / "gen3_lite", folder)
    return folder


@pytest.mark.parametrize(("old", "new", "key", "words"), [
    ("  joint: right", "  jiont: right", "gripper.jiont", "did you mean 'joint'"),
    ("  max_effort: 100.0", "  max_effort: 100.0\n  speed: 1.0", "gripper.speed",
     "unknown key"),
    ("  unit: rad", "", "gripper.unit", "missing key"),
    ("position_range: [0.0, 0.81]", "position_range: [0.0, 0.9]", "gripper.position_range",
     "exceeds the URDF's limits of 'right_finger_bottom_joint' \\[0, 0.85\\]"),
    ("  unit: rad", "  unit: m", "gripper.unit", "moves in \\[rad\\], not \\[m\\]"),
    ("  joint: right_finger_bottom_joint", "  joint: finger", "gripper.joint",
     "'finger' is not a joint"),
    ("closed_position: 0.8 ", "closed_position: 0.95 ", "gripper.closed_position",
     "outside the range"),
])
def test_controller_yaml_gripper_section_is_checked(gen3_copy: Path, old: str, new: str,
                                                    key: str, words: str) -> None:
    path = gen3_copy / "controller.yaml"
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    with pytest.raises(ConfigError, match=words) as info:
        load_robot(gen3_copy)
    assert info.value.key == key and info.value.path == path


def test_gripper_section_is_optional(gen3_copy: Path) -> None:
    path = gen3_copy / "controller.yaml"
    text = path.read_text()
    path.write_text(text[:text.index("gripper:")])
    robot = load_robot(gen3_copy)
    assert robot.controller.gripper is None
    assert robot.controller.follow_joint_trajectory_action.startswith("/joint_trajectory")
    with pytest.raises(InputError, match="no 'gripper' section"):
        gripper_command_goal(robot, "open")


def test_gripper_goals_of_a_route_and_its_split() -> None:
    traj = gen3_route()
    goals = gripper_command_goals(traj, backend="rosbags")
    assert [(e.action, g.command.position) for e, g in goals] == [("open", 0.0), ("close", 0.8)]
    steps = split_at_gripper_events(traj)
    assert [type(s).__name__ for s in steps] == ["GripperEvent", "Trajectory", "GripperEvent",
                                                 "Trajectory"]
    with pytest.raises(InputError, match="no 'gripper' section"):
        gripper_command_goals(traj, load_robot("ned3pro"))


def test_bag_with_goals(tmp_path: Path) -> None:
    traj = gen3_route()
    start = 1_700_000_000 * 10**9
    path = write_bag(tmp_path / "pick", [traj], start_time_ns=start, goals=True)
    bag = read_bag(path)
    assert bag.topics[ARM_GOAL_TOPIC] == "control_msgs/action/FollowJointTrajectory_Goal"
    assert bag.topics[GRIPPER_GOAL_TOPIC] == GOAL
    # One goal per motion: the 'close' at 1 s cuts the route in two.
    arms = bag.on(ARM_GOAL_TOPIC)
    assert [m.timestamp - start for m in arms] == [0, 1_000_000_000]
    motions = [s for s in split_at_gripper_events(traj) if isinstance(s, Trajectory)]
    for arm, motion in zip(arms, motions, strict=True):
        assert_same(arm.msg, follow_joint_trajectory_goal(motion, backend="rosbags"))
        # Points at most 4 ms apart (robots/gen3_lite/controller.yaml): every knot (50 ms
        # apart) and 12 points of their quintic in between, in the controller's order.
        assert arm.msg.trajectory.joint_names == list(GEN3)
        assert len(arm.msg.trajectory.points) == 20 * 13 + 1
    grip = bag.on(GRIPPER_GOAL_TOPIC)
    assert [(m.timestamp - start, m.msg.command.position) for m in grip] == [
        (0, 0.0), (1_000_000_000, 0.8)]
    assert len(bag.on(GRIPPER_TOPIC)) == 2 and len(bag.on(TRAJECTORY_TOPIC)) == 2
    # /joint_states carries the finger joint (RViz draws the fingers): open (0.0) from the
    # 'open' at 0 s, closed (0.8) from the 'close' at 1 s.
    states = bag.on(JOINT_STATES_TOPIC)
    assert all(m.msg.name == [*GEN3, "right_finger_bottom_joint"] for m in states)
    finger = {m.timestamp - start: m.msg.position[-1] for m in states}
    assert finger[0] == 0.0 and finger[990_000_000] == 0.0
    assert finger[1_000_000_000] == 0.8 and finger[2_000_000_000] == 0.8
    # Without goals=True the bag is as before; a robot without a gripper section gets no
    # gripper goal topic.
    plain = read_bag(write_bag(tmp_path / "plain", [traj]))
    assert ARM_GOAL_TOPIC not in plain.topics and GRIPPER_GOAL_TOPIC not in plain.topics


def test_bag_joint_states_hold_the_locked_fingers(tmp_path: Path,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    """Given the robot's locked joints, ``/joint_states`` holds every finger joint: the
    gripper joint from the events and the three that mimic it (URDF ``<mimic>``) mapped
    from it; locked over their whole travel with no gripper event, they have no value
    and are left out, with a warning naming them."""
    robot = load_robot("gen3_lite")
    locked = robot.locked_joints
    assert all(j.value is None for j in locked)  # the fingers cover their whole travel
    traj = gen3_route()
    bag = read_bag(write_bag(tmp_path / "pick", [traj], locked_joints=locked))
    states = bag.on(JOINT_STATES_TOPIC)
    grip = "right_finger_bottom_joint"
    mimics = [j for j in locked if j.follows is not None]
    assert {j.follows[0] for j in mimics if j.follows} == {grip} and len(mimics) == 3
    for m in states:
        assert m.msg.name == [*GEN3, grip, *(j.name for j in mimics)]
        position = dict(zip(m.msg.name, m.msg.position, strict=True))
        for j in mimics:
            assert j.follows is not None
            assert position[j.name] == pytest.approx(position[grip] * j.follows[1]
                                                     + j.follows[2])
    assert {round(float(m.msg.position[6]), 3) for m in states} == {0.0, 0.8}
    # With a value, every finger is at it; without events and values, none is given.
    held = load_robot("gen3_lite", locked_joints={grip: 0.5}).locked_joints
    bag = read_bag(write_bag(tmp_path / "held", [gen3_route(events=False)],
                             locked_joints=held))
    expected = {j.name: j.value for j in held}
    for m in bag.on(JOINT_STATES_TOPIC):
        assert dict(zip(m.msg.name[6:], m.msg.position[6:], strict=True)) == expected
    with caplog.at_level(logging.WARNING, logger="safepath.ros.bag"):
        bag = read_bag(write_bag(tmp_path / "none", [gen3_route(events=False)],
                                 locked_joints=locked))
    assert all(m.msg.name == list(GEN3) for m in bag.on(JOINT_STATES_TOPIC))
    assert all(j.name in caplog.text for j in locked) and "whole travel" in caplog.text
