"""The monitor node's core (:class:`~safepath.monitor.node.MonitorNodeCore`) closed loop on
the twin.

The node core's commands are carried out as the ROS node carries them out: a
``SendGoal`` becomes a ``FollowJointTrajectory`` goal for the simulated controller,
stamped with the goal's ``start`` (a replacement's ``replacement_start``, so the
controller joins it where the monitor timed it), a ``Gripper`` a gripper goal; the
newest arm goal's success comes back as ``on_motion_done`` (the core moves the route on
only when the monitor's motion has reached the end of its path, never after a stop at
rest), a gripper goal's as ``on_gripper_done``, the node's timer as ``on_tick``. A kill can
be pressed at any simulated time (:meth:`MonitorTwin.run` ``kill_at``), e.g. just before a
motion ends; at the instant it is pressed it comes before the goal results of that
instant. Scans are not simulated here: the monitor's options should name no sensor, or it
stops on their silence; :class:`safepath.sim.obstacles.ObstacleTwin` adds a moving body
and the sensors that see it.

Every arm goal sent (:class:`ArmGoal`) and every gripper action with where the arm was
(:class:`GripperAction`) is kept, and the motion the trajectory controller commands (its
:class:`~safepath.model.execution.ControllerModel`, ``twin.arm.commanded``) is sampled at every
physics step for its largest speed, acceleration and jerk against the robot's limits
(:meth:`MonitorTwin.commanded_peaks`), so a run can be judged: a gripper action away from
the pose its route plans it at drops (or misses) the object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError
from .arm import CANCELED, ArmResult
from .twin import GripperResult, RobotTwin, TwinOptions

if TYPE_CHECKING:
    from ..monitor import MonitorOptions
    from ..monitor.node import Gripper, MonitorNodeCore

__all__ = ["MonitorTwin", "IssuedCommand", "ArmGoal", "GripperAction", "CommandedPeak",
           "check_run", "configured_core"]

#: Where a gripper action must happen when the robot's controller has no goal tolerance:
#: within this of its planned pose, per joint [rad].
GRIPPER_POSE_TOLERANCE = 0.01

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


@dataclass(frozen=True)
class ArmGoal:
    """An arm goal the twin sent to its controller.

    Attributes:
        goal_id: The goal's id.
        time: When it was sent [s].
        reason: The ``SendGoal``'s reason (``next motion``, ``stop``, ...).
        start: Its header stamp: when its t = 0 applies [s] (None: on receipt).
        end: When its last point is due [s].
    """

    goal_id: int
    time: float
    reason: str
    start: float | None
    end: float


@dataclass(frozen=True)
class GripperAction:
    """A gripper goal the twin sent, and where the arm was then.

    Attributes:
        time: When it was sent [s].
        action: ``open`` or ``close``.
        object: The object released (open) or attached (close), if any.
        error: Executed minus planned joint positions then [rad] (None: the route plans
            no pose for it).
        at_pose: Whether every joint was within the controller's goal tolerance of the
            planned pose (:data:`GRIPPER_POSE_TOLERANCE` when it has none).
    """

    time: float
    action: str
    object: str | None
    error: np.ndarray | None = field(repr=False)
    at_pose: bool

    @property
    def offset(self) -> float:
        """Largest ``|error|`` over the joints [rad] (0 without a planned pose)."""
        return 0.0 if self.error is None else float(np.max(np.abs(self.error)))


@dataclass(frozen=True)
class CommandedPeak:
    """The largest ratio of one derivative of the commanded motion to its limit.

    Attributes:
        ratio: Largest ``|derivative| / limit`` over the joints and the physics steps.
        joint: The joint where it is.
        time: When [s].
    """

    ratio: float
    joint: str
    time: float


@dataclass
class MonitorTwin:
    """The node core and a robot twin on one clock.

    Args:
        core: A configured node core (its cell's robot is simulated).
        options: How the robot is simulated.
        tick: The node's timer period [s].
        extra_world: MJCF of further world bodies (a moving obstacle:
            :mod:`safepath.sim.obstacles`).

    Attributes:
        issued: The commands the core issued, in order.
        arm_goals: The arm goals sent, in order.
        gripper_actions: The gripper goals sent, in order.
    """

    core: MonitorNodeCore
    options: TwinOptions = field(default_factory=TwinOptions)
    tick: float = 0.01
    issued: list[IssuedCommand] = field(default_factory=list)
    extra_world: str = ""

    def __post_init__(self) -> None:
        from ..model.trajectory import Trajectory

        monitor = self.core.monitor
        if monitor is None:
            from ..errors import InputError

            raise InputError("configure() the node core first", key="core")
        first = next(p for p in self.core.sequence if isinstance(p, Trajectory))
        self.twin = RobotTwin(monitor.cell.robot, monitor.cell.scene, first.q[0],
                              options=self.options, extra_world=self.extra_world)
        self.arm_goals: list[ArmGoal] = []
        self.gripper_actions: list[GripperAction] = []
        self._goal_id = 0
        self._arm_goal: int | None = None
        self._arm_done = True  # the newest arm goal has its result
        robot = monitor.cell.robot
        controller = robot.controller
        if controller.goal_tolerance is None:
            self._pose_tolerance = np.full(len(first.q[0]), GRIPPER_POSE_TOLERANCE)
        else:  # the controller's joint order to the twin's
            by_name = dict(zip(controller.joint_names, controller.goal_tolerance,
                               strict=True))
            self._pose_tolerance = np.array([float(by_name[n])
                                             for n in self.twin.model.joint_names])
        self._limits = np.array([robot.velocity_limits, robot.acceleration_limits,
                                 robot.jerk_limits], dtype=float)
        self._peaks = np.zeros_like(self._limits)  # speed, acceleration, jerk ratios
        self._peak_times = np.zeros_like(self._limits)
        self._sampled = self.twin.step  # the commanded motion is sampled up to here

    @property
    def goal_end(self) -> float | None:
        """When the running arm goal's last point is due [s] (None: no goal runs)."""
        return None if self._arm_done or not self.arm_goals else self.arm_goals[-1].end

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
                stamp_ns = 0 if cmd.start is None else max(1, round(cmd.start * _NS))
                goal = follow_joint_trajectory_goal(cmd.trajectory, controller=robot.controller,
                                                    stamp_ns=stamp_ns, limits=robot,
                                                    backend="rosbags")
                last = goal.trajectory.points[-1].time_from_start
                t0 = now if stamp_ns == 0 else stamp_ns / _NS
                self._goal_id += 1
                self._arm_goal = self._goal_id
                self._arm_done = False
                self.arm_goals.append(ArmGoal(
                    self._goal_id, now, cmd.reason, cmd.start,
                    max(now, t0 + int(last.sec) + int(last.nanosec) / _NS)))
                if self.twin.send_arm_goal(goal, self._goal_id) is not None:
                    self._arm_done = True  # rejected (in twin.arm.results)
            elif isinstance(cmd, Gripper):
                self.issued.append(IssuedCommand(now, "gripper", cmd.event.action))
                self.gripper_actions.append(self._gripper_action(cmd))
                self._goal_id += 1
                # The goal the robot's gripper takes: GripperCommand when its
                # controller.yaml has a gripper section, else Niryo's Tool.
                grip = gripper_command_goal(robot, cmd.event.action, backend="rosbags") \
                    if robot.controller.gripper is not None \
                    else tool_goal(cmd.event.action, backend="rosbags")
                self.twin.send_gripper_goal(grip,
                                            self._goal_id)

    def _gripper_action(self, cmd: Gripper) -> GripperAction:
        """``cmd`` and where the arm is now, against the pose its route plans it at."""
        error = None if cmd.q is None else self.twin.q - np.asarray(cmd.q, dtype=float)
        at_pose = error is None or bool(np.all(np.abs(error) <= self._pose_tolerance))
        return GripperAction(self.twin.now, cmd.event.action, cmd.event.object, error,
                             at_pose)

    def run(self, duration: float, *, kill_at: float | None = None) -> None:
        """Activate the node and run the loop for ``duration`` [s] of simulated time,
        pressing the kill switch at ``kill_at`` [s] (None: never)."""
        self._dispatch(self.core.activate(self.twin.now))
        end = self.twin.now + duration
        killed = kill_at is None
        while self.twin.now < end - 1e-9:
            nxt = min(self.twin.now + self.tick, end)
            due = None if killed else kill_at
            if due is not None:
                nxt = min(nxt, max(due, self.twin.now + self.twin.options.timestep))
            killed = self._advance(nxt, due) or killed
            self._dispatch(self.core.on_tick(self.twin.now))

    def _advance(self, until: float, kill_due: float | None) -> bool:
        """Run the twin to ``until`` [s] and hand the goal results to the core in time
        order; a kill due at ``kill_due`` [s] (None: none) is pressed before the results
        of its instant. Returns whether it was pressed."""
        results = self.twin.advance(until)
        self._sample_commanded()
        pressed = False
        for result in results:
            if not pressed and kill_due is not None and result.time >= kill_due - 1e-9:
                self._press_kill()
                pressed = True
            self._on_result(result)
        if not pressed and kill_due is not None and self.twin.now >= kill_due - 1e-9:
            self._press_kill()
            pressed = True
        return pressed

    def _sample_commanded(self) -> None:
        """The commanded motion's speed, acceleration and jerk ratios at the physics
        steps run since the last call (its model keeps the last goals only: called after
        every advance)."""
        steps = np.arange(self._sampled + 1, self.twin.step + 1)
        if steps.size == 0:
            return
        times = steps * self.twin.options.timestep
        _, v, a, j = self.twin.arm.commanded.sample(times)
        for k, rate in enumerate((v, a, j)):
            ratio = np.abs(rate) / self._limits[k]
            i = np.argmax(ratio, axis=0)
            best = ratio[i, np.arange(ratio.shape[1])]
            higher = best > self._peaks[k]
            self._peaks[k] = np.where(higher, best, self._peaks[k])
            self._peak_times[k] = np.where(higher, times[i], self._peak_times[k])
        self._sampled = self.twin.step

    def commanded_peaks(self) -> tuple[CommandedPeak, CommandedPeak, CommandedPeak]:
        """The largest speed, acceleration and jerk of the commanded motion against the
        robot's limits so far, at every physics step (a step of a goal switch shows in
        ``twin.arm.switches``, not here)."""
        names = self.twin.robot.joint_names
        out = []
        for k in range(3):
            joint = int(np.argmax(self._peaks[k]))
            out.append(CommandedPeak(float(self._peaks[k, joint]), names[joint],
                                     float(self._peak_times[k, joint])))
        return out[0], out[1], out[2]

    def _press_kill(self) -> None:
        """The kill switch, pressed now."""
        self._dispatch(self.core.kill(self.twin.now))

    def _on_result(self, result: ArmResult | GripperResult) -> None:
        now = self.twin.now
        if isinstance(result, GripperResult):
            self._dispatch(self.core.on_gripper_done(now))
        elif result.error_code != CANCELED and result.goal_id == self._arm_goal:
            self._arm_done = True
            # The core moves the route on only if the monitor's motion is at its path's
            # end (a stop's goal succeeds at rest mid-path: nothing follows it).
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


def check_run(seed: int, duration: float, *, shortest: float) -> None:
    """Refuse a run's seed unless an integer >= 0, its duration [s] unless finite and
    above ``shortest`` [s].

    Raises:
        InputError: Naming ``seed`` or ``duration``.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"expected an integer >= 0, got {seed!r}", key="seed")
    if not (isinstance(duration, (int, float)) and math.isfinite(duration)
            and duration > shortest):
        raise InputError(f"expected a finite number > {shortest:g} [s], got {duration!r}",
                         key="duration")


def configured_core(cell: str, route: str, options: MonitorOptions) -> MonitorNodeCore:
    """A node core on route ``route`` of the scene folder ``cell``, its monitor with
    ``options``, configured (its motions planned)."""
    from ..monitor.node import MonitorNodeCore, NodeParameters

    core = MonitorNodeCore(NodeParameters(scene=str(cell), route=route, options=options))
    core.configure()
    return core
