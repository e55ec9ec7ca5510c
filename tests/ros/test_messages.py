"""Message types, CDR round trips and the goal builders of safepath.ros."""

from __future__ import annotations

import array
import dataclasses
import importlib.util
import math
import sys
import types
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.base import Nodetype

from safepath.errors import InputError, RosError, TrajectoryError
from safepath.model.controller_spec import controller_for
from safepath.model.limits import MotionLimits
from safepath.model.trajectory import GripperEvent, Trajectory
from safepath.ros import goals
from safepath.ros.goals import (
    check_start,
    follow_joint_trajectory_goal,
    joint_trajectory,
    robot_move_goal,
    split_at_gripper_events,
    tool_goal,
    tool_goals,
)
from safepath.ros.messages import DEFINITIONS, deserialize, message_factory, serialize, typestore

NED_JOINT_NAMES = tuple(f"joint_{i}" for i in range(1, 7))
#: Niryo's niryo_controllers.yaml, as robots/ned3pro/controller.yaml must give them [rad].
GOAL_TOLERANCE = (0.002, 0.001, 0.001, 0.03, 0.03, 0.03)

# Taught joint poses of the quality-check cell [rad] (Niryo ROSCon 2025 workshop numbers).
POSES = {
    "grip": [-0.01677, -0.02075, -0.84359, -0.04593, -0.65195, -0.02445],
    "high1": [-0.01543, -0.00560, 0.07336, 0.00163, -1.59688, -0.01678],
    "high2": [1.59256, 0.03005, -0.02943, -0.00758, -1.58000, -0.01832],
    "low1": [1.40178, -0.23052, -0.68808, -0.05513, -0.66729, -0.03979],
    "safe": [1.45355, -0.91659, 0.52377, 0.06912, -1.16430, -0.10729],
    "unsafe": [2.87210, -1.13251, 0.51744, 0.17190, -0.85443, -0.10729],
}
NIRYO = "niryo_ned_ros2_interfaces"


def quintic_route(route: str, poses: list[str], events: tuple[tuple[int, str], ...] = (), *,
                  seg_time: float = 0.6, knots: int = 13,
                  joint_names: tuple[str, ...] = NED_JOINT_NAMES) -> Trajectory:
    """Rest-to-rest quintic moves through named poses; ``events``: (pose index, action).

    Faster than the Ned3 Pro may move (these test messages, not timing): the trajectory
    records limits of its own, 10x the robot's, which its goals are checked against.
    """
    tau = np.linspace(0.0, 1.0, knots)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / seg_time
    dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / seg_time**2
    t, q, qd, qdd, idx = [], [], [], [], []
    for k in range(len(poses) - 1):
        a, b = np.array(POSES[poses[k]]), np.array(POSES[poses[k + 1]])
        sel = slice(0 if k == 0 else 1, None)
        t.append((k + tau[sel]) * seg_time)
        q.append(a + np.outer(s[sel], b - a))
        qd.append(np.outer(ds[sel], b - a))
        qdd.append(np.outer(dds[sel], b - a))
        idx.append(np.full(tau[sel].size, k))
    evs = tuple(GripperEvent(time=i * seg_time, action=action, step=poses[i],  # type: ignore[arg-type]
                             object="vial") for i, action in events)
    return Trajectory(joint_names, np.concatenate(t), np.concatenate(q), np.concatenate(qd),
                      np.concatenate(qdd), np.concatenate(idx),
                      tuple(f"to_{p}" for p in poses[1:]), evs, "ned3pro", route,
                      limits=MotionLimits.from_dict(FAST_LIMITS))


#: Limits 10x the Ned3 Pro's, which the test trajectories record (see quintic_route).
FAST_LIMITS = {"velocity": [24.5, 10.47, 15.0, 40.76, 33.57, 50.36],
               "acceleration": [43.63, 21.8, 43.63, 299.6, 262.15, 393.23],
               "jerk": [872.6, 436.0, 872.6, 5992.0, 5243.0, 7864.6]}


def phase1() -> Trajectory:
    return quintic_route("phase1", ["grip", "high1", "high2", "low1", "high2"],
                         ((0, "close"), (3, "open")))


def motion1() -> Trajectory:
    """phase1's motion without its gripper events (a goal refuses an event inside)."""
    return quintic_route("phase1", ["grip", "high1", "high2", "low1", "high2"])


def motion2() -> Trajectory:
    """phase2_safe's motion without its gripper events."""
    return quintic_route("phase2_safe", ["high2", "low1", "high2", "safe", "high2", "high1",
                                         "grip"])


def phase2(target: str) -> Trajectory:
    return quintic_route(f"phase2_{target}",
                         ["high2", "low1", "high2", target, "high2", "high1", "grip"],
                         ((1, "close"), (3, "open")))


# -- generic message helpers -------------------------------------------------------------------
_INT_RANGES = {"int8": (-128, 127), "uint8": (0, 255), "byte": (0, 255), "char": (0, 255),
               "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
               "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1),
               "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1)}


def _value(desc: Any, rng: np.random.Generator) -> Any:
    """A random value for one field (scalar base types)."""
    kind, rest = desc
    if kind == Nodetype.NAME:
        return populate(rest, rng)
    name = rest[0]
    if name == "bool":
        return bool(rng.integers(2))
    if name in _INT_RANGES:
        low, high = _INT_RANGES[name]
        return int(rng.integers(low, high, endpoint=True, dtype=np.int64 if high < 2**63
                                else np.uint64))
    if name == "float32":
        return float(np.float32(rng.normal() * 100))
    if name == "float64":
        return float(rng.normal() * 1e3)
    if name == "string":
        return "".join(rng.choice(list("abcXYZ_/é 09"), size=int(rng.integers(0, 12))))
    raise AssertionError(f"no generator for {name}")


_DTYPES = {"bool": np.bool_, "float32": np.float32, "float64": np.float64, "int8": np.int8,
           "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
           "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64}


def populate(typename: str, rng: np.random.Generator) -> Any:
    """A message of ``typename`` with every field (nested ones too) set to random values."""
    store = typestore()
    _, fields = store.fielddefs[typename]
    values: dict[str, Any] = {}
    for name, (kind, rest) in fields:
        if kind in (Nodetype.SEQUENCE, Nodetype.ARRAY):
            sub, size = rest
            n = size if kind == Nodetype.ARRAY else int(rng.integers(0, 4))
            items = [_value(sub, rng) for _ in range(n)]
            if sub[0] == Nodetype.BASE and sub[1][0] in _DTYPES:
                values[name] = np.array(items, dtype=_DTYPES[sub[1][0]])
            else:
                values[name] = items
        else:
            values[name] = _value((kind, rest), rng)
    return store.types[typename](**values)


def assert_same(a: Any, b: Any, where: str = "msg") -> None:
    """Field-by-field equality: arrays exactly (dtype and values), floats exactly."""
    if dataclasses.is_dataclass(a):
        assert type(a).__name__ == type(b).__name__, where
        for f in dataclasses.fields(a):
            if not f.name.startswith("__"):
                assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype, where
        assert np.array_equal(a, b), where
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{k}]")
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


def round_trip(msg: Any) -> Any:
    data = serialize(msg)
    back = deserialize(data, msg.__msgtype__)
    assert_same(msg, back)
    assert serialize(back) == data
    return back


# -- the type store ----------------------------------------------------------------------------
ALL_TYPES = sorted(DEFINITIONS) + [
    "trajectory_msgs/msg/JointTrajectory", "sensor_msgs/msg/JointState", "std_msgs/msg/String",
    "builtin_interfaces/msg/Duration"]


@pytest.mark.parametrize("typename", ALL_TYPES)
def test_every_type_round_trips_through_cdr(typename: str) -> None:
    rng = np.random.default_rng(sum(typename.encode()))
    for _ in range(3):
        round_trip(populate(typename, rng))


def test_assert_same_notices_a_changed_field() -> None:
    msg = populate(f"{NIRYO}/msg/ArmMoveCommand", np.random.default_rng(1))
    back = deserialize(serialize(msg), msg.__msgtype__)
    back.trajectory.joint_names.append("extra")
    with pytest.raises(AssertionError):
        assert_same(msg, back)


def test_known_cdr_bytes() -> None:
    store = typestore()
    # Little-endian CDR header, then one byte for the empty request's placeholder member.
    request = store.types["rpi_manager/srv/GetSafety_Request"](
        structure_needs_at_least_one_member=0)
    assert serialize(request) == b"\x00\x01\x00\x00\x00"
    # A string is a uint32 length (with its NUL) then the bytes and the NUL.
    response = store.types["rpi_manager/srv/GetSafety_Response"](state="safe")
    assert serialize(response) == b"\x00\x01\x00\x00\x05\x00\x00\x00safe\x00"
    conveyor = store.types[f"{NIRYO}/srv/ControlConveyor_Request"](
        id=9, control_on=True, speed=60, direction=-1)
    assert serialize(conveyor) == b"\x00\x01\x00\x00\x09\x01\x3c\x00\xff"


def test_constants_match_the_robot() -> None:
    t = typestore().types
    assert t[f"{NIRYO}/msg/ArmMoveCommand"].EXECUTE_FULL_TRAJ == 11
    assert t[f"{NIRYO}/msg/ArmMoveCommand"].EXECUTE_RAW_TRAJ == 12
    assert t[f"{NIRYO}/msg/ToolCommand"].OPEN_GRIPPER == 1
    assert t[f"{NIRYO}/msg/ToolCommand"].CLOSE_GRIPPER == 2
    assert t[f"{NIRYO}/srv/SetConveyor_Request"].ADD == 1
    assert t["control_msgs/action/FollowJointTrajectory_Result"].GOAL_TOLERANCE_VIOLATED == -5


def test_serialize_errors_are_typed() -> None:
    with pytest.raises(RosError):
        serialize(object())
    with pytest.raises(RosError):
        deserialize(b"\x00\x01\x00\x00", "no_pkg/msg/Nothing")
    with pytest.raises(RosError):
        deserialize(b"\x00\x01\x00\x00\x01", "std_msgs/msg/String")


REFERENCE = Path("/work/shared/reference")


def _reference_types() -> dict[str, Any]:
    """Field lists of the upstream interface files (kept outside the project)."""
    out: dict[str, Any] = {}
    files = [*sorted((REFERENCE / "niryo_interfaces").glob("*.*")),
             REFERENCE / "roscon2025_cell" / "GetSafety.srv"]
    for path in files:
        pkg = "rpi_manager" if path.name == "GetSafety.srv" else NIRYO
        text = path.read_text()
        kind = path.suffix[1:]
        if kind == "msg":
            parts = {f"{pkg}/msg/{path.stem}": text}
        elif kind in ("srv", "action"):
            names = ["Request", "Response"] if kind == "srv" else ["Goal", "Result", "Feedback"]
            parts = {f"{pkg}/{kind}/{path.stem}_{n}": p
                     for n, p in zip(names, text.split("\n---"), strict=True)}
        else:
            continue
        for name, part in parts.items():
            alias = name.replace(f"/{kind}/", "/msg/")
            out[name] = get_types_from_msg(part, alias)[alias][1]
    return out


@pytest.mark.skipif(not REFERENCE.is_dir(), reason="reference interfaces not available")
def test_definitions_match_the_upstream_field_lists() -> None:
    ref = _reference_types()
    assert len(ref) == 19  # 7 msg + 3 srv x 2 + 2 action x 3
    for name, fields in ref.items():
        ours = typestore().fielddefs[name][1]
        if not fields:  # rosidl gives an empty structure one placeholder member
            fields = [("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))]
        assert ours == fields, name


# -- joint_trajectory --------------------------------------------------------------------------
def _seconds(duration: Any) -> int:
    return duration.sec * 1_000_000_000 + duration.nanosec


def test_joint_trajectory_samples_every_period_and_ends_exactly() -> None:
    traj = motion1()  # 4 x 0.6 s
    msg = joint_trajectory(traj, backend="rosbags")
    assert msg.joint_names == list(NED_JOINT_NAMES)
    ns = [_seconds(p.time_from_start) for p in msg.points]
    # Every knot (50 ms apart), and one point between two knots: the controller's period
    # is 40 ms at most.
    assert ns == [25_000_000 * k for k in range(96)] + [2_400_000_000]
    assert msg.points[-1].time_from_start.sec == 2 and msg.points[-1].time_from_start.nanosec \
        == 400_000_000
    q, qd, qdd = traj.sample(np.array(ns[:-1]) / 1e9)
    positions = np.array([p.positions for p in msg.points])
    assert np.allclose(positions[:-1], q, rtol=0, atol=1e-12)
    assert np.allclose(np.array([p.velocities for p in msg.points])[:-1], qd, rtol=0, atol=1e-12)
    assert np.allclose(np.array([p.accelerations for p in msg.points])[:-1], qdd, rtol=0,
                       atol=1e-12)
    last = msg.points[-1]
    assert np.array_equal(last.positions, traj.q[-1])
    assert np.array_equal(last.velocities, traj.qd[-1])
    assert np.array_equal(last.accelerations, traj.qdd[-1])
    assert np.array_equal(msg.points[0].positions, traj.q[0])
    assert all(p.effort.size == 0 for p in msg.points)
    round_trip(msg)


def test_time_from_start_is_rounded_to_the_nanosecond() -> None:
    traj = quintic_route("r", ["grip", "high1"], seg_time=1.2345678906)
    msg = joint_trajectory(traj, period=0.5, backend="rosbags")
    ends = [(p.time_from_start.sec, p.time_from_start.nanosec) for p in msg.points]
    # Every knot (a twelfth of the move apart), its time rounded to the nanosecond.
    expected = [divmod(round(float(t) * 1e9), 1_000_000_000) for t in traj.t]
    assert ends == expected and ends[-1] == (1, 234_567_891)
    # Knots 20 ms apart, under the 40 ms period: the knots alone, the last not repeated.
    assert len(joint_trajectory(quintic_route("r", ["grip", "high1"], seg_time=0.48,
                                              knots=25), backend="rosbags").points) == 25


def test_columns_follow_the_robot_order() -> None:
    traj = motion1()
    order = [5, 0, 3, 1, 4, 2]
    shuffled = Trajectory(tuple(traj.joint_names[k] for k in order), traj.t, traj.q[:, order],
                          traj.qd[:, order], traj.qdd[:, order], traj.step_index, traj.steps,
                          traj.events, traj.robot, traj.route,
                          limits=MotionLimits.from_dict(FAST_LIMITS).columns(order))
    a = joint_trajectory(traj, backend="rosbags")
    b = joint_trajectory(shuffled, backend="rosbags")
    assert_same(a, b)
    custom = ("j1", "j2", "j3", "j4", "j5", "j6")
    renamed = dataclasses.replace(traj, joint_names=custom)
    assert joint_trajectory(renamed, robot_joint_names=custom,
                            backend="rosbags").joint_names == list(custom)


@pytest.mark.parametrize("period", [0, -0.04, math.nan, math.inf, 1e-12, True, "0.04"])
def test_bad_period_is_refused(period: Any) -> None:
    with pytest.raises(TrajectoryError) as info:
        joint_trajectory(motion1(), period=period, backend="rosbags")
    assert info.value.key == "period"


def test_joint_names_must_match_the_robot() -> None:
    traj = motion1()
    wrong = dataclasses.replace(traj, joint_names=("a", "b", "c", "d", "e", "f"))
    for build in (joint_trajectory, follow_joint_trajectory_goal, robot_move_goal):
        with pytest.raises(TrajectoryError) as info:
            build(wrong, backend="rosbags")
        assert info.value.key == "joint_names"
    five = Trajectory(NED_JOINT_NAMES[:5], traj.t, traj.q[:, :5], traj.qd[:, :5],
                      traj.qdd[:, :5], traj.step_index, traj.steps, robot="ned3pro",
                      limits=MotionLimits.from_dict(FAST_LIMITS).columns(range(5)))
    with pytest.raises(TrajectoryError):
        joint_trajectory(five, backend="rosbags")
    # A robot without a controller file: its own joints, in its own order.
    anonymous = dataclasses.replace(five, robot="")
    assert joint_trajectory(anonymous, backend="rosbags").joint_names == list(
        NED_JOINT_NAMES[:5])
    with pytest.raises(TrajectoryError):
        joint_trajectory(traj, robot_joint_names=list(NED_JOINT_NAMES) + ["joint_7"],
                         backend="rosbags")


def test_non_finite_and_non_increasing_are_refused_by_constructor_and_builders() -> None:
    traj = motion1()
    q = traj.q.copy()
    q[3, 1] = math.nan
    with pytest.raises(TrajectoryError):
        dataclasses.replace(traj, q=q)
    t = traj.t.copy()
    t[4] = t[3]
    with pytest.raises(TrajectoryError):
        dataclasses.replace(traj, t=t)
    # The arrays of a built Trajectory can still be changed in place: builders re-check.
    broken = motion1()
    broken.qd[7, 2] = math.inf
    with pytest.raises(TrajectoryError) as info:
        joint_trajectory(broken, backend="rosbags")
    assert info.value.key == "qd"
    late = motion1()
    late.t[5] = late.t[4] - 0.01
    for build in (joint_trajectory, follow_joint_trajectory_goal, robot_move_goal):
        with pytest.raises(TrajectoryError) as info:
            build(late, backend="rosbags")
        assert info.value.key == "t"
    with pytest.raises(TrajectoryError):
        split_at_gripper_events(late)


# -- goals -------------------------------------------------------------------------------------
def test_follow_joint_trajectory_goal() -> None:
    traj = motion2()
    goal = follow_joint_trajectory_goal(traj, backend="rosbags")
    assert goal.__msgtype__ == "control_msgs/action/FollowJointTrajectory_Goal"
    assert_same(goal.trajectory, joint_trajectory(traj, backend="rosbags"))
    assert [(t.name, t.position) for t in goal.goal_tolerance] == list(
        zip(NED_JOINT_NAMES, GOAL_TOLERANCE, strict=True))
    assert (goal.goal_time_tolerance.sec, goal.goal_time_tolerance.nanosec) == (1, 0)
    assert goal.path_tolerance == [] and goal.multi_dof_trajectory.points == []
    round_trip(goal)
    loose = follow_joint_trajectory_goal(traj, goal_tolerance=None, goal_time_tolerance=0.25,
                                         backend="rosbags")
    assert loose.goal_tolerance == [] and loose.goal_time_tolerance.nanosec == 250_000_000
    with pytest.raises(TrajectoryError):
        follow_joint_trajectory_goal(traj, goal_tolerance=[0.1] * 5, backend="rosbags")
    with pytest.raises(TrajectoryError):
        follow_joint_trajectory_goal(traj, goal_tolerance=[0.1] * 5 + [math.nan],
                                     backend="rosbags")
    with pytest.raises(TrajectoryError):
        follow_joint_trajectory_goal(traj, goal_time_tolerance=-1.0, backend="rosbags")


def test_robot_move_goal_is_a_full_trajectory_command() -> None:
    traj = motion1()
    goal = robot_move_goal(traj, backend="rosbags")
    assert goal.__msgtype__ == f"{NIRYO}/action/RobotMove_Goal"
    assert goal.cmd.cmd_type == 11 == goal.cmd.EXECUTE_FULL_TRAJ
    assert_same(goal.cmd.trajectory, joint_trajectory(traj, backend="rosbags"))
    assert goal.cmd.joints.size == 0 and goal.cmd.list_poses == []
    round_trip(goal)


def test_tool_goals() -> None:
    close = tool_goal("close", backend="rosbags")
    assert close.__msgtype__ == f"{NIRYO}/action/Tool_Goal"
    assert (close.cmd.cmd_type, close.cmd.tool_id) == (close.cmd.CLOSE_GRIPPER, 11)
    assert (close.cmd.max_torque_percentage, close.cmd.hold_torque_percentage) == (100, 100)
    opened = round_trip(tool_goal("open", tool_id=12, max_torque=80, hold_torque=30,
                                  backend="rosbags"))
    assert (opened.cmd.cmd_type, opened.cmd.tool_id) == (1, 12)
    assert (opened.cmd.max_torque_percentage, opened.cmd.hold_torque_percentage) == (80, 30)
    pairs = tool_goals(phase1(), backend="rosbags")
    assert [(e.action, g.cmd.cmd_type) for e, g in pairs] == [("close", 2), ("open", 1)]
    with pytest.raises(InputError):
        tool_goal("grab", backend="rosbags")  # type: ignore[arg-type]
    for bad in ({"max_torque": 101}, {"hold_torque": -1}, {"tool_id": 300}, {"tool_id": 1.5}):
        with pytest.raises(InputError):
            tool_goal("open", backend="rosbags", **bad)  # type: ignore[arg-type]


def test_split_at_gripper_events() -> None:
    traj = phase1()  # close at 0 s (grip), open at 1.8 s (low1)
    program = split_at_gripper_events(traj)
    kinds = [x.action if isinstance(x, GripperEvent) else "move" for x in program]
    assert kinds == ["close", "move", "open", "move"]
    first, second = program[1], program[3]
    assert isinstance(first, Trajectory) and isinstance(second, Trajectory)
    assert first.t[0] == 0.0 and second.t[0] == 0.0
    assert first.duration == pytest.approx(1.8) and second.duration == pytest.approx(0.6)
    assert second.info["time_offset"] == pytest.approx(1.8)
    assert np.allclose(first.q[-1], POSES["low1"]) and np.allclose(second.q[0], POSES["low1"])
    assert np.array_equal(second.q[-1], traj.q[-1])
    assert first.events == () and first.steps == traj.steps and first.route == "phase1"
    # The cut segments sample the same motion.
    q, _, _ = traj.sample(second.t + 1.8)
    assert np.allclose(second.q, q, atol=1e-12)
    end_events = quintic_route("r", ["grip", "high1", "high2"], ((0, "open"), (2, "close")))
    assert [type(x).__name__ for x in split_at_gripper_events(end_events)] == [
        "GripperEvent", "Trajectory", "GripperEvent"]


def test_goals_refuse_a_gripper_event_inside() -> None:
    """One goal through the 'open' at 1.8 s would never open the gripper: every builder
    refuses it, naming the event and split_at_gripper_events; events at the ends are
    fine, and so is each motion the split gives."""
    traj = phase1()  # close at 0 s (its start), open at 1.8 s of 2.4 s
    for build in (joint_trajectory, follow_joint_trajectory_goal, robot_move_goal):
        with pytest.raises(TrajectoryError, match=r"'open' of step 'low1' at t=1\.800 s.*"
                                                  r"split_at_gripper_events") as info:
            build(traj, backend="rosbags")
        assert info.value.key == "events[1]"
    end_events = quintic_route("r", ["grip", "high1", "high2"], ((0, "open"), (2, "close")))
    assert len(joint_trajectory(end_events, backend="rosbags").points) > 0
    motions = [x for x in split_at_gripper_events(traj) if isinstance(x, Trajectory)]
    assert [len(follow_joint_trajectory_goal(m, backend="rosbags").trajectory.points) > 0
            for m in motions] == [True, True]


def test_gripper_events_must_be_at_rest_and_inside() -> None:
    traj = phase1()
    moving = dataclasses.replace(traj, events=(GripperEvent(0.9, "close", "to_high2"),))
    with pytest.raises(TrajectoryError, match="not at rest"):
        split_at_gripper_events(moving)
    outside = dataclasses.replace(traj, events=(GripperEvent(9.0, "open", "x"),))
    with pytest.raises(TrajectoryError, match="outside"):
        split_at_gripper_events(outside)


def test_check_start() -> None:
    traj = phase1()
    at_start = dict(zip(NED_JOINT_NAMES, traj.q[0] + 0.02, strict=True))
    check_start(traj, at_start)
    with pytest.raises(TrajectoryError, match="joint_3"):
        check_start(traj, {**at_start, "joint_3": traj.q[0, 2] + 0.2})
    with pytest.raises(TrajectoryError, match="no measured"):
        check_start(traj, {"joint_1": 0.0})


# -- backends ----------------------------------------------------------------------------------
def test_rclpy_backend_without_ros_is_a_typed_error() -> None:
    if importlib.util.find_spec("rclpy") is not None:
        pytest.skip("rclpy is installed")
    for build in (joint_trajectory, follow_joint_trajectory_goal, robot_move_goal):
        with pytest.raises(RosError, match="rclpy"):
            build(motion1(), backend="rclpy")
    with pytest.raises(RosError):
        tool_goal("open", backend="rclpy")
    with pytest.raises(InputError):
        joint_trajectory(motion1(), backend="ros1")  # type: ignore[arg-type]
    # auto falls back to rosbags messages
    assert joint_trajectory(motion1()).__msgtype__ == "trajectory_msgs/msg/JointTrajectory"


class _FakeRosMessage:
    """Mimics an rclpy message: keyword fields; float64[] must not be a numpy array."""

    def __init__(self, **fields: Any):
        for name, value in fields.items():
            assert not isinstance(value, np.ndarray), f"{name}: rclpy rejects numpy arrays"
            setattr(self, name, value)


def _fake_package(monkeypatch: pytest.MonkeyPatch, package: str, kind: str,
                  names: list[str]) -> None:
    root = types.ModuleType(package)
    root.__path__ = []  # type: ignore[attr-defined]
    module = types.ModuleType(f"{package}.{kind}")
    for name in names:
        setattr(module, name, type(name, (_FakeRosMessage,), {}))
    monkeypatch.setitem(sys.modules, package, root)
    monkeypatch.setitem(sys.modules, f"{package}.{kind}", module)


def test_rclpy_branch_builds_native_classes(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rclpy", types.ModuleType("rclpy"))
    _fake_package(monkeypatch, "trajectory_msgs", "msg", ["JointTrajectory",
                                                          "JointTrajectoryPoint"])
    _fake_package(monkeypatch, "std_msgs", "msg", ["Header"])
    _fake_package(monkeypatch, "builtin_interfaces", "msg", ["Time", "Duration"])
    assert message_factory("auto", ["trajectory_msgs/msg/JointTrajectory"]).backend == "rclpy"
    traj = motion1()
    msg = joint_trajectory(traj, backend="auto")
    assert type(msg).__name__ == "JointTrajectory" and isinstance(msg, _FakeRosMessage)
    first = msg.points[0]
    assert isinstance(first.positions, array.array) and first.positions.typecode == "d"
    assert list(first.positions) == list(traj.q[0])
    assert (msg.points[-1].time_from_start.sec, msg.points[-1].time_from_start.nanosec) == (2,
                                                                                      400_000_000)
    # control_msgs is still missing: the goal needs it.
    with pytest.raises(RosError, match="control_msgs"):
        follow_joint_trajectory_goal(traj, backend="rclpy")
    action = types.ModuleType("control_msgs.action")
    action.FollowJointTrajectory = types.SimpleNamespace(  # type: ignore[attr-defined]
        Goal=type("Goal", (_FakeRosMessage,), {}))
    _fake_package(monkeypatch, "control_msgs", "msg", ["JointTolerance"])
    monkeypatch.setitem(sys.modules, "control_msgs.action", action)
    _fake_package(monkeypatch, "trajectory_msgs", "msg", ["JointTrajectory",
                                                          "JointTrajectoryPoint",
                                                          "MultiDOFJointTrajectory"])
    goal = follow_joint_trajectory_goal(traj, backend="rclpy")
    assert [t.position for t in goal.goal_tolerance] == list(GOAL_TOLERANCE)


def test_ned_controller_comes_from_its_robot_folder() -> None:
    ned = controller_for("ned3pro", NED_JOINT_NAMES)
    assert ned.source is not None and ned.source.name == "controller.yaml"
    assert ned.follow_joint_trajectory_action == (
        "/niryo_robot_follow_joint_trajectory_controller/follow_joint_trajectory")
    assert ned.period == 0.04 and ned.goal_tolerance == GOAL_TOLERANCE
    assert goals.controller_of(phase1()) == ned


def test_float_rows_are_the_rows_as_floats_gives_them_in_any_memory_order() -> None:
    f = message_factory("rosbags", ["trajectory_msgs/msg/JointTrajectoryPoint"])
    values = np.asfortranarray(np.arange(12.0).reshape(4, 3))
    rows = f.float_rows(values)
    assert len(rows) == 4
    for row, expected in zip(rows, values, strict=True):
        assert row.dtype == np.float64 and row.flags.c_contiguous
        assert np.array_equal(row, f.floats(expected))
    values[0, 0] = 99.0  # the rows are copies: the message does not follow its source
    assert rows[0][0] == 0.0
    point = f.cls("trajectory_msgs/msg/JointTrajectoryPoint")
    zero = f.cls("builtin_interfaces/msg/Duration")(sec=0, nanosec=0)
    assert serialize(point(positions=rows[1], velocities=f.float_rows(values[:, :0])[1],
                           accelerations=rows[2], effort=f.floats([]), time_from_start=zero)) \
        == serialize(point(positions=f.floats(values[1]), velocities=f.floats([]),
                           accelerations=f.floats(values[2]), effort=f.floats([]),
                           time_from_start=zero))
