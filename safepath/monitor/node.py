"""The monitor node's logic without ROS: lifecycle, parameters, scans in, goals out.

``examples/ros2/monitor_node.py`` wires :class:`MonitorNodeCore` to a ROS 2 lifecycle
node as the fourth brief recommends: *configure* loads the cell, validates the
parameters (a ``ros__parameters`` YAML file) and warms the runtime planner; *activate*
starts the motion; *deactivate* stops it along its path (a stop replacement, not a
latched kill). Sensor data come on a best-effort QoS (the newest scan matters, a lost
one is covered by the silence rule); decisions and goals go reliable.

Every callback returns :class:`Command` s for the node to execute, so the whole logic
is tested here with real messages (rosbags) and real trajectories.

**One gate.** Every goal the core sends (a :class:`SendGoal` or a :class:`Gripper`) leaves
through one method, which refuses it while the monitor's kill switch is latched or the
node is not active, with a single exception: a replacement that brakes to rest (a stop,
the kill's own) always goes out. A refused goal is logged and kept in
:attr:`MonitorNodeCore.refused`; a refused step of the route (the next motion, a gripper
action, a re-plan's first motion) waits, and the first tick with the gate open starts it.

**The route moves on only at a path's end.** A motion goal that succeeds because a stop
brought the arm to rest mid-path does not advance the route (:meth:`Monitor.at_end`): the
monitor resumes the motion by its hold-time rule (a ``resume`` replacement), and the goal
that reaches the end of the path moves the route on.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import ConfigError
from ..model.scene import placement
from ..model.trajectory import GripperEvent, Trajectory
from .monitor import Decision, Monitor, ReplanRequest
from .options import MonitorOptions

__all__ = ["NodeParameters", "load_node_parameters", "MonitorNodeCore", "SendGoal",
           "Publish", "Gripper", "Replan", "Refusal", "Command", "NODE_NAME"]

log = logging.getLogger(__name__)

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
                "horizon", "parked_speed")


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
    from ..files._io import read_yaml

    path = Path(path)
    data = read_yaml(path)
    section = data.get(node) if isinstance(data, dict) else None
    if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
        raise ConfigError(f"expected '{node}: ros__parameters:'", path=path, key=node)
    return parameters_from_mapping(section["ros__parameters"], path=path)


@dataclass(frozen=True)
class SendGoal:
    """Send this trajectory as a FollowJointTrajectory goal (replaces the running one).

    Attributes:
        trajectory: The motion (t = 0 at ``start``).
        reason: ``next motion``, or the kind of the decision whose replacement it is
            (``stop``, ``slow``, ``resume``).
        start: Monitor time at which the goal's t = 0 applies [s], the goal's header
            stamp: the decision's ``replacement_start`` for a replacement, the time the
            monitor follows a next motion from; None: on receipt.
    """

    trajectory: Trajectory
    reason: str
    start: float | None = None


@dataclass(frozen=True)
class Publish:
    """Publish this decision (reliable)."""

    decision: Decision


@dataclass(frozen=True)
class Gripper:
    """Run this gripper action (the arm is at rest at the end of a motion).

    Attributes:
        event: The route's gripper event.
        q: The joint state the route performs it at [rad] (the end of the motion before
            it, or the start of the first motion): where the arm must rest; None in a
            route without a motion.
    """

    event: GripperEvent
    q: np.ndarray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class Refusal:
    """A goal the core's gate did not let out (see :attr:`MonitorNodeCore.refused`).

    Attributes:
        time: Monitor time [s].
        command: The goal refused.
        why: ``kill switch latched``, ``node <state>`` or ``no motion running``.
    """

    time: float
    command: SendGoal | Gripper
    why: str


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

    Attributes:
        refused: Every goal the gate refused, in order (see the module docstring).
    """

    def __init__(self, parameters: NodeParameters) -> None:
        self.parameters = parameters
        self.state: _LIFECYCLE = "unconfigured"
        self.monitor: Monitor | None = None
        self.sequence: list[Trajectory | GripperEvent] = []
        self.motions: list[tuple[Trajectory, str | None]] = []
        self.refused: list[Refusal] = []
        self._next = 0
        self._held: str | None = None
        self._started = False
        self._held_back = False  # the gate refused the route's next step: it waits
        # The step of the route under way: a motion, a gripper action, or none yet.
        self._running: Literal["motion", "gripper"] | None = None

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
        self._held_back, self._running = False, None
        self.state = "inactive"

    def activate(self, now: float) -> list[Command]:
        """Start the route (the first time), or release the stop of a deactivation
        (motion resumes by the hold-time rule; a step of the route held back while
        inactive starts at the next tick)."""
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
        return self._commands(self.monitor.kill(now), now)

    def kill(self, now: float) -> list[Command]:
        """Kill switch: stop along the path, latched until :meth:`reset`."""
        if self.monitor is None:
            return []
        return self._commands(self.monitor.kill(now), now)

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
        return self._commands(self.monitor.observe(msg, now), now)

    def on_tick(self, now: float) -> list[Command]:
        """Timer: silence must stop the robot even without callbacks."""
        if self.state != "active" or self.monitor is None:
            return []
        out = self._commands(self.monitor.tick(now), now)
        if self._held_back and self._closed() is None:
            out += self._advance(now)
        return out

    def on_motion_done(self, now: float) -> list[Command]:
        """The latest motion goal succeeded: when the monitor's motion has reached the
        end of its path (:meth:`Monitor.at_end`), the route's next step (a gripper
        action or the next motion).

        A goal that succeeds because a stop brought the arm to rest before the end moves
        nothing on: the monitor resumes the motion by its hold-time rule, and the goal
        that reaches the end advances the route. While the kill switch is latched (or
        the node is inactive) the next step is refused by the gate and waits; the first
        tick with the gate open starts it.
        """
        if self._running != "motion" or self.monitor is None \
                or not self.monitor.at_end(now):
            return []
        return self._advance(now)

    def on_gripper_done(self, now: float) -> list[Command]:
        """The gripper action finished: the next motion (through the gate, as
        :meth:`on_motion_done`)."""
        if self._running != "gripper" or self.monitor is None:
            return []
        return self._advance(now)

    def on_replanned(self, request: ReplanRequest, traj: Trajectory, now: float
                     ) -> list[Command]:
        """A re-plan finished: its box joins the static scene, the new route replaces the
        rest of the old one, its first part starts (through the gate: while the kill
        switch is latched or the node is inactive it waits, and the first tick with the
        gate open starts it)."""
        from ..ros.goals import split_at_gripper_events

        if self.state == "unconfigured" or self.monitor is None:
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

    # -- the gate ---------------------------------------------------------------------
    def _closed(self) -> str | None:
        """Why the gate refuses goals now (None: open)."""
        if self.monitor is not None and self.monitor.last.latched:
            return "kill switch latched"
        if self.state != "active":
            return f"node {self.state}"
        return None

    def _send(self, command: SendGoal | Gripper, now: float,
              role: Literal["route", "replacement", "brake"]) -> list[Command]:
        """The one way out for goals: ``[command]``, or ``[]`` with the refusal logged
        and kept in :attr:`refused`.

        Args:
            command: The goal.
            now: Monitor time [s].
            role: ``brake``: a replacement that brakes to rest (a stop), which always
                goes out, whatever the kill switch and the lifecycle; ``replacement``: a
                re-timing of the running motion (slow, resume), refused as a step of
                the ``route`` is, and when no motion runs (a gripper acts: a re-timing
                of the finished motion would move nothing).
        """
        if role == "brake":
            return [command]
        why = self._closed()
        if why is None and role == "replacement" and self._running != "motion":
            why = "no motion running"
        if why is None:
            return [command]
        self.refused.append(Refusal(now, command, why))
        what = command.reason if isinstance(command, SendGoal) else \
            f"gripper {command.event.action}"
        log.info("monitor node: %s goal refused at %.3f s: %s", what, now, why)
        return []

    # -- the route ---------------------------------------------------------------------
    def _advance(self, now: float) -> list[Command]:
        """The route's next step, through the gate (refused: it waits, see
        :meth:`on_tick`)."""
        assert self.monitor is not None
        if self._next >= len(self.sequence):
            self._held_back = False
            return []
        part = self.sequence[self._next]
        command: SendGoal | Gripper = Gripper(part, self._pose_of(self._next)) \
            if isinstance(part, GripperEvent) else SendGoal(part, "next motion", start=now)
        out = self._send(command, now, "route")
        self._held_back = not out
        if not out:
            return []
        self._next += 1
        if isinstance(part, GripperEvent):
            self._held = part.object if part.action == "close" else None
            self._running = "gripper"
        else:
            self._running = "motion"
            # Assessed before it leaves: a motion the separation does not allow at all is
            # not sent; the arm waits at its start and a resume decision starts it.
            self.monitor.follow(part, start=now, held=self._held)
            decision = self.monitor.tick(now)
            if decision.scale <= 0.0:
                self.monitor.follow(part, start=now, held=self._held, scale=0.0)
                return [Publish(replace(decision, reason=decision.reason + "; the next "
                                        "motion waits at its start", replacement=None,
                                        replacement_start=None, switch=None))]
            return out + self._commands(decision, now)
        return out

    def _pose_of(self, index: int) -> np.ndarray | None:
        """Where the arm rests for the gripper event ``sequence[index]`` [rad]: the end of
        the motion before it, else the start of the motion after it (None: no motion)."""
        before = [p for p in self.sequence[:index] if isinstance(p, Trajectory)]
        if before:
            return before[-1].q[-1].copy()
        after = [p for p in self.sequence[index:] if isinstance(p, Trajectory)]
        return after[0].q[0].copy() if after else None

    def _commands(self, decision: Decision, now: float) -> list[Command]:
        """The decision's replacement (through the gate), the decision published, and its
        re-plan: a stop's goal is the first command, before anything else is done."""
        out: list[Command] = []
        if decision.replacement is not None:
            out += self._send(SendGoal(decision.replacement, decision.kind,
                                       start=decision.replacement_start), now,
                              "brake" if decision.scale == 0.0 else "replacement")
        out.append(Publish(decision))
        if decision.replan is not None:
            out.append(Replan(decision.replan, self.parameters.route, self._held,
                              self.parameters.replan_margin))
        return out
