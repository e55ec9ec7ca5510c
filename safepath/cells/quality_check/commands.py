"""The quality-check controller's options, commands and cycle report.

:class:`~.controller.QualityCheckController` returns these commands for the ROS node to
carry out (and answer); :class:`~safepath.ros.commands.CancelGoal` and
:class:`~safepath.ros.commands.Fault` are the library's, shared with the other cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from ...errors import InputError
from ...model.trajectory import GripperEvent, Trajectory
from ...ros.commands import CancelGoal, Fault

__all__ = [
    "ActuateGripper",
    "CancelGoal",
    "Command",
    "ControllerOptions",
    "CycleReport",
    "Fault",
    "MoveArm",
    "RequestVerdict",
    "SetConveyor",
    "VERDICT_TIMEOUT",
]


#: The verdict time-out when none is given [s]: a service answering each request (the
#: rewritten node's test zone answers in 0.2-1.5 s).
VERDICT_TIMEOUT = 5.0


@dataclass(frozen=True, kw_only=True)
class ControllerOptions:
    """Route names and time-outs of the cell.

    Attributes:
        phase1_route: Conveyor -> test plate -> out of the camera's view.
        safe_route: Test plate -> packaging line -> back to the conveyor.
        unsafe_route: Test plate -> reject bin -> back to the conveyor.
        verdict_timeout: Longest wait for the verdict before deciding 'unsafe' [s]; None:
            :data:`VERDICT_TIMEOUT` (a caller that knows how its test zone answers, e.g.
            the twin's sequential baseline reading a publication every 5 s, sets it from
            that; see :attr:`verdict_wait`).
        motion_timeout_margin: Time allowed beyond a motion's duration [s].
        gripper_timeout: Longest gripper action [s].
        conveyor_timeout: Longest conveyor service call [s].
        belt_runs_while_working: Keep the conveyor running during the cycle, stopped only
            while a vial stands at the sensor (see the module docstring); False: stopped
            from the vial's detection to the arm's return, as the brief's node does.
    """

    phase1_route: str = "phase1"
    safe_route: str = "phase2_safe"
    unsafe_route: str = "phase2_unsafe"
    verdict_timeout: float | None = None
    motion_timeout_margin: float = 5.0
    gripper_timeout: float = 5.0
    conveyor_timeout: float = 5.0
    belt_runs_while_working: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.belt_runs_while_working, bool):
            raise InputError(f"expected True or False, got {self.belt_runs_while_working!r}",
                             key="belt_runs_while_working")
        routes = (self.phase1_route, self.safe_route, self.unsafe_route)
        if not all(isinstance(r, str) and r for r in routes) or len(set(routes)) != 3:
            raise InputError(f"need three distinct route names, got {list(routes)}",
                             key="routes")
        for name in ("verdict_timeout", "motion_timeout_margin", "gripper_timeout",
                     "conveyor_timeout"):
            value = getattr(self, name)
            if name == "verdict_timeout" and value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0:
                raise InputError(f"must be > 0 [s], got {value!r}", key=name)

    @property
    def verdict_wait(self) -> float:
        """The verdict time-out in force [s]: ``verdict_timeout``, else
        :data:`VERDICT_TIMEOUT`."""
        return VERDICT_TIMEOUT if self.verdict_timeout is None else float(self.verdict_timeout)

    @property
    def routes(self) -> tuple[str, str, str]:
        """The three route names."""
        return (self.phase1_route, self.safe_route, self.unsafe_route)


# -- commands ------------------------------------------------------------------------------
@dataclass(frozen=True)
class SetConveyor:
    """Run or stop the conveyor; answer with ``on_goal_result(goal_id, ...)``."""

    goal_id: int
    running: bool


@dataclass(frozen=True)
class MoveArm:
    """Execute one motion of a route; answer with ``on_goal_result(goal_id, ...)``."""

    goal_id: int
    route: str
    index: int
    trajectory: Trajectory = field(repr=False)


@dataclass(frozen=True)
class ActuateGripper:
    """Open or close the gripper; answer with ``on_goal_result(goal_id, ...)``."""

    goal_id: int
    route: str
    index: int
    event: GripperEvent


@dataclass(frozen=True)
class RequestVerdict:
    """Ask the test zone for the vial's verdict; answer with ``on_verdict``."""

    request_id: int



@dataclass(frozen=True)
class CycleReport:
    """One vial handled: for the HMI and the logs.

    Attributes:
        cycle: Cycle number, from 1.
        verdict: The decision taken.
        reason: Why (the verdict received, or why it counts as 'unsafe').
        route: The phase-2 route run.
        cycle_time: Object seen -> back at the conveyor [s].
        motion_time: Time the arm's motion goals took [s].
        planned_motion_time: Duration of those motions as planned by safepath [s].
        verdict_time: Wait for the verdict [s].
    """

    cycle: int
    verdict: Literal["safe", "unsafe"]
    reason: str
    route: str
    cycle_time: float
    motion_time: float
    planned_motion_time: float
    verdict_time: float



Command = (SetConveyor | MoveArm | ActuateGripper | RequestVerdict | CancelGoal | CycleReport
           | Fault)
