"""The gravimetric pour's decision logic, without ROS: an explicit state machine.

As :class:`~safepath.cells.quality_check.controller.QualityCheckController` does for the
quality-check cell: events in (weight readings with their stamps, goal results and
feedback, clock ticks), each with the current clock time [s]; commands out, for the node
to carry out.
No threads and no clock inside: a pour can be replayed in a test.

::

    READY --start()--> BEFORE: the steps before the pour (e.g. the pick route: motions and
        gripper goals, each after the previous one succeeded)
    BEFORE --done--> POURING: the planned tilt, as one goal
    POURING --predicted final mass reaches the target--> STOPPING: a stop goal replaces the
        tilt (its own knots, then path-consistent braking); the return is computed at once
    POURING --tilt finished first--> HOLDING: still tilted, still reading
    HOLDING --target predicted, or hold_timeout--> RETURNING
    STOPPING --stop done--> RETURNING: the return upright goal
    RETURNING --done--> AFTER: the steps after the pour (e.g. the place route) --> DONE
    POURING / HOLDING --no reading for weight_timeout--> STOPPING / RETURNING (scale silent)
    any --failed or overdue goal--> FAULT (the running goal cancelled)
    any --kill()--> FAULT: a tilt is braked along its path, any other goal cancelled

The stop and the return never leave the tilt's verified path: the stop holds the tilt's
own knots then brakes along it (:class:`~safepath.planning.stop.StopPlanner`), the return
runs the same path backwards, timed by TOPP-RA (:meth:`PourStopper.back`); both are
re-checked by the independent FCL verifier. The stop is computed when the decision is
taken (a few milliseconds, well within ``stop_lead``), the return at the next tick, while
the arm brakes.

Every arm goal carries ``start_time``: the clock time of its trajectory's t = 0, for the
goal's ``header.stamp``. Motions from rest start ``start_delay`` after they are sent (the
controller holds the arm at their first point until then), so the controller knows when
the tilt, and so the commanded flow, began; a stop goal is stamped with the time of its
first knot, which is already running, so the trajectory controller joins it where the arm
is; the return starts as soon as the stop has succeeded. Weight readings are stamped with
the clock time they were taken.
"""

from __future__ import annotations

import enum
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from ...errors import InputError, SafepathError
from ...model.trajectory import GripperEvent, Trajectory
from ...ros.commands import CancelGoal, Fault
from .commands import (
    PourCommand,
    PourControllerOptions,
    PourReport,
    SendArmGoal,
    SendGripperGoal,
)
from .parts import MassPredictor, PourStopper

if TYPE_CHECKING:
    from ...cell import Cell
    from ...planning.pour import PourMotion
    from .flow import FlowModel

__all__ = ["PourCommand", "PourController", "PourControllerOptions",
           "PourReport", "PourState", "SendArmGoal", "SendGripperGoal"]

logger = logging.getLogger(__name__)

#: Largest jump between the end of one motion and the start of the next [rad].
JOIN_TOLERANCE = 1e-3


class PourState(enum.Enum):
    """States of :class:`PourController`."""

    READY = "ready"
    BEFORE = "before"
    POURING = "pouring"
    STOPPING = "stopping"
    HOLDING = "holding"
    RETURNING = "returning"
    AFTER = "after"
    DONE = "done"
    FAULT = "fault"


@dataclass
class _Pending:
    goal_id: int
    kind: Literal["route", "pour", "stop", "return", "gripper"]
    deadline: float
    start_time: float = 0.0


class PourController:
    """The gravimetric pour's state machine (see the module docstring).

    Not thread-safe: a node calls it from one thread at a time.

    Args:
        cell: The cell the tilt was planned in (limits, scene and held cup: the stop and
            the return are re-checked in it).
        pour: The planned, verified tilt (:func:`~safepath.planning.pour.plan_tilt`).
        flow: The controller's model of the cup and the scale (see :class:`MassPredictor`).
        options: Target and time-outs.
        still: What the stop and the return pour per unit gain; default: measured on the
            controller's own stops and returns (:meth:`PourStopper.calibrate_still`).
        return_angular_speed: Bound on the cup's angular speed on the way back [rad/s].
        before: Motions and gripper events before the pour, in order (e.g.
            ``split_at_gripper_events(pick)``); the last motion must end where the tilt
            starts.
        after: Motions and gripper events after the return upright.
    """

    def __init__(self, cell: Cell, pour: PourMotion, flow: FlowModel, *,
                 options: PourControllerOptions | None = None,
                 still: Callable[[float], float] | None = None,
                 return_angular_speed: float = math.radians(30.0),
                 before: Sequence[Trajectory | GripperEvent] = (),
                 after: Sequence[Trajectory | GripperEvent] = ()) -> None:
        self.options = options or PourControllerOptions()
        self.pour = pour
        traj = pour.trajectory
        _check_chain([*before, traj], "before")
        self._before, self._after = list(before), list(after)
        self._stopper = PourStopper(cell, pour, return_angular_speed=return_angular_speed)
        if still is None:
            still = self._stopper.calibrate_still(flow)
        self._predictor = MassPredictor(traj.t, pour.tilt, flow, still=still,
                                        min_reading=self.options.min_reading)
        self._state = PourState.READY
        self._queue: list[Trajectory | GripperEvent] = []
        self._pending: _Pending | None = None
        self._next_id = 0
        self._t0 = math.nan  # clock time at which the tilt started
        self._last_reading: float | None = None
        self._last_reading_time = math.nan
        self._early: list[tuple[float, float]] = []  # (stamp, mass) before the tilt
        self._tare: float | None = None
        self._hold_since = math.nan
        self._return: Trajectory | None = None
        self._s_rest = 0.0  # path parameter where the tilt comes to rest
        self._decision: tuple[float | None, float | None, str, bool] | None = None
        self.report: PourReport | None = None

    @property
    def state(self) -> PourState:
        """The current state."""
        return self._state

    @property
    def predictor(self) -> MassPredictor:
        """The mass predictor (its fitted gain, for logs and plots)."""
        return self._predictor

    # -- events ----------------------------------------------------------------------------
    def start(self, now: float) -> list[PourCommand]:
        """Run the steps before the pour, then the pour. Only from READY."""
        if self._state is not PourState.READY:
            logger.warning("start in state %s: ignored", self._state.value)
            return []
        self._state = PourState.BEFORE
        self._queue = list(self._before)
        return self._next(now)

    def on_weight(self, mass: float, stamp: float, now: float) -> list[PourCommand]:
        """A scale reading of ``mass`` [g] taken at clock time ``stamp`` [s]."""
        if not (math.isfinite(mass) and math.isfinite(stamp)):
            logger.warning("reading %r at %r ignored (not finite)", mass, stamp)
            return []
        self._last_reading, self._last_reading_time = float(mass), float(now)
        pouring = self._state in (PourState.POURING, PourState.HOLDING)
        if not pouring or stamp < self._t0:
            if self._state in (PourState.READY, PourState.BEFORE, PourState.POURING):
                self._early.append((float(stamp), float(mass)))
            return []
        if self._tare is None:
            recent = [m for t, m in self._early if t >= self._t0 - self.options.tare_window]
            self._tare = float(np.mean(recent)) if recent else 0.0
            self._early = []
        self._predictor.add(mass - self._tare, stamp - self._t0)
        predicted = self._stop_now(now)
        if predicted is not None:
            return self._end_pour(now, f"final mass {predicted:.1f} g predicted", predicted)
        return []

    def _stop_now(self, now: float) -> float | None:
        """The final mass predicted for ending the pour now, if now is the moment to
        (None: not yet).

        Holding at the end of the tilt: once the target is predicted. While tilting, the
        stop brakes ``stop_lead`` from now; it ends the pour now when the target is
        predicted, or when braking from the next reading (a scale period later) would end
        farther beyond the target than braking now ends short of it (what the stop pours
        is not smooth in where it brakes: the next chance may pour grams more)."""
        target = self.options.target
        if self._state is not PourState.POURING:
            predicted = self._predictor.predict(now - self._t0)
            return predicted if predicted is not None and predicted >= target else None
        tau = now + self.options.stop_lead - self._t0
        predicted = self._predictor.predict(tau)
        if predicted is None or predicted >= target:
            return predicted
        later = self._predictor.predict(tau + self._predictor.flow.period)
        if later is not None and later - target > target - predicted:
            return predicted
        return None

    def on_goal_result(self, goal_id: int, success: bool, message: str,
                       now: float) -> list[PourCommand]:
        """An arm or gripper goal finished. Results of replaced goals are ignored."""
        pending = self._pending
        if pending is None or pending.goal_id != goal_id:
            logger.debug("result of goal %d ignored (not the one awaited)", goal_id)
            return []
        self._pending = None
        if not success:
            return self._fault(f"{pending.kind} goal {goal_id} failed: {message}",
                               cancel=False)
        if pending.kind == "pour":
            self._state = PourState.HOLDING
            self._hold_since = now
            return []
        if pending.kind == "stop":
            return self._send_return(now)
        if pending.kind == "return":
            self._state = PourState.AFTER
            self._queue = list(self._after)
        return self._next(now)

    def on_arm_feedback(self, goal_id: int, time_from_start: float,
                        now: float) -> list[PourCommand]:
        """The trajectory controller's progress on a goal (its ``desired.time_from_start``
        [s]); a tilt that runs out of step with the controller's clock is a fault (the
        commanded flow would be wrong)."""
        pending = self._pending
        if pending is None or pending.goal_id != goal_id or pending.kind != "pour":
            return []
        lag = (now - self._t0) - time_from_start
        if abs(lag) > self.options.sync_tolerance:
            return self._fault(f"the tilt is {lag:+.3f} s out of step with the clock "
                               f"(tolerance {self.options.sync_tolerance} s)")
        return []

    def on_tick(self, now: float) -> list[PourCommand]:
        """Time passes: time-outs, a silent scale, the hold at the end of the tilt."""
        opts = self.options
        if self._state in (PourState.POURING, PourState.HOLDING) and \
                now - self._last_reading_time > opts.weight_timeout:
            return self._end_pour(now, f"no weight reading for {opts.weight_timeout:g} s", None)
        if self._state is PourState.HOLDING and now - self._hold_since > opts.hold_timeout:
            return self._end_pour(now, f"target not reached {opts.hold_timeout:g} s after "
                                  f"the tilt ended", None)
        if self._state is PourState.STOPPING:
            problem = self._prepare_return()
            if problem is not None:
                return self._fault(problem)
        pending = self._pending
        if pending is not None and now > pending.deadline:
            return self._fault(f"{pending.kind} goal {pending.goal_id} overdue")
        return []

    def kill(self, now: float) -> list[PourCommand]:
        """Stop everything now: a running tilt brakes along its path, a running stop
        finishes, any other goal is cancelled (the trajectory controller then holds the
        arm where it is); no further motion (FAULT)."""
        if self._state in (PourState.DONE, PourState.FAULT, PourState.READY):
            return []
        if self._state is PourState.POURING and self._pending is not None:
            try:
                stop = self._stop_goal(now, lead=0.0)  # a kill brakes at once
            except SafepathError as exc:  # no braking within the limits: cancel instead
                return self._fault(f"killed (no path-consistent stop: {exc})")
            return [stop, *self._fault("killed", cancel=False)]
        # Already braking along the path: let the stop finish (a cancel would halt the arm
        # at once), send nothing after it.
        return self._fault("killed", cancel=self._state is not PourState.STOPPING)

    # -- transitions -----------------------------------------------------------------------
    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    def _arm_goal(self, purpose: Literal["route", "pour", "stop", "return"],
                  traj: Trajectory, start_time: float) -> SendArmGoal:
        goal_id = self._new_id()
        deadline = start_time + traj.duration + self.options.motion_timeout_margin
        self._pending = _Pending(goal_id, purpose, deadline, start_time)
        return SendArmGoal(goal_id, purpose, traj, start_time)

    def _next(self, now: float) -> list[PourCommand]:
        if self._queue:
            step = self._queue.pop(0)
            if isinstance(step, GripperEvent):
                goal_id = self._new_id()
                self._pending = _Pending(goal_id, "gripper", now + self.options.gripper_timeout)
                return [SendGripperGoal(goal_id, step)]
            return [self._arm_goal("route", step, now + self.options.start_delay)]
        if self._state is PourState.BEFORE:
            self._state = PourState.POURING
            goal = self._arm_goal("pour", self.pour.trajectory, now + self.options.start_delay)
            self._t0 = goal.start_time
            self._last_reading_time = max(self._last_reading_time, self._t0) \
                if math.isfinite(self._last_reading_time) else self._t0
            return [goal]
        if self._state is PourState.AFTER:
            self._state = PourState.DONE
            predicted, decided, reason, stopped = self._decision or (None, None, "", False)
            self.report = PourReport(self.options.target, self._tare or 0.0,
                                     self._last_reading, predicted,
                                     self._predictor.gain, decided, reason, stopped)
            return [self.report]
        return []

    def _stop_goal(self, now: float, *, lead: float | None = None) -> SendArmGoal:
        """The stop braking ``lead`` after ``now`` (default ``stop_lead``, the lead the
        mass predictor assumes; a kill braking at once gives 0)."""
        tau = now - self._t0
        lead = self.options.stop_lead if lead is None else lead
        stop = self._stopper.stop(tau, tau + lead)
        return self._arm_goal("stop", stop, self._t0 + stop.info["time_offset"])

    def _end_pour(self, now: float, reason: str, predicted: float | None) -> list[PourCommand]:
        """Brake (while pouring) or not (holding at the end), then back upright.

        Only the stop is computed here (the decision's latency); the return is computed
        at the next event (a tick), while the arm brakes."""
        logger.info("pour ends: %s", reason)
        stopped = self._state is PourState.POURING
        self._decision = (predicted, now - self._t0, reason, stopped)
        self._return = None
        if not stopped:  # at rest at the end of the tilt
            self._s_rest = float(self.pour.s[-1])
            return self._send_return(now)
        try:
            stop = self._stop_goal(now)
        except SafepathError as exc:
            return self._fault(f"no path-consistent stop: {exc}")
        self._s_rest = float(stop.trajectory.info["s_rest"])
        self._state = PourState.STOPPING
        return [stop]

    def _prepare_return(self) -> str | None:
        """Compute the return upright from where the stop ends (None: done, else why not)."""
        if self._return is not None or self._s_rest <= 1e-9:
            return None
        try:
            self._return = self._stopper.back(self._s_rest)
        except SafepathError as exc:
            return f"no return upright within the limits: {exc}"
        return None

    def _send_return(self, now: float) -> list[PourCommand]:
        """The arm is at rest where the tilt stopped: back upright."""
        problem = self._prepare_return()
        if problem is not None:
            return self._fault(problem)
        if self._return is None:  # stopped before the cup turned at all
            self._state = PourState.AFTER
            self._queue = list(self._after)
            return self._next(now)
        self._state = PourState.RETURNING
        return [self._arm_goal("return", self._return, now)]

    def _fault(self, reason: str, *, cancel: bool = True) -> list[PourCommand]:
        logger.error("pour fault: %s", reason)
        out: list[PourCommand] = []
        pending = self._pending
        if cancel and pending is not None:
            out.append(CancelGoal(pending.goal_id))
        self._state = PourState.FAULT
        self._pending = None
        self._queue = []
        out.append(Fault(reason))
        return out


def _check_chain(steps: Sequence[Trajectory | GripperEvent], key: str) -> None:
    """Consecutive motions of ``steps`` join (each starts where the previous one ends)."""
    motions = [s for s in steps if isinstance(s, Trajectory)]
    for k in range(1, len(motions)):
        jump = float(np.max(np.abs(motions[k].q[0] - motions[k - 1].q[-1])))
        if not jump <= JOIN_TOLERANCE:
            raise InputError(f"motion {k} starts {jump:.4g} rad away from where the one "
                             f"before it ends", key=key)
