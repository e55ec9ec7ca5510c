"""The quality-check cell's twin: its state machine closed loop on a simulated cell.

The cell's own state machine
(:class:`~safepath.cells.quality_check.QualityCheckController`) decides; everything
around it is simulated on one clock:
vials arriving on the conveyor (:class:`~safepath.sim.conveyor.Conveyor`), the IR
sensor, the verdict service with its latency, time-outs and malformed answers
(:class:`~safepath.sim.conveyor.VerdictService`), and the robot
(:class:`~safepath.sim.twin.RobotTwin`: MuJoCo physics, its trajectory controller
executing the ``FollowJointTrajectory`` goals the library emits, the gripper executing
Niryo ``Tool`` goals). The node's timer ticks every ``tick`` (time-outs), events are
handled at the physics step they fall in.

Two architectures run on the same twin:

* ``safepath``: the planned, blended motions and a verdict service answering each
  request (the rewritten node of ``examples/ros2/quality_check_node.py``);
* ``sequential``: the brief's: every route step rest to rest
  (:func:`~safepath.sim.stop_and_go.stop_and_go`), the verdict read from the test zone's
  publications every 5 s, with a time-out those publications can meet (their period plus
  the longest inference, 6.5 s); the same state machine sequences the cell, so the
  difference is the architecture, not the bookkeeping.

``QualityCheckParams(controller=ControllerOptions(belt_runs_while_working=True))`` runs
the ``safepath`` architecture with the belt running while the robot works: the next vial
rides to the sensor during the cycle and waits there; every motion during which a vial
stood at the sensor is checked against the cell with that vial in it
(:func:`waiting_vial_cell`).

:func:`run_quality_check` is a plain function of ``(cell, seed, params)``: a process pool
(:func:`safepath.sim.sweep.run_many`) or a cluster engine maps it over seeds and
parameters, and a seed gives the same run.
"""

from __future__ import annotations

import functools
import heapq
import json
import math
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..errors import InputError
from .arm import CANCELED, ArmResult
from .bag import RunRecord
from .clearance import ExecutedClearance, MotionWorld, executed_clearance, tcp_deviation
from .conveyor import Conveyor, VerdictService, Vial
from .kept_warnings import kept_warnings
from .twin import GripperResult, RobotTwin, TwinOptions

if TYPE_CHECKING:
    from ..cell import Cell
    from ..cells.quality_check.commands import Command, ControllerOptions, CycleReport
    from ..model.trajectory import Trajectory

__all__ = ["QualityCheckParams", "QualityCheckRun", "run_quality_check", "ARCHITECTURES",
           "WAITING_VIAL", "waiting_vial_cell", "QUEUED_VIAL", "queued_vials_cell",
           "SEQUENTIAL_PERIOD"]

Architecture = Literal["safepath", "sequential"]
#: The brief's test zone publishes its verdict every 5 s (seed 000) [s].
SEQUENTIAL_PERIOD = 5.0
ARCHITECTURES: tuple[str, ...] = ("safepath", "sequential")


def _controller_options() -> ControllerOptions:
    from ..cells.quality_check.commands import ControllerOptions

    return ControllerOptions()


@dataclass(frozen=True, kw_only=True)
class QualityCheckParams:
    """One run of the quality-check twin.

    Attributes:
        duration: Simulated time [s].
        architecture: ``safepath`` or ``sequential`` (see the module docstring).
        arrival_interval: Mean time between vials put on the belt [s] (exponential).
        belt_speed: Conveyor speed [m/s].
        belt_length: Distance a vial rides to the sensor [m].
        vial_spacing: Least distance between vials' centres on the belt [m]. The default
            is the quality-check cell's minimum (``scenes/quality_check_cell/README.md``:
            the open jaws straddle the picked vial along the belt and keep the cell's
            10 mm margin from a vial queued 35 mm behind it; vials touching, 16 mm
            apart, are hit by the jaws at ``grip`` whatever the route).
        p_unsafe: Probability that a vial is unsafe.
        verdict: The test zone's service (its ``period`` is set to
            :data:`SEQUENTIAL_PERIOD` for the sequential architecture unless given).
        controller: The state machine's route names and time-outs. With the verdict read
            from publications (``verdict.period``) and no ``verdict_timeout`` given, the
            time-out is their longest answer, period + longest inference
            (:attr:`VerdictService.longest_answer`, 6.5 s); a given one is kept.
        twin: How the robot is simulated.
        tick: Period of the node's timer [s].
        conveyor_latency: Answer time of the conveyor service [s].
    """

    duration: float = 300.0
    architecture: Architecture = "safepath"
    arrival_interval: float = 10.0
    belt_speed: float = 0.05
    belt_length: float = 0.40
    vial_spacing: float = 0.035
    p_unsafe: float = 0.3
    verdict: VerdictService = field(default_factory=VerdictService)
    controller: ControllerOptions = field(default_factory=_controller_options)
    twin: TwinOptions = field(default_factory=TwinOptions)
    tick: float = 0.01
    conveyor_latency: float = 0.05

    def __post_init__(self) -> None:
        if self.architecture not in ARCHITECTURES:
            raise InputError(f"expected one of {list(ARCHITECTURES)}, got "
                             f"{self.architecture!r}", key="architecture")
        for key in ("duration", "arrival_interval", "belt_speed", "belt_length",
                    "vial_spacing", "tick", "conveyor_latency"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0:
                raise InputError(f"expected a finite number > 0, got {value!r}", key=key)
        if not 0 <= self.p_unsafe <= 1:
            raise InputError(f"expected a probability, got {self.p_unsafe!r}", key="p_unsafe")


@dataclass(frozen=True)
class QualityCheckRun:
    """What one run of the twin did.

    Attributes:
        seed: The run's seed.
        architecture: Its architecture.
        duration: Simulated time [s].
        wall_time: Computation time of the simulation [s] (planning and the clearance
            check excluded, each given apart).
        clearance_time: Computation time of the executed-clearance check [s].
        vials_arrived: Vials put on the belt.
        cycles: The controller's cycle reports, in order (a cycle ends with the arm
            back at the conveyor).
        packaging: Vials placed on the packaging line by a reported cycle.
        rejected: Vials dropped into the reject bin by a reported cycle (with
            ``packaging``, ``len(cycles)`` in all, but for ``empty_picks``).
        unsafe_packaged: Unsafe vials placed on the packaging line by any cycle (must
            be 0).
        in_progress: Vials picked whose cycle the run's end cut short (at most one).
        reasons: How often each verdict reason occurred.
        faults: The controller's faults, in words.
        robot_idle: Time the arm had no goal [s].
        conveyor_idle: Time the belt stood still [s].
        tracking: Largest |commanded - executed| position per joint while goals ran [rad].
        speed_ratio: Largest |executed speed| / limit per joint.
        contact_steps: Physics steps in which the arm touched the cell (MuJoCo).
        clearance: Executed clearance against the cell (safepath's checker).
        tcp_deviation: Largest distance between the executed and the commanded TCP
            position while goals ran (at the record rate) [m]: the tracking allowance.
        margin: The cell's safety margin [m].
        joint_names: Joint order of ``tracking`` and ``speed_ratio``.
        record: The bag's material (``/joint_states`` as executed, goals, reports),
            when asked for.
        belt_runs: Whether the belt ran while the robot worked
            (``ControllerOptions.belt_runs_while_working``).
        empty_picks: Times the gripper closed on the conveyor with no vial at the sensor
            (must be 0).
        belt_moving_at_sensor: Time the belt moved while a vial stood at the sensor [s]
            (must be 0: the cell's own stop).
        belt_commanded_at_sensor: Time the belt was commanded to run while a vial stood
            at the sensor [s] (the controller's stop on its way: one conveyor latency per
            vial arriving during a cycle).
        waiting_motions: Motion goals during which a vial stood at the sensor (checked
            with it in the cell).
        queued_motions: Motion goals during which vials stood on the belt behind the
            sensor (checked with them in the cell, where they were at each state).
        warnings: The cell controller's warnings during the run, in order (kept here,
            not logged: see :mod:`safepath.sim.kept_warnings`).
        verdict_timeout: The controller's verdict time-out in force [s] (see
            :class:`QualityCheckParams`).
    """

    seed: int
    architecture: str
    duration: float
    wall_time: float
    clearance_time: float
    vials_arrived: int
    cycles: tuple[CycleReport, ...]
    packaging: int
    rejected: int
    unsafe_packaged: int
    reasons: dict[str, int]
    faults: tuple[str, ...]
    robot_idle: float
    conveyor_idle: float
    tracking: np.ndarray
    speed_ratio: np.ndarray
    contact_steps: int
    clearance: ExecutedClearance
    tcp_deviation: float
    margin: float
    joint_names: tuple[str, ...]
    record: RunRecord | None = field(default=None, repr=False)
    belt_runs: bool = False
    empty_picks: int = 0
    belt_moving_at_sensor: float = 0.0
    belt_commanded_at_sensor: float = 0.0
    waiting_motions: int = 0
    queued_motions: int = 0
    warnings: tuple[str, ...] = ()
    in_progress: int = 0
    verdict_timeout: float = math.nan

    @property
    def vials_per_minute(self) -> float:
        """Vials handled (cycles completed) per simulated minute."""
        return len(self.cycles) / (self.duration / 60.0)

    @property
    def cycle_times(self) -> np.ndarray:
        """Object seen -> back at the conveyor, per cycle [s]."""
        return np.array([c.cycle_time for c in self.cycles])

    @property
    def real_time_factor(self) -> float:
        """Simulated time per computation time (simulation only)."""
        return self.duration / self.wall_time if self.wall_time > 0 else math.inf


@functools.lru_cache(maxsize=4)
def _planned(scene: str, architecture: str) -> tuple[Cell, dict[str, Trajectory]]:
    """The cell and its routes as the architecture runs them (planned once per process)."""
    from .. import PlanOptions, load_cell, plan_cell
    from .stop_and_go import stop_and_go

    cell = load_cell(scene)
    trajs = plan_cell(cell, PlanOptions())
    if architecture == "sequential":
        trajs = {name: stop_and_go(cell, traj) for name, traj in trajs.items()}
    return cell, trajs


#: The name of the vial waiting at the sensor in :func:`waiting_vial_cell`.
WAITING_VIAL = "vial_waiting"


@functools.lru_cache(maxsize=4)
def _waiting_cell(scene: str) -> Cell:
    from .. import load_cell

    return waiting_vial_cell(load_cell(scene))


def waiting_vial_cell(cell: Cell) -> Cell:
    """``cell`` with a second vial standing at the sensor (:data:`WAITING_VIAL`, a static
    copy of the grasped object at its scene placement, the vial's margin), the open jaws
    allowed to straddle it where the grasp's object is picked from the conveyor (the
    poses where the object meets the gripper and the conveyor: ``grip``).

    Raises:
        InputError: The cell has no grasped object.
    """
    import dataclasses

    from ..model.scene import AllowedContact

    scene = cell.scene
    if scene.grasp is None:
        raise InputError("the cell has no grasp: no vial to wait at the sensor", key="grasp")
    vial = scene.objects[scene.grasp.object]
    waiting = dataclasses.replace(vial, name=WAITING_VIAL, movable=False)
    pick_poses = {p for c in scene.allowed_contacts if vial.name in c.between
                  and "gripper" in c.between for p in c.at}
    on_belt = {p for c in scene.allowed_contacts if vial.name in c.between
               and "gripper" not in c.between for p in c.at
               if any(o in c.between for o in ("qc_conveyor", "conveyor"))}
    at = tuple(sorted(pick_poses & on_belt)) or tuple(sorted(pick_poses))
    contacts = (*scene.allowed_contacts,
                AllowedContact((WAITING_VIAL, "gripper"), at=at,
                               reason="the open jaws arrive around the vial waiting at the "
                                      "sensor, to pick it"))
    new_scene = dataclasses.replace(scene, objects={**scene.objects, WAITING_VIAL: waiting},
                                    allowed_contacts=contacts)
    return dataclasses.replace(cell, scene=new_scene)


#: The name prefix of the vials queued behind the sensor in :func:`queued_vials_cell`.
QUEUED_VIAL = "vial_queued"
#: The name of the vial riding in to the sensor in :func:`queued_vials_cell`.
RIDING_IN_VIAL = "vial_riding_in"


def queued_vials_cell(cell: Cell, behind: tuple[float, ...], *, riding_in: float | None = None
                      ) -> Cell:
    """``cell`` with static copies of the grasped vial standing on the belt ``behind``
    the sensor: one per distance [m] (centre to centre, from the vial's scene placement
    at the sensor), named ``vial_queued_1``, ``vial_queued_2``, … with the vial's margin,
    no contact with them allowed. The belt is the object the vial stands on at the pick
    pose (its allowed contact there other than the gripper, a box under the vial's scene
    placement); its longer horizontal axis,
    pointing from the vial towards the belt's centre, is where the next vials come from.
    ``riding_in``: a vial that far behind the sensor [m], closer than the spacing of the
    queue: the next one on its way to the sensor, into the open jaws waiting there
    (``vial_riding_in``, the open jaws allowed around it where the vial at the sensor is
    picked, as :func:`waiting_vial_cell` allows them around the vial waiting there).

    Raises:
        InputError: The cell has no grasped object, or no belt under it.
    """
    import dataclasses

    scene = cell.scene
    if scene.grasp is None:
        raise InputError("the cell has no grasp: no vial queued on the belt", key="grasp")
    vial = scene.objects[scene.grasp.object]
    pick_poses = {p for c in scene.allowed_contacts if vial.name in c.between
                  and "gripper" in c.between for p in c.at}
    supports = sorted({o for c in scene.allowed_contacts if vial.name in c.between
                       and "gripper" not in c.between and set(c.at) & pick_poses
                       for o in c.between if o != vial.name and o in scene.objects})

    def under_vial(name: str) -> bool:  # the vial's scene placement above its footprint
        obj = scene.objects[name]
        local = np.linalg.solve(obj.T_world_object, vial.T_world_object[:, 3])
        return obj.shape.kind == "box" and all(
            abs(local[i]) <= obj.shape.size[i] / 2 for i in (0, 1))

    belts = [name for name in supports if under_vial(name)]
    if not belts:
        raise InputError("no support under the vial where it is picked: no belt to queue "
                         "vials on", key="allowed_contacts")
    belt = scene.objects[belts[0]]
    T_belt = belt.T_world_object  # noqa: N806
    axis = T_belt[:3, 0] if belt.shape.size[0] >= belt.shape.size[1] else T_belt[:3, 1]
    if float(axis @ (T_belt[:3, 3] - vial.T_world_object[:3, 3])) < 0:
        axis = -axis
    objects = dict(scene.objects)
    for i, d in enumerate(behind, start=1):
        T = vial.T_world_object.copy()  # noqa: N806
        T[:3, 3] += d * axis
        name = f"{QUEUED_VIAL}_{i}"
        objects[name] = dataclasses.replace(vial, name=name, movable=False, T_world_object=T)
    contacts = tuple(scene.allowed_contacts)
    if riding_in is not None:
        from ..model.scene import AllowedContact

        T = vial.T_world_object.copy()  # noqa: N806
        T[:3, 3] += riding_in * axis
        objects[RIDING_IN_VIAL] = dataclasses.replace(vial, name=RIDING_IN_VIAL, movable=False,
                                                      T_world_object=T)
        at = tuple(sorted(set(pick_poses) & {p for c in scene.allowed_contacts
                                             if belt.name in c.between for p in c.at}))
        contacts += (AllowedContact((RIDING_IN_VIAL, "gripper"), at=at,
                                    reason="the next vial rides into the open jaws waiting "
                                           "at the sensor"),)
    return dataclasses.replace(cell, scene=dataclasses.replace(
        scene, objects=objects, allowed_contacts=contacts))


@dataclass
class _Motion:
    goal_id: int
    start: float
    end: float
    traj: Trajectory
    world: MotionWorld


class _Cell:
    """One run's state: the controller, the twin and the cell around them."""

    def __init__(self, cell: Cell, trajs: dict[str, Trajectory], seed: int,
                 params: QualityCheckParams) -> None:
        from ..cells.quality_check.controller import QualityCheckController

        self.cell, self.trajs, self.params = cell, trajs, params
        self.verdict = params.verdict
        if params.architecture == "sequential" and self.verdict.period is None:
            self.verdict = replace(self.verdict, period=SEQUENTIAL_PERIOD)
        opts = params.controller
        if opts.verdict_timeout is None and self.verdict.period is not None:
            # A time-out the test zone's publications can meet (an explicit one is kept).
            opts = replace(opts, verdict_timeout=self.verdict.longest_answer)
        self.ctl = QualityCheckController(opts)
        start = trajs[opts.phase1_route].q[0]
        self.twin = RobotTwin(cell.robot, cell.scene, start, options=params.twin)
        self.conveyor = Conveyor(params.belt_length, params.belt_speed, params.vial_spacing,
                                 params.arrival_interval, params.p_unsafe,
                                 rng=np.random.default_rng([seed, 1]))
        self.verdict_rng = np.random.default_rng([seed, 2])
        self.events: list[tuple[float, int, str, Any]] = []
        self._seq = 0
        self.grippers: dict[int, Any] = {}
        self.motions: list[_Motion] = []
        self.vial: Vial | None = None
        self.world = MotionWorld(None, None)
        self.sensor = False
        self.sensor_spans: list[list[float]] = []  # [on, off] of the IR sensor
        # (from when, the vials behind the sensor: distances [m], floored to the mm)
        self.queue_log: list[tuple[float, tuple[float, ...]]] = []
        self.empty_picks = 0
        self.belt_moving_at_sensor = self.belt_commanded_at_sensor = 0.0
        self.robot_idle = 0.0
        self.faults: list[str] = []
        self.reports: list[CycleReport] = []
        self.placed: Vial | None = None  # placed by phase 2, its cycle not yet reported
        self.handled: list[Vial] = []  # the vial of each reported cycle (placed by it)
        self.record = RunRecord()

    # -- commands --------------------------------------------------------------------
    def schedule(self, when: float, kind: str, payload: Any) -> None:
        self._seq += 1
        heapq.heappush(self.events, (when, self._seq, kind, payload))

    def dispatch(self, commands: list[Command]) -> None:
        from ..cells.quality_check import controller as c

        for cmd in commands:
            if isinstance(cmd, c.SetConveyor):
                self.conveyor.commanded = cmd.running
                self.schedule(self.twin.now + self.params.conveyor_latency, "result",
                              (cmd.goal_id, True, ""))
            elif isinstance(cmd, c.MoveArm):
                self._move(cmd)
            elif isinstance(cmd, c.ActuateGripper):
                self._grip(cmd)
            elif isinstance(cmd, c.RequestVerdict):
                answer = self.verdict.answer(self.vial, self.twin.now, self.verdict_rng)
                if answer.text is not None:
                    self.schedule(self.twin.now + answer.latency, "verdict",
                                  (cmd.request_id, answer.text))
            elif isinstance(cmd, c.CancelGoal):
                self.twin.cancel_arm_goal(cmd.goal_id)
            elif isinstance(cmd, c.CycleReport):
                self.reports.append(cmd)
                if self.placed is not None:
                    self.handled.append(self.placed)
                    self.placed = None
                self.record.events.append((self.twin.now, {"type": "cycle", **{
                    k: getattr(cmd, k) for k in ("cycle", "verdict", "reason", "route",
                                                 "cycle_time")}}))
            elif isinstance(cmd, c.Fault):
                self.faults.append(cmd.reason)
                self.record.events.append((self.twin.now, {"type": "fault",
                                                           "reason": cmd.reason}))

    def _move(self, cmd: Any) -> None:
        from ..ros import follow_joint_trajectory_goal

        goal = follow_joint_trajectory_goal(cmd.trajectory, controller=self.cell.robot.controller,
                                            backend="rosbags")
        self.record.goals.append((self.twin.now, "arm", goal))
        self.motions.append(_Motion(cmd.goal_id, self.twin.now, math.inf, cmd.trajectory,
                                    self.world))
        rejected = self.twin.send_arm_goal(goal, cmd.goal_id)
        if rejected is not None:
            self.schedule(self.twin.now, "result", (cmd.goal_id, False, rejected.error_string))

    def _grip(self, cmd: Any) -> None:
        from ..ros import tool_goal

        goal = tool_goal(cmd.event.action, tool_id=self.cell.robot.tool.tool_id
                         if self.cell.robot.tool and self.cell.robot.tool.tool_id is not None
                         else 11, backend="rosbags")
        self.record.goals.append((self.twin.now, "tool", goal))
        self.grippers[cmd.goal_id] = cmd
        rejected = self.twin.send_gripper_goal(goal, cmd.goal_id)
        if rejected is not None:
            self.schedule(self.twin.now, "result", (cmd.goal_id, False, rejected.message))

    # -- events ----------------------------------------------------------------------
    def on_gripper(self, result: GripperResult) -> None:
        cmd = self.grippers.pop(result.goal_id)
        opts = self.params.controller
        now = self.twin.now
        grasp = self.cell.scene.grasp
        obj = grasp.object if grasp is not None else None
        if result.action == "close":
            if cmd.route == opts.phase1_route:
                self.vial = self.conveyor.pick(now)
                if self.vial is None:
                    self.empty_picks += 1
            self.world = MotionWorld(obj, None)
        else:
            T_world_tcp = self.cell.robot.frame_pose(self.twin.q).homogeneous  # noqa: N806
            rest = T_world_tcp @ grasp.T_tcp_object if grasp is not None else None
            self.world = MotionWorld(None, rest)
            if cmd.route != opts.phase1_route and self.vial is not None:
                where = "packaging" if cmd.route == opts.safe_route else "reject"
                self.vial.placed = (where, now)
                self.placed, self.vial = self.vial, None
        self.dispatch(self.ctl.on_goal_result(result.goal_id, result.success, result.message,
                                              now))

    def on_arm(self, result: ArmResult) -> None:
        for motion in reversed(self.motions):
            if motion.goal_id == result.goal_id:
                motion.end = result.time
                break
        if result.error_code == CANCELED:
            return
        self.dispatch(self.ctl.on_goal_result(result.goal_id, result.success,
                                              result.error_string, self.twin.now))

    def step(self, until: float) -> None:
        before = self.twin.now
        results = self.twin.advance(until)
        now = self.twin.now
        dt = now - before
        if self.twin.arm.active is None and not self.grippers:
            self.robot_idle += dt
        if self.conveyor.sensor:
            self.belt_moving_at_sensor += dt if self.conveyor.running else 0.0
            self.belt_commanded_at_sensor += dt if self.conveyor.commanded else 0.0
        self.conveyor.advance(now, dt)
        queue = tuple(math.floor(d * 1000.0 + 1e-6) / 1000.0 for d in self.conveyor.queued())
        if not self.queue_log or self.queue_log[-1][1] != queue:
            self.queue_log.append((now, queue))
        for result in results:
            if isinstance(result, GripperResult):
                self.on_gripper(result)
            else:
                self.on_arm(result)
        while self.events and self.events[0][0] <= now + 1e-12:
            _, _, kind, payload = heapq.heappop(self.events)
            if kind == "result":
                goal_id, success, message = payload
                self.dispatch(self.ctl.on_goal_result(goal_id, success, message, now))
            else:
                request_id, text = payload
                self.dispatch(self.ctl.on_verdict(text, now, request_id=request_id))
        if self.conveyor.sensor != self.sensor:
            self.sensor = self.conveyor.sensor
            if self.sensor:
                self.sensor_spans.append([now, math.inf])
            elif self.sensor_spans:
                self.sensor_spans[-1][1] = now
            if self.sensor and self.world.held is None and self.world.resting is not None \
                    and self.ctl.state.value == "idle":
                self.world = MotionWorld(None, None)  # the new vial at its scene place
            self.dispatch(self.ctl.on_sensor(self.sensor, now))
        self.dispatch(self.ctl.on_tick(now))


def _waiting_motions(run: _Cell) -> list[_Motion]:
    """The motions during which a vial stood at the sensor (other than the one picked)."""
    return [m for m in run.motions
            if any(on < m.end and off > m.start for on, off in run.sensor_spans)]


@dataclass
class _Span:
    """A part of a motion (its states from ``start`` to ``end``), the motion's own
    trajectory time starting at ``t0``."""

    start: float
    end: float
    traj: Trajectory
    world: MotionWorld
    t0: float


def _queue_spans(run: _Cell, motion: _Motion) -> list[tuple[tuple[float, ...], _Span]]:
    """``motion`` cut where the vials behind the sensor moved, with where they stood."""
    log = run.queue_log
    out: list[tuple[tuple[float, ...], _Span]] = []
    for k, (since, queue) in enumerate(log):
        until = log[k + 1][0] if k + 1 < len(log) else math.inf
        start, end = max(since, motion.start), min(until, motion.end)
        if start > end or (until < math.inf and start >= until):
            continue
        # a state exactly at ``until`` belongs to the next entry
        stop = end if end < until else math.nextafter(until, -math.inf)
        out.append((queue, _Span(start, stop, motion.traj, motion.world, motion.start)))
    if not log:
        out.append(((), _Span(motion.start, motion.end, motion.traj, motion.world,
                               motion.start)))
    return out


def _queued_motions(run: _Cell) -> list[_Motion]:
    """The motions during which vials stood on the belt behind the sensor."""
    return [m for m in run.motions if any(q for q, _ in _queue_spans(run, m))]


def _clearance(run: _Cell) -> ExecutedClearance:
    """The executed states of every motion, checked in their world: with the vial waiting
    at the sensor in it while one stood there, and the vials queued behind the sensor
    where they stood at each state (to the millimetre, rounded towards the sensor)."""
    waiting = {id(m) for m in _waiting_motions(run)}
    folder = run.cell.folder
    groups: dict[tuple[bool, tuple[float, ...]], list[_Span]] = {}
    for motion in run.motions:
        for queue, span in _queue_spans(run, motion):
            groups.setdefault((id(motion) in waiting, queue), []).append(span)
    best = ExecutedClearance(math.inf, None, math.nan, 0)
    states = 0
    for (wait, queue), spans in groups.items():
        cell = run.cell
        if wait:
            cell = _waiting_cell(str(folder)) if folder is not None \
                else waiting_vial_cell(run.cell)
        if queue:
            # the front vial, closer to the sensor than the queue's spacing, is riding
            # in to it: into the open jaws, when they wait there
            riding = queue[0] if queue[0] < run.params.vial_spacing - 1e-3 else None
            cell = queued_vials_cell(cell, queue[1:] if riding is not None else queue,
                                     riding_in=riding)
        got = executed_clearance(cell, run.twin.recording, spans)
        states += got.states
        if got.clearance < best.clearance:
            best = got
    return ExecutedClearance(best.clearance, best.pair, best.time, states)


def _tcp_deviation(run: _Cell) -> float:
    """Largest executed-vs-commanded TCP distance while goals ran [m]."""
    return tcp_deviation(run.cell.robot, run.twin.recording)


def run_quality_check(cell: str | Path, seed: int, params: QualityCheckParams | None = None,
                      *, record: bool = False) -> QualityCheckRun:
    """Run the quality-check cell's twin (see the module docstring).

    Args:
        cell: The cell's scene folder (planned once per process and architecture).
        seed: The run's seed: arrivals, vial classes and verdicts (the same seed gives
            the same run).
        params: The run's parameters.
        record: Keep the material of a bag (:func:`safepath.sim.bag.write_run_bag`).

    Raises:
        InputError: Bad parameters or seed.
        SafepathError: The cell cannot be loaded or planned.
    """
    params = params or QualityCheckParams()
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"expected an integer >= 0, got {seed!r}", key="seed")
    loaded, trajs = _planned(str(cell), params.architecture)
    from ..cells.quality_check import controller

    with kept_warnings(controller.__name__) as kept:
        run = _Cell(loaded, trajs, int(seed), params)
        t0 = time.perf_counter()
        for name in params.controller.routes:
            run.dispatch(run.ctl.on_route_ready(name, trajs[name], 0.0))
        while run.twin.now < params.duration - 1e-9 and not run.faults:
            nxt = min(run.twin.now + params.tick, params.duration)
            if run.events:
                nxt = min(nxt, max(run.events[0][0], run.twin.now + run.twin.options.timestep))
            run.step(nxt)
        wall = time.perf_counter() - t0
    t1 = time.perf_counter()
    clearance = _clearance(run)
    deviation = _tcp_deviation(run)
    clearance_time = time.perf_counter() - t1
    vials = run.conveyor.arrived
    cycles = tuple(run.reports)
    handled = run.handled
    rec = run.twin.recording
    material = None
    if record:
        run.record.time = np.asarray(rec.time)
        run.record.q = np.asarray(rec.q)
        run.record.qd = np.asarray(rec.qd)
        run.record.joint_names = tuple(loaded.robot.joint_names)
        material = run.record
    return QualityCheckRun(
        seed=int(seed), architecture=params.architecture, duration=run.twin.now,
        wall_time=wall, clearance_time=clearance_time, vials_arrived=len(vials),
        cycles=cycles,
        packaging=sum(1 for v in handled if v.placed and v.placed[0] == "packaging"),
        rejected=sum(1 for v in handled if v.placed and v.placed[0] == "reject"),
        unsafe_packaged=sum(1 for v in vials if v.unsafe and v.placed
                            and v.placed[0] == "packaging"),
        in_progress=sum(1 for v in vials if v.picked is not None) - len(handled),
        reasons=dict(Counter(c.reason for c in cycles)), faults=tuple(run.faults),
        robot_idle=run.robot_idle, conveyor_idle=run.conveyor.stopped_time,
        tracking=rec.tracking.copy(), speed_ratio=rec.speed_ratio.copy(),
        contact_steps=rec.contact_steps, clearance=clearance,
        tcp_deviation=deviation, margin=loaded.scene.margin,
        joint_names=tuple(loaded.robot.joint_names), record=material,
        belt_runs=params.controller.belt_runs_while_working, empty_picks=run.empty_picks,
        belt_moving_at_sensor=run.belt_moving_at_sensor,
        belt_commanded_at_sensor=run.belt_commanded_at_sensor,
        waiting_motions=len(_waiting_motions(run)),
        queued_motions=len(_queued_motions(run)), warnings=tuple(kept),
        verdict_timeout=run.ctl.options.verdict_wait)


def events_json(run: QualityCheckRun) -> list[tuple[float, str]]:
    """The run's recorded events as (time [s], JSON) pairs (for a bag)."""
    if run.record is None:
        return []
    return [(t, json.dumps(e, sort_keys=True)) for t, e in run.record.events]
