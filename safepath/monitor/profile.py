"""Path-consistent re-timing: the same knots, a new speed along them.

The path is the knots of a verified trajectory, parametrised by its own time ``tau``
(with states of their join between knots more than :data:`FINE_ABOVE` x 4 ms apart).
A :class:`Timing` is a new speed profile ``r = dtau/dt`` in [0, 1] along it (1: the
verified timing), built by the greedy pass of :func:`safepath.monitor._kernels.march`:
toward a speed scale as fast as the joint acceleration limits allow, or braking as hard
as they allow to rest. Positions stay the path's own knots (the first one is the state
where the new timing starts), so the shape never changes; velocities and accelerations
at every knot are within the robot's limits (checked before a timing is released).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import TimingError
from ..model.execution import interval_ratios
from ..model.robot import Robot
from ..model.trajectory import Trajectory

__all__ = ["MonitoredPath", "Timing"]


def _kernels():  # noqa: ANN202
    from . import _kernels as K  # noqa: N812

    return K


@dataclass(frozen=True)
class Timing:
    """A speed profile along a path, started at ``start`` on the monitor's clock.

    The *raw* profile is the greedy one (:meth:`MonitoredPath.march`): ``r`` piecewise
    linear in time from ``start + lead`` on, following the profile ``before`` it until
    then. The robot follows its centred moving average over ``width`` seconds (the
    path parameter ``tau_f(t)`` is the raw one averaged over ``[t - width/2, t +
    width/2]``): the path acceleration ``r'`` is then continuous and the jerk bounded,
    a steady raw speed is followed as it is, and since the raw profile only changes
    from ``start + width/2`` on, the followed one only changes from ``start`` on.

    Attributes:
        start: Monitor time of the first knot of the replacement [s].
        tau: Path parameter of each raw knot [s].
        x: Squared raw speed ``r^2`` at each raw knot.
        u: Raw path acceleration ``dr/dt`` on the interval after each raw knot [1/s].
        t: Time of each raw knot from ``start + lead`` [s].
        rest: Whether the profile ends at rest before the path's end.
        lead: Where the raw knots start, after ``start`` [s] (half the width).
        width: Width of the moving average [s] (0: the raw profile is followed).
        before: The profile followed before this one (None: a steady speed).
    """

    start: float
    tau: np.ndarray
    x: np.ndarray
    u: np.ndarray
    t: np.ndarray
    rest: bool
    lead: float = 0.0
    width: float = 0.0
    before: Timing | None = None

    @property
    def end(self) -> float:
        """Monitor time at which the followed profile ends [s]."""
        return self.start + self.lead + float(self.t[-1]) + self.width / 2

    def _raw(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                np.ndarray]:
        """Raw ``tau``, ``r``, ``u`` and the integral of ``tau`` from the first raw knot
        (negative before it) at monitor ``times``."""
        dt_all = np.asarray(times, dtype=float) - (self.start + self.lead)
        r_k = np.sqrt(self.x)
        dt_k = np.diff(self.t)
        cum = np.concatenate([[0.0], np.cumsum(self.tau[:-1] * dt_k + r_k[:-1] * dt_k ** 2 / 2
                                               + self.u[:-1] * dt_k ** 3 / 6)])
        k = np.clip(np.searchsorted(self.t, dt_all, side="right") - 1, 0, self.t.size - 1)
        dt = dt_all - self.t[k]
        last = k == self.t.size - 1
        u = np.where(last, 0.0, self.u[k])
        tau = self.tau[k] + r_k[k] * dt + u * dt * dt / 2
        r = r_k[k] + u * dt
        F = cum[k] + self.tau[k] * dt + r_k[k] * dt ** 2 / 2 + u * dt ** 3 / 6  # noqa: N806
        early = dt_all < 0.0
        if early.any():
            if self.before is None:  # a steady speed before
                d = dt_all[early]
                tau[early] = self.tau[0] + r_k[0] * d
                r[early], u[early] = r_k[0], 0.0
                F[early] = self.tau[0] * d + r_k[0] * d * d / 2
            else:
                b_tau, b_r, b_u, b_F = self.before._raw(  # noqa: N806
                    np.append(np.asarray(times, dtype=float)[early], self.start + self.lead))
                tau[early], r[early], u[early] = b_tau[:-1], b_r[:-1], b_u[:-1]
                F[early] = b_F[:-1] - b_F[-1]
        return tau, r, u, F

    def followed(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Path parameter [s], speed ``r`` and path acceleration ``r'`` [1/s] of the
        followed (averaged) profile at monitor ``times``."""
        times = np.asarray(times, dtype=float)
        if self.width <= 0.0:
            tau, r, u, _ = self._raw(times)
        else:
            h = self.width / 2
            tau_hi, r_hi, _, f_hi = self._raw(times + h)
            tau_lo, r_lo, _, f_lo = self._raw(times - h)
            tau, r, u = ((f_hi - f_lo) / self.width, (tau_hi - tau_lo) / self.width,
                         (r_hi - r_lo) / self.width)
        # Rounding leaves speeds of ~1e-19 where the window lies at rest: zero them.
        r = np.where(np.abs(r) < 1e-12, 0.0, r)
        u = np.where(np.abs(u) < 1e-12, 0.0, u)
        if self.rest:  # at rest once the window has passed the raw profile's end, exactly
            done = times - self.width / 2 >= self.start + self.lead + float(self.t[-1])
            tau[done], r[done], u[done] = self.tau[-1], 0.0, 0.0
        # A profile that runs to the path's end is followed up to it.
        return np.minimum(tau, self.tau[-1]), r, u

    def raw_state(self, time: float) -> tuple[float, float]:
        """Raw path parameter [s] and speed at monitor time ``time``."""
        tau, r, _, _ = self._raw(np.array([time]))
        return float(tau[0]), float(max(r[0], 0.0))

    def state_at(self, time: float) -> tuple[float, float]:
        """Path parameter [s] and speed ``r`` the robot follows at monitor time ``time``
        (held after the end)."""
        tau, r, _ = self.followed(np.array([time]))
        if time >= self.end:
            return float(tau[0]), 0.0 if self.rest else float(max(r[0], 0.0))
        return float(tau[0]), float(max(r[0], 0.0))

    def trimmed(self, keep_from: float) -> Timing:
        """This profile without what lies before monitor time ``keep_from`` (its
        ``before`` chain cut where no longer needed)."""
        if self.before is None:
            return self
        if self.start + self.lead <= keep_from:
            return dataclasses.replace(self, before=None)
        return dataclasses.replace(self, before=self.before.trimmed(keep_from))


#: Fractions of the acceleration limits a raw braking profile may use, tried in turn
#: until the replacement is within every limit as executed (the averaging, the path's
#: curvature and the verified motion's own jerk take the rest). The last, gentlest, is
#: what the separation assessment assumes (:attr:`MonitoredPath.amax`): any of them stops
#: sooner. Braking starts at once with each: a stop is never postponed (when none is
#: within the limits, :meth:`MonitoredPath.forced_stop` brakes anyway).
BRAKE_SCALES = (0.9, 0.6)
BRAKE_SCALE = BRAKE_SCALES[0]
#: Holds [s] of the running speed before braking at the gentlest scale, tried last for a
#: stop: where the running motion is in a phase at its own jerk limit, braking adds to
#: that jerk until the phase ends. The separation assessment assumes the longest hold
#: (a stop is sent at once either way: the hold is part of the stop it sends).
BRAKE_HOLDS = (0.024, 0.048)
#: Longer holds [s] :meth:`MonitoredPath.forced_stop` tries.
GENTLE_HOLDS = (0.1, 0.2)
#: Gentler braking [fraction of the acceleration limits] a stop falls back on when none
#: of :data:`BRAKE_SCALES` (and their holds) is within the limits from the state it
#: starts in: it comes to rest later than the assessment assumed, and says so.
GENTLE_SCALES = (0.4, 0.25, 0.15, 0.1)
#: Braking [fraction of the acceleration limits] :meth:`MonitoredPath.brake_out` tries
#: after each hold along the running profile, hardest first.
BRAKE_OUT_SCALES = (0.6, 0.25, 0.1)
#: Fractions of the acceleration limits a speed-up may use, tried in turn: the first is
#: the assessment's; a gentler speed-up is slower at every instant, so it stops sooner.
SPEED_UP_SCALES = (0.6, 0.4, 0.25, 0.15, 0.1)
#: Share of each joint's jerk limit left to the change of the path acceleration
#: (``q'(tau) r''``); the rest is for the verified motion's own jerk and curvature terms.
JERK_SHARE = 0.25
#: Spacing of a replacement's knots [s] (whole nanoseconds) on a path whose own knots are
#: not evenly spaced; on an evenly spaced one (as the planner's timing makes them), the
#: replacement keeps the path's spacing, so that where it follows the verified timing its
#: knots are the path's own and the controller's join is the verified one exactly.
KNOT_NS = 4_000_000
#: Knots further apart than this many :data:`KNOT_NS` get states of their join between
#: them in the knots profiles march over (:meth:`MonitoredPath.knots`).
FINE_ABOVE = 1.25


class MonitoredPath:
    """A verified trajectory's motion as a path to re-time.

    The path parameter is the trajectory's own time; its positions, velocities and
    accelerations at a path parameter are the trajectory's (its knots joined by
    :attr:`~safepath.model.trajectory.Trajectory.interpolation`).

    Args:
        traj: The verified trajectory (one motion: no gripper event inside it).
        robot: Its robot (limits).
    """

    def __init__(self, traj: Trajectory, robot: Robot) -> None:
        self.traj = traj
        self.robot = robot
        #: The acceleration limits the separation assessment's profiles use.
        self.amax = robot.acceleration_limits * BRAKE_SCALES[-1]
        #: Width of the moving average every profile on this path is followed through
        #: [s]: a change of the raw path acceleration from 0 to braking at
        #: ``BRAKE_SCALE`` of the limits, spread over it, keeps ``q' r''`` within
        #: ``JERK_SHARE`` of the jerk limits (at least three knots).
        steps = np.diff(np.asarray(traj.t, dtype=float))
        #: Spacing of a replacement's knots [s].
        self.knot = float(steps[0]) if steps.size and float(np.ptp(steps)) <= 1e-9 and \
            steps[0] <= 2 * KNOT_NS / 1e9 else KNOT_NS / 1e9
        self.width = max(3 * KNOT_NS / 1e9, float(np.max(
            BRAKE_SCALE * robot.acceleration_limits / (JERK_SHARE * robot.jerk_limits))))
        self._knots = self._fine_knots()

    @property
    def end(self) -> float:
        """Path parameter of the last knot [s]."""
        return float(self.traj.t[-1])

    @property
    def knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The knots profiles march over (:meth:`grid`): path parameters, positions,
        velocities and accelerations; the trajectory's own, with states of their join
        between those more than :data:`FINE_ABOVE` knot spacings apart
        (:meth:`_fine_knots`)."""
        return self._knots

    def _fine_knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The knots profiles march over (:attr:`knots`): the trajectory's own, and where
        two lie more than :data:`FINE_ABOVE` knot spacings apart, states of their join
        between them (:meth:`states`), evenly, at most :data:`KNOT_NS` apart (the same
        motion: a profile's braking is only as fine as the knots it is marched over)."""
        tr = self.traj
        t = np.asarray(tr.t, dtype=float)
        parts = np.ones(max(t.size - 1, 0), dtype=np.int64)
        steps = np.diff(t)
        wide = steps > FINE_ABOVE * KNOT_NS / 1e9
        if not np.any(wide):
            return t, tr.q, tr.qd, tr.qdd
        parts[wide] = np.ceil(steps[wide] / (KNOT_NS / 1e9) - 1e-9).astype(np.int64)
        first = np.concatenate([[0], np.cumsum(parts)])  # each knot's index among the fine
        fine = np.repeat(t[:-1], parts) + (np.arange(int(first[-1])) - np.repeat(
            first[:-1], parts)) * np.repeat(steps / parts, parts)
        fine = np.append(fine, t[-1])
        q, qd, qdd = self.states(fine)
        q[first], qd[first], qdd[first] = tr.q, tr.qd, tr.qdd  # its own knots exactly
        return fine, q, qd, qdd

    def states(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations of the verified trajectory at path
        parameters ``tau`` (clamped to its ends): its knots joined by the trajectory's
        interpolation (compiled for quintics: a replacement samples it at every knot, for
        every candidate profile)."""
        tr = self.traj
        return tr.interpolation.states(tr.t, tr.q, tr.qd, tr.qdd, np.asarray(tau, dtype=float))

    def sample(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration of the verified trajectory at ``tau``."""
        q, qd, qdd = self.states(np.array([float(tau)]))
        return q[0], qd[0], qdd[0]

    def grid(self, tau0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Knots from ``tau0`` on: (tau, q, Q', Q''); the first is the state at ``tau0``."""
        t, q, qd, qdd = self.knots
        tau0 = min(max(float(tau0), float(t[0])), float(t[-1]))
        k = int(np.searchsorted(t, tau0 + 1e-9, side="right"))
        q0, qd0, qdd0 = self.sample(tau0)
        tau = np.concatenate([[tau0], t[k:]])
        return (tau, np.vstack([q0, q[k:]]), np.vstack([qd0, qd[k:]]),
                np.vstack([qdd0, qdd[k:]]))

    def march(self, start: float, tau0: float, r0: float, scale: float, brake_after: float,
              *, limit: int | None = None, before: Timing | None = None,
              accel_scale: float | None = None, lead: float | None = None) -> Timing:
        """A profile toward speed ``scale``, braking to rest from ``brake_after`` [s] on
        (``inf``: never), followed from monitor time ``start`` on.

        Args:
            start: Monitor time of the first knot of the followed profile [s].
            tau0: Where the raw profile starts [s of the path], without ``before``.
            r0: Its speed there, in [0, 1], without ``before``.
            scale: Target speed, in [0, 1].
            brake_after: When braking begins, from the raw profile's start [s].
            limit: Knots to consider at most (None: all).
            before: The profile followed until then: the raw profile starts where its raw
                profile is half a width after ``start`` (``tau0`` and ``r0`` unused).
            accel_scale: Fraction of the acceleration limits the raw profile uses
                (default: the assessment's, :attr:`amax`).
            lead: Where the raw knots start after ``start`` [s] (default half the width:
                the followed profile changes from ``start`` on). 0 for a motion followed
                as it was verified from ``start`` (a steady raw speed before it: the
                followed path parameter at ``start`` is then ``tau0`` itself).
        """
        lead = self.width / 2 if lead is None else float(lead)
        if before is not None:
            tau0, r0 = before.raw_state(start + lead)
            before = before.trimmed(start - self.width)
        tau, _, qd, qdd = self.grid(tau0)
        if limit is not None:
            tau, qd, qdd = tau[:limit], qd[:limit], qdd[:limit]
        n = tau.size
        x, u, t = np.empty(n), np.empty(n), np.empty(n)
        amax = self.amax if accel_scale is None else self.robot.acceleration_limits * accel_scale
        m, _, rest = _kernels().march(tau, qd, qdd, amax, r0 * r0, scale * scale,
                                      brake_after, x, u, t)
        at_end = m == n and (limit is None or limit >= n)
        return Timing(start, tau[:m].copy(), x[:m].copy(), u[:m].copy(), t[:m].copy(),
                      bool(rest and not (at_end and x[m - 1] > 0)), lead, self.width, before)

    def replacement(self, start: float, scale: float, brake_after: float, *,
                    before: Timing | None, tau0: float, r0: float, kind: str
                    ) -> tuple[Timing, Trajectory]:
        """The followed timing toward ``scale`` and its trajectory: the raw profile at
        each of :data:`BRAKE_SCALES` in turn, or for a speed-up each of
        :data:`SPEED_UP_SCALES`, the first whose trajectory is within every limit as
        executed.

        Raises:
            TimingError: None is (naming the last excess).
        """
        current = before.state_at(start)[1] if before is not None else r0
        if scale == 0.0:
            stops = [(a, 0.0) for a in BRAKE_SCALES] + [(BRAKE_SCALES[-1], h)
                                                        for h in BRAKE_HOLDS]
            error: TimingError | None = None
            for accel_scale, hold in stops:
                timing = self.stop_timing(start, accel_scale, hold, before=before,
                                          tau0=tau0, r0=r0)
                try:
                    traj = self.trajectory(timing, kind=kind, scale=scale, t0=start)
                except TimingError as exc:
                    error = exc
                    continue
                traj.info["stop"] = {"accel_scale": accel_scale, "hold": hold}
                return timing, traj
            assert error is not None
            raise error
        error = None
        for accel_scale in (BRAKE_SCALES if scale <= current else SPEED_UP_SCALES):
            timing = self.march(start, tau0, r0, scale, brake_after, before=before,
                                accel_scale=accel_scale)
            try:
                return timing, self.trajectory(timing, kind=kind, scale=scale)
            except TimingError as exc:
                error = exc
        assert error is not None
        raise error

    def stop_timing(self, start: float, accel_scale: float, hold: float, *,
                    before: Timing | None, tau0: float, r0: float) -> Timing:
        """Braking to rest from monitor time ``start`` (followed from then on), as hard as
        ``accel_scale`` of the acceleration limits allows, after following the running
        profile for ``hold`` [s] (its raw speed kept at the full limits meanwhile)."""
        if hold <= 0.0:
            return self.march(start, tau0, r0, 0.0, 0.0, before=before,
                              accel_scale=accel_scale)
        raw = before.raw_state(start + self.width / 2)[1] if before is not None else r0
        kept = self.march(start, tau0, r0, raw, np.inf, before=before, accel_scale=1.0)
        return self.march(start + hold, tau0, r0, 0.0, 0.0, before=kept,
                          accel_scale=accel_scale)

    def forced_stop(self, start: float, *, before: Timing | None, tau0: float, r0: float
                    ) -> tuple[Timing, Trajectory]:
        """The stop sent when no re-timing of :meth:`replacement` stays within every limit
        as executed from this state: a stop is never postponed (it is sent at once), and
        the one within the limits that rests first wins.

        The candidates, in groups (a group only when none before is within the limits):
        the motion's own timing to its end and the assessed braking after a longer hold
        (:data:`GENTLE_HOLDS`); braking gentler than assessed (:data:`GENTLE_SCALES`);
        then the earliest brake-out from the running profile (:meth:`brake_out`). The
        running profile itself, followed as it is to where it rests (the path's end, or
        where a running stop rests), is always a candidate: it is the verified motion or a
        replacement that was within every limit as executed when it was sent, so a stop
        within the limits is always among them (see docs/monitor.md, "the stop rule").
        ``info["executed_ratios"]`` holds the speed, acceleration and jerk ratios to the
        limits as executed of the stop chosen, ``info["stop"]`` how it brakes
        (acceleration scale, hold [s]: how long it follows the running profile first).
        """
        best = _Earliest()
        # Near the end of a motion that decelerates at its limits, braking along the path
        # adds to that deceleration: the motion's own timing to its end may be within
        # the limits and at rest no later than braking would be.
        current = before.state_at(start)[1] if before is not None else r0
        timing = self.march(start, tau0, r0, current, np.inf, before=before)
        traj = self.trajectory(timing, kind="stop", scale=current, check=False)
        if traj.t.size > 1 and traj.info["path_tau"][-1] >= self.end - 1e-9:
            best.consider(timing, traj, {"accel_scale": 1.0, "hold": float("inf")})
        groups = ([(a, h) for a in BRAKE_SCALES for h in GENTLE_HOLDS],
                  [(a, h) for a in GENTLE_SCALES for h in (0.0, *GENTLE_HOLDS)])
        for k, group in enumerate(groups):
            if k and best.within:  # gentler braking only when none before is within
                break
            for accel_scale, hold in group:
                timing = self.stop_timing(start, accel_scale, hold, before=before,
                                          tau0=tau0, r0=r0)
                best.consider(timing, self.trajectory(timing, kind="stop", scale=0.0,
                                                      check=False, t0=start),
                              {"accel_scale": accel_scale, "hold": hold})
        within = best.within
        running = before if before is not None else \
            self.march(start, tau0, r0, r0, np.inf)  # a steady speed, kept
        # Followed as it is, the running profile may rest before a stop found within the
        # limits (one speeding up into the motion's end): it is a candidate too.
        best.consider(running, self.trajectory(running, kind="stop", scale=0.0, check=False,
                                               t0=start),
                      {"accel_scale": 0.0, "hold": float("inf")})
        if not within:
            found = self.brake_out(start, running)
            if found is not None:
                best.consider(*found)
        return best.chosen()

    def brake_out(self, start: float, running: Timing
                  ) -> tuple[Timing, Trajectory, dict[str, float]] | None:
        """The earliest stop found that follows the running profile from monitor time
        ``start`` for a hold, then brakes at one of :data:`BRAKE_OUT_SCALES` (hardest
        first), within every limit as executed: holds of 1, 2, 4, ... knots until one is,
        then bisected (in whole knots) down to a hold one knot after one that is not.

        Until the hold ends the stop's knots are the running goal's, so what it adds to
        the running motion is its braking alone; a hold that reaches the running
        profile's end is the running profile itself (not searched: the caller has it).

        Returns:
            (timing, trajectory, how it brakes), or None (none found before the running
            profile ends).
        """
        # The last hold whose braking starts (half a width on, in the raw profile)
        # before the running raw profile ends.
        raw_end = running.start + running.lead + float(running.t[-1])
        last = int(np.floor((raw_end - self.width / 2 - start) / self.knot - 1e-9))
        lo, hi, found = 0, 1, None  # holds in knots: lo not within the limits
        while hi <= last and found is None:
            found = self._brake_after(start, running, hi)
            if found is None:
                lo, hi = hi, 2 * hi
        hi = min(hi, last + 1)  # last + 1: the running profile itself
        while hi - lo > 1:
            mid = (lo + hi) // 2
            within = self._brake_after(start, running, mid)
            if within is None:
                lo = mid
            else:
                hi, found = mid, within
        return found

    def _brake_after(self, start: float, running: Timing, knots: int
                     ) -> tuple[Timing, Trajectory, dict[str, float]] | None:
        """Braking after following ``running`` for ``knots`` knots from ``start``, at the
        hardest of :data:`BRAKE_OUT_SCALES` within every limit as executed (None: none)."""
        hold = knots * self.knot
        for accel_scale in BRAKE_OUT_SCALES:
            timing = self.march(start + hold, 0.0, 0.0, 0.0, 0.0, before=running,
                                accel_scale=accel_scale)
            traj = self.trajectory(timing, kind="stop", scale=0.0, check=False, t0=start)
            if max(traj.info["executed_ratios"]) <= 1.0:
                return timing, traj, {"accel_scale": accel_scale, "hold": hold}
        return None

    def trajectory(self, timing: Timing, *, kind: str, scale: float, check: bool = True,
                   t0: float | None = None) -> Trajectory:
        """The followed timing as a trajectory starting at t = 0 (a replacement goal):
        knots every :attr:`knot` seconds on the verified motion, speeds ``Q' r`` and accelerations
        ``Q'' r^2 + Q' r'``, until it rests or reaches the path's end.

        Args:
            t0: Monitor time of the first knot (default the timing's start; a profile
                chained after a hold starts later than the replacement).

        Raises:
            TimingError: The join of the knots (as the controller executes them) would
                exceed a speed, acceleration or jerk limit.
        """
        first = timing.start if t0 is None else t0  # the first knot's monitor time
        n = max(2, int(np.ceil((timing.end - first) / self.knot - 1e-9)) + 1)
        t = np.arange(n) * self.knot
        tau, r, rd = timing.followed(first + t)
        done = np.flatnonzero(tau >= self.end - 1e-12)
        if done.size:  # reaches the path's end: stop there
            n = int(done[0]) + 1
            t, tau, r, rd = t[:n], tau[:n], r[:n], rd[:n]
        q, Qd, Qdd = self.states(tau)  # noqa: N806
        v = Qd * r[:, None]
        a = Qdd * (r * r)[:, None] + Qd * rd[:, None]
        v[-1] = a[-1] = 0.0
        peaks = (0.0, 0.0, 0.0)
        if n > 1:
            rv, ra, rj = interval_ratios(t, q, v, a, vmax=self.robot.velocity_limits,
                                         amax=self.robot.acceleration_limits,
                                         jmax=self.robot.jerk_limits,
                                         interpolation=self.traj.interpolation)
            peaks = (float(rv.max()), float(ra.max()), float(rj.max()))
            if check and not max(peaks) <= 1.0:
                k = int(np.argmax(np.maximum(np.maximum(rv, ra), rj)))
                raise TimingError(
                    f"re-timed motion at {max(peaks)!r} of a limit as executed ({kind} to "
                    f"scale {scale:g}; speed, acceleration, jerk ratios "
                    f"{peaks[0]:.3f}, {peaks[1]:.3f}, {peaks[2]:.3f}; at {t[k]:.3f} s)")
        tr = self.traj
        knot = np.clip(np.searchsorted(tr.t, tau, side="right") - 1, 0, tr.t.size - 1)
        info = {"monitor": kind, "speed_scale": scale, "path_start": float(tau[0]),
                "path_tau": tau.tolist(), "source_route": tr.route,
                "executed_ratios": list(peaks)}
        return Trajectory(tr.joint_names, t, q, v, a, tr.step_index[knot],
                          tr.steps, (), tr.robot, tr.route, info, self.robot.motion_limits,
                          tr.interpolation)


class _Earliest:
    """The stop chosen so far among candidates: the least excess over the limits as
    executed (none: within them), then the earliest at rest."""

    def __init__(self) -> None:
        self.key = (np.inf, np.inf)  # (largest ratio, at least 1; time to rest [s])
        self.pick: tuple[Timing, Trajectory] | None = None

    @property
    def within(self) -> bool:
        """Whether the stop chosen is within every limit as executed."""
        return self.key[0] <= 1.0

    def consider(self, timing: Timing, traj: Trajectory, how: dict[str, float]) -> None:
        """Take this candidate if it comes before the one chosen (``how``: how it brakes,
        recorded as ``info["stop"]``)."""
        traj.info["stop"] = how
        key = (max(max(traj.info["executed_ratios"]), 1.0), traj.duration)
        if key < self.key:
            self.key, self.pick = key, (timing, traj)

    def chosen(self) -> tuple[Timing, Trajectory]:
        """The stop chosen."""
        assert self.pick is not None
        return self.pick
