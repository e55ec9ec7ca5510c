"""The pouring cell's twin: :class:`~safepath.cells.pouring.controller.PourController` closed loop.

The cell's own state machine decides, as ``examples/ros2/pour_node.py`` runs it; around it,
on one simulated clock:

* the **robot** (:class:`~safepath.sim.twin.RobotTwin`): MuJoCo physics at 1 kHz, the
  trajectory controller of the robot's ``controller.yaml`` executing the
  ``FollowJointTrajectory`` goals the node sends (stamped with the controller's
  ``start_time``; a stop stamped in the past joins the running tilt where it is), the
  gripper executing ``GripperCommand`` goals (or Niryo ``Tool`` goals for a robot with
  no ``GripperCommand`` gripper). Goals other than a stop are refused, as the node
  refuses them, when the executed arm is not at their first point
  (:func:`safepath.ros.goals.check_start`); the tilt's progress is fed back every
  ``feedback_period`` (``desired.time_from_start``);
* the **cup and the scale** (:class:`~safepath.cells.pouring.flow.FlowModel`, the
  project's flow law ``gain * (tilt - spill_angle) ** 1.5``): the flow is integrated
  every ``step`` from the tilt the *simulated* arm really has (forward kinematics of the
  MuJoCo joints, the held cup's axis from the scene's grasp; 0 while the cup is not
  held), lands ``fall_time`` later, and the scale publishes what has landed
  ``latency`` before, every ``period``, plus Gaussian noise. Each seed draws the flow
  gain (``gain_range``) and the scale's latency (``latency_range``); the controller knows
  the latency and the law's shape, not the gain (as in ``tests/ros``).

Routes: by default the pick route before the pour and the place route after it, as the
cell's ``routes.yaml`` declares them (the pour route's ``after`` route, and the route
that follows it from the pour's start without pouring); the tilt is the pour route's
first ``tilt`` step, the return speed its second's bound. Nothing here names a robot or a
cell: :func:`run_pouring` works on any cell whose routes hold such a pour.

:func:`run_pouring` is a plain function of ``(cell, seed, params)``, mapped over seeds by
:func:`safepath.sim.sweep.run_many`; a seed gives the same run.
"""

from __future__ import annotations

import bisect
import functools
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError, InputError
from .arm import CANCELED, ArmResult
from .bag import RunRecord
from .clearance import ExecutedClearance, MotionWorld, executed_clearance, tcp_deviation
from .twin import GripperResult, RobotTwin, TwinOptions

if TYPE_CHECKING:
    from ..cell import Cell
    from ..cells.pouring.commands import PourReport
    from ..cells.pouring.flow import FlowModel
    from ..model.trajectory import GripperEvent, Trajectory
    from ..planning.pour import PourMotion

__all__ = ["PouringParams", "PouringRun", "run_pouring", "pour_plan", "pour_route_of"]

_NS = 1_000_000_000


def _positive(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value) and value > 0


@dataclass(frozen=True, kw_only=True)
class PouringParams:
    """One run of the pouring twin.

    Attributes:
        target: Mass to pour [g].
        tolerance: A final mass within ``target +- tolerance`` counts as within tolerance
            [g] (the controller's closed-loop tests allow 3.5 g).
        gain_range: The cup's flow gain is drawn uniformly from it per seed
            [g/s/rad^1.5].
        latency_range: The scale's latency is drawn uniformly from it per seed [s].
        noise: Standard deviation of a scale reading [g].
        period: The scale's reading period [s].
        fall_time: Time from the lip to the bowl [s].
        pour_route: The route whose first step is the tilt; None: the cell's first
            route that starts with a ``tilt`` not followed by a ``circle``.
        pick_and_place: Run the pick route before the pour and the place route after
            it (False: the run starts at the pour's start with the cup held).
        kill_at: Simulated time of a kill [s] (None: none).
        twin: How the robot is simulated.
        step: Period of the flow's integration and of the node's event loop [s].
        tick: Period of the node's timer [s].
        feedback_period: Period of the trajectory controller's feedback [s].
        max_time: Longest run [s].
    """

    target: float = 100.0
    tolerance: float = 3.5
    gain_range: tuple[float, float] = (40.0, 120.0)
    latency_range: tuple[float, float] = (0.05, 0.2)
    noise: float = 0.2
    period: float = 0.0125
    fall_time: float = 0.15
    pour_route: str | None = None
    pick_and_place: bool = True
    kill_at: float | None = None
    twin: TwinOptions = field(default_factory=TwinOptions)
    step: float = 0.004
    tick: float = 0.01
    feedback_period: float = 0.1
    max_time: float = 180.0

    def __post_init__(self) -> None:
        for key in ("target", "tolerance", "period", "fall_time", "step", "tick",
                    "feedback_period", "max_time"):
            if not _positive(getattr(self, key)):
                raise InputError(f"expected a finite number > 0, got {getattr(self, key)!r}",
                                 key=key)
        if not (isinstance(self.noise, (int, float)) and math.isfinite(self.noise)
                and self.noise >= 0):
            raise InputError(f"expected a finite number >= 0 [g], got {self.noise!r}",
                             key="noise")
        for key in ("gain_range", "latency_range"):
            pair = getattr(self, key)
            ok = isinstance(pair, (tuple, list)) and len(pair) == 2 \
                and all(_positive(v) or (key == "latency_range" and v == 0) for v in pair) \
                and pair[0] <= pair[1]
            if not ok:
                raise InputError(f"expected (low, high) with 0 < low <= high, got {pair!r}",
                                 key=key)
        if self.kill_at is not None and not (_positive(self.kill_at)):
            raise InputError(f"expected a time > 0 [s] or None, got {self.kill_at!r}",
                             key="kill_at")
        if self.pour_route is not None and (not isinstance(self.pour_route, str)
                                            or not self.pour_route):
            raise InputError(f"expected a route name or None, got {self.pour_route!r}",
                             key="pour_route")


@dataclass(frozen=True)
class PourPlan:
    """What the pour needs, planned once per process: the tilt, the steps around it.

    Attributes:
        cell: The cell.
        pour_route: The route the tilt was taken from.
        tilt: The planned, verified tilt.
        return_speed: Bound on the cup's angular speed on the way back [rad/s].
        before: Steps before the tilt (the pick route split at its gripper events).
        after: Steps after the return upright (the place route).
        still: What the stop and the return pour per unit gain (the controller's
            calibration, computed once).
    """

    cell: Cell
    pour_route: str
    tilt: PourMotion
    return_speed: float
    before: tuple[Trajectory | GripperEvent, ...]
    after: tuple[Trajectory | GripperEvent, ...]
    still: Any = field(repr=False)


def pour_route_of(cell: Cell) -> str | None:
    """The cell's first route that starts with a ``tilt`` not followed by a ``circle``
    (a pour the controller can stop on the scale), or None."""
    for name, route in cell.route_table().items():
        kinds = [s.kind for s in route.steps]
        if kinds and kinds[0] == "tilt" and (len(kinds) < 2 or kinds[1] != "circle"):
            return name
    return None


def _routes(cell: Cell, pour_route: str | None) -> tuple[str, str | None, str | None]:
    """The pour route and the pick and place routes around it, from the cell's routes."""
    table = cell.route_table()
    if pour_route is None:
        pour_route = pour_route_of(cell)
        if pour_route is None:
            raise ConfigError(f"cell '{cell.scene.name}' has no route starting with a tilt "
                              "(a pour)", key="pour_route")
    if pour_route not in table:
        raise InputError(f"the cell has no route '{pour_route}' (known: {', '.join(table)})",
                         key="pour_route")
    pour = table[pour_route]
    if pour.steps[0].kind != "tilt":
        raise InputError(f"route '{pour_route}' does not start with a tilt", key="pour_route")
    pick = pour.after
    place = next((name for name, r in table.items() if name != pour_route and pick is not None
                  and r.after == pick and r.start == pour.start
                  and not any(s.kind in ("tilt", "circle") for s in r.steps)), None)
    return pour_route, pick, place


@functools.lru_cache(maxsize=4)
def pour_plan(scene: str, pour_route: str | None = None, pick_and_place: bool = True
              ) -> PourPlan:
    """Plan the cell's pour (the tilt, and the pick and place routes) once per process.

    Raises:
        InputError / ConfigError: No such route, or no pour in the cell.
        SafepathError: Planning failed.
    """
    from .. import load_cell
    from ..cell.pour_steps import Tilt
    from ..cells.pouring.flow import FlowModel
    from ..cells.pouring.parts import PourStopper
    from ..planning.pour import PourOptions, plan_tilt
    from ..planning.route_planner import plan_cell
    from ..ros.goals import split_at_gripper_events

    cell = load_cell(scene)
    name, pick, place = _routes(cell, pour_route)
    route = cell.route_table()[name]
    step = route.steps[0]
    assert isinstance(step.pour, Tilt) and step.max_angular_speed is not None
    q0 = cell.pose(route.start)
    T0 = cell.robot.frame_pose(q0).homogeneous  # noqa: N806
    tilt = plan_tilt(cell, q0, step.pour.goal(T0[:3, :3]), step.pour.pivot_in_world(T0),
                     options=PourOptions(max_angular_speed=step.max_angular_speed))
    back = route.steps[1].max_angular_speed if len(route.steps) > 1 \
        and route.steps[1].max_angular_speed is not None else math.radians(30.0)
    before: tuple[Trajectory | GripperEvent, ...] = ()
    after: tuple[Trajectory | GripperEvent, ...] = ()
    if pick_and_place and pick is not None:
        table = cell.route_table()
        names = [pick] + ([place] if place is not None else [])
        planned = plan_cell(cell, routes={n: table[n] for n in names})
        before = tuple(split_at_gripper_events(planned[pick]))
        if place is not None:
            after = tuple(split_at_gripper_events(planned[place]))
    still = PourStopper(cell, tilt, return_angular_speed=back).calibrate_still(FlowModel())
    return PourPlan(cell, name, tilt, back, before, after, still)


@dataclass(frozen=True)
class PouringRun:
    """What one run of the pouring twin did.

    Attributes:
        seed: The run's seed.
        gain: The cup's true flow gain [g/s/rad^1.5].
        latency: The scale's latency [s].
        final_mass: Mass in the bowl once everything landed [g].
        target: The target [g].
        tolerance: The tolerance [g].
        report: The controller's report (None: it did not finish).
        state: The controller's final state.
        goals: Purposes of the arm goals sent, in order (``route``, ``pour``, ``stop``,
            ``return``).
        faults: The controller's faults, in words.
        duration: Simulated time [s].
        wall_time: Computation time of the simulation [s] (the clearance check apart).
        clearance_time: Computation time of the executed-clearance check [s].
        tracking: Largest |commanded - executed| per joint while goals ran [rad].
        speed_ratio: Largest |executed speed| / limit per joint.
        limit_margin: Smallest distance of an executed position to its joint limit [rad]
            (negative: over a limit).
        contact_steps: Physics steps in which the arm touched the cell (MuJoCo).
        clearance: Executed clearance against the cell (safepath's checker, cup held).
        tcp_deviation: Largest executed-vs-commanded TCP distance while goals ran [m].
        margin: The cell's safety margin [m].
        joint_names: Joint order of the per-joint figures.
        killed_at: Simulated time of the kill, if any [s].
        moved_after_kill: Largest joint motion from 1 s after the kill on [rad].
        record: The bag's material (when asked for).
    """

    seed: int
    gain: float
    latency: float
    final_mass: float
    target: float
    tolerance: float
    report: PourReport | None
    state: str
    goals: tuple[str, ...]
    faults: tuple[str, ...]
    duration: float
    wall_time: float
    clearance_time: float
    tracking: np.ndarray
    speed_ratio: np.ndarray
    limit_margin: float
    contact_steps: int
    clearance: ExecutedClearance
    tcp_deviation: float
    margin: float
    joint_names: tuple[str, ...]
    killed_at: float | None = None
    moved_after_kill: float = 0.0
    record: RunRecord | None = field(default=None, repr=False)

    @property
    def error(self) -> float:
        """``final_mass - target`` [g]."""
        return self.final_mass - self.target

    @property
    def within_tolerance(self) -> bool:
        """Whether the final mass is within the tolerance of the target."""
        return abs(self.error) <= self.tolerance

    @property
    def real_time_factor(self) -> float:
        """Simulated time per computation time (simulation only)."""
        return self.duration / self.wall_time if self.wall_time > 0 else math.inf


@dataclass
class _Motion:
    goal_id: int
    start: float
    end: float
    traj: Trajectory
    world: MotionWorld
    t0: float


class _Pour:
    """One run's state: the controller, the twin, the cup and the scale."""

    def __init__(self, plan: PourPlan, truth: FlowModel, params: PouringParams) -> None:
        from ..cells.pouring.commands import PourControllerOptions
        from ..cells.pouring.controller import PourController
        from ..cells.pouring.flow import FlowModel
        from ..planning.pour import cup_axis_in_tcp

        self.plan, self.truth, self.params = plan, truth, params
        cell = plan.cell
        self.robot = cell.robot
        self.ctl = PourController(
            cell, plan.tilt, FlowModel(latency=truth.latency, fall_time=truth.fall_time,
                                       spill_angle=truth.spill_angle, period=truth.period),
            options=PourControllerOptions(target=params.target), still=plan.still,
            return_angular_speed=plan.return_speed,
            before=plan.before if params.pick_and_place else (),
            after=plan.after if params.pick_and_place else ())
        first = next((s for s in plan.before if hasattr(s, "q")), None) \
            if params.pick_and_place else None
        q_start = first.q[0] if first is not None else plan.tilt.trajectory.q[0]
        self.twin = RobotTwin(self.robot, cell.scene, q_start, options=params.twin)
        grasp = cell.scene.grasp
        self.cup = grasp.object if grasp is not None else None
        self.holding = not (params.pick_and_place and plan.before)
        self.world = MotionWorld(self.cup if self.holding else None, None)
        self.axis = cup_axis_in_tcp(cell)
        # The cup's axis in the frame of the TCP's parent joint (a MuJoCo body: the bodies
        # are the joint frames), for the tilt from MuJoCo's own kinematics.
        import mujoco

        frame = self.robot.model.frames[self.robot.tcp_frame_id]
        parent = self.robot.model.names[int(frame.parentJoint)]
        self._mujoco = mujoco
        self._tcp_body = mujoco.mj_name2id(self.twin.model.model, mujoco.mjtObj.mjOBJ_BODY,
                                           parent)
        self._axis_in_body = np.asarray(frame.placement.rotation) @ self.axis
        self.rng = np.random.default_rng([truth.seed, 3])
        self.motions: list[_Motion] = []
        self.stamps: dict[int, float] = {}
        self.purpose: dict[int, str] = {}
        self.arm_goal: int | None = None
        self.grippers: set[int] = set()
        self.faults: list[str] = []
        self.goals: list[str] = []
        self.record = RunRecord()
        # The flow: mass out of the cup at times ts [g].
        self.ts: list[float] = [0.0]
        self.out: list[float] = [0.0]
        self.tilt = self._tilt()

    def _tilt(self) -> float:

        if not self.holding:
            return 0.0
        m, d = self.twin.model.model, self.twin.data
        self._mujoco.mj_kinematics(m, d)  # at the current positions (mj_step's are before)
        up = d.xmat[self._tcp_body].reshape(3, 3) @ self._axis_in_body
        return math.acos(max(-1.0, min(1.0, float(up[2]))))

    # -- commands --------------------------------------------------------------------
    def dispatch(self, commands: list[Any]) -> None:
        from ..cells.pouring.commands import PourReport, SendArmGoal, SendGripperGoal
        from ..ros.commands import CancelGoal, Fault

        now = self.twin.now
        for cmd in commands:
            if isinstance(cmd, SendArmGoal):
                self._move(cmd)
            elif isinstance(cmd, SendGripperGoal):
                self._grip(cmd)
            elif isinstance(cmd, CancelGoal):
                self.twin.cancel_arm_goal(cmd.goal_id)
            elif isinstance(cmd, Fault):
                self.faults.append(cmd.reason)
                self.record.events.append((now, {"type": "fault", "reason": cmd.reason}))
            elif isinstance(cmd, PourReport):
                self.record.events.append((now, {"type": "report", "reason": cmd.reason,
                                                 "predicted": cmd.predicted,
                                                 "stopped": cmd.stopped}))

    def _move(self, cmd: Any) -> None:
        from ..errors import SafepathError
        from ..ros.goals import check_start, follow_joint_trajectory_goal

        now = self.twin.now
        self.goals.append(cmd.purpose)
        self.record.events.append((now, {"type": "goal", "purpose": cmd.purpose,
                                         "start_time": cmd.start_time}))
        try:
            if cmd.purpose != "stop":  # as the node: a stop joins the running motion
                check_start(cmd.trajectory, dict(zip(self.robot.joint_names, self.twin.q,
                                                     strict=True)))
            goal = follow_joint_trajectory_goal(
                cmd.trajectory, controller=self.robot.controller,
                stamp_ns=max(1, round(cmd.start_time * _NS)), backend="rosbags")
        except SafepathError as exc:
            self.dispatch(self.ctl.on_goal_result(cmd.goal_id, False, str(exc), now))
            return
        self.record.goals.append((now, "arm", goal))
        if self.twin.arm.active is not None:  # replaced: its motion ends now
            for motion in reversed(self.motions):
                if motion.goal_id == self.twin.arm.active:
                    motion.end = min(motion.end, now)
                    break
        self.motions.append(_Motion(cmd.goal_id, now, math.inf, cmd.trajectory, self.world,
                                    cmd.start_time))
        self.stamps[cmd.goal_id] = cmd.start_time
        self.purpose[cmd.goal_id] = cmd.purpose
        self.arm_goal = cmd.goal_id
        rejected = self.twin.send_arm_goal(goal, cmd.goal_id)
        if rejected is not None:
            self.dispatch(self.ctl.on_goal_result(cmd.goal_id, False, rejected.error_string,
                                                  now))

    def _grip(self, cmd: Any) -> None:
        from ..ros import gripper_command_goal, tool_goal

        robot = self.robot
        if robot.controller.gripper is not None:
            goal = gripper_command_goal(robot, cmd.event.action, backend="rosbags")
            kind = "gripper"
        else:
            goal = tool_goal(cmd.event.action, backend="rosbags")
            kind = "tool"
        self.record.goals.append((self.twin.now, kind, goal))
        self.grippers.add(cmd.goal_id)
        rejected = self.twin.send_gripper_goal(goal, cmd.goal_id)
        if rejected is not None:
            self.grippers.discard(cmd.goal_id)
            self.dispatch(self.ctl.on_goal_result(cmd.goal_id, False, rejected.message,
                                                  self.twin.now))

    # -- events ----------------------------------------------------------------------
    def on_result(self, result: ArmResult | GripperResult) -> None:
        now = self.twin.now
        if isinstance(result, GripperResult):
            self.grippers.discard(result.goal_id)
            if result.success:
                grasp = self.plan.cell.scene.grasp
                if result.action == "close":
                    self.holding = True
                    self.world = MotionWorld(self.cup, None)
                elif self.holding:  # a release (an open with nothing held changes nothing)
                    self.holding = False
                    rest = None
                    if grasp is not None:
                        T = self.robot.frame_pose(self.twin.q).homogeneous  # noqa: N806
                        rest = T @ grasp.T_tcp_object
                    self.world = MotionWorld(None, rest)
            self.dispatch(self.ctl.on_goal_result(result.goal_id, result.success,
                                                  result.message, now))
            return
        for motion in reversed(self.motions):
            if motion.goal_id == result.goal_id:
                motion.end = result.time
                break
        if self.arm_goal == result.goal_id:
            self.arm_goal = None
        if result.error_code == CANCELED:
            return
        self.dispatch(self.ctl.on_goal_result(result.goal_id, result.success,
                                              result.error_string, now))

    def flow(self) -> None:
        """Integrate the flow out of the cup over the last step (trapezoid on the tilt the
        simulated arm has)."""
        tilt = self._tilt()
        rate = self.truth.rate(np.array([self.tilt, tilt]))
        dt = self.twin.now - self.ts[-1]
        self.ts.append(self.twin.now)
        self.out.append(self.out[-1] + 0.5 * float(rate.sum()) * dt)
        self.tilt = tilt

    def reading(self) -> float:
        """What landed ``latency`` ago, plus noise [g]."""
        truth = self.truth
        t = self.twin.now - truth.latency - truth.fall_time
        k = bisect.bisect_right(self.ts, t)
        if k == 0:
            landed = 0.0
        elif k == len(self.ts):
            landed = self.out[-1]
        else:
            t0, t1 = self.ts[k - 1], self.ts[k]
            landed = self.out[k - 1] + (self.out[k] - self.out[k - 1]) * (t - t0) / (t1 - t0)
        return landed + float(self.rng.normal(0.0, truth.noise))

    def feedback(self) -> None:
        """The tilt's progress: the trajectory controller's ``desired.time_from_start``."""
        goal = self.arm_goal
        if goal is not None and self.purpose.get(goal) == "pour":
            tfs = max(0.0, self.twin.now - self.stamps[goal])
            self.dispatch(self.ctl.on_arm_feedback(goal, tfs, self.twin.now))


    def loop(self) -> None:
        """Run the node's event loop on the simulated clock until the pour is over (and
        what was poured has landed), or ``max_time``."""
        from ..cells.pouring.controller import PourState

        params, truth, twin = self.params, self.truth, self.twin
        self.dispatch(self.ctl.start(0.0))
        next_reading, next_tick = truth.period, params.tick
        next_feedback = params.feedback_period
        kill_at = params.kill_at
        done_at: float | None = None
        settle = truth.latency + truth.fall_time + 0.5
        while twin.now < params.max_time - 1e-9:
            nxt = twin.now + params.step
            for when in (next_reading, next_tick, kill_at):
                if when is not None:
                    nxt = min(nxt, max(when, twin.now + twin.options.timestep))
            results = twin.advance(nxt)
            self.flow()
            now = twin.now
            for result in results:
                self.on_result(result)
            if now >= next_reading - 1e-9:
                next_reading += truth.period
                self.dispatch(self.ctl.on_weight(self.reading(), now, now))
            if kill_at is not None and now >= kill_at - 1e-9:
                kill_at = None
                self.record.events.append((now, {"type": "kill"}))
                self.dispatch(self.ctl.kill(now))
            if now >= next_feedback - 1e-9:
                next_feedback += params.feedback_period
                self.feedback()
            if now >= next_tick - 1e-9:
                next_tick += params.tick
                self.dispatch(self.ctl.on_tick(now))
            finished = self.ctl.state in (PourState.DONE, PourState.FAULT)
            if done_at is None and finished and twin.arm.active is None and not self.grippers:
                done_at = now
            if done_at is not None and now > done_at + settle:
                break


def _truth(seed: int, params: PouringParams) -> FlowModel:
    from ..cells.pouring.flow import FlowModel

    rng = np.random.default_rng([seed, 0])
    gain = float(rng.uniform(*params.gain_range))
    latency = float(rng.uniform(*params.latency_range))
    return FlowModel(gain=gain, latency=latency, fall_time=params.fall_time,
                     period=params.period, noise=params.noise, seed=seed)


def run_pouring(cell: str | Path, seed: int, params: PouringParams | None = None, *,
                record: bool = False) -> PouringRun:
    """Run the pouring cell's twin (see the module docstring).

    Args:
        cell: The cell's scene folder (its pour planned once per process).
        seed: The run's seed: the cup's flow gain, the scale's latency and noise.
        params: The run's parameters.
        record: Keep the material of a bag (:func:`safepath.sim.bag.write_run_bag`).

    Raises:
        InputError: Bad parameters or seed.
        SafepathError: The cell cannot be loaded or its pour planned.
    """
    params = params or PouringParams()
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"expected an integer >= 0, got {seed!r}", key="seed")
    plan = pour_plan(str(cell), params.pour_route, params.pick_and_place)
    truth = _truth(int(seed), params)
    run = _Pour(plan, truth, params)
    twin = run.twin
    t0 = time.perf_counter()
    run.loop()
    wall = time.perf_counter() - t0
    t1 = time.perf_counter()
    robot = plan.cell.robot
    clearance = executed_clearance(plan.cell, twin.recording, run.motions)
    deviation = tcp_deviation(robot, twin.recording)
    clearance_time = time.perf_counter() - t1
    rec = twin.recording
    q = np.asarray(rec.q)
    lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    limit_margin = float(np.min(np.minimum(q - lower, upper - q)))
    killed = params.kill_at if params.kill_at is not None and params.kill_at <= twin.now \
        else None
    moved = 0.0
    if killed is not None:
        late = q[np.asarray(rec.time) >= killed + 1.0]
        moved = float(np.ptp(late, axis=0).max()) if late.shape[0] else 0.0
    material = None
    if record:
        run.record.time = np.asarray(rec.time)
        run.record.q = q
        run.record.qd = np.asarray(rec.qd)
        run.record.joint_names = tuple(robot.joint_names)
        material = run.record
    return PouringRun(
        seed=int(seed), gain=truth.gain, latency=truth.latency,
        final_mass=float(run.out[-1]), target=params.target, tolerance=params.tolerance,
        report=run.ctl.report, state=run.ctl.state.value, goals=tuple(run.goals),
        faults=tuple(run.faults), duration=twin.now, wall_time=wall,
        clearance_time=clearance_time, tracking=rec.tracking.copy(),
        speed_ratio=rec.speed_ratio.copy(), limit_margin=limit_margin,
        contact_steps=rec.contact_steps, clearance=clearance, tcp_deviation=deviation,
        margin=plan.cell.scene.margin, joint_names=tuple(robot.joint_names),
        killed_at=killed, moved_after_kill=moved, record=material)
