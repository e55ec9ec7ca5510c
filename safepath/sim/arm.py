"""A simulated ``FollowJointTrajectory`` action server: ros2_control's trajectory controller.

It takes the goal messages safepath emits (:func:`safepath.ros.follow_joint_trajectory_goal`,
rosbags or rclpy classes) and does what ``joint_trajectory_controller`` does with them:

* **joins the points** as the robot's ``controller.yaml`` says (``interpolation``,
  :func:`safepath.model.execution.join`: quintic when points carry positions, velocities and
  accelerations);
* **samples the joined motion every controller cycle** (``cycle``) as the drives'
  setpoint; between two cycles the drives extrapolate it at the sampled velocity (a
  first-order hold: the Ned's 25 Hz controller would otherwise command a staircase);
* **switches** as :class:`safepath.model.execution.ControllerModel` says (the one model of the
  controller the monitor builds its replacements against): a goal is taken at its
  ``header.stamp`` (0: on receipt; a stamp later than its arrival is the command latency
  the sender stated, and the running goal goes on until then; one in the past is taken
  on receipt); the state (position, velocity and acceleration) commanded then is joined
  to the first point not in the past, and earlier points are dropped;
* **reports** feedback (desired, actual, error) and the result: ``SUCCESSFUL`` once the
  trajectory's time is over and every joint is within its goal tolerance, else
  ``GOAL_TOLERANCE_VIOLATED`` when ``goal_time_tolerance`` has passed too;
  ``INVALID_JOINTS`` / ``INVALID_GOAL`` for a goal it cannot run (as a result, never
  an exception: a real server answers bad goals too);
* **cancels**: the arm holds the position commanded at the cancel.

Times are on the simulated clock [s]; the server computes the drives' controls for the
physics steps ahead of time (:meth:`ArmServer.controls`), so that stepping MuJoCo needs
no Python per step beyond copying a row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model.controller_spec import ControllerSpec
from ..model.execution import ControllerModel
from .model import RobotModel

__all__ = ["ArmServer", "ArmFeedback", "ArmResult", "SUCCESSFUL", "INVALID_GOAL",
           "INVALID_JOINTS", "GOAL_TOLERANCE_VIOLATED", "CANCELED"]

# control_msgs/action/FollowJointTrajectory result codes.
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
GOAL_TOLERANCE_VIOLATED = -5
#: Not a FollowJointTrajectory error code: the goal was cancelled (the action's status).
CANCELED = -100

_NS = 1_000_000_000


@dataclass(frozen=True)
class ArmResult:
    """The result of one goal.

    Attributes:
        goal_id: The goal.
        error_code: ``SUCCESSFUL``, ``INVALID_GOAL``, ``INVALID_JOINTS``,
            ``GOAL_TOLERANCE_VIOLATED`` or ``CANCELED``.
        error_string: Why, in words ('' on success).
        time: Simulated time of the result [s].
        final_error: Position error per joint at the result [rad] (safepath's order).
    """

    goal_id: int
    error_code: int
    error_string: str
    time: float
    final_error: np.ndarray = field(repr=False)

    @property
    def success(self) -> bool:
        """Whether the goal succeeded."""
        return self.error_code == SUCCESSFUL


@dataclass(frozen=True)
class ArmFeedback:
    """``FollowJointTrajectory_Feedback``: desired, actual and error at one instant.

    Attributes:
        goal_id: The running goal.
        time: Simulated time [s].
        desired: Commanded positions [rad] (the joined motion), safepath's order.
        actual: Simulated positions [rad].
    """

    goal_id: int
    time: float
    desired: np.ndarray
    actual: np.ndarray

    @property
    def error(self) -> np.ndarray:
        """``desired - actual`` [rad]."""
        return self.desired - self.actual


@dataclass
class _Goal:
    goal_id: int
    start_step: int              # first physics step the reference covers
    q_ref: np.ndarray            # joined motion at every physics step (n, dof)
    qd_ref: np.ndarray
    ctrl: np.ndarray             # drives' controls at every physics step (n, nu)
    end_time: float              # the trajectory's last point [s]
    tolerance: np.ndarray        # per joint [rad]; inf: none
    time_tolerance: float


def _duration(msg: Any) -> float:
    return int(msg.sec) + int(msg.nanosec) / _NS


class ArmServer:
    """The arm's trajectory controller, simulated (see the module docstring).

    Args:
        model: The robot's MuJoCo model (joint order, drives).
        controller: The robot's trajectory controller settings (``robot.controller``).
        q_initial: Where the arm rests at the start [rad] (safepath's order).
        timestep: Physics timestep [s].
    """

    def __init__(self, model: RobotModel, controller: ControllerSpec,
                 q_initial: np.ndarray, timestep: float) -> None:
        self.model = model
        self.controller = controller
        self.timestep = timestep
        self._cycle_steps = max(1, round(controller.cycle / timestep))
        dof = len(model.joint_names)
        self._default_tol = (np.full(dof, np.inf) if controller.goal_tolerance is None else
                             self._ordered(controller.joint_names, controller.goal_tolerance))
        self._goal: _Goal | None = None
        self._hold_q = np.asarray(q_initial, dtype=float).copy()
        #: What the controller commands, goal after goal.
        self.commanded = ControllerModel(self._hold_q,
                                         interpolation=controller.interpolation)
        #: Each switch to a goal that arrived while another ran: (goal id, Switch).
        self.switches: list[tuple[int, Any]] = []
        self._hold_ctrl = model.control(self._hold_q, np.zeros(dof), np.zeros(dof))
        self.results: list[ArmResult] = []

    # -- goals -----------------------------------------------------------------------
    @property
    def active(self) -> int | None:
        """The running goal's id, or None."""
        return None if self._goal is None else self._goal.goal_id

    def _ordered(self, names: Any, values: Any) -> np.ndarray:
        by_name = dict(zip(names, values, strict=True))
        return np.array([float(by_name[n]) for n in self.model.joint_names])

    def _reject(self, goal_id: int, code: int, why: str, now: float) -> ArmResult:
        result = ArmResult(goal_id, code, why, now, np.zeros(len(self.model.joint_names)))
        self.results.append(result)
        return result

    def accept(self, goal: Any, goal_id: int, step: int, q_now: np.ndarray
               ) -> ArmResult | None:
        """Take a ``FollowJointTrajectory_Goal`` at physics step ``step``; it replaces the
        running goal (whose result is then ``CANCELED``).

        Args:
            goal: The goal message.
            goal_id: Its id (echoed in results and feedback).
            step: The physics step at which it arrives.
            q_now: The arm's simulated positions [rad] (the reference before the
                trajectory when the goal starts later than now).

        Returns:
            The rejection result, or None when accepted.
        """
        now = step * self.timestep
        traj = goal.trajectory
        names = list(traj.joint_names)
        if sorted(names) != sorted(self.model.joint_names):
            return self._reject(goal_id, INVALID_JOINTS, f"joints {names} are not the arm's "
                                f"{list(self.model.joint_names)}", now)
        points = list(traj.points)
        cols = [names.index(n) for n in self.model.joint_names]
        try:
            t = np.array([_duration(p.time_from_start) for p in points])
            q = np.array([np.asarray(p.positions, dtype=float)[cols] for p in points])
            qd = np.array([np.asarray(p.velocities, dtype=float)[cols] if len(p.velocities)
                           else np.zeros(len(cols)) for p in points])
            qdd = np.array([np.asarray(p.accelerations, dtype=float)[cols]
                            if len(p.accelerations) else np.zeros(len(cols)) for p in points])
        except (IndexError, ValueError) as exc:
            return self._reject(goal_id, INVALID_GOAL, f"malformed points: {exc}", now)
        if t.size == 0 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(q)):
            return self._reject(goal_id, INVALID_GOAL, "no points, times not increasing, or "
                                "non-finite positions", now)
        stamp = _duration(traj.header.stamp)
        t0 = now if stamp == 0 else stamp
        running = self._goal is not None
        switch = self.commanded.take(t, q, qd, qdd, start=t0, time=max(t0, now))
        if running:
            self.switches.append((goal_id, switch))
            self._finish(CANCELED, "replaced by a new goal", step, q_now, hold=False)
        tol = self._tolerances(goal)
        time_tol = _duration(goal.goal_time_tolerance)
        self._goal = self._build(goal_id, step, tol,
                                 time_tol if time_tol > 0 else self.controller.goal_time_tolerance)
        return None

    def _tolerances(self, goal: Any) -> np.ndarray:
        if not len(goal.goal_tolerance):
            return self._default_tol
        tol = dict(zip(self.model.joint_names, self._default_tol.tolist(), strict=True))
        for jt in goal.goal_tolerance:
            if jt.name in tol and jt.position > 0:
                tol[jt.name] = float(jt.position)
        return np.array([tol[n] for n in self.model.joint_names])

    def _build(self, goal_id: int, step: int, tol: np.ndarray, time_tol: float) -> _Goal:
        """The commanded motion (:attr:`commanded`) at every physics step from ``step`` to
        the end, and the drives' controls: samples every controller cycle, extrapolated
        in between."""
        dt, c = self.timestep, self._cycle_steps
        end = self.commanded.end
        n = max(1, math.ceil((end - step * dt) / dt - 1e-9) + 1)
        steps = step + np.arange(n)
        q_ref, qd_ref, _, _ = self.commanded.sample(steps * dt)
        # Controller cycles fall on the global grid of the cycle period.
        ticks = (steps // c) * c
        ticks = np.maximum(ticks, step)
        uniq, where = np.unique(ticks, return_inverse=True)
        sq, sqd, sqdd, _ = self.commanded.sample(uniq * dt)
        lag = ((steps - ticks) * dt)[:, None]
        set_q = sq[where] + sqd[where] * lag
        ctrl = self.model.control(set_q, sqd[where], sqdd[where])
        return _Goal(goal_id, step, q_ref, qd_ref, ctrl, float(end), tol, time_tol)

    def cancel(self, goal_id: int, step: int, q_now: np.ndarray) -> ArmResult | None:
        """Cancel ``goal_id`` if it runs: the arm holds the position commanded now."""
        if self._goal is None or self._goal.goal_id != goal_id:
            return None
        return self._finish(CANCELED, "cancelled", step, q_now)

    def _finish(self, code: int, why: str, step: int, q_now: np.ndarray, *,
                hold: bool = True) -> ArmResult:
        goal = self._goal
        assert goal is not None
        q_ref = self.reference_at(step)
        self._hold_q = q_ref.copy()
        dof = q_ref.size
        self._hold_ctrl = self.model.control(q_ref, np.zeros(dof), np.zeros(dof))
        if hold and step * self.timestep < self.commanded.end:
            # Cancelled while moving: the controller holds the position commanded now.
            self.commanded.take(np.zeros(1), q_ref[None], np.zeros((1, dof)),
                                np.zeros((1, dof)), start=step * self.timestep)
        self._goal = None
        result = ArmResult(goal.goal_id, code, why, step * self.timestep, q_ref - q_now)
        self.results.append(result)
        return result

    # -- stepping --------------------------------------------------------------------
    def reference_at(self, step: int) -> np.ndarray:
        """The commanded position at physics step ``step`` [rad]."""
        goal = self._goal
        if goal is None:
            return self._hold_q.copy()
        k = min(max(step - goal.start_step, 0), goal.q_ref.shape[0] - 1)
        return goal.q_ref[k].copy()

    def controls(self, step: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The drives' controls and the commanded positions for physics steps
        ``step .. step + n - 1`` (each (n, dof))."""
        goal = self._goal
        if goal is None:
            return (np.repeat(self._hold_ctrl[None], n, 0), np.repeat(self._hold_q[None], n, 0))
        k = np.clip(step - goal.start_step + np.arange(n), 0, goal.q_ref.shape[0] - 1)
        return goal.ctrl[k], goal.q_ref[k]

    def feedback(self, step: int, q_now: np.ndarray) -> ArmFeedback | None:
        """Feedback of the running goal at physics step ``step``, or None."""
        if self._goal is None:
            return None
        return ArmFeedback(self._goal.goal_id, step * self.timestep, self.reference_at(step),
                           np.asarray(q_now, dtype=float).copy())

    def update(self, step: int, q_now: np.ndarray) -> ArmResult | None:
        """Check the running goal at physics step ``step`` (the arm at ``q_now``): its
        result once it is over, else None."""
        goal = self._goal
        if goal is None:
            return None
        now = step * self.timestep
        if now < goal.end_time - 1e-9:
            return None
        error = np.abs(goal.q_ref[-1] - q_now)
        if np.all(error <= goal.tolerance):
            return self._finish(SUCCESSFUL, "", step, q_now)
        if now > goal.end_time + goal.time_tolerance + 1e-9:
            worst = int(np.argmax(error - np.where(np.isfinite(goal.tolerance),
                                                   goal.tolerance, np.inf)))
            return self._finish(GOAL_TOLERANCE_VIOLATED,
                                f"'{self.model.joint_names[worst]}' is {error[worst]:.4f} rad "
                                f"from the goal (tolerance {goal.tolerance[worst]:g}) "
                                f"{goal.time_tolerance:g} s after the end", step, q_now)
        return None
