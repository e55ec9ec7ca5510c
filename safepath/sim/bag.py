"""A ROS 2 bag (MCAP) of a twin's run: what the simulated robot did, and what it was told.

==============================  ==========================================  ====================
topic                           type                                        one message
==============================  ==========================================  ====================
``/joint_states``               ``sensor_msgs/msg/JointState``              per record (executed)
``/safepath/arm_goal``          ``control_msgs/action/FollowJointTrajectory_Goal``  per motion goal
``/safepath/tool_goal``         ``niryo_ned_ros2_interfaces/action/Tool_Goal``  per Niryo tool goal
``/safepath/gripper_goal``      ``control_msgs/action/GripperCommand_Goal``  per gripper goal
``/safepath/sim/events``        ``std_msgs/msg/String`` (JSON)              per cycle or fault
==============================  ==========================================  ====================

Stamps are the simulated clock from ``start_time_ns``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RosError

__all__ = ["RunRecord", "write_run_bag", "JOINT_STATES", "ARM_GOALS", "TOOL_GOALS", "GRIPPER_GOALS",
           "EVENTS"]

JOINT_STATES = "/joint_states"
ARM_GOALS = "/safepath/arm_goal"
TOOL_GOALS = "/safepath/tool_goal"
GRIPPER_GOALS = "/safepath/gripper_goal"
EVENTS = "/safepath/sim/events"
_TYPES = {
    JOINT_STATES: "sensor_msgs/msg/JointState",
    ARM_GOALS: "control_msgs/action/FollowJointTrajectory_Goal",
    TOOL_GOALS: "niryo_ned_ros2_interfaces/action/Tool_Goal",
    GRIPPER_GOALS: "control_msgs/action/GripperCommand_Goal",
    EVENTS: "std_msgs/msg/String",
}
_NS = 1_000_000_000
#: Message type of a recorded goal, by its kind.
_GOAL_TYPES = {"arm": _TYPES[ARM_GOALS], "tool": _TYPES[TOOL_GOALS],
               "gripper": _TYPES[GRIPPER_GOALS]}


@dataclass
class RunRecord:
    """What a twin's run keeps for its bag (``record=True``).

    Attributes:
        goals: ``(time [s], kind, goal message)``; kind ``arm``, ``tool`` or ``gripper``.
        events: ``(time [s], JSON-serialisable event)``: cycles, reports, faults, kills.
        time: Times of the executed joint states [s], shape (N,).
        q: Executed joint positions [rad], shape (N, dof).
        qd: Executed joint velocities [rad/s], shape (N, dof).
        joint_names: Joint order of the columns.
    """

    goals: list[tuple[float, str, Any]] = field(default_factory=list)
    events: list[tuple[float, dict[str, Any]]] = field(default_factory=list)
    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    qd: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    joint_names: tuple[str, ...] = ()

    def __getstate__(self) -> dict[str, Any]:
        """The record as pickled (a pool's worker sends it back with its run): the goal
        messages as CDR bytes, since rosbags makes their classes at run time and they
        do not pickle."""
        from ..ros.messages import serialize

        state = dict(self.__dict__)
        state["goals"] = [(t, kind, serialize(goal, _GOAL_TYPES[kind]))
                          for t, kind, goal in self.goals]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Inverse of :meth:`__getstate__`: the goals as messages again."""
        from ..ros.messages import deserialize

        state = dict(state)
        state["goals"] = [(t, kind, deserialize(raw, _GOAL_TYPES[kind]))
                          for t, kind, raw in state["goals"]]
        self.__dict__.update(state)


def write_run_bag(path: str | Path, record: RunRecord | None, *, start_time_ns: int = 0) -> Path:
    """Write the bag of a run recorded with ``record=True``.

    Args:
        path: The bag folder to create (must not exist).
        record: ``QualityCheckRun.record`` or ``PouringRun.record``.
        start_time_ns: Clock time of the run's start [ns].

    Raises:
        RosError: No record, ``path`` exists, or the bag cannot be written.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

    from ..ros.messages import serialize, typestore

    if record is None:
        raise RosError("the run kept no record: run it with record=True")
    path = Path(path)
    if path.exists():
        raise RosError(f"{path} exists already, not overwriting")
    types = typestore().types
    rows: list[tuple[int, int, str, Any]] = []

    def stamp(t: float) -> int:
        return start_time_ns + round(t * _NS)

    for t, q, qd in zip(record.time, record.q, record.qd, strict=True):
        ns = stamp(float(t))
        header = types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=ns // _NS, nanosec=ns % _NS),
            frame_id="")
        rows.append((ns, 2, JOINT_STATES, types["sensor_msgs/msg/JointState"](
            header=header, name=list(record.joint_names),
            position=np.asarray(q, dtype=np.float64), velocity=np.asarray(qd, dtype=np.float64),
            effort=np.zeros(0))))
    for t, kind, goal in record.goals:
        topic = {"arm": ARM_GOALS, "tool": TOOL_GOALS, "gripper": GRIPPER_GOALS}[kind]
        rows.append((stamp(t), 0, topic, goal))
    for t, event in record.events:
        rows.append((stamp(t), 1, EVENTS, types["std_msgs/msg/String"](
            data=json.dumps(event, sort_keys=True))))
    rows.sort(key=lambda r: (r[0], r[1]))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with Writer(path, version=Writer.VERSION_LATEST,
                    storage_plugin=StoragePlugin.MCAP) as writer:
            used = {r[2] for r in rows} | {JOINT_STATES, ARM_GOALS, EVENTS}
            conns = {topic: writer.add_connection(topic, msgtype, typestore=typestore())
                     for topic, msgtype in _TYPES.items() if topic in used}
            for ns, _, topic, msg in rows:
                writer.write(conns[topic], ns, serialize(msg, _TYPES[topic]))
    except (WriterError, OSError) as exc:
        raise RosError(f"cannot write bag {path}: {exc}") from None
    return path
