"""ROS 2 bags (MCAP) of a cycle, read back with rosbags' own Reader."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from safepath.errors import RosError, TrajectoryError
from safepath.model.trajectory import Trajectory
from safepath.ros import bag as bag_module
from safepath.ros.bag import (
    GRIPPER_TOPIC,
    JOINT_STATES_TOPIC,
    ROUTE_TOPIC,
    TRAJECTORY_TOPIC,
    read_bag,
    write_bag,
)
from safepath.ros.goals import joint_trajectory, split_at_gripper_events

from .test_messages import NED_JOINT_NAMES, assert_same, phase1, phase2

START = 1_700_000_000 * 10**9  # a fixed clock start [ns]


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


@pytest.fixture()
def cycle_bag(tmp_path: Path) -> Path:
    return write_bag(tmp_path / "cycle", [phase1(), phase2("safe")], start_time_ns=START)


def test_bag_is_mcap_and_nothing_else_is_left(cycle_bag: Path) -> None:
    assert sorted(p.name for p in cycle_bag.parent.iterdir()) == ["cycle"]
    assert sorted(p.name for p in cycle_bag.iterdir()) == ["cycle.mcap", "metadata.yaml"]
    meta = yaml.safe_load((cycle_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap"
    assert (cycle_bag / "cycle.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_bag_decodes_from_its_own_definitions(cycle_bag: Path) -> None:
    """A reader with no safepath types (like ros2 bag or Foxglove) can decode every topic."""
    store = get_typestore(Stores.EMPTY)
    with Reader(cycle_bag) as reader:
        for conn in reader.connections:
            store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        counts: dict[str, int] = {}
        for conn, _, raw in reader.messages():
            store.deserialize_cdr(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert reader.start_time == START
    assert topics == {TRAJECTORY_TOPIC: "trajectory_msgs/msg/JointTrajectory",
                      ROUTE_TOPIC: "std_msgs/msg/String", GRIPPER_TOPIC: "std_msgs/msg/String",
                      JOINT_STATES_TOPIC: "sensor_msgs/msg/JointState"}
    total = phase1().duration + phase2("safe").duration  # 2.4 + 3.6 s
    # One message per motion between gripper events: phase1 2 (events at 0 and 1.8 s of
    # 2.4 s), phase2 3 (events at 0.6 and 1.8 s of 3.6 s).
    assert counts == {TRAJECTORY_TOPIC: 5, ROUTE_TOPIC: 2, GRIPPER_TOPIC: 4,
                      JOINT_STATES_TOPIC: round(total * 50) + 1}


def test_bag_contents(cycle_bag: Path) -> None:
    one, two = phase1(), phase2("safe")
    bag = read_bag(cycle_bag)
    # The motions between gripper events back to back on one clock, each as
    # joint_trajectory() builds it (a whole route with an event inside is refused).
    motions = [p for traj in (one, two) for p in split_at_gripper_events(traj)
               if isinstance(p, Trajectory)]
    trajs = bag.on(TRAJECTORY_TOPIC)
    assert [m.timestamp - START for m in trajs] == [0, _ns(1.8), _ns(2.4), _ns(3.0),
                                                    _ns(4.2)]
    for m, motion in zip(trajs, motions, strict=True):
        assert_same(m.msg, joint_trajectory(motion, stamp_ns=m.timestamp, backend="rosbags"))
    assert [m.timestamp for m in bag.on(ROUTE_TOPIC)] == [START, START + _ns(one.duration)]
    routes = [json.loads(m.msg.data) for m in bag.on(ROUTE_TOPIC)]
    assert [(r["route"], r["duration"]) for r in routes] == [("phase1", one.duration),
                                                            ("phase2_safe", two.duration)]
    grip = [(m.timestamp - START, json.loads(m.msg.data)) for m in bag.on(GRIPPER_TOPIC)]
    assert [(t, g["action"], g["step"]) for t, g in grip] == [
        (0, "close", "grip"), (_ns(1.8), "open", "low1"),
        (_ns(2.4 + 0.6), "close", "low1"), (_ns(2.4 + 1.8), "open", "safe")]
    # Joint states every 20 ms, consecutive across the two trajectories.
    states = bag.on(JOINT_STATES_TOPIC)
    stamps = np.array([m.timestamp for m in states])
    assert stamps[0] == START and np.all(np.diff(stamps) == 20_000_000)
    assert all(m.msg.name == list(NED_JOINT_NAMES) for m in states)
    assert all(m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec == m.timestamp
               for m in states)
    pos = np.array([m.msg.position for m in states])
    assert np.array_equal(pos[0], one.q[0])
    boundary = int((_ns(one.duration)) // 20_000_000)  # the sample at 2.4 s
    assert np.allclose(pos[boundary], two.q[0], atol=1e-12)
    assert np.allclose(pos[-1], two.q[-1], atol=1e-12)
    t_mid = 2.4 + 1.0
    q_mid, qd_mid, _ = two.sample([1.0])
    k = round(t_mid / 0.02)
    assert np.allclose(pos[k], q_mid[0], atol=1e-12)
    assert np.allclose(states[k].msg.velocity, qd_mid[0], atol=1e-12)
    assert all(m.msg.effort.size == 0 for m in states)


def test_rate_and_start_time(tmp_path: Path) -> None:
    path = write_bag(tmp_path / "slow", [phase1()], joint_state_rate=10.0, start_time_ns=0)
    states = read_bag(path).on(JOINT_STATES_TOPIC)
    assert [m.timestamp for m in states] == [100_000_000 * k for k in range(25)]
    # Without a start time, the bag is stamped from now (not from 1970).
    before = time.time_ns()
    now = read_bag(write_bag(tmp_path / "now", [phase1()])).on(JOINT_STATES_TOPIC)
    assert before <= now[0].timestamp <= time.time_ns()
    assert now[0].msg.header.stamp.sec == now[0].timestamp // 10**9
    with pytest.raises(TrajectoryError) as info:
        write_bag(tmp_path / "neg", [phase1()], start_time_ns=-1)
    assert info.value.key == "start_time_ns"


def test_existing_path_is_never_overwritten(cycle_bag: Path) -> None:
    before = (cycle_bag / "cycle.mcap").read_bytes()
    with pytest.raises(RosError, match="exists"):
        write_bag(cycle_bag, [phase1()])
    assert (cycle_bag / "cycle.mcap").read_bytes() == before


def test_bad_input_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "bad"
    with pytest.raises(TrajectoryError, match="not one cycle"):
        write_bag(target, [phase1(), phase1()])  # phase1 ends at high2, not at grip
    with pytest.raises(TrajectoryError):
        write_bag(target, [])
    with pytest.raises(TrajectoryError):
        write_bag(target, [phase1()], joint_state_rate=0.0)
    with pytest.raises(TrajectoryError):
        write_bag(target, [phase1()], period=-1.0)
    broken = phase1()
    broken.q[2, 0] = float("nan")
    with pytest.raises(TrajectoryError):
        write_bag(target, [broken])
    assert list(tmp_path.iterdir()) == []


def test_failure_while_writing_removes_the_temporary_bag(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    real = bag_module.Writer.write
    calls = {"n": 0}

    def failing(self: object, *args: object) -> None:
        calls["n"] += 1
        if calls["n"] == 50:
            raise OSError("disk full")
        real(self, *args)

    monkeypatch.setattr(bag_module.Writer, "write", failing)
    with pytest.raises(RosError, match="disk full"):
        write_bag(tmp_path / "cut", [phase1(), phase2("unsafe")])
    assert calls["n"] == 50
    assert list(tmp_path.iterdir()) == []


def test_read_bag_errors(tmp_path: Path) -> None:
    with pytest.raises(RosError):
        read_bag(tmp_path / "missing")


def test_joint_states_are_the_bytes_rosbags_serialises() -> None:
    """The cycle's ``/joint_states`` are laid out at once (``_cdr``): each is
    byte for byte what rosbags serialises for the same ``JointState`` (names of any
    length and count, stamps over the whole range of a ROS 2 Time)."""
    from safepath.ros import _cdr
    from safepath.ros.messages import serialize, written_typestore

    store = written_typestore()
    header, stamp, state = (store.types[n] for n in (
        "std_msgs/msg/Header", "builtin_interfaces/msg/Time", "sensor_msgs/msg/JointState"))
    rng = np.random.default_rng(4)
    for names in (["joint_1"], ["a", "bb", "ccc", "dddd", "eeeee"], list(NED_JOINT_NAMES),
                  [f"joint_{k}" for k in range(12)]):
        rows = 15
        stamps = rng.integers(0, (2**31 - 1) * 10**9, rows)
        stamps[0] = 0
        q, qd = rng.normal(0.0, 2.0, (rows, len(names))), rng.normal(0.0, 2.0, (rows, len(names)))
        got = _cdr.joint_states_cdr(stamps, names, q, qd)
        for k in range(rows):
            msg = state(header=header(stamp=stamp(sec=int(stamps[k] // 10**9),
                                                  nanosec=int(stamps[k] % 10**9)), frame_id=""),
                        name=list(names), position=q[k], velocity=qd[k], effort=np.zeros(0))
            assert got[k] == serialize(msg, "sensor_msgs/msg/JointState"), (names, k)


def test_a_start_past_what_a_ros_time_holds_is_refused_before_writing(tmp_path: Path) -> None:
    with pytest.raises(TrajectoryError, match="ROS 2 Time") as info:
        write_bag(tmp_path / "late", [phase1()], start_time_ns=2**31 * 10**9)
    assert info.value.key == "start_time_ns"
    assert list(tmp_path.iterdir()) == []
    # A cycle that starts in time but ends past it: its states cannot be stamped either.
    with pytest.raises(RosError, match="ROS 2 Time"):
        write_bag(tmp_path / "later", [phase1()], start_time_ns=2**31 * 10**9 - 10**9)
    assert list(tmp_path.iterdir()) == []
