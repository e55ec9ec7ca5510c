"""Path-consistent re-timing: the same knots, a new speed along them.

The path is the knots of a verified trajectory, parametrised by its own time ``tau``.
A :class:`Timing` is a new speed profile ``r = dtau/dt`` in [0, 1] along it (1: the
verified timing), built by the greedy pass of :func:`safepath.monitor._kernels.march`:
toward a speed scale as fast as the joint acceleration limits allow, or braking as hard
as they allow to rest. Positions stay the path's own knots (the first one is the state
where the new timing starts), so the shape never changes; velocities and accelerations
at every knot are within the robot's limits (checked before a timing is released).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TimingError
from ..execution import LIMITS_KEY, robot_limits
from ..robot import Robot
from ..trajectory import Trajectory

__all__ = ["MonitoredPath", "Timing"]


def _kernels():  # noqa: ANN202
    from . import _kernels as K  # noqa: N812

    return K


@dataclass(frozen=True)
class Timing:
    """A speed profile along a path, started at ``start`` on the monitor's clock.

    Attributes:
        start: Monitor time of the first knot [s].
        tau: Path parameter of each knot [s].
        x: Squared speed ``r^2`` at each knot.
        u: Path acceleration ``dr/dt`` on the interval after each knot [1/s].
        t: Time of each knot from ``start`` [s].
        rest: Whether the profile ends at rest before the path's end.
    """

    start: float
    tau: np.ndarray
    x: np.ndarray
    u: np.ndarray
    t: np.ndarray
    rest: bool

    @property
    def end(self) -> float:
        """Monitor time of the last knot [s]."""
        return self.start + float(self.t[-1])

    def state_at(self, time: float) -> tuple[float, float]:
        """Path parameter [s] and speed ``r`` at monitor time ``time`` (held after the
        end)."""
        dt_all = time - self.start
        if dt_all <= 0.0:
            return float(self.tau[0]), float(np.sqrt(self.x[0]))
        k = int(np.searchsorted(self.t, dt_all, side="right") - 1)
        if k >= self.t.size - 1:
            return float(self.tau[-1]), float(np.sqrt(self.x[-1]))
        dt = dt_all - float(self.t[k])
        r0 = float(np.sqrt(self.x[k]))
        u = float(self.u[k])
        tau = float(self.tau[k]) + r0 * dt + 0.5 * u * dt * dt
        return min(tau, float(self.tau[k + 1])), max(r0 + u * dt, 0.0)


class MonitoredPath:
    """A verified trajectory's knots as a path to re-time.

    Args:
        traj: The verified trajectory (one motion: no gripper event inside it).
        robot: Its robot (limits).
    """

    def __init__(self, traj: Trajectory, robot: Robot) -> None:
        self.traj = traj
        self.robot = robot
        self.amax = robot.acceleration_limits * (1.0 - 1e-9)

    @property
    def end(self) -> float:
        """Path parameter of the last knot [s]."""
        return float(self.traj.t[-1])

    def sample(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration of the verified trajectory at ``tau``
        (its own cubic Hermite interpolation, as :meth:`Trajectory.sample`)."""
        tr = self.traj
        t = tr.t
        if t.size == 1 or tau <= t[0]:
            return tr.q[0].copy(), tr.qd[0].copy(), tr.qdd[0].copy()
        if tau >= t[-1]:
            return tr.q[-1].copy(), tr.qd[-1].copy(), tr.qdd[-1].copy()
        k = min(int(np.searchsorted(t, tau, side="right")) - 1, t.size - 2)
        h = t[k + 1] - t[k]
        s = (tau - t[k]) / h
        s2, s3 = s * s, s * s * s
        p0, p1, m0, m1 = tr.q[k], tr.q[k + 1], tr.qd[k] * h, tr.qd[k + 1] * h
        q = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0
             + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1)
        dq = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0
              + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * m1) / h
        ddq = tr.qdd[k] + s * (tr.qdd[k + 1] - tr.qdd[k])
        return q, dq, ddq

    def grid(self, tau0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Knots from ``tau0`` on: (tau, q, Q', Q''); the first is the state at ``tau0``."""
        tr = self.traj
        tau0 = min(max(float(tau0), float(tr.t[0])), float(tr.t[-1]))
        k = int(np.searchsorted(tr.t, tau0 + 1e-9, side="right"))
        q0, qd0, qdd0 = self.sample(tau0)
        tau = np.concatenate([[tau0], tr.t[k:]])
        return (tau, np.vstack([q0, tr.q[k:]]), np.vstack([qd0, tr.qd[k:]]),
                np.vstack([qdd0, tr.qdd[k:]]))

    def march(self, start: float, tau0: float, r0: float, scale: float, brake_after: float,
              *, limit: int | None = None) -> Timing:
        """A profile from path parameter ``tau0`` at speed ``r0``, toward speed
        ``scale``, braking to rest from ``brake_after`` [s] on (``inf``: never).

        Args:
            start: Monitor time of the first knot [s].
            tau0: Where it starts [s of the path].
            r0: Speed there, in [0, 1].
            scale: Target speed, in [0, 1].
            brake_after: When braking begins, from ``start`` [s].
            limit: Knots to consider at most (None: all).
        """
        tau, _, qd, qdd = self.grid(tau0)
        if limit is not None:
            tau, qd, qdd = tau[:limit], qd[:limit], qdd[:limit]
        n = tau.size
        x, u, t = np.empty(n), np.empty(n), np.empty(n)
        m, _, rest = _kernels().march(tau, qd, qdd, self.amax, r0 * r0, scale * scale,
                                      brake_after, x, u, t)
        at_end = m == n and (limit is None or limit >= n)
        return Timing(start, tau[:m].copy(), x[:m].copy(), u[:m].copy(), t[:m].copy(),
                      bool(rest and not (at_end and x[m - 1] > 0)))

    def trajectory(self, timing: Timing, *, kind: str, scale: float) -> Trajectory:
        """The timing as a trajectory starting at t = 0 (a replacement goal).

        Raises:
            TimingError: A knot would exceed a velocity or acceleration limit.
        """
        tau, q, qd, qdd = self.grid(float(timing.tau[0]))
        m = timing.tau.size
        q, qd, qdd = q[:m], qd[:m], qdd[:m]
        r = np.sqrt(timing.x)[:, None]
        v = qd * r
        a = qdd * timing.x[:, None] + qd * timing.u[:, None]
        if timing.rest or timing.tau[-1] >= self.end:
            v[-1] = 0.0
            a[-1] = 0.0
        t = timing.t
        if m > 1 and np.any(np.diff(t) <= 0):
            raise TimingError("re-timed knots are not increasing in time")
        vr = float(np.max(np.abs(v) / self.robot.velocity_limits)) if m else 0.0
        ar = float(np.max(np.abs(a) / self.robot.acceleration_limits)) if m else 0.0
        if not (vr <= 1.0 and ar <= 1.0):
            raise TimingError(f"re-timed knot at {max(vr, ar)!r} of its limit")
        tr = self.traj
        knot = np.clip(np.searchsorted(tr.t, tau, side="right") - 1, 0, tr.t.size - 1)
        info = {"monitor": kind, "speed_scale": scale, "path_start": float(tau[0]),
                "source_route": tr.route, LIMITS_KEY: robot_limits(self.robot)}
        return Trajectory(tr.joint_names, t.copy(), q, v, a, tr.step_index[knot][:m],
                          tr.steps, (), tr.robot, tr.route, info)
