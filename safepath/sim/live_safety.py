"""The live-safety suite: randomized, seeded closed-loop runs of the monitor node in the
twin, judged against the invariants of issue 34.

Each run (:func:`run_live_safety`) draws from its seed alone (:meth:`LiveSafetyDraw.draw`):

* **a body**: one crossing the cell from any direction at up to 1.6 m/s (a person-sized
  or an arm-sized :class:`~safepath.sim.obstacles.MovingBody`), or a small object that
  walks in at up to 1.6 m/s and parks on the route (within 5 cm of the TCP's path), beside
  it (10-25 cm off), or on it and then walks away again (:class:`ParkingBody`), never
  standing inside the arm (drawn again when it would, before it enters or once parked);
* **sensor silences**: the laser's, the camera's or both sensors' messages dropped for
  30 ms to 1.2 s;
* **a kill**: none, at a random instant, 0-5 ms before the end of a motion (as the
  controller runs it, ``kill_lead``), or while a re-plan is being planned (between the
  request and its answer, both ends included).

The re-plan's answer reaches the node a seeded 80-600 ms after its request (the warm
runtime planner's latency and more), not after the twin's own planning wall time, so
that a run replays exactly from its seed.

A run fails (:attr:`LiveSafetyRun.failures`) on anything :class:`ObstacleRun` fails (a
commanded speed, acceleration or jerk over its limit, a goal switch that steps the
controller's state, a held object dropped, a goal rejected or aborted, a command after
the kill, motion after it) and on: contact with the body while the arm moves (true
distance < 0 while a joint's executed speed exceeds
:data:`~safepath.sim.obstacles.MOVING_SPEED`), a closest approach while moving below the
protective minimum (``MonitorOptions.min_separation``), a goal after the kill other than
the kill's own stop, a stop the monitor deferred, a stop beyond the limits.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..errors import InputError
from .monitor_loop import check_run, configured_core
from .obstacles import MovingBody, ObstacleRun, ObstacleTwin, SensorRig

if TYPE_CHECKING:
    from ..monitor.node import MonitorNodeCore

__all__ = ["ParkingBody", "Silence", "LiveSafetyDraw", "LiveSafetyTwin", "LiveSafetyRun",
           "run_live_safety", "LIVE_SAFETY_ROUTE", "BodyKind", "KillMode"]

#: The route the suite runs (the node core plans it alone: it follows no other route).
LIVE_SAFETY_ROUTE = "phase1"
#: Simulated time of a run [s]: the route (about 7 s undisturbed), a stop, the hold
#: time, a re-plan after ``replan_after`` + ``rest_window`` and its motion.
DURATION = 14.0
#: Fastest body [m/s] (ISO 13855's walking speed, the monitor's ``approach_speed``).
TOP_SPEED = 1.6
#: How long a re-plan's answer takes to reach the node [s] (drawn per request).
REPLAN_LATENCY = (0.08, 0.6)
#: A parking body stands at least this far from the arm's enclosing spheres [m].
_CLEAR = 0.005
#: Parking draws tried before a seed is refused.
_REDRAWS = 50
#: The twin's gripper action takes this long [s] (TwinOptions' default).
_GRIPPER_TIME = 0.5

BodyKind = Literal["crossing", "parked on route", "parked beside", "parked then leaves"]
KillMode = Literal["none", "instant", "motion end", "replan"]
_KINDS: tuple[BodyKind, ...] = ("crossing", "parked on route", "parked beside",
                                "parked then leaves")
_KIND_SHARE = (0.35, 0.3, 0.15, 0.2)
_KILLS: tuple[KillMode, ...] = ("none", "instant", "motion end", "replan")
_KILL_SHARE = (0.25, 0.3, 0.25, 0.2)


@dataclass(frozen=True)
class ParkingBody(MovingBody):
    """A :class:`MovingBody` that parks where its straight walk ends (at ``leave``) and,
    from ``depart`` on, walks away at ``depart_velocity`` for ``depart_for``.

    Attributes:
        depart: When it walks away again [s] (inf: it stays).
        depart_velocity: Its horizontal velocity then (x, y) [m/s].
        depart_for: How long it walks away [s] (it waits there after).
    """

    depart: float = math.inf
    depart_velocity: tuple[float, float] = (0.0, 0.0)
    depart_for: float = 0.0

    def at(self, t: float) -> np.ndarray:
        """Centre of the cylinder at ``t`` [s] (x, y, z) [m]."""
        c = super().at(t)
        if t > self.depart:
            s = min(t - self.depart, self.depart_for)
            c[0] += self.depart_velocity[0] * s
            c[1] += self.depart_velocity[1] * s
        return c


@dataclass(frozen=True)
class Silence:
    """Sensors whose messages are dropped for a while.

    Attributes:
        frames: The sensors' frame ids.
        start: From [s] (capture time).
        end: Until [s].
    """

    frames: tuple[str, ...]
    start: float
    end: float


@dataclass(frozen=True)
class LiveSafetyDraw:
    """What one run of the suite draws from its seed.

    Attributes:
        seed: The run's seed.
        kind: Which kind of body.
        body: The body.
        silences: The sensor silences.
        kill: How the kill is pressed.
        kill_at: When, for ``instant`` [s].
        kill_before_end_of: Which motion's end, for ``motion end`` (0: the first).
        kill_lead: How long before that end [s] (0-5 ms).
        kill_share: Where between the first re-plan's request and its answer, for
            ``replan`` (0: at the request, 1: at the answer's arrival).
        duration: Simulated time [s].
    """

    seed: int
    kind: BodyKind
    body: MovingBody
    silences: tuple[Silence, ...]
    kill: KillMode
    kill_at: float | None
    kill_before_end_of: int | None
    kill_lead: float
    kill_share: float
    duration: float

    @classmethod
    def draw(cls, seed: int, core: MonitorNodeCore, *, duration: float = DURATION
             ) -> LiveSafetyDraw:
        """The draws of run ``seed`` on the route of a configured node core."""
        from ..model.trajectory import Trajectory

        rng = np.random.default_rng([seed, 34])
        assert core.monitor is not None
        robot = core.monitor.cell.robot
        # Each motion and when it starts, undisturbed [s].
        motions: list[tuple[Trajectory, float]] = []
        clock = 0.0
        for part in core.sequence:
            if isinstance(part, Trajectory):
                motions.append((part, clock))
                clock += part.duration
            else:
                clock += _GRIPPER_TIME
        kind = _KINDS[int(rng.choice(len(_KINDS), p=_KIND_SHARE))]
        if kind == "crossing":
            body = _crossing(rng)
        else:
            k = 0 if len(motions) == 1 or rng.uniform() < 0.8 else int(
                rng.integers(1, len(motions)))
            motion, begins = motions[k]
            arm = _ArmClear(core, motions)
            for _ in range(_REDRAWS):  # a body that would stand inside the arm: again
                tau = float(rng.uniform(0.15, 0.95)) * motion.duration
                tcp = np.asarray(robot.tcp_position(motion.sample([tau])[0][0]),
                                 dtype=float)
                body = _parking(rng, kind, tcp, begins + tau)
                if arm.clear(body):
                    break
            else:
                raise InputError(f"seed {seed}: no parking spot clear of the arm in "
                                 f"{_REDRAWS} draws", key="seed")
        silences = tuple(_silence(rng, duration)
                         for _ in range(int(rng.choice(3, p=(0.5, 0.35, 0.15)))))
        kill = _KILLS[int(rng.choice(len(_KILLS), p=_KILL_SHARE))]
        if kill == "replan" and kind == "crossing":
            kill = "instant"  # nothing parks: no re-plan to kill during
        kill_at = float(rng.uniform(0.2, duration - 1.5)) if kill == "instant" else None
        before_end = int(rng.integers(0, len(motions))) if kill == "motion end" else None
        lead = float(rng.uniform(0.0, 0.005))
        share = float(rng.uniform(0.0, 1.0))
        return cls(int(seed), kind, body, silences, kill, kill_at, before_end, lead, share,
                   duration)

    def describe(self) -> str:
        """One line: the body, the silences, the kill."""
        b = self.body
        speed = math.hypot(*b.velocity)
        text = f"{self.kind} (r {b.radius:.2f} m, {speed:.2f} m/s"
        if isinstance(b, ParkingBody) and math.isfinite(b.depart):
            text += f", leaves at {b.depart:.2f} s at {math.hypot(*b.depart_velocity):.2f} m/s"
        text += ")"
        for s in self.silences:
            text += f"; {'+'.join(s.frames)} silent {s.start:.2f}-{s.end:.2f} s"
        if self.kill == "instant":
            text += f"; kill at {self.kill_at:.3f} s"
        elif self.kill == "motion end":
            text += (f"; kill {1000 * self.kill_lead:.2f} ms before the end of motion "
                     f"{self.kill_before_end_of}")
        elif self.kill == "replan":
            text += f"; kill during the first re-plan ({self.kill_share:.2f} of its wait)"
        return text


def _crossing(rng: np.random.Generator) -> MovingBody:
    """A person (r 8-20 cm, 1 m tall, on the table's plane) or an arm (r 4-7 cm,
    15-35 cm long, 5-30 cm up) crossing past the base axis at 5-60 cm."""
    if rng.uniform() < 0.6:
        size: dict[str, float] = {"radius": float(rng.uniform(0.08, 0.2)), "height": 1.0,
                                  "base_z": 0.0}
    else:
        size = {"radius": float(rng.uniform(0.04, 0.07)),
                "height": float(rng.uniform(0.15, 0.35)),
                "base_z": float(rng.uniform(0.05, 0.3))}
    return MovingBody.crossing(rng, **size, pass_distance=(0.05, 0.6),
                               speed=(0.2, TOP_SPEED), enter=(0.2, 9.0), reach=1.5)


def _parking(rng: np.random.Generator, kind: BodyKind, tcp: np.ndarray, due: float
             ) -> ParkingBody:
    """A small object (r 4-6 cm, 5-14 cm tall) that walks in and parks near ``tcp``
    [m] (on the route: within 5 cm; beside it: 10-25 cm off, horizontally), arriving
    0.3-3 s before the arm is due there (``due`` [s])."""
    if kind == "parked beside":
        heading = float(rng.uniform(0.0, 2.0 * math.pi))
        offset = float(rng.uniform(0.1, 0.25)) * np.array([math.cos(heading),
                                                           math.sin(heading), 0.0])
    else:
        v = rng.normal(size=3)
        offset = float(rng.uniform(0.0, 0.05)) * v / np.linalg.norm(v)
    spot = tcp + offset
    radius, height = float(rng.uniform(0.04, 0.06)), float(rng.uniform(0.05, 0.14))
    heading = float(rng.uniform(0.0, 2.0 * math.pi))
    u = np.array([math.cos(heading), math.sin(heading)])
    speed = float(rng.uniform(0.2, TOP_SPEED))
    walk = float(rng.uniform(0.5, 1.0))
    arrive = max(0.3, due - float(rng.uniform(0.3, 3.0)))
    enter = max(0.0, arrive - walk / speed)
    start = spot[:2] - u * speed * (arrive - enter)
    depart, away, away_for = math.inf, (0.0, 0.0), 0.0
    if kind == "parked then leaves":
        depart = arrive + float(rng.uniform(0.5, 6.0))
        turn = float(rng.uniform(0.0, 2.0 * math.pi))
        away_speed = float(rng.uniform(0.2, TOP_SPEED))
        away = (away_speed * math.cos(turn), away_speed * math.sin(turn))
        away_for = 1.5 / away_speed
    return ParkingBody(radius, height, float(spot[2] - height / 2),
                       (float(start[0]), float(start[1])),
                       (float(speed * u[0]), float(speed * u[1])), enter, arrive,
                       depart, away, away_for)


class _ArmClear:
    """Whether a parking body stays clear of the arm where it stands still: before it
    enters (at its start) and once parked (from its arrival), against the arm's
    enclosing spheres at its undisturbed pose then. The twin's body passes through the
    arm (it has no contacts); a real one cannot stand inside it, and the sensors cannot
    see one that does."""

    def __init__(self, core: MonitorNodeCore, motions: list[tuple[Any, float]]) -> None:
        from ..monitor.sweep import RobotSpheres

        assert core.monitor is not None
        cell = core.monitor.cell
        self.robot = cell.robot
        self.spheres = RobotSpheres.build(cell.robot, cell.scene, None)
        self.motions = motions

    def _pose(self, t: float) -> np.ndarray:
        """The arm's undisturbed joint position at ``t`` [s]."""
        traj, begins = self.motions[0]
        for m, b in self.motions:
            if b <= t:
                traj, begins = m, b
        return traj.sample([min(max(t - begins, 0.0), traj.duration)])[0][0]

    def clear(self, body: ParkingBody) -> bool:
        for t in (0.0, body.leave):
            centers, _ = self.spheres.place(self.robot, self._pose(t)[None])
            c = body.at(t)
            radial = np.maximum(np.linalg.norm(centers[0][:, :2] - c[:2], axis=1)
                                - body.radius, 0.0)
            axial = np.maximum(np.abs(centers[0][:, 2] - c[2]) - body.height / 2, 0.0)
            if np.any(np.hypot(radial, axial) < self.spheres.radii + _CLEAR):
                return False
        return True


def _silence(rng: np.random.Generator, duration: float) -> Silence:
    which = int(rng.integers(0, 3))
    frames = (("laser",), ("camera",), ("laser", "camera"))[which]
    start = float(rng.uniform(0.3, duration - 0.5))
    return Silence(frames, start, start + float(rng.uniform(0.03, 1.2)))


class LiveSafetyTwin(ObstacleTwin):
    """:class:`ObstacleTwin` with sensor silences, seeded re-plan latencies, a kill
    during a re-plan and the re-plans' outcomes kept.

    Attributes (beyond :class:`ObstacleTwin`'s):
        silences: The sensor silences.
        kill_share: For a kill during the first re-plan: where in its wait (None: no
            such kill).
        dropped_messages: Sensor messages dropped by the silences.
        replan_answers: Each re-plan's planner outcome, in order: (``ok``, "") or
            (``failed``, the planner's why).
        replan_outcomes: What became of each answer that reached the node: ``taken``
            (its first motion sent), ``held by the gate`` (taken, its first motion
            refused: the kill), ``discarded`` (the arm had moved on) or
            ``failed: <why>``.
        kill_in_replan: Whether the kill was pressed while a re-plan was being planned.
    """

    def __init__(self, core: MonitorNodeCore, *, body: MovingBody, rig: SensorRig,
                 seed: int, silences: tuple[Silence, ...] = (),
                 kill_share: float | None = None) -> None:
        super().__init__(core, body=body, rig=rig, seed=seed)
        self.silences = silences
        self.kill_share = kill_share
        self.dropped_messages = 0
        self.replan_answers: list[tuple[str, str]] = []
        self.replan_outcomes: list[str] = []
        self.kill_in_replan = False
        self._latency_rng = np.random.default_rng([seed, 11])
        self._replan_kill: float | None = None
        # Unanswered re-plans: (arrival time [s], the planner's why, "" if it found one).
        self._pending: list[tuple[float, str]] = []

    def _push(self, when: float, kind: str, payload: Any) -> None:
        now = self.twin.now
        if kind == "scan":
            frame = str(payload.header.frame_id)
            if any(s.start <= now < s.end and frame in s.frames for s in self.silences):
                self.dropped_messages += 1
                return
        elif kind == "replan":
            status, value = payload[1]
            self.replan_answers.append((status, "" if status == "ok" else str(value)))
            when = now + float(self._latency_rng.uniform(*REPLAN_LATENCY))
            self._pending.append((when, "" if status == "ok" else str(value)))
            if self.kill_share is not None and self._replan_kill is None \
                    and self.kill_time is None:
                self._replan_kill = now + self.kill_share * (when - now)
        super()._push(when, kind, payload)

    def _kill_due(self, kill_at: float | None, before_end_of: int | None, lead: float
                  ) -> float | None:
        if self.kill_share is None:
            return super()._kill_due(kill_at, before_end_of, lead)
        return None if self.kill_time is not None else self._replan_kill

    def _press_kill(self) -> None:
        now = self.twin.now
        self.kill_in_replan = any(now <= t + 1e-12 for t, _ in self._pending)
        super()._press_kill()

    def _deliver(self, now: float) -> None:
        answered = len(self.replans)
        sequence, goals, refused = self.core.sequence, len(self.arm_goals), \
            len(self.core.refused)
        super()._deliver(now)
        for _, status in self.replans[answered:]:
            # Answers arrive in the order of their arrival times.
            _, why = self._pending.pop(self._pending.index(min(self._pending)))
            if status != "ok":
                self.replan_outcomes.append(f"failed: {why}")
            elif self.core.sequence is sequence:
                self.replan_outcomes.append("discarded")
            elif len(self.arm_goals) > goals:
                self.replan_outcomes.append("taken")
            elif len(self.core.refused) > refused:
                self.replan_outcomes.append("held by the gate")
            else:
                self.replan_outcomes.append("taken")
            sequence = self.core.sequence


@dataclass(frozen=True)
class LiveSafetyRun:
    """One run of the suite, judged.

    Attributes:
        draw: What the run drew.
        obstacle: The obstacle twin's report of it (its own failures among ours).
        min_separation: The protective minimum, ``MonitorOptions.min_separation`` [m].
        goals_after_kill: Goals (arm, gripper) the core sent after the kill, other than
            the kill's own stop, as ``"<time> <reason>"``.
        stats: The monitor's counters (``deferred``, ``stops_over_limit``,
            ``gentle_stops``, ``switch_steps``, ...).
        switches: Goal switches the controller took while a goal ran.
        switch_steps: Those that stepped its commanded state (not continuous).
        replan_requests: Re-plan requests the core issued.
        replan_outcomes: What became of each answer (see
            :attr:`LiveSafetyTwin.replan_outcomes`); requests without one were still
            unanswered at the run's end.
        kill_in_replan: Whether the kill was pressed while a re-plan was being planned.
        dropped_messages: Sensor messages the silences dropped.
        failures: What broke, one line each (empty: the run passed).
    """

    draw: LiveSafetyDraw
    obstacle: ObstacleRun
    min_separation: float
    goals_after_kill: tuple[str, ...]
    stats: dict[str, int]
    switches: int
    switch_steps: int
    replan_requests: int
    replan_outcomes: tuple[str, ...]
    kill_in_replan: bool
    dropped_messages: int
    failures: tuple[str, ...]

    @property
    def seed(self) -> int:
        """The run's seed."""
        return self.draw.seed

    @property
    def ok(self) -> bool:
        """Whether the run passed."""
        return not self.failures

    @property
    def contact_moving(self) -> bool:
        """Whether the arm touched the body while it moved."""
        return self.obstacle.closest_moving < 0.0

    @property
    def dropped(self) -> tuple[str, ...]:
        """The obstacle twin's failures that are gripper actions away from their pose (a
        held object dropped, or an object missed)."""
        return tuple(f for f in self.obstacle.failures if f.startswith("gripper "))


def run_live_safety(cell: str, seed: int, *, duration: float = DURATION,
                    rig: SensorRig | None = None) -> LiveSafetyRun:
    """One run of the suite (see the module docstring): seed ``seed`` alone decides it.

    Args:
        cell: Scene folder (the suite's route, :data:`LIVE_SAFETY_ROUTE`, must be one
            of its routes).
        seed: The run's seed (>= 0).
        duration: Simulated time [s].
        rig: The sensors (default: :class:`SensorRig()`).

    Raises:
        InputError: A bad seed or duration.
    """
    from ..monitor import MonitorOptions

    check_run(seed, duration, shortest=2.0)
    rig = rig or SensorRig()
    options = MonitorOptions(sensors=rig.sensors())
    core = configured_core(cell, LIVE_SAFETY_ROUTE, options)
    draw = LiveSafetyDraw.draw(int(seed), core, duration=float(duration))
    loop = LiveSafetyTwin(core, body=draw.body, rig=rig, seed=int(seed),
                          silences=draw.silences,
                          kill_share=draw.kill_share if draw.kill == "replan" else None)
    t0 = time.perf_counter()
    loop.run(draw.duration, kill_at=draw.kill_at, kill_before_end_of=draw.kill_before_end_of,
             kill_lead=draw.kill_lead)
    report = loop.report(wall_time=time.perf_counter() - t0)
    return _judge(draw, loop, report, options.min_separation)


def _goals_after_kill(loop: LiveSafetyTwin) -> tuple[str, ...]:
    """Goals issued after the kill was pressed, less the kill's own stop (the first goal
    after it, at its instant, a stop)."""
    pressed = next((i for i, c in enumerate(loop.issued) if c.kind == "kill"), None)
    if pressed is None:
        return ()
    goals = [c for c in loop.issued[pressed + 1:] if c.kind in ("goal", "gripper")]
    if goals and goals[0].kind == "goal" and goals[0].detail == "stop" \
            and goals[0].time <= loop.issued[pressed].time + 1e-12:
        goals = goals[1:]
    return tuple(f"{c.time:.3f} s {c.kind} {c.detail}" for c in goals)


def _judge(draw: LiveSafetyDraw, loop: LiveSafetyTwin, report: ObstacleRun,
           min_separation: float) -> LiveSafetyRun:
    """The run's figures and failures."""
    assert loop.core.monitor is not None
    stats = dict(loop.core.monitor.stats)
    after = _goals_after_kill(loop)
    switches = loop.twin.arm.switches
    steps = sum(1 for _, s in switches if not s.continuous)
    failures = list(report.failures)
    moving = report.closest_moving
    if moving < 0.0:
        failures.append(f"contact while the arm moves: {1000 * moving:.1f} mm")
    elif moving < min_separation:
        failures.append(f"closest approach while moving {1000 * moving:.1f} mm < the "
                        f"protective minimum {1000 * min_separation:.0f} mm")
    if after and not any(f.startswith("after the kill") for f in report.failures):
        failures.append(f"goals after the kill: {', '.join(after)}")
    for key, what in (("deferred", "stops deferred"),
                      ("stops_over_limit", "stops beyond the limits")):
        if stats.get(key, 0):
            failures.append(f"{what}: {stats[key]}")
    requests = sum(1 for c in loop.issued if c.kind == "replan")
    return LiveSafetyRun(draw, report, min_separation, after, stats, len(switches), steps,
                         requests, tuple(loop.replan_outcomes), loop.kill_in_replan,
                         loop.dropped_messages, tuple(failures))
