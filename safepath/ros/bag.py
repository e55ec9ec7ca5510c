"""ROS 2 bags (MCAP storage) of a cycle of trajectories, for review and replay.

One bag holds a cycle: the trajectories in the order the robot runs them, back to
back on one clock. Each trajectory runs as a node runs it: the motions between its
gripper events (:func:`~safepath.ros.goals.split_at_gripper_events`), one message each,
and each gripper event when the motion before it has ended. Only standard ROS 2 types
are used, so ``ros2 bag play``, Foxglove or PlotJuggler read it with no Niryo packages
installed:

=======================  ==================================  ===============================
topic                    type                                one message
=======================  ==================================  ===============================
``/safepath/trajectory`` ``trajectory_msgs/msg/JointTrajectory``  per motion, at its start
``/safepath/route``      ``std_msgs/msg/String`` (JSON)       per trajectory, at its start
``/safepath/gripper``    ``std_msgs/msg/String`` (JSON)       per gripper event, at its time
``/joint_states``        ``sensor_msgs/msg/JointState``       every 1/``joint_state_rate``
=======================  ==================================  ===============================

``/joint_states`` holds the controller's joints and, for a robot whose ``controller.yaml``
has a ``gripper`` section and a cycle with gripper events, its gripper joint (open or
closed after each event, the other position before the first), and the locked joints
given as ``locked_joints`` at their values (``safepath plan --bag`` gives the cell's robot's),
so that RViz draws the fingers. The bag is stamped from ``start_time_ns`` (default: now).

With ``goals=True`` the bag also holds the goals a node sends, as it would send them:
``/safepath/arm_goal`` (``control_msgs/action/FollowJointTrajectory_Goal``, per motion,
at its start) and, for a robot whose ``controller.yaml`` has a ``gripper`` section,
``/safepath/gripper_goal`` (``control_msgs/action/GripperCommand_Goal``, per gripper event,
at its time).
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError

from ..errors import RosError, TrajectoryError
from ..model._knots import interval_index
from ..model.controller_spec import ControllerSpec
from ..model.trajectory import GripperEvent, Trajectory
from ._cdr import joint_states_cdr
from .goals import (
    _joint_trajectory_cdr,
    controller_of,
    follow_joint_trajectory_goal,
    split_at_gripper_events,
)
from .gripper import gripper_command_goal
from .messages import deserialize, serialize, written_typestore

if TYPE_CHECKING:
    from ..model._locked import LockedJoint

__all__ = ["ARM_GOAL_TOPIC", "BagContents", "BagMessage", "GRIPPER_GOAL_TOPIC", "GRIPPER_TOPIC",
           "JOINT_STATES_TOPIC", "ROUTE_TOPIC", "TRAJECTORY_TOPIC", "read_bag", "write_bag"]

logger = logging.getLogger(__name__)

TRAJECTORY_TOPIC = "/safepath/trajectory"
ROUTE_TOPIC = "/safepath/route"
GRIPPER_TOPIC = "/safepath/gripper"
JOINT_STATES_TOPIC = "/joint_states"
ARM_GOAL_TOPIC = "/safepath/arm_goal"
GRIPPER_GOAL_TOPIC = "/safepath/gripper_goal"
#: Largest jump allowed between the end of one trajectory and the start of the next [rad].
JOIN_TOLERANCE = 1e-4

_NS = 1_000_000_000
_TOPICS = {
    TRAJECTORY_TOPIC: "trajectory_msgs/msg/JointTrajectory",
    ROUTE_TOPIC: "std_msgs/msg/String",
    GRIPPER_TOPIC: "std_msgs/msg/String",
    JOINT_STATES_TOPIC: "sensor_msgs/msg/JointState",
}
_GOAL_TOPICS = {
    ARM_GOAL_TOPIC: "control_msgs/action/FollowJointTrajectory_Goal",
    GRIPPER_GOAL_TOPIC: "control_msgs/action/GripperCommand_Goal",
}


@dataclass(frozen=True)
class BagMessage:
    """One message read from a bag.

    Attributes:
        topic: Topic name.
        timestamp: Log time [ns].
        msg: The deserialised message (rosbags class).
    """

    topic: str
    timestamp: int
    msg: Any


@dataclass(frozen=True)
class BagContents:
    """Everything in a bag, in log-time order.

    Attributes:
        topics: Message type of each topic.
        messages: The messages.
    """

    topics: dict[str, str]
    messages: tuple[BagMessage, ...] = field(repr=False)

    def on(self, topic: str) -> list[BagMessage]:
        """The messages of one topic, in log-time order."""
        return [m for m in self.messages if m.topic == topic]


def _string(data: dict[str, Any]) -> Any:
    return written_typestore().types["std_msgs/msg/String"](data=json.dumps(data, sort_keys=True))


def _gripper_positions(trajs: Sequence[Trajectory], starts_ns: Sequence[int],
                       spec: ControllerSpec, times: np.ndarray) -> np.ndarray | None:
    """The gripper joint's position at ``times`` [ns from the cycle's start]: the open or
    closed position of the last gripper event at or before each time; before the first
    event, the other one (the gripper changes at each event). None for a cycle without
    gripper events (nothing says whether the gripper is open)."""
    assert spec.gripper is not None
    grip = spec.gripper
    where = {"open": grip.open_position, "close": grip.closed_position}
    changes = sorted((start + round((e.time - traj.t[0]) * _NS), where[e.action])
                     for traj, start in zip(trajs, starts_ns, strict=True) for e in traj.events)
    if not changes:
        return None
    first = grip.closed_position if changes[0][1] == grip.open_position else grip.open_position
    values = np.array([first] + [v for _, v in changes])
    return values[np.searchsorted([t for t, _ in changes], times, side="right")]


def _locked_states(locked: Sequence[LockedJoint], names: tuple[str, ...], spec: ControllerSpec,
                   fingers: np.ndarray | None, size: int) -> dict[str, np.ndarray]:
    """The positions ``/joint_states`` gives the joints outside ``names``, at each of
    ``size`` times: the gripper joint of ``spec`` from its events (``fingers``), every
    locked joint at its value, a mimic joint following its driver; a joint locked over
    its whole travel (no value) that no gripper event places has no position and is left
    out (logged)."""
    out: dict[str, np.ndarray] = {}
    grip = spec.gripper.joint if spec.gripper is not None else None
    if fingers is not None and grip is not None:
        out[grip] = fingers
    unplaced = []
    for joint in locked:
        if joint.name in names or joint.name in out:
            continue
        if joint.value is not None:
            out[joint.name] = np.full(size, joint.value)
        elif joint.follows is not None and joint.follows[0] in out:
            driver, multiplier, offset = joint.follows
            out[joint.name] = out[driver] * multiplier + offset
        else:
            unplaced.append(joint.name)
    if unplaced:
        logger.warning("/joint_states leaves out %s: locked over their whole travel, they "
                       "have no position (give them a value in locked_joints)", unplaced)
    return out


def _joint_states(trajs: Sequence[Trajectory], starts_ns: Sequence[int], total_ns: int,
                  rate: float, names: tuple[str, ...], start_time_ns: int,
                  spec: ControllerSpec, locked: Sequence[LockedJoint]
                  ) -> list[tuple[int, bytes]]:
    """``/joint_states`` every 1/``rate`` over the whole cycle, from the true motion; with
    the gripper joint of ``spec``'s ``gripper`` section and the robot's ``locked`` joints
    (:func:`_locked_states`: RViz draws the fingers from them): (stamp [ns], CDR bytes)."""
    step_ns = round(_NS / rate)
    times = np.arange(0, total_ns + step_ns, step_ns, dtype=np.int64)
    which = interval_index(np.asarray(starts_ns), times, len(trajs))
    fingers = _gripper_positions(trajs, starts_ns, spec, times) \
        if spec.gripper is not None and spec.gripper.joint not in names else None
    held = _locked_states(locked, names, spec, fingers, times.size)
    all_names = [*names, *held]
    held_q = np.column_stack([*held.values()]) if held else np.zeros((times.size, 0))
    out: list[tuple[int, bytes]] = []
    for k, traj in enumerate(trajs):
        mine = times[which == k]
        if mine.size == 0:
            continue
        cols = [traj.joint_names.index(n) for n in names]
        q, qd, _ = traj.sample(traj.t[0] + (mine - starts_ns[k]) / _NS)
        q = np.column_stack([q[:, cols], held_q[which == k]])
        qd = np.column_stack([qd[:, cols], np.zeros((mine.size, len(held)))])
        stamps = start_time_ns + mine
        out.extend(zip(stamps.tolist(), joint_states_cdr(stamps, all_names, q, qd),
                       strict=True))
    return out


def _serialized(msg: Any, typename: str) -> bytes:
    """The CDR bytes of a record's message (kept as bytes already, or rosbags')."""
    return msg if isinstance(msg, bytes) else serialize(msg, typename)


def _check_joins(trajs: Sequence[Trajectory], names: tuple[str, ...]) -> None:
    for k in range(1, len(trajs)):
        prev, cur = trajs[k - 1], trajs[k]
        end = prev.q[-1, [prev.joint_names.index(n) for n in names]]
        start = cur.q[0, [cur.joint_names.index(n) for n in names]]
        jump = float(np.max(np.abs(end - start)))
        if not jump <= JOIN_TOLERANCE:
            raise TrajectoryError(f"route '{cur.route}' starts {jump:.4g} rad away from where "
                                  f"'{prev.route}' ends: not one cycle", key=f"trajectories[{k}]")


def _cycle_records(trajs: Sequence[Trajectory], names: tuple[str, ...], period: float,
                   spec: ControllerSpec, start_time_ns: int, goals: bool
                   ) -> tuple[list[tuple[int, int, str, Any]], list[int], int]:
    """Messages of the trajectories back to back: (time [ns], order, topic, message), the
    start of each trajectory and the end of the cycle [ns from its start].

    Each trajectory runs as a node runs it (:func:`split_at_gripper_events`): one
    ``JointTrajectory`` (and goal) per motion between gripper events, each event at the
    end of the motion before it."""
    records: list[tuple[int, int, str, Any]] = []  # (time [ns], order, topic, message)
    starts_ns: list[int] = []
    clock_ns = 0
    for traj in trajs:
        starts_ns.append(clock_ns)
        records.append((start_time_ns + clock_ns, 1, ROUTE_TOPIC, _string(
            {"route": traj.route, "robot": traj.robot, "duration": traj.duration,
             "steps": traj.step_durations()})))
        for part in split_at_gripper_events(traj):
            t_ns = start_time_ns + clock_ns
            if isinstance(part, GripperEvent):
                records.append((t_ns, 2, GRIPPER_TOPIC,
                                _string({"route": traj.route, "time": part.time,
                                         "action": part.action, "step": part.step,
                                         "object": part.object})))
                if goals and spec.gripper is not None:
                    records.append((t_ns, 2, GRIPPER_GOAL_TOPIC, gripper_command_goal(
                        spec, part.action, backend="rosbags")))
                continue
            data, last_ns = _joint_trajectory_cdr(part, period=period,
                                                  robot_joint_names=names, stamp_ns=t_ns)
            records.append((t_ns, 0, TRAJECTORY_TOPIC, data))
            if goals:
                records.append((t_ns, 1, ARM_GOAL_TOPIC, follow_joint_trajectory_goal(
                    part, period=period, robot_joint_names=names, controller=spec,
                    backend="rosbags")))
            clock_ns += last_ns
    return records, starts_ns, clock_ns


def write_bag(path: str | Path, trajectories: Iterable[Trajectory], *,
              joint_state_rate: float | None = None, period: float | None = None,
              robot_joint_names: Sequence[str] | None = None,
              controller: ControllerSpec | None = None,
              start_time_ns: int | None = None, goals: bool = False,
              locked_joints: Sequence[LockedJoint] = ()) -> Path:
    """Write a ROS 2 bag (MCAP) of a cycle; see the module docstring for its layout.

    Each trajectory starts where the previous one ends, on one clock from
    ``start_time_ns``; ``/joint_states`` samples the motion every 1/``joint_state_rate``
    from the cycle's start to its end (the last sample at or just after the end holds
    the final pose). The bag is written to a temporary folder next to ``path`` and
    renamed at the end: ``path`` is either the whole bag or absent.

    Args:
        path: The bag folder to create (must not exist).
        trajectories: The cycle's trajectories, in execution order.
        joint_state_rate: ``/joint_states`` rate [Hz]; default: the controller's (the
            Ned publishes at 50 Hz).
        period: Point spacing of the ``JointTrajectory`` messages [s]; default: the
            controller's.
        robot_joint_names: The controller's joint names; default: the controller's.
        controller: The robot's trajectory controller; default: the one of the robot
            the first trajectory names (see :func:`safepath.ros.goals.controller_of`).
        start_time_ns: Clock time of the cycle's start [ns since the epoch]; default:
            now (a bag stamped from 0 would read as 1970).
        goals: Also write the arm's ``FollowJointTrajectory`` goals and, for a robot with
            a ``gripper`` section in its ``controller.yaml``, the ``GripperCommand`` goals
            of its gripper events.
        locked_joints: The robot's locked joints (:attr:`safepath.Robot.locked_joints`,
            a gripper's): ``/joint_states`` gives each its locked value (a mimic joint
            its driver's, mapped); one locked over its whole travel has no value and is
            left out unless it is, or mimics, the gripper joint that gripper events place.

    Returns:
        ``path``.

    Raises:
        TrajectoryError: No trajectories, a bad trajectory, consecutive trajectories that
            do not join, or a bad rate or period.
        RosError: ``path`` exists or the bag cannot be written.
    """
    path = Path(path)
    trajs = list(trajectories)
    if start_time_ns is None:
        start_time_ns = time.time_ns()
    if isinstance(start_time_ns, bool) or not isinstance(start_time_ns, (int, np.integer)) \
            or not 0 <= start_time_ns < 2**31 * _NS:
        raise TrajectoryError(f"expected an integer >= 0 [ns since the epoch] whose seconds "
                              f"fit a ROS 2 Time (< 2^31), got {start_time_ns!r}",
                              key="start_time_ns")
    start_time_ns = int(start_time_ns)
    if not trajs:
        raise TrajectoryError("no trajectories to write", key="trajectories")
    spec = controller_of(trajs[0], controller)
    if joint_state_rate is None:
        joint_state_rate = spec.joint_state_rate
    if isinstance(joint_state_rate, bool) or not isinstance(joint_state_rate, (int, float)) \
            or not math.isfinite(joint_state_rate) or not 0 < joint_state_rate <= 1e6:
        raise TrajectoryError(f"must be in (0, 1e6] [Hz], got {joint_state_rate!r}",
                              key="joint_state_rate")
    names = tuple(spec.joint_names if robot_joint_names is None else robot_joint_names)
    period = spec.period if period is None else period

    # Build (and so validate) every message before touching the file system.
    records, starts_ns, clock_ns = _cycle_records(trajs, names, period, spec, start_time_ns,
                                                  goals)
    _check_joins(trajs, names)
    records += [(t, 3, JOINT_STATES_TOPIC, m) for t, m in
                _joint_states(trajs, starts_ns, clock_ns, joint_state_rate, names,
                              start_time_ns, spec, locked_joints)]
    records.sort(key=lambda r: (r[0], r[1]))

    if path.exists():
        raise RosError(f"{path} exists already, not overwriting")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp_root = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp",
                                         dir=path.parent))
    except OSError as exc:
        raise RosError(f"cannot write bag {path}: {exc}") from None
    try:
        # Inside the temp folder the bag has its final name, so its .mcap file has too.
        tmp_bag = tmp_root / path.name
        with Writer(tmp_bag, version=Writer.VERSION_LATEST,
                    storage_plugin=StoragePlugin.MCAP) as writer:
            types = {**_TOPICS, **(_GOAL_TOPICS if goals else {})}
            if spec.gripper is None:
                types.pop(GRIPPER_GOAL_TOPIC, None)
            conns = {topic: writer.add_connection(topic, msgtype,
                                                  typestore=written_typestore())
                     for topic, msgtype in types.items()}
            for time_ns, _, topic, msg in records:
                writer.write(conns[topic], time_ns, _serialized(msg, types[topic]))
        os.rename(tmp_bag, path)
    except (WriterError, OSError) as exc:
        raise RosError(f"cannot write bag {path}: {exc}") from None
    finally:
        shutil.rmtree(tmp_root, ignore_errors=True)
    logger.info("wrote %s: %d trajectories, %.3f s, %d messages", path, len(trajs),
                clock_ns / _NS, len(records))
    return path


def read_bag(path: str | Path) -> BagContents:
    """Read every message of a ROS 2 bag (any storage) with the safepath type store.

    Returns:
        A :class:`BagContents`: ``topics`` (message type by topic) and ``messages``, each
        a :class:`BagMessage` with ``topic``, ``timestamp`` (log time [ns]) and ``msg``
        (the deserialised ``rosbags`` message: ``msg.points``, ``msg.header.stamp``, ...);
        ``contents.on(topic)`` lists one topic's messages in log-time order.

    Raises:
        RosError: No bag at ``path``, a corrupt bag, or a type the store does not know.
    """
    path = Path(path)
    try:
        with Reader(path) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            messages = tuple(BagMessage(conn.topic, timestamp, deserialize(raw, conn.msgtype))
                             for conn, timestamp, raw in reader.messages())
    except (ReaderError, OSError) as exc:
        raise RosError(f"cannot read bag {path}: {exc}") from None
    return BagContents(topics, messages)
