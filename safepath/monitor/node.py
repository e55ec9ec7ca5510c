"""The monitor node's logic without ROS: lifecycle, parameters, scans in, goals out.

``examples/ros2/monitor_node.py`` wires :class:`MonitorNodeCore` to a ROS 2 lifecycle
node as the fourth brief recommends: *configure* loads the cell, validates the
parameters (a ``ros__parameters`` YAML file) and warms the runtime planner; *activate*
starts the motion; *deactivate* stops it along its path (a stop replacement, not a
latched kill). Sensor data come on a best-effort QoS (the newest scan matters, a lost
one is covered by the silence rule); decisions and goals go reliable.

Every callback returns :class:`Command` s for the node to execute, so the whole logic
is tested here with real messages (rosbags) and real trajectories.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import ConfigError
from ..scene import placement
from ..trajectory import GripperEvent, Trajectory
from .monitor import Decision, Monitor, ReplanRequest
from .options import MonitorOptions

__all__ = ["NodeParameters", "load_node_parameters", "MonitorNodeCore", "SendGoal",
           "Publish", "Gripper", "Replan", "NODE_NAME"]

NODE_NAME = "safepath_monitor"
_LIFECYCLE = Literal["unconfigured", "inactive", "active"]


@dataclass(frozen=True, kw_only=True)
class NodeParameters:
    """The node's parameters (``ros__parameters`` of :data:`NODE_NAME`).

    Attributes:
        scene: Scene folder of the cell.
        route: Route to run on activation.
        scan_topic: LaserScan topic (best effort).
        scan_frame: The scan's frame id.
        scan_xyz: Sensor position in the world [m].
        scan_rpy: Sensor orientation (roll, pitch, yaw) [rad].
        decision_topic: Where decisions are published (reliable).
        replan_margin: Clearance a re-planned path keeps from the obstacle's box [m].
        options: The monitor's options (from the remaining keys).
    """

    scene: str
    route: str = "phase1"
    scan_topic: str = "/scan"
    scan_frame: str = "laser"
    scan_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scan_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    decision_topic: str = "/safepath/monitor/decision"
    replan_margin: float = 0.03
    options: MonitorOptions = field(default_factory=MonitorOptions)


_NODE_NUMBERS = ("replan_margin",)
_OPTION_KEYS = ("approach_speed", "min_separation", "sensor_uncertainty", "robot_uncertainty",
                "stale_after", "command_latency", "hold_time", "replan_after", "min_scale",
                "horizon")


def parameters_from_mapping(raw: Mapping[str, Any], *, path: Path | None = None
                            ) -> NodeParameters:
    """Validate a ``ros__parameters`` mapping (as ``rclpy`` gives it, or from YAML).

    Raises:
        ConfigError: An unknown key, a missing ``scene``, or a value of the wrong type
            or range (names the file and the key).
    """
    known = {"scene", "route", "scan_topic", "scan_frame", "scan_xyz", "scan_rpy",
             "decision_topic", *_OPTION_KEYS, *_NODE_NUMBERS}
    for key in raw:
        if key not in known:
            raise ConfigError(f"unknown parameter (known: {', '.join(sorted(known))})",
                              path=path, key=key)
    if "scene" not in raw:
        raise ConfigError("missing", path=path, key="scene")
    strings = {k: raw[k] for k in ("scene", "route", "scan_topic", "scan_frame",
                                   "decision_topic") if k in raw}
    for k, v in strings.items():
        if not isinstance(v, str) or not v:
            raise ConfigError(f"must be a non-empty string, got {v!r}", path=path, key=k)
    vectors = _vectors(raw, path)
    numbers = _numbers(raw, path)
    frame = strings.get("scan_frame", "laser")
    xyz = vectors.get("scan_xyz", (0.0, 0.0, 0.0))
    rpy = vectors.get("scan_rpy", (0.0, 0.0, 0.0))
    margin = numbers.pop("replan_margin", 0.03)
    if not (np.isfinite(margin) and margin >= 0):
        raise ConfigError(f"must be >= 0 [m], got {margin}", path=path, key="replan_margin")
    try:
        options = MonitorOptions(sensors={frame: placement(xyz, rpy)}, **numbers)  # type: ignore[arg-type]
    except ConfigError as exc:
        raise ConfigError(exc.reason, path=path, key=exc.key) from None
    return NodeParameters(options=options, scan_xyz=xyz, scan_rpy=rpy, replan_margin=margin,
                          **strings)


def _vectors(raw: Mapping[str, Any], path: Path | None
             ) -> dict[str, tuple[float, float, float]]:
    """The scanner placement parameters given, each 3 finite numbers."""
    vectors: dict[str, tuple[float, float, float]] = {}
    for k in ("scan_xyz", "scan_rpy"):
        if k in raw:
            v = raw[k]
            if not isinstance(v, (list, tuple)) or len(v) != 3 or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool)
                    and np.isfinite(x) for x in v):
                raise ConfigError(f"must be 3 finite numbers, got {v!r}", path=path, key=k)
            vectors[k] = (float(v[0]), float(v[1]), float(v[2]))
    return vectors


def _numbers(raw: Mapping[str, Any], path: Path | None) -> dict[str, float]:
    """The numeric parameters given (monitor options and the node's own)."""
    numbers: dict[str, float] = {}
    for k in (*_OPTION_KEYS, *_NODE_NUMBERS):
        if k in raw:
            v = raw[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"must be a number, got {v!r}", path=path, key=k)
            numbers[k] = float(v)
    return numbers


def load_node_parameters(path: str | Path, node: str = NODE_NAME) -> NodeParameters:
    """Read ``<node>: ros__parameters:`` from a ROS 2 parameter file.

    Raises:
        ConfigError: Missing file, node or ``ros__parameters``, or a bad parameter.
    """
    from .._io import read_yaml

    path = Path(path)
    data = read_yaml(path)
    section = data.get(node) if isinstance(data, dict) else None
    if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
        raise ConfigError(f"expected '{node}: ros__parameters:'", path=path, key=node)
    return parameters_from_mapping(section["ros__parameters"], path=path)


@dataclass(frozen=True)
class SendGoal:
    """Send this trajectory as a FollowJointTrajectory goal (replaces the running one)."""

    trajectory: Trajectory
    reason: str


@dataclass(frozen=True)
class Publish:
    """Publish this decision (reliable)."""

    decision: Decision


@dataclass(frozen=True)
class Gripper:
    """Run this gripper action (the arm is at rest at the end of a motion)."""

    event: GripperEvent


@dataclass(frozen=True)
class Replan:
    """Plan the rest of the route around an obstacle (off the callback thread: call
    :func:`safepath.monitor.replan.replan` with these, then
    :meth:`MonitorNodeCore.on_replanned`)."""

    request: ReplanRequest
    route: str
    held: str | None
    margin: float


Command = SendGoal | Publish | Gripper | Replan


class MonitorNodeCore:
    """The lifecycle and callbacks of the monitor node, ROS-free.

    Args:
        parameters: Validated parameters.
    """

    def __init__(self, parameters: NodeParameters) -> None:
        self.parameters = parameters
        self.state: _LIFECYCLE = "unconfigured"
        self.monitor: Monitor | None = None
        self.sequence: list[Trajectory | GripperEvent] = []
        self.motions: list[tuple[Trajectory, str | None]] = []
        self._next = 0
        self._held: str | None = None
        self._started = False
        self._held_back = False  # a part completed while the kill was latched

    def configure(self, *, planner: Any = None) -> None:
        """Load the cell, build the monitor, plan the route (with ``planner``, a
        :class:`~safepath.runtime.RuntimePlanner`, when given: it warms it too).

        Raises:
            SafepathError: A bad cell or route, or a planning failure.
        """
        from .. import load_cell, plan_cell
        from ..ros.goals import split_at_gripper_events

        p = self.parameters
        cell = load_cell(p.scene)
        if planner is not None:
            traj = planner.plan_route(p.route).result()
        else:
            routes = cell.route_table()
            if p.route not in routes:
                raise ConfigError(f"unknown route (routes: {', '.join(routes)})",
                                  key="route")
            traj = plan_cell(cell, routes={p.route: routes[p.route]})[p.route]
        self.sequence = split_at_gripper_events(traj)
        held: str | None = None
        self.motions = []
        for part in self.sequence:
            if isinstance(part, Trajectory):
                self.motions.append((part, held))
            else:
                held = part.object if part.action == "close" else None
        self.monitor = Monitor(cell, p.options)
        self._next, self._held, self._started = 0, None, False
        self.state = "inactive"

    def activate(self, now: float) -> list[Command]:
        """Start the route (the first time), or release the stop of a deactivation
        (motion resumes by the hold-time rule)."""
        if self.state != "inactive" or self.monitor is None:
            raise ConfigError(f"cannot activate from state '{self.state}'", key="lifecycle")
        self.state = "active"
        if self._started:
            self.monitor.reset()
            return []
        self._started = True
        return self._advance(now)

    def deactivate(self, now: float) -> list[Command]:
        """Stop along the path, latched until the next activation."""
        if self.state != "active" or self.monitor is None:
            raise ConfigError(f"cannot deactivate from state '{self.state}'",
                              key="lifecycle")
        self.state = "inactive"
        return self._commands(self.monitor.kill(now))

    def kill(self, now: float) -> list[Command]:
        """Kill switch: stop along the path, latched until :meth:`reset`."""
        if self.monitor is None:
            return []
        return self._commands(self.monitor.kill(now))

    def reset(self) -> None:
        """Release the kill switch (motion resumes by the hold-time rule)."""
        if self.monitor is not None:
            self.monitor.reset()

    def on_scan(self, msg: Any, now: float) -> list[Command]:
        """A LaserScan arrived (ignored unless active).

        Raises:
            ObservationError: A malformed scan (the last decision stands).
        """
        if self.state != "active" or self.monitor is None:
            return []
        return self._commands(self.monitor.observe(msg, now))

    def on_tick(self, now: float) -> list[Command]:
        """Timer: silence must stop the robot even without callbacks."""
        if self.state != "active" or self.monitor is None:
            return []
        out = self._commands(self.monitor.tick(now))
        if self._held_back and not self.monitor.last.latched:
            self._held_back = False
            out += self._advance(now)
        return out

    def on_motion_done(self, now: float) -> list[Command]:
        """The latest goal succeeded and the monitor's motion is complete: the next
        gripper action or motion. While the kill switch is latched nothing starts (a kill
        just before a motion's end must not be followed by the next action); the next
        part waits for :meth:`reset`, and the first tick after it starts it."""
        if self.state != "active":
            return []
        if self.monitor is not None and self.monitor.last.latched:
            self._held_back = True
            return []
        return self._advance(now)

    def on_gripper_done(self, now: float) -> list[Command]:
        """The gripper action finished: the next motion."""
        return self.on_motion_done(now)

    def on_replanned(self, request: ReplanRequest, traj: Trajectory, now: float
                     ) -> list[Command]:
        """A re-plan finished: its box joins the static scene, the new route replaces the
        rest of the old one, its first part starts."""
        from ..ros.goals import split_at_gripper_events

        if self.state != "active" or self.monitor is None:
            return []
        if self.monitor.last.scale > 0.0:
            # The obstacle left while the re-plan ran and the robot moves on along the old
            # path: a motion planned from the rest state would start from a moving robot.
            return []
        self.monitor.add_static_box(request.obstacle_center, request.obstacle_size)
        self.sequence = split_at_gripper_events(traj)
        self._next = 0
        return self._advance(now)

    def on_replan_failed(self, request: ReplanRequest, reason: str, now: float
                         ) -> list[Command]:
        """A re-plan found no way (``reason``: the planner's why, e.g. the
        ``PlanningError``'s message): the robot stays stopped, its decisions say why, and
        the monitor asks again once the obstacle has moved
        (:meth:`safepath.monitor.Monitor.replan_failed`)."""
        if self.state == "active" and self.monitor is not None:
            self.monitor.replan_failed(request, reason)
        return []

    def _advance(self, now: float) -> list[Command]:
        assert self.monitor is not None
        if self._next >= len(self.sequence):
            return []
        part = self.sequence[self._next]
        self._next += 1
        if isinstance(part, GripperEvent):
            self._held = part.object if part.action == "close" else None
            return [Gripper(part)]
        self.monitor.follow(part, start=now, held=self._held)
        return [SendGoal(part, "next motion")]

    def _commands(self, decision: Decision) -> list[Command]:
        out: list[Command] = [Publish(decision)]
        if decision.replacement is not None:
            out.append(SendGoal(decision.replacement, decision.kind))
        if decision.replan is not None:
            out.append(Replan(decision.replan, self.parameters.route, self._held,
                              self.parameters.replan_margin))
        return out
