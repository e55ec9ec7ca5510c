"""The quality-check cell's state machine, driven through full cycles by a simulated cell."""

from __future__ import annotations

import heapq
import itertools
import math
import py_compile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from safepath.cells.quality_check.controller import (
    ActuateGripper,
    CancelGoal,
    CellState,
    Command,
    ControllerOptions,
    CycleReport,
    Fault,
    MoveArm,
    QualityCheckController,
    RequestVerdict,
    SetConveyor,
)
from safepath.errors import InputError

from .test_messages import phase1, phase2

TIMEOUT = object()  # the test zone never answers
GRIPPER_TIME = 0.3
CONVEYOR_TIME = 0.05
VERDICT_TIME = 0.2


class SimCell:
    """A fake cell: carries out the controller's commands and feeds the results back.

    Time advances only through scheduled events and 0.1 s ticks, so runs are exact.
    It also checks the cell's physical invariants as it goes.
    """

    def __init__(self, controller: QualityCheckController, *,
                 verdicts: tuple[object, ...] = (),
                 fail: Callable[[Command], bool] = lambda c: False,
                 silent: Callable[[Command], bool] = lambda c: False):
        self.ctrl = controller
        self.now = 0.0
        self.verdicts = list(verdicts)
        self.fail, self.silent = fail, silent
        self.conveyor: bool | None = None
        self.arm_q: np.ndarray | None = None
        self.holding = False
        self.placed: list[str] = []  # where the gripper released a vial
        self.commands: list[tuple[float, Command]] = []
        self.violations: list[str] = []
        self.queue: list[tuple[float, int, Callable[[], list[Command]]]] = []
        self.seq = itertools.count()
        self.next_tick = 0.1

    # -- driving ---------------------------------------------------------------------------
    def feed(self, commands: list[Command]) -> None:
        for cmd in commands:
            self.commands.append((self.now, cmd))
            self.execute(cmd)

    def start(self) -> None:
        for name, traj in (("phase1", phase1()), ("phase2_safe", phase2("safe")),
                           ("phase2_unsafe", phase2("unsafe"))):
            self.feed(self.ctrl.on_route_ready(name, traj, self.now))
        self.arm_q = phase1().q[0]
        self.run(1.0)

    def sensor(self, present: bool) -> None:
        self.feed(self.ctrl.on_sensor(present, self.now))

    def run(self, duration: float) -> None:
        end = self.now + duration
        while True:
            t_event = self.queue[0][0] if self.queue else math.inf
            t = min(t_event, self.next_tick)
            if t > end:
                self.now = end
                return
            self.now = t
            if self.next_tick <= t_event:
                self.next_tick += 0.1
                self.feed(self.ctrl.on_tick(t))
            else:
                _, _, action = heapq.heappop(self.queue)
                self.feed(action())

    def later(self, delay: float, action: Callable[[], list[Command]]) -> None:
        heapq.heappush(self.queue, (self.now + delay, next(self.seq), action))

    # -- the fake hardware -----------------------------------------------------------------
    def execute(self, cmd: Command) -> None:
        if isinstance(cmd, SetConveyor):
            self.later(CONVEYOR_TIME, lambda: self.conveyor_done(cmd))
        elif isinstance(cmd, MoveArm):
            self.move(cmd)
        elif isinstance(cmd, ActuateGripper):
            self.later(GRIPPER_TIME, lambda: self.gripper_done(cmd))
        elif isinstance(cmd, RequestVerdict):
            verdict = self.verdicts.pop(0)
            if verdict is not TIMEOUT:
                self.later(VERDICT_TIME, lambda: self.ctrl.on_verdict(
                    verdict, self.now, request_id=cmd.request_id))  # type: ignore[arg-type]

    def conveyor_done(self, cmd: SetConveyor) -> list[Command]:
        self.conveyor = cmd.running
        return self.ctrl.on_goal_result(cmd.goal_id, True, "ok", self.now)

    def move(self, cmd: MoveArm) -> None:
        traj = cmd.trajectory
        if self.conveyor is not False:
            self.violations.append(f"arm moved with the conveyor {self.conveyor}")
        if self.arm_q is not None and not np.allclose(self.arm_q, traj.q[0], atol=1e-9):
            self.violations.append(f"{cmd.route}[{cmd.index}] does not start at the arm")
        if self.silent(cmd):
            return
        ok = not self.fail(cmd)

        def done() -> list[Command]:
            if ok:
                self.arm_q = traj.q[-1]
            return self.ctrl.on_goal_result(cmd.goal_id, ok, "ok" if ok else "aborted",
                                            self.now)
        self.later(traj.duration + 0.01, done)

    def gripper_done(self, cmd: ActuateGripper) -> list[Command]:
        out: list[Command] = []
        if cmd.event.action == "close":
            self.holding = True
            if cmd.event.step == "grip":  # the vial leaves the sensor
                out += self.ctrl.on_sensor(False, self.now)
        else:
            self.holding = False
            self.placed.append(cmd.event.step)
        return out + self.ctrl.on_goal_result(cmd.goal_id, True, "ok", self.now)

    # -- views -----------------------------------------------------------------------------
    def of(self, kind: type) -> list:
        return [c for _, c in self.commands if isinstance(c, kind)]


def _cell(**kwargs: object) -> SimCell:
    cell = SimCell(QualityCheckController(), **kwargs)  # type: ignore[arg-type]
    cell.start()
    assert cell.ctrl.state is CellState.IDLE and cell.conveyor is True
    return cell


def test_safe_vial_goes_to_packaging() -> None:
    cell = _cell(verdicts=("safe",))
    cell.sensor(True)
    assert cell.conveyor is True  # the stop is pending; the arm has not moved yet
    assert cell.of(MoveArm) == [] and cell.of(ActuateGripper) == []
    cell.run(20.0)
    assert cell.violations == []
    assert cell.placed == ["low1", "safe"]
    assert cell.ctrl.state is CellState.IDLE and cell.conveyor is True
    (report,) = cell.of(CycleReport)
    assert (report.cycle, report.verdict, report.route) == (1, "safe", "phase2_safe")
    planned = phase1().duration + phase2("safe").duration
    assert report.planned_motion_time == pytest.approx(planned)
    assert report.motion_time == pytest.approx(planned + 5 * 0.01)
    assert report.verdict_time == pytest.approx(VERDICT_TIME)
    assert report.cycle_time == pytest.approx(CONVEYOR_TIME + planned + 5 * 0.01
                                              + 4 * GRIPPER_TIME + VERDICT_TIME)
    routes = [(c.route, c.index) for c in cell.of(MoveArm)]
    assert routes == [("phase1", 1), ("phase1", 3), ("phase2_safe", 0), ("phase2_safe", 2),
                      ("phase2_safe", 4)]
    # the verdict is asked only once the arm has left the test zone
    t_verdict = next(t for t, c in cell.commands if isinstance(c, RequestVerdict))
    t_last_phase1 = max(t for t, c in cell.commands
                        if isinstance(c, MoveArm) and c.route == "phase1")
    assert t_verdict >= t_last_phase1 + 0.6  # after the last phase-1 motion (0.6 s) ends


def test_unsafe_vial_goes_to_the_reject_bin() -> None:
    cell = _cell(verdicts=("unsafe",))
    cell.sensor(True)
    cell.run(20.0)
    assert cell.violations == [] and cell.placed == ["low1", "unsafe"]
    assert {c.route for c in cell.of(MoveArm)} == {"phase1", "phase2_unsafe"}
    (report,) = cell.of(CycleReport)
    assert (report.verdict, report.reason) == ("unsafe", "verdict 'unsafe'")
    assert cell.conveyor is True and cell.ctrl.state is CellState.IDLE


def test_missing_verdict_times_out_as_unsafe_and_a_late_answer_is_ignored() -> None:
    cell = _cell(verdicts=(TIMEOUT,))
    cell.sensor(True)
    cell.run(3.5)
    assert cell.ctrl.state is CellState.VERDICT
    (request,) = cell.of(RequestVerdict)
    cell.run(5.0)
    assert cell.ctrl.state is CellState.PHASE2
    # The answer arrives after the time-out: it must not change the decision.
    assert cell.ctrl.on_verdict("safe", cell.now, request_id=request.request_id) == []
    cell.run(20.0)
    (report,) = cell.of(CycleReport)
    assert report.verdict == "unsafe" and "no verdict within 5 s" in report.reason
    assert report.verdict_time == pytest.approx(5.0, abs=0.1)
    assert cell.placed == ["low1", "unsafe"] and cell.violations == []


@pytest.mark.parametrize("answer", [None, "", "SAFE", "safe ", "maybe", "Safe"])
def test_failed_or_malformed_verdict_is_unsafe(answer: str | None) -> None:
    cell = _cell(verdicts=(answer,))
    cell.sensor(True)
    cell.run(20.0)
    (report,) = cell.of(CycleReport)
    assert report.verdict == "unsafe" and cell.placed == ["low1", "unsafe"]


def test_verdict_outside_the_test_zone_is_ignored() -> None:
    cell = _cell(verdicts=("unsafe",))
    assert cell.ctrl.on_verdict("safe", cell.now) == []
    cell.sensor(True)
    cell.run(1.0)  # phase 1 under way
    assert cell.ctrl.on_verdict("safe", cell.now) == []
    cell.run(20.0)
    assert cell.of(CycleReport)[0].verdict == "unsafe"


def test_failed_robot_goal_stops_the_cell() -> None:
    cell = _cell(verdicts=("safe",),
                 fail=lambda c: isinstance(c, MoveArm) and c.route == "phase1" and c.index == 3)
    cell.sensor(True)
    cell.run(20.0)
    assert cell.ctrl.state is CellState.FAULT
    (fault,) = cell.of(Fault)
    assert "motion goal" in fault.reason and "aborted" in fault.reason
    assert cell.conveyor is False
    moves = len(cell.of(MoveArm))
    # Nothing moves any more: sensor, verdicts, ticks are all ignored.
    cell.sensor(True)
    cell.sensor(False)
    cell.sensor(True)
    assert cell.ctrl.on_verdict("safe", cell.now) == []
    cell.run(30.0)
    assert len(cell.of(MoveArm)) == moves and cell.conveyor is False
    assert cell.of(RequestVerdict) == [] and cell.of(CycleReport) == []
    # Only reset() leaves FAULT: the conveyor runs again, a new vial is needed.
    cell.arm_q = phase1().q[0]
    cell.feed(cell.ctrl.reset(cell.now))
    cell.run(1.0)
    assert cell.ctrl.state is CellState.IDLE and cell.conveyor is True
    assert len(cell.of(MoveArm)) == moves


def test_overdue_goal_is_cancelled_and_stops_the_cell() -> None:
    cell = _cell(silent=lambda c: isinstance(c, MoveArm))
    cell.sensor(True)
    cell.run(30.0)
    assert cell.ctrl.state is CellState.FAULT and cell.conveyor is False
    (move,) = cell.of(MoveArm)
    assert cell.of(CancelGoal) == [CancelGoal(move.goal_id)]
    assert "overdue" in cell.of(Fault)[0].reason


def test_sensor_glitch_during_motion_is_ignored() -> None:
    cell = _cell(verdicts=("safe",))
    cell.sensor(True)
    cell.run(1.5)
    assert cell.ctrl.state is CellState.PHASE1
    before = len(cell.commands)
    cell.sensor(True)
    cell.sensor(False)
    cell.sensor(True)
    cell.sensor(False)
    assert len(cell.commands) == before
    cell.run(20.0)
    assert len(cell.of(CycleReport)) == 1 and cell.violations == []
    assert cell.ctrl.state is CellState.IDLE and cell.conveyor is True
    assert [c.running for c in cell.of(SetConveyor)] == [True, False, True]


def test_object_waiting_at_the_end_starts_the_next_cycle() -> None:
    cell = _cell(verdicts=("safe", "unsafe"))
    cell.sensor(True)
    cell.run(5.0)
    cell.sensor(True)  # a second vial is already at the sensor
    cell.run(40.0)
    assert [r.verdict for r in cell.of(CycleReport)] == ["safe", "unsafe"]
    assert cell.violations == [] and cell.placed == ["low1", "safe", "low1", "unsafe"]
    assert cell.ctrl.cycles == 2 and cell.conveyor is True


def test_stale_goal_results_are_ignored() -> None:
    cell = _cell(verdicts=("safe",))
    cell.sensor(True)
    cell.run(1.0)
    assert cell.ctrl.on_goal_result(999, False, "stale", cell.now) == []
    assert cell.ctrl.state is CellState.PHASE1


def test_planning_failure_keeps_the_conveyor_stopped() -> None:
    ctrl = QualityCheckController()
    ctrl.on_route_ready("phase1", phase1(), 0.0)
    out = ctrl.on_route_failed("phase2_safe", "no path", 0.5)
    assert ctrl.state is CellState.FAULT
    assert [type(c) for c in out] == [SetConveyor, Fault] and out[0].running is False
    assert ctrl.on_sensor(True, 1.0) == []
    with pytest.raises(InputError):
        ctrl.on_route_ready("phase3", phase1(), 1.0)
    # Routes planned meanwhile are kept but start nothing until reset().
    assert ctrl.on_route_ready("phase2_unsafe", phase2("unsafe"), 1.5) == []
    assert ctrl.reset(2.0) == [] and ctrl.state is CellState.PLANNING
    out = ctrl.on_route_ready("phase2_safe", phase2("safe"), 3.0)  # re-planned
    assert ctrl.state is CellState.IDLE and out == [SetConveyor(out[0].goal_id, running=True)]


def test_nothing_runs_before_every_route_is_planned() -> None:
    ctrl = QualityCheckController()
    assert ctrl.on_sensor(True, 0.0) == []
    assert ctrl.on_route_ready("phase1", phase1(), 0.1) == []
    assert ctrl.on_route_ready("phase2_safe", phase2("safe"), 0.2) == []
    out = ctrl.on_route_ready("phase2_unsafe", phase2("unsafe"), 0.3)
    # the object seen while planning starts the first cycle: conveyor stop first
    assert out == [SetConveyor(out[0].goal_id, running=False)]
    assert ctrl.state is CellState.PHASE1


def test_options_are_checked() -> None:
    with pytest.raises(InputError):
        ControllerOptions(verdict_timeout=0.0)
    with pytest.raises(InputError):
        ControllerOptions(safe_route="phase1")
    opts = ControllerOptions(phase1_route="a", safe_route="b", unsafe_route="c",
                             verdict_timeout=2.0)
    ctrl = QualityCheckController(opts)
    for name, traj in (("a", phase1()), ("b", phase2("safe")), ("c", phase2("unsafe"))):
        ctrl.on_route_ready(name, traj, 0.0)
    assert ctrl.state is CellState.IDLE


def test_example_node_compiles(tmp_path: Path) -> None:
    example = Path(__file__).parents[2] / "examples" / "ros2" / "quality_check_node.py"
    py_compile.compile(str(example), cfile=str(tmp_path / "node.pyc"), doraise=True)


# -- the belt that keeps running while the robot works --------------------------------------
def _belt_cell(**kwargs: object) -> SimCell:
    ctrl = QualityCheckController(ControllerOptions(belt_runs_while_working=True))
    cell = SimCell(ctrl, **kwargs)  # type: ignore[arg-type]
    cell.start()
    assert ctrl.state is CellState.IDLE and cell.conveyor is True
    return cell


def _timeline(cell: SimCell) -> list[str]:
    out = []
    for _, c in cell.commands:
        if isinstance(c, SetConveyor):
            out.append("run" if c.running else "stop")
        elif isinstance(c, MoveArm):
            out.append(f"{c.route}[{c.index}]")
        elif isinstance(c, ActuateGripper):
            out.append(c.event.action)
    return out


def test_belt_runs_while_the_robot_works() -> None:
    cell = _belt_cell(verdicts=("safe", "unsafe"))
    cell.sensor(True)
    cell.run(3.0)  # the lift has ended (phase 1's first motion: 1.0 s)
    assert cell.conveyor is True and cell.ctrl.state is CellState.PHASE1
    # stop, pick, carry the vial off the belt, then restart the belt before the put-down
    assert _timeline(cell)[:5] == ["run", "stop", "close", "phase1[1]", "run"]
    cell.run(1.0)
    # the next vial reaches the sensor while the robot works: stopped at once
    n = len(cell.commands)
    cell.sensor(True)
    (stop,) = [c for _, c in cell.commands[n:]]
    assert isinstance(stop, SetConveyor) and stop.running is False
    assert cell.ctrl.state in (CellState.PHASE1, CellState.VERDICT, CellState.PHASE2)
    cell.run(0.5)
    assert cell.conveyor is False
    cell.run(40.0)
    assert [r.verdict for r in cell.of(CycleReport)] == ["safe", "unsafe"]
    assert cell.placed == ["low1", "safe", "low1", "unsafe"]
    # the second cycle starts at the first one's end, the belt confirmed stopped first
    line = _timeline(cell)
    picks = [k for k in range(len(line) - 1) if line[k:k + 2] == ["close", "phase1[1]"]]
    assert len(picks) == 2
    second = picks[1]
    assert line[second - 1] == "stop" and line[second + 2] == "run"
    assert cell.ctrl.state is CellState.IDLE and cell.conveyor is True
    assert cell.of(Fault) == []


def test_belt_is_not_restarted_while_a_vial_stands_at_the_sensor() -> None:
    cell = _belt_cell(verdicts=("safe", "safe"))
    cell.sensor(True)
    cell.run(0.5)  # the lift is under way
    assert cell.of(ActuateGripper)
    cell.sensor(True)  # a vial at the sensor as the lift runs (a sensor report)
    cell.run(20.0)
    line = _timeline(cell)
    # no restart after the lift: a vial stands at the sensor; the next cycle takes it
    assert line[:4] == ["run", "stop", "close", "phase1[1]"] and line[4] == "open"
    assert len(cell.of(CycleReport)) >= 1 and cell.of(Fault) == []


def test_gripper_does_not_close_unless_the_sensor_reports_a_vial() -> None:
    cell = _belt_cell(verdicts=("safe",))
    cell.sensor(True)
    cell.sensor(False)  # the vial was taken away before the belt's stop was confirmed
    cell.run(5.0)
    assert cell.ctrl.state is CellState.FAULT
    assert cell.of(ActuateGripper) == [] and cell.of(MoveArm) == []
    assert "no vial" in cell.of(Fault)[0].reason and cell.conveyor is False


def test_belt_stop_that_is_never_confirmed_stops_the_cell() -> None:
    cell = _belt_cell(verdicts=("safe",))
    cell.sensor(True)
    cell.run(4.0)
    ctrl = cell.ctrl
    (stop,) = ctrl.on_sensor(True, cell.now)  # sent, never answered
    assert isinstance(stop, SetConveyor) and stop.running is False
    out = ctrl.on_tick(cell.now + ctrl.options.conveyor_timeout + 0.01)
    assert ctrl.state is CellState.FAULT and "overdue" in out[-1].reason  # type: ignore[union-attr]


def test_belt_option_is_checked_and_off_by_default() -> None:
    assert ControllerOptions().belt_runs_while_working is False
    with pytest.raises(InputError):
        ControllerOptions(belt_runs_while_working=1)  # type: ignore[arg-type]
