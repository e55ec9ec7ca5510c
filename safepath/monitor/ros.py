"""ROS 2 messages of the monitor, and MCAP bags of its runs (``rosbags``, no ROS needed).

A monitor bag records what the monitor saw and decided, on one clock:

=================================  ==================================  =========================
topic                              type                                one message
=================================  ==================================  =========================
``/safepath/monitor/config``       ``std_msgs/msg/String`` (JSON)      at the start: sensor
                                                                       poses, protective-
                                                                       distance parameters
``<sensor topic>``                 ``sensor_msgs/msg/LaserScan`` or    per observation, at its
                                   ``sensor_msgs/msg/PointCloud2``     delivery (stamp inside)
``/safepath/monitor/decision``     ``std_msgs/msg/String`` (JSON)      per decision
``/safepath/monitor/replacement``  ``trajectory_msgs/msg/JointTrajectory``  per replacement goal
``/safepath/monitor/goal``         ``trajectory_msgs/msg/JointTrajectory``  per motion sent whole
``/joint_states``                  ``sensor_msgs/msg/JointState``      the robot's state
``/safepath/monitor/truth``        ``std_msgs/msg/String`` (JSON)      simulations only: the
                                                                       obstacle's true centre
=================================  ==================================  =========================

:func:`read_monitor_bag` turns one back into arrays for the replay in the review page
(:mod:`safepath.view.monitor_replay`).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RosError
from ..model.trajectory import Trajectory
from .monitor import Decision
from .observations import Cloud, Scan
from .options import MonitorOptions

__all__ = ["MonitorRecorder", "MonitorRun", "read_monitor_bag", "decision_dict",
           "scan_message", "cloud_message", "CONFIG_TOPIC", "DECISION_TOPIC",
           "REPLACEMENT_TOPIC", "GOAL_TOPIC", "TRUTH_TOPIC", "JOINT_STATES_TOPIC"]

CONFIG_TOPIC = "/safepath/monitor/config"
DECISION_TOPIC = "/safepath/monitor/decision"
REPLACEMENT_TOPIC = "/safepath/monitor/replacement"
GOAL_TOPIC = "/safepath/monitor/goal"
TRUTH_TOPIC = "/safepath/monitor/truth"
JOINT_STATES_TOPIC = "/joint_states"
_NS = 1_000_000_000
_SCAN, _CLOUD = "sensor_msgs/msg/LaserScan", "sensor_msgs/msg/PointCloud2"
_STRING = "std_msgs/msg/String"


def _ts() -> Any:
    from ..ros.messages import typestore

    return typestore()


def _header(stamp: float, frame: str) -> Any:
    T = _ts().types  # noqa: N806
    sec = math.floor(stamp)
    nsec = min(round((stamp - sec) * _NS), _NS - 1)
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec,
                                                                           nanosec=nsec),
                                    frame_id=frame)


def scan_message(scan: Scan) -> Any:
    """``sensor_msgs/msg/LaserScan`` (rosbags) of a :class:`Scan`."""
    n = scan.ranges.size
    return _ts().types[_SCAN](
        header=_header(scan.stamp, scan.frame_id), angle_min=scan.angle_min,
        angle_max=scan.angle_min + max(n - 1, 0) * scan.angle_increment,
        angle_increment=scan.angle_increment, time_increment=0.0, scan_time=0.0,
        range_min=scan.range_min, range_max=scan.range_max,
        ranges=scan.ranges.astype(np.float32), intensities=np.zeros(0, dtype=np.float32))


def cloud_message(cloud: Cloud) -> Any:
    """``sensor_msgs/msg/PointCloud2`` (rosbags, float32 x/y/z, 12-byte points) of a
    :class:`Cloud`."""
    T = _ts().types  # noqa: N806
    fields = [T["sensor_msgs/msg/PointField"](name=c, offset=4 * k, datatype=7, count=1)
              for k, c in enumerate("xyz")]
    n = len(cloud.points)
    data = np.ascontiguousarray(cloud.points, dtype="<f4").view(np.uint8).ravel()
    return T[_CLOUD](header=_header(cloud.stamp, cloud.frame_id), height=1, width=n,
                     fields=fields, is_bigendian=False, point_step=12, row_step=12 * n,
                     data=data, is_dense=not np.isnan(cloud.points).any())


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def decision_dict(d: Decision) -> dict[str, Any]:
    """A decision as JSON-compatible data (infinite separations as None)."""
    return {
        "time": d.time, "kind": d.kind, "reason": d.reason, "scale": d.scale,
        "separation_now": _finite_or_none(d.separation_now),
        "separation_path": _finite_or_none(d.separation_path),
        "protective_distance": d.protective_distance,
        "separation_kept": _finite_or_none(d.separation_kept),
        "stopping_time": d.stopping_time, "stopping_distance": d.stopping_distance,
        "replacement_start": d.replacement_start,
        "replacement_duration": d.replacement.duration if d.replacement else None,
        "replan": None if d.replan is None else {
            "q": d.replan.q.tolist(), "step": d.replan.step,
            "obstacle_center": d.replan.obstacle_center.tolist(),
            "obstacle_size": d.replan.obstacle_size.tolist()},
        "counts": dict(d.counts.__dict__),
        "closest": None if d.closest is None else d.closest.tolist(),
        "latched": d.latched, "elapsed": d.elapsed,
    }


def _string(data: dict[str, Any]) -> Any:
    return _ts().types[_STRING](data=json.dumps(data))


@dataclass
class MonitorRecorder:
    """Collects a run's messages; :meth:`write` puts them in an MCAP bag.

    Args:
        options: The monitor's options (sensor poses and parameters go in the config).
        joint_names: The robot's joint names.
        topics: Topic of each sensor frame (default ``/<frame>``).
    """

    options: MonitorOptions
    joint_names: Sequence[str]
    topics: dict[str, str] = field(default_factory=dict)
    _records: list[tuple[int, int, str, str, Any]] = field(default_factory=list, repr=False)

    def _add(self, time: float, order: int, topic: str, typename: str, msg: Any) -> None:
        if not math.isfinite(time) or time < 0:
            raise RosError(f"bag times must be finite and >= 0 [s], got {time}")
        self._records.append((round(time * _NS), order, topic, typename, msg))

    def observation(self, time: float, obs: Scan | Cloud) -> None:
        """An observation delivered to the monitor at ``time`` [s]."""
        topic = self.topics.get(obs.frame_id, f"/{obs.frame_id}")
        if isinstance(obs, Scan):
            self._add(time, 1, topic, _SCAN, scan_message(obs))
        else:
            self._add(time, 1, topic, _CLOUD, cloud_message(obs))

    def decision(self, d: Decision) -> None:
        """A decision (and its replacement goal, if any)."""
        self._add(d.time, 2, DECISION_TOPIC, _STRING, _string(decision_dict(d)))
        if d.replacement is not None and d.replacement_start is not None:
            from ..ros.goals import joint_trajectory

            msg = joint_trajectory(d.replacement, robot_joint_names=list(self.joint_names),
                                   stamp_ns=round(d.replacement_start * _NS),
                                   backend="rosbags")
            self._add(d.time, 3, REPLACEMENT_TOPIC, "trajectory_msgs/msg/JointTrajectory",
                      msg)

    def goal(self, time: float, traj: Trajectory, start: float) -> None:
        """A motion sent whole as a goal at ``time`` [s], stamped ``start`` (the
        verified motions the monitor follows; its replacements come with
        :meth:`decision`)."""
        from ..ros.goals import joint_trajectory

        msg = joint_trajectory(traj, robot_joint_names=list(self.joint_names),
                               stamp_ns=round(start * _NS), backend="rosbags")
        self._add(time, 3, GOAL_TOPIC, "trajectory_msgs/msg/JointTrajectory", msg)

    def joint_state(self, time: float, q: np.ndarray, qd: np.ndarray) -> None:
        """The robot's state at ``time`` [s]."""
        T = _ts().types  # noqa: N806
        msg = T["sensor_msgs/msg/JointState"](
            header=_header(time, ""), name=list(self.joint_names),
            position=np.asarray(q, dtype=float), velocity=np.asarray(qd, dtype=float),
            effort=np.zeros(0))
        self._add(time, 4, JOINT_STATES_TOPIC, "sensor_msgs/msg/JointState", msg)

    def truth(self, time: float, center: np.ndarray, radius: float) -> None:
        """The true obstacle (simulations)."""
        self._add(time, 5, TRUTH_TOPIC, _STRING,
                  _string({"center": [float(v) for v in center], "radius": radius}))

    def write(self, path: str | Path) -> Path:
        """Write the bag (atomically: the folder appears complete or not at all).

        Raises:
            RosError: ``path`` exists or cannot be written.
        """
        from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

        from ..ros.messages import serialize

        path = Path(path)
        if path.exists():
            raise RosError(f"{path} exists already, not overwriting")
        o = self.options
        config = {"sensors": {k: np.asarray(v).tolist() for k, v in o.sensors.items()},
                  "topics": {f: self.topics.get(f, f"/{f}") for f in o.sensors},
                  "approach_speed": o.approach_speed, "min_separation": o.min_separation,
                  "sensor_uncertainty": o.sensor_uncertainty,
                  "robot_uncertainty": o.robot_uncertainty, "stale_after": o.stale_after,
                  "command_latency": o.command_latency}
        start = min((r[0] for r in self._records), default=0)
        records = [(start, 0, CONFIG_TOPIC, _STRING, _string(config)), *self._records]
        records.sort(key=lambda r: (r[0], r[1]))
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp_root = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp",
                                         dir=path.parent))
        try:
            tmp_bag = tmp_root / path.name
            with Writer(tmp_bag, version=Writer.VERSION_LATEST,
                        storage_plugin=StoragePlugin.MCAP) as writer:
                conns: dict[str, Any] = {}
                for time_ns, _, topic, typename, msg in records:
                    if topic not in conns:
                        conns[topic] = writer.add_connection(topic, typename, typestore=_ts())
                    writer.write(conns[topic], time_ns, serialize(msg, typename))
            os.rename(tmp_bag, path)
        except (WriterError, OSError) as exc:
            raise RosError(f"cannot write bag {path}: {exc}") from None
        finally:
            shutil.rmtree(tmp_root, ignore_errors=True)
        return path


@dataclass(frozen=True)
class MonitorRun:
    """A recorded run, as arrays.

    Attributes:
        sensors: World pose of each sensor frame (4x4).
        parameters: The protective-distance parameters recorded.
        observation_times: Delivery time of each observation [s].
        observation_stamps: Capture time (header stamp) of each observation [s].
        observations: World points of each observation (n, 3) [m] (valid readings).
        decisions: Each decision as :func:`decision_dict` gives it.
        joint_times: Times of the robot states [s].
        joint_positions: Robot states (n, dof) [rad].
        truth: (time [s], centre (3,) [m], radius [m]) of the true obstacle, if recorded.
    """

    sensors: dict[str, np.ndarray]
    parameters: dict[str, Any]
    observation_times: np.ndarray
    observation_stamps: np.ndarray
    observations: list[np.ndarray]
    decisions: list[dict[str, Any]]
    joint_times: np.ndarray
    joint_positions: np.ndarray
    truth: list[tuple[float, np.ndarray, float]]


def read_monitor_bag(path: str | Path) -> MonitorRun:
    """Read a bag written by :class:`MonitorRecorder`.

    Raises:
        RosError: Not a monitor bag (no config), or unreadable.
    """
    from ..ros.bag import read_bag

    contents = read_bag(path)
    config_msgs = contents.on(CONFIG_TOPIC)
    if not config_msgs:
        raise RosError(f"{path}: no {CONFIG_TOPIC} message: not a monitor bag")
    config = json.loads(config_msgs[0].msg.data)
    sensors = {k: np.asarray(v, dtype=float) for k, v in config["sensors"].items()}
    topic_frame = {t: f for f, t in config.get("topics", {}).items()}
    obs_t: list[float] = []
    stamps: list[float] = []
    obs: list[np.ndarray] = []
    for m in contents.messages:
        if m.topic not in topic_frame:
            continue
        msg = m.msg
        o: Scan | Cloud = Scan.from_ros(msg) if hasattr(msg, "ranges") else Cloud.from_ros(msg)
        P = o.points()[0] if isinstance(o, Scan) else o.valid_points()[0]  # noqa: N806
        T = sensors[o.frame_id]  # noqa: N806
        obs_t.append(m.timestamp / _NS)
        stamps.append(o.stamp)
        obs.append(P @ T[:3, :3].T + T[:3, 3])
    decisions = [json.loads(m.msg.data) for m in contents.on(DECISION_TOPIC)]
    js = contents.on(JOINT_STATES_TOPIC)
    truth = [(m.timestamp / _NS, np.asarray(json.loads(m.msg.data)["center"]),
              float(json.loads(m.msg.data)["radius"])) for m in contents.on(TRUTH_TOPIC)]
    return MonitorRun(sensors, config, np.array(obs_t), np.array(stamps), obs, decisions,
                      np.array([m.timestamp / _NS for m in js]),
                      np.array([np.asarray(m.msg.position) for m in js]).reshape(len(js), -1),
                      truth)
