"""How a trajectory controller executes a goal's points, and the check of that motion.

A robot does not run safepath's samples: its trajectory controller joins the points of a
``JointTrajectory`` and follows the result. ros2_control's ``joint_trajectory_controller``
(``joint_trajectory_controller/trajectory.cpp``, ``interpolate_between_points``) joins
two points per joint with

* a **quintic** polynomial matching position, velocity and acceleration at both ends when
  every point carries all three (what safepath sends),
* a **cubic** matching position and velocity when points carry no accelerations,
* a **linear** ramp when they carry positions only.

The ROS 1 ``joint_trajectory_controller`` behind Niryo's
``/niryo_robot_follow_joint_trajectory_controller`` (``QuinticSplineSegment``) and
ros2_kortex's (ros2_control's) join points the same way. Each robot's ``controller.yaml``
names its interpolation (the ``interpolation`` of
:class:`safepath.model.controller_spec.ControllerSpec`).

:func:`executed_peaks` finds, per joint, the largest speed, acceleration and jerk of
that joined motion: acceleration and jerk exactly (the jerk of a quintic is a quadratic,
its acceleration a cubic: their extremes are at the ends or where the next derivative
vanishes), speed at the ends, and where the acceleration changes sign inside an interval
on a grid of at least ``rate`` samples per second plus a bound of what a peak between two
samples can add (``|jerk| dt^2 / 8``), so every figure is an upper bound of the motion at
every instant (compiled for quintics: :mod:`safepath.model._joinkernel`).
:func:`check_executed` raises
:class:`~safepath.errors.ExecutedLimitError` when one is over its limit.

A quintic on an interval, restricted to part of it, is the quintic through its own
values at the part's ends: inserting points sampled from the joined motion changes
nothing (:func:`join` gives their values), which is how goals keep at most the
controller's point spacing without leaving the verified motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ExecutedLimitError
from .interpolation import QUINTIC, Interpolation, as_interpolation

__all__ = ["ExecutedPeaks", "join", "executed_peaks",
           "interval_ratios", "check_executed", "CHECK_RATE", "ControllerModel", "Switch",
           "SWITCH_TOLERANCE"]

#: Samples per second at which the speed is evaluated between points (at least).
CHECK_RATE = 1000.0


def join(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, times: np.ndarray,
         *, interpolation: Interpolation | str = QUINTIC
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The motion a controller executes from points ``(t, q, qd, qdd)``, at ``times`` [s].

    Args:
        t: Point times [s], strictly increasing (N,).
        q, qd, qdd: Positions [rad], velocities [rad/s], accelerations [rad/s^2] (N, dof).
        times: Where to evaluate [s]; clamped to ``[t[0], t[-1]]``.
        interpolation: How the controller joins points.

    Returns:
        Positions, velocities, accelerations and jerks [rad/s^3] at ``times``.
    """
    t = np.asarray(t, dtype=float)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    times = np.clip(np.asarray(times, dtype=float), t[0], t[-1])
    if t.size == 1:
        rest = np.repeat(q, times.size, 0)
        zero = np.zeros_like(rest)
        return rest, np.repeat(np.atleast_2d(qd), times.size, 0), \
            np.repeat(np.atleast_2d(qdd), times.size, 0), zero
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 2)
    tau = (times - t[k])[:, None]
    qd, qdd = np.atleast_2d(qd), np.atleast_2d(qdd)
    out = as_interpolation(interpolation).evaluate(t, q, qd, qdd, k, tau)
    # At (and past) the ends: the end points themselves, not their polynomial's rounding.
    for end, row in ((times <= t[0], 0), (times >= t[-1], -1)):
        if end.any():
            for arr, value in zip(out[:3], (q, qd, qdd), strict=True):
                arr[end] = np.atleast_2d(value)[row]
    return out[0], out[1], out[2], out[3]


@dataclass(frozen=True)
class ExecutedPeaks:
    """The largest speed, acceleration and jerk of an executed motion, per joint.

    Attributes:
        velocity: Per joint, an upper bound of ``|v|`` at every instant [rad/s].
        acceleration: Per joint, the largest ``|a|`` [rad/s^2] (exact).
        jerk: Per joint, the largest ``|j|`` [rad/s^3] (exact; the jerk of one interval,
            each interval's polynomial on its own).
        rate: Samples per second at which speeds were evaluated.
        interpolation: How the points were joined.
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    rate: float
    interpolation: str

    def ratios(self, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray
               ) -> tuple[float, float, float]:
        """The largest peak / limit of speed, acceleration and jerk."""
        return (float(np.max(self.velocity / vmax)), float(np.max(self.acceleration / amax)),
                float(np.max(self.jerk / jmax)))


def _peaks_of(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
              interpolation: Interpolation | str, rate: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per interval and joint: bound of |v|, max |a| and |j| (compiled for quintics)."""
    return as_interpolation(interpolation).peaks(t, q, qd, qdd, rate)


def executed_peaks(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *,
                   interpolation: Interpolation | str = QUINTIC, rate: float = CHECK_RATE
                   ) -> ExecutedPeaks:
    """The peaks of the motion a controller executes from points ``(t, q, qd, qdd)``.

    Args:
        t: Point times [s], strictly increasing.
        q, qd, qdd: Positions [rad], velocities [rad/s], accelerations [rad/s^2] (N, dof).
        interpolation: How the controller joins points.
        rate: Least number of speed samples per second [Hz].
    """
    t = np.asarray(t, dtype=float)
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    if t.size < 2:
        return ExecutedPeaks(np.abs(qd[0]), np.abs(qdd[0]), np.zeros(q.shape[1]), rate,
                             str(interpolation))
    v, a, j = _peaks_of(t, q, qd, qdd, interpolation, rate)
    return ExecutedPeaks(v.max(axis=0), a.max(axis=0), j.max(axis=0), rate,
                         str(interpolation))


def interval_ratios(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *,
                    vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray,
                    interpolation: Interpolation | str = QUINTIC, rate: float = CHECK_RATE
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per interval between points, the largest speed, acceleration and jerk ratio to the
    limits (each (N-1,)); limits may be per interval (N-1, dof) or per joint (dof,)."""
    v, a, j = _peaks_of(t, q, qd, qdd, interpolation, rate)
    # numpy reduces a short last axis slowly; across the long one it is ~10x faster.
    return tuple(np.max(np.ascontiguousarray((x / lim).T), axis=0)  # type: ignore[return-value]
                 for x, lim in ((v, vmax), (a, amax), (j, jmax)))


def check_executed(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *,
                   velocity_limits: np.ndarray, acceleration_limits: np.ndarray,
                   jerk_limits: np.ndarray, interpolation: Interpolation | str = QUINTIC,
                   rate: float = CHECK_RATE, what: str = "goal") -> tuple[float, float, float]:
    """Check that the motion a controller executes from the points stays within the limits.

    Returns:
        The largest speed, acceleration and jerk ratio to the limits (each <= 1).

    Raises:
        ExecutedLimitError: A ratio is over 1 (or not finite), naming ``what``, the
            quantity, the joint column and the time.
    """
    t = np.asarray(t, dtype=float)
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    if t.size < 2:
        peaks = executed_peaks(t, q, qd, qdd, interpolation=interpolation, rate=rate)
        ratios = peaks.ratios(velocity_limits, acceleration_limits, jerk_limits)
    else:
        per = _peaks_of(t, q, qd, qdd, interpolation, rate)
        ratios = (0.0, 0.0, 0.0)
        names = ("velocity", "acceleration", "jerk")
        out = []
        for name, values, lim in zip(names, per, (velocity_limits, acceleration_limits,
                                                  jerk_limits), strict=True):
            r = values / lim
            worst = float(np.max(r))
            if not worst <= 1.0:  # also NaN
                k, col = np.unravel_index(int(np.nanargmax(np.where(np.isfinite(r), r,
                                                                        np.inf))), r.shape)
                raise ExecutedLimitError(
                    f"{what}: the {interpolation} join of its points reaches "
                    f"{worst:.4f}x the {name} limit of joint column {int(col)} between "
                    f"t = {t[k]:.4f} and {t[k + 1]:.4f} s", key=name, ratio=worst)
            out.append(worst)
        ratios = (out[0], out[1], out[2])
    return ratios


#: Two times closer than this [s] are the same instant for a goal switch (a point at the
#: switch time is joined with zero length: a step, not a quintic).
SWITCH_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Switch:
    """How a controller took a goal that replaced the motion it was running.

    Attributes:
        time: When the controller took the goal [s].
        state: The controller's commanded position, velocity and acceleration then, on
            the motion it was running (each (dof,)).
        first: Index of the goal's first point it kept (earlier points lay in the past).
        joined: Whether that point lies later than ``time`` (a quintic joins the state
            to it); else the point replaced the state at once.
        position_step: Largest ``|p_point - p_state|`` of an instant join [rad] (0 when
            joined).
        velocity_step: Largest ``|v_point - v_state|`` of an instant join [rad/s].
        acceleration_step: Largest ``|a_point - a_state|`` of an instant join [rad/s^2].
    """

    time: float
    state: tuple[np.ndarray, np.ndarray, np.ndarray]
    first: int
    joined: bool
    position_step: float
    velocity_step: float
    acceleration_step: float

    @property
    def continuous(self) -> bool:
        """Whether the switch keeps position, velocity and acceleration (to 1e-6)."""
        return max(self.position_step, self.velocity_step, self.acceleration_step) <= 1e-6


@dataclass(frozen=True)
class _Running:
    """A goal as the controller runs it: points at absolute times, from ``since`` on."""

    since: float
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


class ControllerModel:
    """What a joint trajectory controller does with the goals it is sent, one after another.

    This is the one model of the controller the monitor's replacement goals are built
    against, their switches checked with, and the twin executes (ros2_control's
    ``joint_trajectory_controller``, ``trajectory.cpp``: a new goal is taken at once; the
    state it is commanding then is the point before the new trajectory, joined to the
    first point not yet in the past; points already in the past are dropped; after the
    last point it holds that position):

    * a goal with header stamp ``start`` runs its points at ``start + time_from_start``;
    * taken at ``time`` (the moment it reaches the controller), the controller's
      commanded state ``(p, v, a)`` at ``time`` on the motion it was running is joined by
      one interpolation segment to the first point at or after ``time``; a point at
      ``time`` itself (within :data:`SWITCH_TOLERANCE`) replaces the state at once (a step
      in position, velocity and acceleration unless they are equal);
    * points are joined as :func:`join` joins them (the controller's interpolation).

    Args:
        q_rest: Where the arm rests before the first goal [rad] (dof,).
        interpolation: How the controller joins points (``controller.yaml``).
        history: How many taken goals are kept for :meth:`sample` (older times are
            answered from the oldest kept).
    """

    def __init__(self, q_rest: np.ndarray, *, interpolation: Interpolation | str = QUINTIC,
                 history: int = 64) -> None:
        q0 = np.asarray(q_rest, dtype=float).reshape(1, -1)
        zero = np.zeros_like(q0)
        self.interpolation: Interpolation = as_interpolation(interpolation)
        self.history = max(1, int(history))
        self._runs: list[_Running] = [_Running(-np.inf, np.zeros(1), q0, zero, zero)]

    @property
    def running(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The points of the motion running now as the controller joins them: absolute
        times [s], positions, velocities, accelerations (the switch state first)."""
        r = self._runs[-1]
        return r.t, r.q, r.qd, r.qdd

    @property
    def end(self) -> float:
        """When the last goal's last point is reached [s] (``-inf`` before any goal)."""
        r = self._runs[-1]
        return float(r.t[-1]) if np.isfinite(r.since) else -np.inf

    def state(self, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The commanded position, velocity and acceleration at ``time`` [s] (held at rest
        after the last point)."""
        p, v, a, _ = self.sample(np.array([float(time)]))
        return p[0], v[0], a[0]

    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                 np.ndarray]:
        """Commanded positions, velocities, accelerations and jerks at ``times`` [s]."""
        times = np.atleast_1d(np.asarray(times, dtype=float))
        dof = self._runs[0].q.shape[1]
        out = [np.zeros((times.size, dof)) for _ in range(4)]
        since = np.array([r.since for r in self._runs])
        which = np.searchsorted(since, times, side="right") - 1
        for k in np.unique(which):
            r, sel = self._runs[max(int(k), 0)], which == k
            p, v, a, j = join(r.t, r.q, r.qd, r.qdd, times[sel],
                              interpolation=self.interpolation)
            after = times[sel] >= r.t[-1]
            v[after] = a[after] = j[after] = 0.0  # holds the last position
            for arr, val in zip(out, (p, v, a, j), strict=True):
                arr[sel] = val
        return out[0], out[1], out[2], out[3]

    def take(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *,
             start: float, time: float | None = None) -> Switch:
        """The controller takes a goal.

        Args:
            t: The goal's ``time_from_start`` of each point [s], increasing.
            q, qd, qdd: Its points (N, dof) [rad, rad/s, rad/s^2].
            start: Its header stamp: when ``t = 0`` is [s].
            time: When the controller takes it [s] (default ``start``).

        Returns:
            How the running motion was switched to it.
        """
        time = float(start if time is None else time)
        t_abs = float(start) + np.asarray(t, dtype=float)
        q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
        p0, v0, a0 = self.state(time)
        first = int(np.searchsorted(t_abs, time - SWITCH_TOLERANCE, side="left"))
        if first >= t_abs.size:  # every point is past: the last one at once
            first = t_abs.size - 1
            t_abs = np.array([time])
            pts = q[-1:], np.zeros_like(q[-1:]), np.zeros_like(q[-1:])
        else:
            pts = q[first:], qd[first:], qdd[first:]
            t_abs = t_abs[first:]
        joined = bool(t_abs[0] > time + SWITCH_TOLERANCE)
        if joined:
            run = _Running(time, np.concatenate([[time], t_abs]),
                           np.vstack([p0, pts[0]]), np.vstack([v0, pts[1]]),
                           np.vstack([a0, pts[2]]))
            steps = (0.0, 0.0, 0.0)
        else:
            run = _Running(time, t_abs, pts[0], pts[1], pts[2])
            dp, dv, da = (float(np.max(np.abs(x[0] - s)))
                          for x, s in zip(pts, (p0, v0, a0), strict=True))
            steps = (dp, dv, da)
        self._runs = [*self._runs[-self.history + 1:], run] if self.history > 1 else [run]
        return Switch(time, (p0, v0, a0), first, joined, *steps)
