"""The simulated robot: MuJoCo physics, its trajectory controller and gripper, one clock.

:class:`RobotTwin` owns the physics (1 kHz), the simulated
:class:`~safepath.sim.arm.ArmServer` and :class:`GripperServer`, and the simulated clock
(``step * timestep``). A cell's twin sends goals and advances the clock; the twin returns
the results as they happen and records what the arm did: ``/joint_states`` as executed,
the commanded motion, the tracking error per joint, the speeds against the limits, and
MuJoCo's contacts of the arm with the cell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..errors import InputError
from .arm import ArmResult, ArmServer
from .model import TIMESTEP, ServoGains, build_robot_model

if TYPE_CHECKING:
    from ..model.robot import Robot
    from ..model.scene import Scene

__all__ = ["TwinOptions", "RobotTwin", "GripperResult", "GripperServer", "Recording"]


@dataclass(frozen=True, kw_only=True)
class TwinOptions:
    """How the robot is simulated.

    Attributes:
        gains: The joints' position servos.
        timestep: Physics timestep [s].
        gripper_time: Duration of a gripper action (open or close) [s].
        check_period: How often goals are checked for their result [s] (at least the
            controller's cycle).
        record_rate: Rate of the executed ``/joint_states`` record [Hz]; None: the
            controller's ``joint_state_rate``.
    """

    gains: ServoGains = field(default_factory=ServoGains)
    timestep: float = TIMESTEP
    gripper_time: float = 0.5
    check_period: float = 0.01
    record_rate: float | None = None

    def __post_init__(self) -> None:
        for key in ("gripper_time", "check_period"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0:
                raise InputError(f"expected a finite number > 0 [s], got {value!r}", key=key)
        if self.record_rate is not None and (not isinstance(self.record_rate, (int, float))
                                             or not 0 < self.record_rate <= 1000):
            raise InputError(f"expected a rate in (0, 1000] [Hz], got {self.record_rate!r}",
                             key="record_rate")


@dataclass(frozen=True)
class GripperResult:
    """The result of a gripper goal.

    Attributes:
        goal_id: The goal.
        action: ``open`` or ``close``.
        success: Whether it succeeded.
        message: Why not ('' on success).
        time: Simulated time of the result [s].
    """

    goal_id: int
    action: Literal["open", "close"]
    success: bool
    message: str
    time: float


class GripperServer:
    """A gripper action server (``GripperCommand`` or Niryo ``Tool``), as a timed action.

    The gripper's fingers are not simulated bodies (see docs/twin.md's limits): a goal
    succeeds ``duration`` after it arrives.

    Args:
        duration: Time an action takes [s].
        open_position: The ``GripperCommand`` position that means open (None: the robot
            has no ``GripperCommand`` gripper); any other means close.
    """

    def __init__(self, duration: float, open_position: float | None = None) -> None:
        self.duration = duration
        self.open_position = open_position
        self._pending: list[tuple[float, GripperResult]] = []

    def accept(self, goal: Any, goal_id: int, now: float) -> GripperResult | None:
        """Take a ``Tool_Goal`` (``cmd.cmd_type`` 1 open, 2 close) or a
        ``GripperCommand_Goal``; a goal of neither kind is answered as failed at once."""
        action: Literal["open", "close"] | None = None
        cmd = getattr(goal, "cmd", None)
        command = getattr(goal, "command", None)
        if cmd is not None and getattr(cmd, "cmd_type", None) in (1, 2):
            action = "open" if cmd.cmd_type == 1 else "close"
        elif command is not None and self.open_position is not None:
            action = "open" if abs(float(command.position) - self.open_position) < 1e-9 \
                else "close"
        if action is None:
            return GripperResult(goal_id, "open", False, "not a Tool or GripperCommand goal "
                                 "this gripper takes", now)
        self._pending.append((now + self.duration,
                              GripperResult(goal_id, action, True, "", now + self.duration)))
        return None

    def next_time(self) -> float:
        """When the next result is due [s] (inf: none)."""
        return min((t for t, _ in self._pending), default=math.inf)

    def due(self, now: float) -> list[GripperResult]:
        """The results due by ``now``."""
        done = [r for t, r in self._pending if t <= now + 1e-12]
        self._pending = [(t, r) for t, r in self._pending if t > now + 1e-12]
        return done


@dataclass
class Recording:
    """What the simulated arm did.

    Attributes:
        time: Record times [s] (at the record rate).
        q: Executed positions there [rad] (safepath's joint order).
        qd: Executed velocities [rad/s].
        q_ref: Commanded positions (the joined motion) there [rad].
        moving: Whether a goal was running there.
        tracking: Largest ``|q_ref - q|`` per joint while goals ran, at every physics
            step [rad].
        speed_ratio: Largest ``|qd| / velocity limit`` per joint, at every physics step.
        contact_steps: Physics steps in which MuJoCo found the arm touching the cell.
        steps: Physics steps taken.
    """

    time: list[float] = field(default_factory=list)
    q: list[np.ndarray] = field(default_factory=list)
    qd: list[np.ndarray] = field(default_factory=list)
    q_ref: list[np.ndarray] = field(default_factory=list)
    moving: list[bool] = field(default_factory=list)
    tracking: np.ndarray = field(default_factory=lambda: np.zeros(0))
    speed_ratio: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_steps: int = 0
    steps: int = 0


class RobotTwin:
    """A robot simulated in MuJoCo, driven by its simulated trajectory controller.

    Args:
        robot: The robot.
        scene: The cell whose static objects the arm may touch (None: none).
        q_initial: Where the arm rests at time 0 [rad].
        options: Simulation options.
        extra_world: MJCF of further world bodies (see :func:`build_robot_model`).
    """

    def __init__(self, robot: Robot, scene: Scene | None, q_initial: np.ndarray, *,
                 options: TwinOptions | None = None, extra_world: str = "") -> None:
        import mujoco

        self._mujoco = mujoco
        self.options = options = options or TwinOptions()
        self.robot = robot
        self.model = build_robot_model(robot, scene, gains=options.gains,
                                       timestep=options.timestep, extra_world=extra_world)
        q0 = robot.as_joint_vector(q_initial, name="q_initial")
        self.data = mujoco.MjData(self.model.model)
        self.data.qpos[self.model.qpos_index] = q0
        mujoco.mj_forward(self.model.model, self.data)
        self.step = 0
        controller = robot.controller
        self.arm = ArmServer(self.model, controller, q0, options.timestep)
        gripper = controller.gripper
        self.gripper = GripperServer(options.gripper_time,
                                     None if gripper is None else gripper.open_position)
        dof = len(q0)
        self.recording = Recording(tracking=np.zeros(dof), speed_ratio=np.zeros(dof))
        rate = options.record_rate or controller.joint_state_rate
        self._record_every = max(1, round(1.0 / (rate * options.timestep)))
        self._check_every = max(1, round(max(options.check_period, controller.cycle)
                                         / options.timestep))
        self._vmax = np.asarray(robot.velocity_limits, dtype=float)
        self._record(0.0, self.q, self.qd, q0, False)

    # -- state -----------------------------------------------------------------------
    @property
    def now(self) -> float:
        """The simulated clock [s]."""
        return self.step * self.options.timestep

    @property
    def q(self) -> np.ndarray:
        """The arm's simulated positions [rad] (safepath's order)."""
        return self.data.qpos[self.model.qpos_index].copy()

    @property
    def qd(self) -> np.ndarray:
        """The arm's simulated velocities [rad/s]."""
        return self.data.qvel[self.model.qpos_index].copy()

    # -- goals -----------------------------------------------------------------------
    def send_arm_goal(self, goal: Any, goal_id: int) -> ArmResult | None:
        """A ``FollowJointTrajectory_Goal`` arrives now; its rejection, or None."""
        return self.arm.accept(goal, goal_id, self.step, self.q)

    def cancel_arm_goal(self, goal_id: int) -> ArmResult | None:
        """Cancel a running arm goal (the arm holds the position commanded now)."""
        return self.arm.cancel(goal_id, self.step, self.q)

    def send_gripper_goal(self, goal: Any, goal_id: int) -> GripperResult | None:
        """A gripper goal arrives now; its rejection, or None."""
        return self.gripper.accept(goal, goal_id, self.now)

    # -- time ------------------------------------------------------------------------
    def advance(self, until: float) -> list[ArmResult | GripperResult]:
        """Run the physics and the controllers to ``until`` [s] (at least one step);
        the results that happened, in time order."""
        out: list[ArmResult | GripperResult] = []
        dt = self.options.timestep
        target = max(self.step + 1, math.ceil(until / dt - 1e-9))
        while self.step < target:
            # Up to the next result check (or gripper result) or the target.
            chunk = min(target, (self.step // self._check_every + 1) * self._check_every)
            due = self.gripper.next_time()
            if math.isfinite(due):
                chunk = min(chunk, max(self.step + 1, math.ceil(due / dt - 1e-9)))
            self._run(chunk - self.step)
            out.extend(self.gripper.due(self.now))
            if self.step % self._check_every == 0 or self.step == target:
                result = self.arm.update(self.step, self.q)
                if result is not None:
                    out.append(result)
        return out

    def _run(self, n: int) -> None:
        mujoco, m, d = self._mujoco, self.model.model, self.data
        moving = self.arm.active is not None
        ctrl, q_ref = self.arm.controls(self.step, n)
        idx = self.model.qpos_index
        rec = self.recording
        q_log = np.empty((n, m.nq))
        qd_log = np.empty((n, m.nv))
        contacts = 0
        for i in range(n):
            d.ctrl[:] = ctrl[i]
            mujoco.mj_step(m, d)
            q_log[i] = d.qpos
            qd_log[i] = d.qvel
            contacts += d.ncon > 0
        q, qd = q_log[:, idx], qd_log[:, idx]
        if moving:
            rec.tracking = np.maximum(rec.tracking, np.abs(q_ref - q).max(axis=0))
        rec.speed_ratio = np.maximum(rec.speed_ratio, (np.abs(qd) / self._vmax).max(axis=0))
        rec.contact_steps += contacts
        first = self.step + 1
        self.step += n
        rec.steps = self.step
        for k in range(first, self.step + 1):
            if k % self._record_every == 0:
                i = k - first
                self._record(k * self.options.timestep, q[i], qd[i], q_ref[i], moving)

    def _record(self, t: float, q: np.ndarray, qd: np.ndarray, q_ref: np.ndarray,
                moving: bool) -> None:
        rec = self.recording
        rec.time.append(t)
        rec.q.append(np.asarray(q, dtype=float).copy())
        rec.qd.append(np.asarray(qd, dtype=float).copy())
        rec.q_ref.append(np.asarray(q_ref, dtype=float).copy())
        rec.moving.append(moving)
