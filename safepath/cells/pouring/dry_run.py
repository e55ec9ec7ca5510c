"""A dry run of the pour controller: a simulated cell around a :class:`PourController`.

A trajectory controller that runs goals by their stamps (a new goal replaces the running
one, as ros2_controllers' does; a cancelled one holds the arm), a gripper (the cup is held
between a ``close`` and an ``open``), and the simulated scale of
:mod:`safepath.cells.pouring.flow` (its :class:`FlowModel`: flow law, fall time, latency,
noise) weighing what the cup pours at the tilt the arm really has (forward kinematics of
the executed joints). Every step is ``DT``; used by the tests and
``benchmarks/pour_controller.py``, and to try a pour before a robot runs it.
"""

from __future__ import annotations

import bisect
import time
from dataclasses import dataclass, field

import numpy as np

from ...cell import Cell
from ...model.trajectory import Trajectory
from ...planning.pour import cup_axis_in_tcp, tilt_of
from ...ros.commands import CancelGoal, Fault
from .controller import PourCommand, PourController, PourReport, SendArmGoal, SendGripperGoal
from .flow import FlowModel

__all__ = ["DT", "PourSim", "Run", "commands_of"]

DT = 0.004  # [s] simulation step (the knot period)


@dataclass
class Run:
    """What happened in one simulated pour.

    Attributes:
        final_mass: Mass poured into the bowl once everything landed [g].
        commands: (clock time [s], command) of every command.
        t: Simulation times [s].
        q: Joint positions at those times [rad].
        tilt: Tilt of the held cup [rad] (0 while it stands on the table).
        readings: (stamp [s], reading [g]) of the scale.
        report: The controller's report (None: it did not finish).
        decision_time: Wall time of the event call that sent the stop [s] (None: none).
        tick_time: Longest wall time of a tick call [s] (the one that computed the return
            upright, when there was a stop).
        faults: Faults the controller reported.
    """

    final_mass: float
    commands: list[tuple[float, PourCommand]]
    t: np.ndarray
    q: np.ndarray
    tilt: np.ndarray
    readings: list[tuple[float, float]]
    report: PourReport | None
    decision_time: float | None = None
    tick_time: float = 0.0
    faults: list[Fault] = field(default_factory=list)


class PourSim:
    """Drives a :class:`PourController` on a simulated clock (see the module doc).

    Args:
        cell: The pouring cell (robot and held cup).
        truth: The simulated cup and scale.
        gripper_time: Duration of a gripper goal [s].
        initial_mass: What the bowl holds before the pour [g] (the scale reads it).
    """

    def __init__(self, cell: Cell, truth: FlowModel, *, gripper_time: float = 0.5,
                 initial_mass: float = 0.0) -> None:
        self.cell, self.truth = cell, truth
        self.axis = cup_axis_in_tcp(cell)
        self.gripper_time, self.initial_mass = gripper_time, initial_mass
        self.decision_time: float | None = None
        self.tick_time = 0.0
        self.rng = np.random.default_rng(truth.seed)
        self.now = 0.0
        self.arm: tuple[int, Trajectory, float] | None = None  # (goal id, trajectory, start)
        self.gripper: tuple[int, float, str] | None = None  # (goal id, end time, action)
        self.holding = True  # the cup is in the gripper (else upright on the table)
        self.log: list[tuple[float, PourCommand]] = []
        self.faults: list[Fault] = []
        self.results: list[tuple[int, bool, str]] = []  # (goal id, success, message)
        self.feedback: list[tuple[int, float]] = []  # (goal id, time from start [s])
        self.ts: list[float] = []
        self.qs: list[np.ndarray] = []
        self.tilts: list[float] = []
        self.out: list[float] = []  # mass out of the cup [g]
        self.readings: list[tuple[float, float]] = []

    def tilt(self, q: np.ndarray) -> float:
        """Tilt of the held cup at joint positions ``q`` [rad]."""
        return tilt_of(self.cell.robot.frame_pose(q).rotation, self.axis)

    def handle(self, cmds: list[PourCommand]) -> None:
        """Carry out the controller's commands."""
        for c in cmds:
            self.log.append((self.now, c))
            if isinstance(c, SendArmGoal):
                if self.arm is not None:  # replaced, as ros2_controllers does
                    self.results.append((self.arm[0], False, "replaced"))
                self.arm = (c.goal_id, c.trajectory, c.start_time)
            elif isinstance(c, SendGripperGoal):
                self.gripper = (c.goal_id, self.now + self.gripper_time, c.event.action)
            elif isinstance(c, CancelGoal):
                if self.arm is not None and self.arm[0] == c.goal_id:
                    self.results.append((self.arm[0], False, "canceled"))
                    self.arm = None
            elif isinstance(c, Fault):
                self.faults.append(c)

    def step_arm(self, q: np.ndarray) -> np.ndarray:
        """The running goal sampled at its own time (held before its start); the gripper."""
        if self.gripper is not None and self.now >= self.gripper[1]:
            self.results.append((self.gripper[0], True, ""))
            self.holding = self.gripper[2] == "close"
            self.gripper = None
        if self.arm is None:
            return q
        goal_id, traj, start = self.arm
        tau = self.now - start
        if tau >= 0.0:
            q = traj.sample([min(tau, traj.duration)])[0][0]
        if tau >= traj.duration:
            self.arm = None
            self.results.append((goal_id, True, ""))
        elif tau >= 0.0 and int(round(tau / DT)) % 25 == 0:
            self.feedback.append((goal_id, tau))
        return q

    def record(self, q: np.ndarray) -> None:
        """The arm's state and the mass out of the cup (flow law of the real tilt)."""
        self.ts.append(self.now)
        self.qs.append(q.copy())
        self.tilts.append(self.tilt(q) if self.holding else 0.0)
        if len(self.tilts) == 1:
            self.out.append(0.0)
            return
        rate = self.truth.rate(np.array(self.tilts[-2:]))
        self.out.append(self.out[-1] + 0.5 * float(rate.sum()) * DT)

    def read_scale(self) -> float:
        """What landed ``latency`` ago, plus noise."""
        truth = self.truth
        at = self.now - truth.latency - truth.fall_time
        # np.interp on the two samples around ``at`` (ts rises): the same number as on
        # every sample, without copying the whole record at every reading.
        k = bisect.bisect_right(self.ts, at)
        lo = max(k - 1, 0)
        landed = float(np.interp(at, np.array(self.ts[lo:k + 1]), np.array(self.out[lo:k + 1]),
                                 left=0.0))
        value = self.initial_mass + landed + float(self.rng.normal(0.0, truth.noise))
        self.readings.append((self.now, value))
        return value

    def deliver(self, ctrl: PourController) -> None:
        """Hand the goal results and feedback of this step to the controller."""
        for goal_id, success, message in self.results:
            self.handle(ctrl.on_goal_result(goal_id, success, message, self.now))
        for goal_id, progress in self.feedback:
            self.handle(ctrl.on_arm_feedback(goal_id, progress, self.now))
        self.results.clear()
        self.feedback.clear()

    def run(self, ctrl: PourController, q_start: np.ndarray, *, max_time: float = 60.0,
            kill_at: float | None = None, silent_after: float | None = None,
            holding: bool = True) -> Run:
        """Run ``ctrl`` from ``start()`` until it is done (plus the time for everything to
        land) or ``max_time`` [s]. One run per :class:`PourSim`.

        Args:
            ctrl: A controller in its READY state.
            q_start: Where the arm is [rad].
            max_time: Longest simulated time [s].
            kill_at: Clock time of a ``kill()`` [s], if any.
            silent_after: The scale stops publishing at this clock time [s], if given.
            holding: Whether the cup is in the gripper at the start.
        """
        truth = self.truth
        self.holding = holding
        q = np.array(q_start, dtype=float)
        self.record(q)
        next_reading = truth.period
        done_at: float | None = None
        self.handle(ctrl.start(self.now))
        while self.now < max_time:
            self.now = round(self.now + DT, 9)
            q = self.step_arm(q)
            self.record(q)
            self.deliver(ctrl)
            if self.now >= next_reading - 1e-9:
                next_reading += truth.period
                if silent_after is None or self.now < silent_after:
                    value = self.read_scale()
                    start = time.perf_counter()
                    cmds = ctrl.on_weight(value, self.now, self.now)
                    if any(isinstance(c, SendArmGoal) for c in cmds):
                        self.decision_time = time.perf_counter() - start
                    self.handle(cmds)
            if kill_at is not None and self.now >= kill_at:
                kill_at = None
                self.handle(ctrl.kill(self.now))
            start = time.perf_counter()
            cmds = ctrl.on_tick(self.now)
            self.tick_time = max(self.tick_time, time.perf_counter() - start)
            self.handle(cmds)
            if done_at is None and (ctrl.report is not None or self.faults) and self.arm is None:
                done_at = self.now
            if done_at is not None and self.now > done_at + truth.latency + truth.fall_time + 0.5:
                break
        return Run(self.out[-1], self.log, np.array(self.ts), np.array(self.qs),
                   np.array(self.tilts), self.readings, ctrl.report, self.decision_time,
                   self.tick_time, self.faults)


def commands_of(run: Run, kind: type) -> list[tuple[float, PourCommand]]:
    """The commands of ``run`` of one type, with their clock times [s]."""
    return [(t, c) for t, c in run.commands if isinstance(c, kind)]
