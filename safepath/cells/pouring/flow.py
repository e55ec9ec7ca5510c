"""The gravimetric pour in simulation: a flow model, a scale, and the stop on its reading.

The brief (001) tilts the cup in 20 separate moves while reading a scale on ``/weight``,
stops once the reading reaches 100 g and goes back upright: ~103 g in the bowl, 110-120 g
with their first version (one move straight to 90 deg). Here the tilt is one continuous timed motion
(:func:`~safepath.planning.pour.plan_tilt`); when the controller decides to stop, the
robot brakes along the same path (:class:`~safepath.planning.stop.StopPlanner`) and
returns upright by a motion planned, checked, timed and verified like any other.

Flow model (documented, deterministic for a seed), two variants:

* ``FlowModel(cup=Cup())``: a cup that empties over its lip
  (:class:`~safepath.cells.pouring.cup.Cup`): ``gain * (tilt - spill_angle(content)) ** 1.5``
  [g/s], the spill angle rising as the cup empties; its fill, repose and gain were fitted
  to the brief's two measured figures (``scenes/pouring_cell/README.md``). The benchmark
  and the tests use it.
* ``FlowModel()`` (``cup=None``): an endless cup, ``gain * (tilt - spill_angle) ** 1.5``
  past a fixed ``spill_angle`` whatever was poured (with it the brief's 20 steps pour
  136-220 g, far from their ~103 g); kept for the ROS pour controller's simulation.

Either way the material reaches the bowl ``fall_time`` later, and the scale reports the
bowl's mass ``latency`` later, every ``period``, with Gaussian ``noise``.

Controller (:func:`simulate_pour`): it knows the flow law's shape (for the cup: the cup
and its fill), the scale's latency and the fall time, but not the flow gain; at each
reading it fits the gain to the readings so far, predicts the final mass if it stopped
now (what is in the air and in the sensor's latency, what the stop and the return still
pour) and stops when that reaches the target (endless cup: a closed-form fit and
:func:`calibrate_still`; cup: :mod:`.stop_decision`). :func:`simulate_stepwise` runs the
seed's stepwise tilt in the same simulation for comparison.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ...errors import ConfigError
from .cup import Cup
from .stop_decision import StopTable, decide, plan_stops

if TYPE_CHECKING:
    from ...cell import Cell
    from ...planning.pour import PourMotion, PourOptions

__all__ = ["FlowModel", "PourRun", "simulate_pour", "simulate_stepwise", "stop_and_return",
           "calibrate_still", "plan_stops", "StopTable", "Cup"]


@dataclass(frozen=True, kw_only=True)
class FlowModel:
    """The cup, the material and the scale.

    Attributes:
        gain: Flow rate per (rad beyond the spill angle)^1.5 [g/s].
        spill_angle: Tilt at which material starts to leave the cup [rad].
        fall_time: Time from the lip to the bowl [s].
        latency: Scale reading delay [s].
        period: Scale reading period [s].
        noise: Standard deviation of a reading [g].
        seed: Seed of the noise.
        cup: The cup that empties (its spill angle rises as it does; ``spill_angle`` is
            then unused), or None: an endless cup spilling past ``spill_angle``.
    """

    gain: float = 30.0
    spill_angle: float = math.radians(70.0)
    fall_time: float = 0.15
    latency: float = 0.10
    period: float = 0.0125
    noise: float = 0.2
    seed: int = 0
    cup: Cup | None = None

    def __post_init__(self) -> None:
        if self.cup is not None and not isinstance(self.cup, Cup):
            raise ConfigError(f"expected a Cup or None, got {type(self.cup).__name__}",
                              key="cup")
        for name in ("gain", "fall_time", "period"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"must be > 0, got {getattr(self, name)!r}", key=name)
        for name in ("latency", "noise"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"must be >= 0, got {getattr(self, name)!r}", key=name)

    def rate(self, tilt: np.ndarray) -> np.ndarray:
        """Flow out of the endless cup at ``tilt`` [rad] (array) [g/s]."""
        return self.gain * np.maximum(np.asarray(tilt) - self.spill_angle, 0.0) ** 1.5


@dataclass(frozen=True)
class PourRun:
    """One simulated pour.

    Attributes:
        final_mass: Mass in the bowl once everything has landed [g].
        stop_time: When the stop was decided [s] (None: never).
        stop_tilt: Tilt when the robot came to rest [rad].
        compute_time: Wall time of the stop computation at the event [s].
        t: Simulation times [s].
        tilt: Tilt of the cup [rad].
        mass: Mass in the bowl [g].
        readings: (time [s], reading [g]) of the scale.
        gain_estimate: The controller's flow gain when it decided [g/s/rad^1.5] (NaN
            where it has none: the brief's way, the endless cup).
    """

    final_mass: float
    stop_time: float | None
    stop_tilt: float
    compute_time: float
    t: np.ndarray
    tilt: np.ndarray
    mass: np.ndarray
    readings: np.ndarray
    gain_estimate: float = float("nan")


def _landed(model: FlowModel, t: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """Mass in the bowl at times ``t`` for a tilt history sampled at ``t`` [g]."""
    if model.cup is not None:
        out = model.cup.pour(t, tilt, model.gain)
    else:
        out = np.concatenate([[0.0], np.cumsum(0.5 * (model.rate(tilt[1:])
                                                      + model.rate(tilt[:-1])) * np.diff(t))])
    return np.interp(t - model.fall_time, t, out, left=0.0)


def _readings(model: FlowModel, t: np.ndarray, mass: np.ndarray, until: float) -> np.ndarray:
    rng = np.random.default_rng(model.seed)
    times = np.arange(model.period, until, model.period)
    true = np.interp(times - model.latency, t, mass, left=0.0)
    return np.column_stack([times, true + rng.normal(0.0, model.noise, times.size)])


def simulate_pour(tilt_of_t: Callable[[float], float], duration: float,
                  stop: Callable[[float], tuple[np.ndarray, np.ndarray, float]],
                  model: FlowModel, *, target: float = 100.0,
                  still: Callable[[float], float] | None = None,
                  return_speed: float = math.radians(30.0), brake_time: float = 0.25,
                  min_reading: float = 5.0, stops: StopTable | None = None,
                  dt: float = 0.002) -> PourRun:
    """Closed loop: follow the tilt, stop on the scale's reading, return upright.

    The controller knows the tilt it commands, the flow law's shape (spill angle,
    exponent), the scale's latency and the fall time, but not the flow gain: it fits the
    gain to the readings (least squares of reading against the flow integral of the tilt
    history ``latency + fall_time`` earlier), predicts the final mass if it stopped now
    (everything poured so far, the flow during braking and while turning back below the
    spill angle) and stops when that reaches ``target``. What the stop and the return
    pour is ``still(tilt)`` (per unit gain; :func:`calibrate_still` measures it on the
    planned motions), else estimated as ``brake_time`` at the current rate plus a turn
    back at ``return_speed``.

    With a cup (``model.cup``), the controller knows the cup and fits the gain on a grid
    instead (:func:`~safepath.cells.pouring.stop_decision.decide`); what its stop and return
    pour comes from ``stops`` (:func:`plan_stops`, made here if not given).

    Args:
        tilt_of_t: Cup tilt along the pour motion at time t [rad].
        duration: Duration of the pour motion [s].
        stop: Called with the event time; returns the tilt history from then on (times
            from the event [s], tilts [rad]: the stop, then the return upright) and the
            wall time the stop computation took [s].
        model: Flow and scale (the simulated truth).
        target: Mass to pour [g].
        still: Flow integral of the stop and the return from a tilt (per unit gain) [s].
        return_speed: Angular speed of the return upright assumed without ``still``
            [rad/s].
        brake_time: Braking (and speeding up back) time assumed without ``still`` [s].
        min_reading: Readings below this are not used to fit the gain [g].
        stops: With a cup: the controller's model of its stops.
        dt: Simulation step [s].
    """
    t_motion = np.arange(0.0, duration + dt, dt)
    tilt_motion = np.array([tilt_of_t(float(x)) for x in t_motion])
    # The readings up to any time depend only on the tilt before it: simulate the motion
    # alone, find the decision, then splice the stop and the return in.
    mass_motion = _landed(model, t_motion, tilt_motion)
    readings = _readings(model, t_motion, mass_motion, duration)
    if model.cup is not None:
        if stops is None:
            stops = plan_stops(stop, tilt_of_t, duration, model.cup)
        decided, gain = decide(model, t_motion, tilt_motion, readings, stops, target)
        return _finish(model, t_motion, tilt_motion, stop, decided, gain, dt)
    shape = dataclasses.replace(model, gain=1.0)  # the flow law without its gain
    poured = np.concatenate([[0.0], np.cumsum(0.5 * (shape.rate(tilt_motion[1:])
                                                      + shape.rate(tilt_motion[:-1]))
                                              * np.diff(t_motion))])
    seen = np.interp(readings[:, 0] - model.latency - model.fall_time, t_motion, poured,
                     left=0.0)
    decided = None
    num = den = 0.0
    for k in range(len(readings)):
        tk, rk = readings[k]
        if rk >= min_reading:
            num += rk * seen[k]
            den += seen[k] ** 2
        if den <= 0.0:
            continue
        gain = num / den
        theta = tilt_of_t(float(tk))
        x = max(theta - model.spill_angle, 0.0)
        so_far = float(np.interp(tk, t_motion, poured))
        coming = still(theta) if still is not None else \
            x ** 1.5 * brake_time + x ** 2.5 / (2.5 * return_speed)
        if gain * (so_far + coming) >= target:
            decided = float(tk)
            break
    return _finish(model, t_motion, tilt_motion, stop, decided, float("nan"), dt)


def _finish(model: FlowModel, t_motion: np.ndarray, tilt_motion: np.ndarray,
            stop: Callable[[float], tuple[np.ndarray, np.ndarray, float]],
            decided: float | None, gain: float, dt: float) -> PourRun:
    """Splice the stop and the return in at the decision, let everything land."""
    if decided is None:
        t_all, tilt_all, compute = t_motion, tilt_motion, 0.0
    else:
        after_t, after_tilt, compute = stop(decided)
        keep = t_motion < decided
        t_all = np.concatenate([t_motion[keep], decided + after_t])
        tilt_all = np.concatenate([tilt_motion[keep], after_tilt])
        t_all, idx = np.unique(t_all, return_index=True)
        tilt_all = tilt_all[idx]
    # Let everything land.
    tail = np.arange(t_all[-1] + dt, t_all[-1] + model.latency + model.fall_time + 2.0, dt)
    t_all = np.concatenate([t_all, tail])
    tilt_all = np.concatenate([tilt_all, np.full(tail.size, tilt_all[-1])])
    mass = _landed(model, t_all, tilt_all)
    rest = tilt_all[np.searchsorted(t_all, decided)] if decided is not None else tilt_all[-1]
    return PourRun(float(mass[-1]), decided, float(rest), compute, t_all, tilt_all, mass,
                   _readings(model, t_all, mass, float(t_all[-1])), gain)


def calibrate_still(stop: Callable[[float], tuple[np.ndarray, np.ndarray, float] | None],
                    tilt_of_t: Callable[[float], float], duration: float, model: FlowModel,
                    *, samples: int = 6, spacing: float | None = None,
                    tolerance: float | None = None, finest: float = 0.004
                    ) -> Callable[[float], float]:
    """What the stop and the return pour from a tilt, per unit flow gain [s], measured
    on the real stop and planned return at ``samples`` events past the spill angle (or
    events ``spacing`` [s] apart, when given) and interpolated in the tilt (the
    controller's model of its own motions). ``stop`` returns the history from the event
    on, or None where no stop can be made (that event is left out).

    With ``tolerance`` [s] (per unit gain), an interval whose midpoint differs from the
    chord by more than it is halved, down to ``finest`` [s] of motion time: what a
    jerk-limited stop pours can step up from one knot to the next where braking takes
    longer, and a chord over the step predicts grams too few just after it."""
    shape = dataclasses.replace(model, gain=1.0)
    times = np.linspace(0.0, duration, 400)
    tilts = np.array([tilt_of_t(float(t)) for t in times])
    first = times[np.argmax(tilts > model.spill_angle)] if (tilts > model.spill_angle).any() \
        else duration
    end = duration * 0.999
    if spacing is not None:
        if not (math.isfinite(spacing) and spacing > 0):
            raise ConfigError(f"must be > 0 [s], got {spacing!r}", key="spacing")
        samples = max(samples, int(math.ceil((end - first) / spacing)) + 1)

    def measure(event: float) -> float | None:
        history = stop(event)
        if history is None:
            return None
        t, tilt, _ = history
        rate = shape.rate(tilt)
        return float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)))

    table = {float(e): measure(float(e)) for e in np.linspace(first, end, samples)}
    if tolerance is not None:
        _refine(table, measure, tolerance, finest)
    events = [e for e in sorted(table) if table[e] is not None]
    if not events:
        raise ConfigError("no stop could be made at any event past the spill angle",
                          key="stop")
    xs = np.array([tilt_of_t(e) for e in events])
    ys = np.array([table[e] for e in events], dtype=float)

    def still(theta: float) -> float:
        return float(np.interp(theta, xs, ys, left=0.0))

    return still


def _refine(table: dict[float, float | None], measure: Callable[[float], float | None],
            tolerance: float, finest: float) -> None:
    """Halve the intervals of ``table`` (event -> value) whose midpoint is farther than
    ``tolerance`` from their chord, until they are ``finest`` long."""
    pending = sorted(table)
    intervals = list(zip(pending[:-1], pending[1:], strict=True))
    while intervals:
        a, b = intervals.pop()
        ya, yb = table[a], table[b]
        if b - a <= finest or ya is None or yb is None:
            continue
        mid = 0.5 * (a + b)
        ym = table[mid] = measure(mid)
        if ym is not None and abs(ym - 0.5 * (ya + yb)) > tolerance:
            intervals += [(a, mid), (mid, b)]


def _move(delta: float, speed: float, accel: float, dt: float) -> np.ndarray:
    """A rest-to-rest move by ``delta`` [rad] (trapezoidal speed), sampled every dt."""
    d = abs(delta)
    t_acc = min(speed / accel, math.sqrt(d / accel))
    v = accel * t_acc
    t_total = 2 * t_acc + max(0.0, d - accel * t_acc ** 2) / v
    ts = np.arange(dt, t_total + dt, dt)
    pos = np.where(ts < t_acc, 0.5 * accel * ts ** 2,
                   np.where(ts < t_total - t_acc, 0.5 * accel * t_acc ** 2 + v * (ts - t_acc),
                            d - 0.5 * accel * np.maximum(t_total - ts, 0) ** 2))
    return float(np.sign(delta)) * np.minimum(pos, d)


def simulate_stepwise(model: FlowModel, *, angle: float = math.radians(115.0), steps: int = 20,
                      speed: float = math.radians(20.0), accel: float = math.radians(40.0),
                      pause: float = 0.3, wait: float = 20.0, target: float = 100.0,
                      dt: float = 0.002) -> PourRun:
    """The brief's way: ``steps`` separate rest-to-rest moves of ``angle / steps`` (bounded
    speed and acceleration, ``pause`` [s] between them for MoveIt's plan-and-execute round
    trip), then waiting at the last tilt (at most ``wait`` [s]), while reading the scale;
    when a reading reaches ``target``, the move in progress finishes (a MoveIt move is
    not interrupted) and the cup goes back upright. ``steps=1, angle=pi/2`` is the
    seed's first version (one move straight to 90 deg)."""
    start = time.perf_counter()
    tilts, ends = [np.zeros(1)], []  # ends: index where each move ends
    for _ in range(steps):
        tilts.append(tilts[-1][-1] + _move(angle / steps, speed, accel, dt))
        ends.append(sum(a.size for a in tilts) - 1)
        tilts.append(np.full(int(round(pause / dt)), tilts[-1][-1]))
    tilts.append(np.full(int(round(wait / dt)), tilts[-1][-1]))
    tilt = np.concatenate(tilts)
    t = dt * np.arange(tilt.size)
    readings = _readings(model, t, _landed(model, t, tilt), float(t[-1]))
    hit = np.flatnonzero(readings[:, 1] >= target)
    decided = float(readings[hit[0], 0]) if hit.size else None
    k = int(np.searchsorted(t, decided)) if decided is not None else tilt.size - 1
    end = k
    if k + 1 < tilt.size and tilt[k + 1] > tilt[k]:  # inside a move: it finishes
        end = next(e for e in ends if e >= k)
    back = tilt[end] + _move(-tilt[end], speed, accel, dt)
    tilt = np.concatenate([tilt[:end + 1], back])
    t = dt * np.arange(tilt.size)
    tail = np.arange(t[-1] + dt, t[-1] + model.latency + model.fall_time + 2.0, dt)
    t = np.concatenate([t, tail])
    tilt = np.concatenate([tilt, np.full(tail.size, tilt[-1])])
    mass = _landed(model, t, tilt)
    return PourRun(float(mass[-1]), decided, float(tilt[end]), time.perf_counter() - start, t,
                   tilt, mass, _readings(model, t, mass, float(t[-1])))


def stop_and_return(cell: Cell, motion: PourMotion, R_upright: np.ndarray, pivot: np.ndarray,
                    *, options: PourOptions | None = None
                    ) -> Callable[[float], tuple[np.ndarray, np.ndarray, float]]:
    """The ``stop`` of :func:`simulate_pour` for a planned tilt: brake along the tilt's
    path at the event (a :class:`~safepath.planning.stop.StopPlanner` prepared here), then
    go back upright about the same pivot with :func:`~safepath.planning.pour.plan_tilt`
    (planned, timed, checked and verified). Returns the tilt history from the event and
    the wall time of the stop computation alone."""
    from ...planning.pour import PourOptions, plan_tilt, tilt_of
    from ...planning.stop import StopPlanner, path_state

    traj = motion.trajectory
    planner = StopPlanner(cell.robot, motion.path,
                          timed=(traj.t, motion.s, traj.q, traj.qd, traj.qdd))
    axis = cup_axis(cell)

    def stop(event: float) -> tuple[np.ndarray, np.ndarray, float]:
        start = time.perf_counter()
        s, sd = path_state(motion.path, motion.s, traj.qd, traj.t, event)
        braking = planner.stop(s, sd, time=event)
        compute = time.perf_counter() - start
        back = plan_tilt(cell, braking.q[-1], R_upright, pivot,
                         options=options or PourOptions())
        tilt_stop = np.array([tilt_of(cell.robot.frame_pose(q).rotation, axis)
                              for q in braking.q])
        times = np.concatenate([braking.t, braking.t[-1] + back.trajectory.t[1:]])
        return times, np.concatenate([tilt_stop, back.tilt[1:]]), compute

    return stop


def cup_axis(cell: Cell) -> np.ndarray:
    """The held cup's axis in the TCP frame."""
    from ...planning.pour import cup_axis_in_tcp

    return cup_axis_in_tcp(cell)
