"""The monitor node's core (:class:`~safepath.monitor.node.MonitorNodeCore`) closed loop on
the twin.

The node core's commands are carried out as the ROS node carries them out: a
``SendGoal`` becomes a ``FollowJointTrajectory`` goal for the simulated controller (a
replacement stamped with the monitor's ``replacement_start``, so the controller joins it
from the current time), a ``Gripper`` a gripper goal; goal results come back as
``on_motion_done`` / ``on_gripper_done``, the node's timer as ``on_tick``. A kill can be
pressed at any simulated time (:meth:`MonitorTwin.run` ``kill_at``), e.g. just before a
motion ends. Scans are not simulated here: the monitor's options should name no sensor,
or it stops on their silence; :class:`safepath.sim.obstacles.ObstacleTwin` adds a moving
body and the sensors that see it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .arm import CANCELED, ArmResult
from .twin import GripperResult, RobotTwin, TwinOptions

if TYPE_CHECKING:
    from ..monitor.node import MonitorNodeCore

__all__ = ["MonitorTwin", "IssuedCommand"]

_NS = 1_000_000_000


@dataclass(frozen=True)
class IssuedCommand:
    """A command the node core issued.

    Attributes:
        time: Simulated time [s].
        kind: ``goal`` (with its reason), ``gripper`` (with its action) or ``decision``.
        detail: The reason, action or decision kind.
    """

    time: float
    kind: str
    detail: str


@dataclass
class MonitorTwin:
    """The node core and a robot twin on one clock.

    Args:
        core: A configured node core (its cell's robot is simulated).
        options: How the robot is simulated.
        tick: The node's timer period [s].
        extra_world: MJCF of further world bodies (a moving obstacle:
            :mod:`safepath.sim.obstacles`).
    """

    core: MonitorNodeCore
    options: TwinOptions = field(default_factory=TwinOptions)
    tick: float = 0.01
    issued: list[IssuedCommand] = field(default_factory=list)
    extra_world: str = ""

    def __post_init__(self) -> None:
        from ..trajectory import Trajectory

        monitor = self.core.monitor
        if monitor is None:
            from ..errors import InputError

            raise InputError("configure() the node core first", key="core")
        first = next(p for p in self.core.sequence if isinstance(p, Trajectory))
        self.twin = RobotTwin(monitor.cell.robot, monitor.cell.scene, first.q[0],
                              options=self.options, extra_world=self.extra_world)
        self._goal_id = 0
        self._arm_goal: int | None = None

    def _dispatch(self, commands: list[Any]) -> None:
        from ..monitor.node import Gripper, Publish, SendGoal
        from ..ros import follow_joint_trajectory_goal, gripper_command_goal, tool_goal

        robot = self.twin.robot
        for cmd in commands:
            now = self.twin.now
            if isinstance(cmd, Publish):
                self.issued.append(IssuedCommand(now, "decision", cmd.decision.kind))
            elif isinstance(cmd, SendGoal):
                self.issued.append(IssuedCommand(now, "goal", cmd.reason))
                decision = self.core.monitor.last if self.core.monitor else None
                start = decision.replacement_start if decision is not None and \
                    decision.replacement is cmd.trajectory else None
                stamp_ns = 0 if start is None else max(1, round(start * _NS))
                goal = follow_joint_trajectory_goal(cmd.trajectory, controller=robot.controller,
                                                    stamp_ns=stamp_ns, limits=robot,
                                                    backend="rosbags")
                self._goal_id += 1
                self._arm_goal = self._goal_id
                self.twin.send_arm_goal(goal, self._goal_id)
            elif isinstance(cmd, Gripper):
                self.issued.append(IssuedCommand(now, "gripper", cmd.event.action))
                self._goal_id += 1
                # The goal the robot's gripper takes: GripperCommand when its
                # controller.yaml has a gripper section, else Niryo's Tool.
                grip = gripper_command_goal(robot, cmd.event.action, backend="rosbags") \
                    if robot.controller.gripper is not None \
                    else tool_goal(cmd.event.action, backend="rosbags")
                self.twin.send_gripper_goal(grip,
                                            self._goal_id)

    def run(self, duration: float, *, kill_at: float | None = None) -> None:
        """Activate the node and run the loop for ``duration`` [s] of simulated time,
        pressing the kill switch at ``kill_at`` [s] (None: never)."""
        self._dispatch(self.core.activate(self.twin.now))
        end = self.twin.now + duration
        killed = kill_at is None
        while self.twin.now < end - 1e-9:
            nxt = min(self.twin.now + self.tick, end)
            if not killed and kill_at is not None:
                nxt = min(nxt, max(kill_at, self.twin.now + self.twin.options.timestep))
            for result in self.twin.advance(nxt):
                self._on_result(result)
            if not killed and kill_at is not None and self.twin.now >= kill_at - 1e-9:
                killed = True
                self._dispatch(self.core.kill(self.twin.now))
            self._dispatch(self.core.on_tick(self.twin.now))

    def _on_result(self, result: ArmResult | GripperResult) -> None:
        now = self.twin.now
        if isinstance(result, GripperResult):
            self._dispatch(self.core.on_gripper_done(now))
        elif result.error_code != CANCELED and result.goal_id == self._arm_goal:
            self._dispatch(self.core.on_motion_done(now) if result.success else [])

    def after(self, time: float, kind: str | None = None) -> list[IssuedCommand]:
        """The commands issued after ``time`` [s] (of one kind)."""
        return [c for c in self.issued if c.time > time and (kind is None or c.kind == kind)]

    @property
    def positions(self) -> np.ndarray:
        """The executed positions recorded so far (N, dof) [rad]."""
        return np.asarray(self.twin.recording.q)

    @property
    def times(self) -> np.ndarray:
        """Their times [s]."""
        return np.asarray(self.twin.recording.time)
