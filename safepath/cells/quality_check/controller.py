"""The decision logic of the quality-check cell, without ROS: an explicit state machine.

Inputs are events (routes planned, sensor reading, safety verdict, goal result, clock
tick), each with the current time; outputs are the commands each event returns, for
the ROS node to carry out and answer with ``on_goal_result`` / ``on_verdict``. No
threads and no clock inside, so every cycle can be replayed in a test.

::

    PLANNING --all routes planned--> IDLE (conveyor running)
    IDLE --object seen--> PHASE1: stop conveyor, pick, place on the test plate, clear the camera
    PHASE1 --done--> VERDICT: ask the test zone, with a time-out
    VERDICT --'safe'--> PHASE2 (safe route: packaging)
    VERDICT --'unsafe', none, malformed, time-out--> PHASE2 (unsafe route: reject)
    PHASE2 --done--> report the cycle; IDLE (conveyor restarted) or PHASE1 (object waiting)
    any --failed or overdue goal, failed planning--> FAULT: conveyor stopped, no motion
    FAULT --reset()--> IDLE (PLANNING while a route is missing)

With ``ControllerOptions(belt_runs_while_working=True)`` the conveyor is restarted as soon
as the picked vial has left the belt (the first phase-1 motion after the gripper closed
has ended, the arm over the test plate) and keeps running while the robot works; when the
next vial reaches the sensor during the cycle the conveyor is stopped at once (a command
of its own, beside the arm's goal: the cell's belt also halts by itself under a vial at
the sensor, ``scenes/quality_check_cell/README.md``), and the next cycle takes it. Before
the gripper closes on the conveyor the sensor must report the vial (else FAULT). The
routes are safe with a vial standing at the sensor while the arm works elsewhere
(``docs/twin.md``); the pick's lift is the only motion that passes where the next vial
would stand, and the belt stays stopped until it has ended.

A route runs as the steps of :func:`~safepath.ros.goals.split_at_gripper_events`: each
motion or gripper goal is sent only after the previous one succeeded. Only the exact
verdict ``'safe'`` sends a vial to packaging.
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass
from typing import Literal

from ...errors import InputError, TrajectoryError
from ...files._io import check_names
from ...model.trajectory import GripperEvent, Trajectory
from ...ros.goals import split_at_gripper_events
from .commands import (
    ActuateGripper,
    CancelGoal,
    Command,
    ControllerOptions,
    CycleReport,
    Fault,
    MoveArm,
    RequestVerdict,
    SetConveyor,
)

__all__ = [
    "ActuateGripper",
    "CancelGoal",
    "CellState",
    "Command",
    "ControllerOptions",
    "CycleReport",
    "Fault",
    "MoveArm",
    "QualityCheckController",
    "RequestVerdict",
    "SetConveyor",
]

logger = logging.getLogger(__name__)


class CellState(enum.Enum):
    """States of :class:`QualityCheckController`."""

    PLANNING = "planning"
    IDLE = "idle"
    PHASE1 = "phase1"
    VERDICT = "verdict"
    PHASE2 = "phase2"
    FAULT = "fault"


_Step = Trajectory | GripperEvent | bool  # bool: a conveyor command (running?)


@dataclass
class _Pending:
    """The one answer the controller is waiting for."""

    goal_id: int
    kind: Literal["conveyor", "motion", "gripper", "verdict"]
    sent: float
    deadline: float
    planned: float = 0.0


class QualityCheckController:
    """The quality-check cell's state machine (see the module docstring).

    Not thread-safe: a node calls it from one thread at a time (e.g. under a lock).

    Args:
        options: Route names and time-outs.
    """

    def __init__(self, options: ControllerOptions | None = None):
        self.options = options or ControllerOptions()
        self._programs: dict[str, list[Trajectory | GripperEvent]] = {}
        self._state = CellState.PLANNING
        self._object_present = False
        self._next_id = 0
        self._pending: _Pending | None = None
        self._belt_goals: dict[int, _Pending] = {}  # conveyor stops sent beside the arm's goal
        self._belt_commanded: bool | None = None
        self._queue: list[tuple[str, int, _Step]] = []
        self._cycles = 0
        self._cycle_start = 0.0
        self._motion_time = self._planned_time = self._verdict_time = 0.0
        self._verdict: tuple[Literal["safe", "unsafe"], str] = ("unsafe", "")
        self.last_report: CycleReport | None = None

    @property
    def state(self) -> CellState:
        """The current state."""
        return self._state

    @property
    def cycles(self) -> int:
        """Number of completed cycles."""
        return self._cycles

    # -- events ----------------------------------------------------------------------------
    def on_route_ready(self, name: str, trajectory: Trajectory, now: float) -> list[Command]:
        """A route has been planned; once all three are, the conveyor starts.

        Routes are taken while planning and in FAULT (kept for after ``reset()``);
        never while the cell runs.
        """
        check_names([name], self.options.routes, path=None, key="route", what="route",
                    error=InputError)
        if self._state not in (CellState.PLANNING, CellState.FAULT):
            logger.warning("route '%s' arrived in state %s: ignored", name, self._state.value)
            return []
        try:
            self._programs[name] = split_at_gripper_events(trajectory)
        except TrajectoryError as exc:
            return self._fault(f"route '{name}' cannot be executed: {exc}")
        if self._state is CellState.PLANNING and all(r in self._programs
                                                     for r in self.options.routes):
            return self._ready(now)
        return []

    def on_route_failed(self, name: str, reason: str, now: float) -> list[Command]:
        """Planning a route failed: the cell cannot run."""
        return self._fault(f"planning route '{name}' failed: {reason}")

    def on_sensor(self, object_present: bool, now: float) -> list[Command]:
        """The conveyor's presence sensor changed. Only acted on in IDLE."""
        self._object_present = bool(object_present)
        if self._state is CellState.IDLE and self._object_present:
            return self._begin_cycle(now)
        if (self._object_present and self.options.belt_runs_while_working
                and self._belt_commanded and self._state in (
                    CellState.PHASE1, CellState.VERDICT, CellState.PHASE2)):
            # the next vial reached the sensor while the robot works: stop the belt now
            goal_id = self._new_id()
            self._belt_goals[goal_id] = _Pending(goal_id, "conveyor", now,
                                                 now + self.options.conveyor_timeout)
            self._belt_commanded = False
            return [SetConveyor(goal_id, running=False)]
        if object_present and self._state is not CellState.IDLE:
            logger.debug("object reading in state %s: not acted on", self._state.value)
        return []

    def on_verdict(self, verdict: str | None, now: float, *,
                   request_id: int | None = None) -> list[Command]:
        """The test zone answered (``None``: the call failed). Anything but 'safe' is unsafe.

        Args:
            verdict: The service's answer.
            now: Current time [s].
            request_id: The :class:`RequestVerdict` it answers; an answer to an older
                request (after a time-out) is ignored.
        """
        pending = self._pending
        if self._state is not CellState.VERDICT or pending is None or (
                request_id is not None and request_id != pending.goal_id):
            logger.warning("verdict %r arrived in state %s: ignored", verdict, self._state.value)
            return []
        self._verdict_time = now - pending.sent
        if verdict == "safe":
            return self._decide("safe", "verdict 'safe'", now)
        if verdict == "unsafe":
            return self._decide("unsafe", "verdict 'unsafe'", now)
        reason = "verdict call failed" if verdict is None else f"malformed verdict {verdict!r}"
        logger.warning("vial treated as unsafe: %s", reason)
        return self._decide("unsafe", reason, now)

    def on_goal_result(self, goal_id: int, success: bool, message: str,
                       now: float) -> list[Command]:
        """A conveyor, motion or gripper goal finished."""
        side = self._belt_goals.pop(goal_id, None)
        if side is not None:
            if not success:
                return self._fault(f"conveyor goal {goal_id} failed: {message}")
            return []
        pending = self._pending
        if pending is None or pending.goal_id != goal_id or pending.kind == "verdict":
            logger.debug("result of goal %d ignored (not the one awaited)", goal_id)
            return []
        self._pending = None
        if not success:
            return self._fault(f"{pending.kind} goal {goal_id} failed: {message}")
        if pending.kind == "motion":
            self._motion_time += now - pending.sent
            self._planned_time += pending.planned
        return self._next(now)

    def on_tick(self, now: float) -> list[Command]:
        """Time passes: enforce the time-outs."""
        for side in self._belt_goals.values():
            if now >= side.deadline:
                return self._fault(f"conveyor goal {side.goal_id} overdue "
                                   f"({now - side.sent:.1f} s)")
        pending = self._pending
        if pending is None or now < pending.deadline:
            return []
        if pending.kind == "verdict":
            self._verdict_time = now - pending.sent
            reason = f"no verdict within {self.options.verdict_wait:g} s"
            logger.warning("vial treated as unsafe: %s", reason)
            return self._decide("unsafe", reason, now)
        return self._fault(f"{pending.kind} goal {pending.goal_id} overdue "
                           f"({now - pending.sent:.1f} s)")

    def reset(self, now: float) -> list[Command]:
        """Leave FAULT once an operator has cleared the cell and brought the arm back to
        the start of the phase-1 route. A no-op in any other state."""
        if self._state is not CellState.FAULT:
            return []
        logger.info("reset")
        self._object_present = False  # ask for a fresh reading, not a stale one
        self._state = CellState.PLANNING
        if all(r in self._programs for r in self.options.routes):
            return self._ready(now)
        return []

    # -- transitions -----------------------------------------------------------------------
    def _new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    def _ready(self, now: float) -> list[Command]:
        """Wait for the next object (or take the one already there)."""
        if self._object_present:
            return self._begin_cycle(now)
        self._state = CellState.IDLE
        self._queue = [("", 0, True)]
        return self._next(now)

    def _begin_cycle(self, now: float) -> list[Command]:
        logger.info("object detected: cycle %d", self._cycles + 1)
        self._state = CellState.PHASE1
        self._cycle_start = now
        self._motion_time = self._planned_time = self._verdict_time = 0.0
        self._queue = [("", 0, False)] + self._route(self.options.phase1_route)
        if self.options.belt_runs_while_working:
            # restart the belt once the motion carrying the vial off the belt has ended
            steps = [step for _, _, step in self._queue]
            close = next((k for k, step in enumerate(steps) if isinstance(step, GripperEvent)
                          and step.action == "close"), None)
            if close is not None:
                lift = next((k for k in range(close + 1, len(steps))
                             if isinstance(steps[k], Trajectory)), None)
                if lift is not None:
                    self._queue.insert(lift + 1, ("", 0, True))
        return self._next(now)

    def _route(self, name: str) -> list[tuple[str, int, _Step]]:
        return [(name, k, step) for k, step in enumerate(self._programs[name])]

    def _decide(self, verdict: Literal["safe", "unsafe"], reason: str,
                now: float) -> list[Command]:
        self._pending = None
        self._verdict = (verdict, reason)
        self._state = CellState.PHASE2
        route = self.options.safe_route if verdict == "safe" else self.options.unsafe_route
        self._queue = self._route(route)
        return self._next(now)

    def _next(self, now: float) -> list[Command]:
        """Send the next step of the current phase, or finish the phase."""
        if not self._queue:
            return self._phase_done(now)
        route, index, step = self._queue.pop(0)
        opts = self.options
        if opts.belt_runs_while_working and self._state is CellState.PHASE1:
            if step is True and self._object_present:
                return self._next(now)  # a vial is at the sensor already: keep the belt still
            if (isinstance(step, GripperEvent) and step.action == "close"
                    and route == opts.phase1_route and not self._object_present):
                return self._fault("the sensor reports no vial at the conveyor: the gripper "
                                   "does not close")
        goal_id = self._new_id()
        if isinstance(step, Trajectory):
            self._pending = _Pending(goal_id, "motion", now,
                                     now + step.duration + opts.motion_timeout_margin,
                                     planned=step.duration)
            return [MoveArm(goal_id, route, index, step)]
        if isinstance(step, GripperEvent):
            self._pending = _Pending(goal_id, "gripper", now, now + opts.gripper_timeout)
            return [ActuateGripper(goal_id, route, index, step)]
        self._pending = _Pending(goal_id, "conveyor", now, now + opts.conveyor_timeout)
        self._belt_commanded = step
        return [SetConveyor(goal_id, running=step)]

    def _phase_done(self, now: float) -> list[Command]:
        if self._state is CellState.PHASE1:
            self._state = CellState.VERDICT
            request_id = self._new_id()
            self._pending = _Pending(request_id, "verdict", now,
                                     now + self.options.verdict_wait)
            return [RequestVerdict(request_id)]
        if self._state is CellState.PHASE2:
            self._cycles += 1
            verdict, reason = self._verdict
            report = CycleReport(
                cycle=self._cycles, verdict=verdict, reason=reason,
                route=self.options.safe_route if verdict == "safe" else self.options.unsafe_route,
                cycle_time=now - self._cycle_start, motion_time=self._motion_time,
                planned_motion_time=self._planned_time, verdict_time=self._verdict_time)
            self.last_report = report
            return [report, *self._ready(now)]
        return []  # IDLE: the conveyor is confirmed running

    def _fault(self, reason: str) -> list[Command]:
        logger.error("fault: %s", reason)
        out: list[Command] = []
        if self._pending is not None and self._pending.kind in ("motion", "gripper"):
            out.append(CancelGoal(self._pending.goal_id))
        self._state = CellState.FAULT
        self._pending = None
        self._belt_goals = {}
        self._belt_commanded = False
        self._queue = []
        out += [SetConveyor(self._new_id(), running=False), Fault(reason)]
        return out
