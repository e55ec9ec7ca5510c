"""What :class:`~safepath.cells.pouring.controller.PourController` takes and hands out: its
options, and the commands a node carries out (goals to send) and reads (the report).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from ...errors import InputError
from ...model.trajectory import GripperEvent, Trajectory
from ...ros.commands import CancelGoal, Fault

__all__ = ["PourCommand", "PourControllerOptions", "PourReport", "SendArmGoal",
           "SendGripperGoal"]


@dataclass(frozen=True, kw_only=True)
class PourControllerOptions:
    """Target and time-outs of the pour.

    Attributes:
        target: Mass to pour [g].
        min_reading: Poured masses below this are not used to fit the flow [g].
        tare_window: The scale's tare is the mean of its readings over this long before
            the tilt starts [s] (what was in the bowl; the target is what is poured).
        stop_lead: Time from a decision to the start of braking [s]: the stop goal must
            reach the trajectory controller before (it holds the tilt's knots until then).
        start_delay: Time from sending a motion from rest to its start [s].
        weight_timeout: Longest gap between readings while pouring [s]; then the pour
            stops and returns upright.
        hold_timeout: Longest wait at the end of the tilt for the target [s].
        motion_timeout_margin: Time allowed beyond a motion's duration [s].
        gripper_timeout: Longest gripper goal [s].
        sync_tolerance: Largest difference between the trajectory controller's progress
            (feedback) and the controller's own clock [s].
    """

    target: float = 100.0
    min_reading: float = 5.0
    tare_window: float = 0.5
    stop_lead: float = 0.05
    start_delay: float = 0.1
    weight_timeout: float = 0.5
    hold_timeout: float = 10.0
    motion_timeout_margin: float = 5.0
    gripper_timeout: float = 5.0
    sync_tolerance: float = 0.1

    def __post_init__(self) -> None:
        for name in ("target", "tare_window", "stop_lead", "start_delay", "weight_timeout",
                     "hold_timeout", "motion_timeout_margin", "gripper_timeout",
                     "sync_tolerance"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0:
                raise InputError(f"must be a number > 0, got {value!r}", key=name)
        if not (isinstance(self.min_reading, (int, float)) and math.isfinite(self.min_reading)
                and self.min_reading >= 0):
            raise InputError(f"must be a number >= 0 [g], got {self.min_reading!r}",
                             key="min_reading")


# -- commands ------------------------------------------------------------------------------
@dataclass(frozen=True)
class SendArmGoal:
    """Send ``trajectory`` to the arm's trajectory controller; answer with
    ``on_goal_result(goal_id, ...)``.

    Attributes:
        goal_id: The goal's id.
        purpose: ``route`` (a step before or after the pour), ``pour``, ``stop`` or
            ``return``. A ``stop`` replaces the running ``pour`` goal.
        trajectory: The motion.
        start_time: Clock time of the trajectory's t = 0 [s] (the goal's header.stamp).
    """

    goal_id: int
    purpose: Literal["route", "pour", "stop", "return"]
    trajectory: Trajectory = field(repr=False)
    start_time: float


@dataclass(frozen=True)
class SendGripperGoal:
    """Open or close the gripper (e.g. :func:`safepath.ros.gripper_command_goal` of
    ``event.action``); answer with ``on_goal_result(goal_id, ...)``."""

    goal_id: int
    event: GripperEvent


@dataclass(frozen=True)
class PourReport:
    """The pour is over.

    Attributes:
        target: The target [g].
        tare: The scale's reading before the tilt began [g].
        last_reading: The last reading when the report was made [g] (poured: minus tare).
        predicted: The final mass predicted at the decision [g] (None: never decided).
        gain: The fitted flow gain [g/s/rad^1.5] (None: no usable reading).
        decided_at: Tilt time of the decision [s] (None: none).
        reason: Why the pour ended (target predicted, scale silent, hold time-out).
        stopped: Whether the tilt was braked (False: it had finished).
    """

    target: float
    tare: float
    last_reading: float | None
    predicted: float | None
    gain: float | None
    decided_at: float | None
    reason: str
    stopped: bool


PourCommand = SendArmGoal | SendGripperGoal | CancelGoal | PourReport | Fault
