"""What the pour controller computes: the mass it will end with, and the stop goal.

* :class:`MassPredictor`: the controller's model of its own pour. It knows the tilt it
  commands (the planned tilt motion), the flow law's shape, the scale's latency and the
  fall time (a :class:`~safepath.cells.pouring.flow.FlowModel`), but not the flow gain:
  it fits the gain to the readings (least squares of each reading against the flow
  integral of the commanded tilt ``latency + fall_time`` before it) and predicts the final
  mass if braking began at a given moment: everything poured until then plus what the
  stop and the return upright pour (``still``, per unit gain). This is the decision rule
  of :func:`~safepath.cells.pouring.flow.simulate_pour`, fed one reading at a time.
* :class:`PourStopper`: the stop goal for a running tilt. It follows the tilt from the
  present knot to the braking point, then brakes along it, jerk-limited (the monitor's
  re-timing, :class:`~safepath.monitor.profile.MonitoredPath`): every knot is a state of
  the verified tilt, and the knots' quintic join (what the controller executes) is within
  the speed, acceleration and jerk limits, so the trajectory controller that receives it
  (stamped with the clock time of its first knot) joins it where the arm is and never
  leaves the verified path. The return upright runs the same path backwards, timed by
  TOPP-RA. Both are re-checked by the independent FCL verifier before they are released
  (about 0.5 ms for a stop, 2-6 ms for a return on the pouring cell).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ...errors import InputError, TimingError
from ...files._digest import sha256
from ...files.derived import DerivedKind
from ...model.trajectory import Trajectory

if TYPE_CHECKING:
    from ...cell import Cell
    from ...planning.pour import PourMotion
    from ...timing import PathSpline, TimedPiece, TimingOptions
    from .flow import FlowModel

__all__ = ["MassPredictor", "PourStopper", "STILL_SPACING"]

#: Motion time between the events at which :meth:`PourStopper.calibrate_still` measures
#: the stop and the return [s]. What they pour is not smooth in the event (the
#: jerk-limited stop takes 0.24 s at one knot and 0.57 s at the next where the path bends),
#: so the table is dense rather than a few points joined by chords.
STILL_SPACING = 0.025

#: Where the table's chord between two events misses its midpoint by more than this per
#: unit gain [s] (0.1 g at a gain of 100 g/s/rad^1.5), the interval is halved down to a
#: knot (:func:`~safepath.cells.pouring.flow.calibrate_still`).
STILL_TOLERANCE = 0.001

#: The table of :meth:`PourStopper.calibrate_still`, kept per robot by what it is made of.
_STILL: DerivedKind[Callable[[float], float]] = DerivedKind("pour stop-and-return table")


class MassPredictor:
    """Fits the flow gain to the scale and predicts the final mass (see the module doc).

    Args:
        t: Times of the commanded tilt motion [s] (from its start).
        tilt: The cup's tilt at those times [rad]; held at the last value afterwards.
        flow: The flow law's shape, the scale's latency and the fall time (its ``gain``
            and ``noise`` are not used: the gain is fitted).
        still: What the stop and the return upright pour from a tilt, per unit gain [s]
            (:func:`~safepath.cells.pouring.flow.calibrate_still`); default: braking for
            ``brake_time`` at the current rate, then turning back at ``return_speed``.
        min_reading: Readings below this are not used for the fit [g].
        return_speed: Angular speed of the return assumed without ``still`` [rad/s].
        brake_time: Braking time assumed without ``still`` [s].

    Raises:
        InputError: Times not increasing, or tilts of another length or not finite.
    """

    def __init__(self, t: np.ndarray, tilt: np.ndarray, flow: FlowModel, *,
                 still: Callable[[float], float] | None = None, min_reading: float = 5.0,
                 return_speed: float = math.radians(30.0), brake_time: float = 0.25) -> None:
        t, tilt = np.asarray(t, dtype=float), np.asarray(tilt, dtype=float)
        if t.ndim != 1 or t.size < 2 or not np.all(np.diff(t) > 0):
            raise InputError("expected at least two strictly increasing times [s]", key="t")
        if tilt.shape != t.shape or not np.all(np.isfinite(tilt)):
            raise InputError(f"expected {t.size} finite tilts [rad]", key="tilt")
        self.flow = flow
        self._t, self._tilt = t, tilt
        rate = dataclasses.replace(flow, gain=1.0).rate(tilt)
        self._rate_end = float(rate[-1])
        self._cum = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])
        self._still = still
        self._min_reading = min_reading
        self._return_speed, self._brake_time = return_speed, brake_time
        self._num = self._den = 0.0
        self.readings = 0

    def tilt(self, tau: float) -> float:
        """Commanded tilt at motion time ``tau`` [s] [rad]."""
        return float(np.interp(tau, self._t, self._tilt))

    def poured(self, tau: float) -> float:
        """Flow integral of the commanded tilt up to motion time ``tau``, per unit gain [s]."""
        if tau <= self._t[0]:
            return 0.0
        if tau >= self._t[-1]:
            return float(self._cum[-1]) + self._rate_end * (tau - float(self._t[-1]))
        return float(np.interp(tau, self._t, self._cum))

    def add(self, mass: float, tau: float) -> None:
        """A reading of ``mass`` [g] taken at motion time ``tau`` [s]."""
        seen = self.poured(tau - self.flow.latency - self.flow.fall_time)
        self.readings += 1
        if mass >= self._min_reading and seen > 0.0:
            self._num += mass * seen
            self._den += seen * seen

    @property
    def gain(self) -> float | None:
        """The fitted flow gain [g/s/rad^1.5], None before a usable reading."""
        return self._num / self._den if self._den > 0.0 else None

    def coming(self, theta: float) -> float:
        """What the stop and the return pour from tilt ``theta``, per unit gain [s]."""
        if self._still is not None:
            return float(self._still(theta))
        x = max(theta - self.flow.spill_angle, 0.0)
        return x ** 1.5 * self._brake_time + x ** 2.5 / (2.5 * self._return_speed)

    def predict(self, tau: float) -> float | None:
        """Final mass if braking began at motion time ``tau`` [g] (None: no fit yet): at
        the first knot of the motion at or after ``tau``, as :meth:`PourStopper.stop`
        brakes."""
        gain = self.gain
        if gain is None:
            return None
        k = int(np.searchsorted(self._t, tau))
        tau = float(self._t[k]) if 0 < k < self._t.size else tau
        return gain * (self.poured(tau) + self.coming(self.tilt(tau)))


class PourStopper:
    """Stop goals and returns upright for a planned tilt (see the module doc).

    Args:
        cell: The cell the tilt was planned in (robot limits, scene, held cup).
        motion: The planned, verified tilt.
        return_angular_speed: Bound on the cup's angular speed on the way back [rad/s].
        timing: TOPP-RA options of the return.
    """

    def __init__(self, cell: Cell, motion: PourMotion, *,
                 return_angular_speed: float = math.radians(30.0),
                 timing: TimingOptions | None = None) -> None:
        from ...monitor.profile import MonitoredPath
        from ...timing import TimingOptions
        from ...verify import FclVerifier

        if not (math.isfinite(return_angular_speed) and return_angular_speed > 0):
            raise InputError(f"must be > 0 [rad/s], got {return_angular_speed!r}",
                             key="return_angular_speed")
        robot = cell.robot
        self.robot, self.motion = robot, motion
        held = cell.scene.grasp.object if cell.scene.grasp is not None else None
        self.verifier = FclVerifier(robot, cell.scene, held=held, resting={})
        self._scene = (cell.scene, held)
        traj = motion.trajectory
        #: The tilt as a path to re-time: its own time is the path parameter (the stops).
        self.path = MonitoredPath(traj, robot)
        # On a rotation about a fixed point the TCP speed is the angular speed times the
        # TCP's distance to it: the bound becomes a TCP speed limit, as in plan_tilt.
        turning = motion.angular_speed > 1e-6
        lever = float(np.median(motion.tcp_speed[turning] / motion.angular_speed[turning])) \
            if turning.any() else 0.0
        self.return_tcp_speed = return_angular_speed * lever if lever > 0 else None
        self.timing = timing or TimingOptions(spacing=0.2)

    def tilt_at(self, s: np.ndarray | float) -> np.ndarray:
        """Tilt of the cup at path parameters ``s`` of the tilt's path [rad]."""
        return np.interp(s, self.motion.s, self.motion.tilt)

    def _stop_arrays(self, tau_now: float, tau_brake: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                int, int]:
        motion, traj = self.motion, self.motion.trajectory
        t = traj.t
        k0 = int(np.clip(np.searchsorted(t, tau_now, side="right") - 1, 0, t.size - 2))
        kb = int(np.searchsorted(t, max(tau_brake, t[k0]), side="left"))
        if kb >= t.size - 1:  # the motion's own end comes first
            kb = t.size - 1
            self._path_tau = t[k0:]
            return (t[k0:] - t[k0], motion.s[k0:], traj.q[k0:], traj.qd[k0:], traj.qdd[k0:],
                    k0, kb)
        # The motion's own time is the path parameter: the stop holds the motion's own
        # knots k0..kb, then brakes along it from knot kb, jerk-limited and checked as
        # executed (the monitor's re-timing, :class:`safepath.monitor.profile.MonitoredPath`,
        # whose followed profile changes from its start on). Braking from k0 instead would
        # begin before the goal can reach the trajectory controller, and pour less than
        # :class:`MassPredictor` predicts for braking at ``tau_brake``.
        kb, stop = self._braking(kb)
        tau = np.concatenate([t[k0:kb], [t[kb]], np.asarray(stop.info["path_tau"])[1:]])
        s = np.interp(tau, t, motion.s)
        # The first braking knot is the motion's own knot kb (the averaging rounds it by
        # ~1e-15).
        held = slice(k0, kb + 1)
        q = np.vstack([traj.q[held], stop.q[1:]])
        qd = np.vstack([traj.qd[held], stop.qd[1:]])
        qdd = np.vstack([traj.qdd[held], stop.qdd[1:]])
        tt = np.concatenate([t[held] - t[k0], float(t[kb] - t[k0]) + stop.t[1:]])
        self._path_tau = tau
        return tt, s, q, qd, qdd, k0, kb

    def _braking(self, kb: int) -> tuple[int, Trajectory]:
        """Braking along the path from the motion's knot ``kb`` on, or from a later knot
        if that comes to rest sooner: the jerk-limited profile comes to rest at a knot, and
        where it reaches the knot before with almost no speed left it creeps over the last
        interval (0.24 s of braking from one knot, 2.1 s from the one before it on the
        pouring cell's tilt, with the cup still tipped). The knots after ``kb`` are tried
        while each comes to rest sooner than the one before."""
        t = self.motion.trajectory.t
        lead = self.path.width / 2

        def brake(k: int) -> Trajectory:
            return self.path.replacement(float(t[k]), 0.0, 0.0, before=None,
                                         tau0=float(t[k]) + lead, r0=1.0, kind="stop")[1]

        best = brake(kb)
        while kb + 1 < t.size - 1:
            try:
                later = brake(kb + 1)
            except TimingError:
                break
            if t[kb + 1] + later.duration >= t[kb] + best.duration:
                break
            kb, best = kb + 1, later
        return kb, best

    def stop(self, tau_now: float, tau_brake: float) -> Trajectory:
        """The stop goal when the arm is at motion time ``tau_now`` [s] and braking may
        begin at ``tau_brake`` [s] (the first knot at or after it).

        The trajectory starts at the last knot at or before ``tau_now`` (its
        ``info['time_offset']`` is that knot's motion time: stamp the goal with the clock
        time of it), follows the motion's own knots to the braking knot, then brakes;
        ``info['s_rest']`` is the path parameter where it comes to rest. When braking
        cannot end before the path does, the rest of the motion (which comes to rest at
        its end) is the stop.

        Raises:
            TimingError: A braking sample would break a limit.
            VerificationError: The independent re-check finds a collision or a margin
                not kept.
        """
        traj = self.motion.trajectory
        tt, s, q, qd, qdd, k0, kb = self._stop_arrays(tau_now, tau_brake)
        self.verifier.verify(tt, q, qd, steps=["stop"] * tt.size)
        return Trajectory(traj.joint_names, tt, q, qd, qdd, np.zeros(tt.size, dtype=int),
                          ("stop",), (), traj.robot, f"{traj.route}:stop",
                          {"time_offset": float(traj.t[k0]), "brake_at": float(traj.t[kb]),
                           "path_tau": np.asarray(self._path_tau).tolist(),
                           "s_rest": float(s[-1])}, self.robot.motion_limits,
                          traj.interpolation)

    def until(self, stop: Trajectory) -> Trajectory:
        """The part of the tilt that ran before ``stop`` (one of :meth:`stop`'s) took over,
        for a bag or a plot of what the arm did: tilt, then stop, then :meth:`back`.

        Raises:
            InputError: ``stop`` took over at the tilt's very start (nothing ran before).
        """
        from ...ros.goals import trajectory_between

        offset = float(stop.info.get("time_offset", 0.0))
        traj = self.motion.trajectory
        if not offset > traj.t[0]:
            raise InputError("the stop took over at the start of the tilt", key="stop")
        return trajectory_between(traj, float(traj.t[0]), offset, 0)

    def back(self, s_rest: float) -> Trajectory:
        """Back upright from rest at path parameter ``s_rest``: the tilt's own path in
        reverse (every sample a state ``q(s)`` of the verified path), timed rest to rest
        by TOPP-RA within the joint limits and ``return_angular_speed``.

        Raises:
            InputError: ``s_rest`` not within the path (or at its start: nothing to undo).
            TimingError: No timing within the limits.
            VerificationError: The independent re-check finds a collision or a margin
                not kept.
        """
        piece, s_rest = self._back_piece(s_rest)
        self.verifier.verify(piece.t, piece.q, piece.qd, steps=["return"] * piece.t.size)
        traj = self.motion.trajectory
        return Trajectory(traj.joint_names, piece.t, piece.q, piece.qd, piece.qdd,
                          np.zeros(piece.t.size, dtype=int), ("return",), (), traj.robot,
                          f"{traj.route}:return",
                          {"s_from": s_rest}, self.robot.motion_limits, traj.interpolation)

    def _back_piece(self, s_rest: float) -> tuple[TimedPiece, float]:
        from ...timing import time_path

        end = float(self.motion.path.x[-1])
        if not (math.isfinite(s_rest) and 1e-9 < s_rest <= end + 1e-12):
            raise InputError(f"expected a path parameter in (0, {end:.6g}], got {s_rest!r}",
                             key="s_rest")
        s_rest = min(float(s_rest), end)
        piece = time_path(self.robot, _Reversed(self.motion.path, s_rest),
                          np.array([0.0, s_rest]), scales=[1.0],
                          tcp_speeds=[self.return_tcp_speed], options=self.timing,
                          step="return")
        return piece, s_rest

    def stop_and_back(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """Times from ``tau`` [s] and tilts [rad] of braking at ``tau`` and returning (the
        stop's first knot is at or before ``tau``: the history starts at ``tau`` itself,
        so that nothing poured before ``tau`` is counted twice)."""
        tt, s, *_ = self._stop_arrays(tau, tau)
        piece, s_rest = self._back_piece(float(s[-1]))
        times = np.concatenate([tt, tt[-1] + piece.t[1:]])
        tilts = self.tilt_at(np.concatenate([s, s_rest - piece.s[1:]]))
        times = times - (tau - float(self._path_tau[0]))  # from tau
        later = times > 0.0
        first = float(np.interp(0.0, times, tilts))
        return np.concatenate([[0.0], times[later]]), np.concatenate([[first], tilts[later]])

    def calibrate_still(self, flow: FlowModel, *, samples: int | None = None,
                        spacing: float = STILL_SPACING) -> Callable[[float], float]:
        """What the stop and the return pour from a tilt, per unit gain [s], measured on
        this stopper's own stops and returns (for :class:`MassPredictor`), at events
        ``spacing`` [s] of motion time apart past the spill angle (``samples``: that many
        events instead). Events at which no stop can be timed are left out.

        Measuring takes hundreds of stops and returns (seconds); the table is kept with
        the robot (:attr:`safepath.Robot.derived`, in memory) for everything it is made
        from: the tilt, the scene, the robot's limits, the return's speed and timing, the
        spill angle and ``samples`` / ``spacing``. Another stopper of the same tilt (a
        controller per pour) gets the same table at once."""
        key = (self._digest(), float(flow.spill_angle), samples, float(spacing))
        return self.robot.derived.get(_STILL, lambda: self._measure_still(flow, samples,
                                                                          spacing),
                                      options=key)

    def _digest(self) -> str:
        """A digest of everything the stops and the returns are made from, but the robot's
        shapes (which :attr:`safepath.Robot.derived` keeps apart)."""
        motion, traj, robot = self.motion, self.motion.trajectory, self.robot
        x = np.asarray(motion.path.x, dtype=float)
        scene, held = self._scene
        placed = [o.T_world_object for o in scene.objects.values()]
        if scene.grasp is not None:
            placed.append(scene.grasp.T_tcp_object)
        parts = [traj.t, traj.q, traj.qd, traj.qdd, motion.s, motion.tilt, x,
                 *(np.asarray(motion.path(x, nu), dtype=float) for nu in range(3)),
                 robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits,
                 *placed]
        h = sha256()
        for a in parts:
            a = np.ascontiguousarray(a, dtype=float)
            h.update(f"{a.shape}".encode() + a.tobytes())
        h.update(repr((traj.joint_names, scene, held, robot.controller,
                       self.return_tcp_speed, self.timing, self.path.knot)).encode())
        return str(h.hexdigest())

    def _measure_still(self, flow: FlowModel, samples: int | None,
                       spacing: float) -> Callable[[float], float]:
        from ...errors import SafepathError
        from .flow import calibrate_still

        traj = self.motion.trajectory

        def knot(event: float) -> float:  # where a stop decided at ``event`` brakes
            return float(traj.t[min(int(np.searchsorted(traj.t, event)), traj.t.size - 1)])

        def stop(event: float) -> tuple[np.ndarray, np.ndarray, float] | None:
            try:
                t, tilt = self.stop_and_back(knot(event))
            except SafepathError:  # the controller faults if it decides there
                return None
            return t, tilt, 0.0

        def tilt_of_t(event: float) -> float:
            return float(np.interp(knot(event), traj.t, self.motion.tilt))

        return calibrate_still(stop, tilt_of_t,
                               traj.duration, flow, samples=samples or 6,
                               spacing=None if samples else spacing,
                               tolerance=STILL_TOLERANCE, finest=self.path.knot)


class _Reversed:
    """A joint path run backwards from ``s_end``: ``u -> path(s_end - u)``."""

    def __init__(self, path: PathSpline, s_end: float) -> None:
        self.path, self.s_end = path, s_end
        inner = path.x[(path.x > 0.0) & (path.x < s_end)]
        self.x = np.concatenate([[0.0], (s_end - inner)[::-1], [s_end]])

    def __call__(self, s: np.ndarray | float, nu: int = 0) -> np.ndarray:
        return np.asarray(self.path(self.s_end - np.asarray(s), nu)) * (-1.0) ** nu
