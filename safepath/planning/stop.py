"""Path-consistent stops: brake along the same, verified path, within the joint limits.

When an event arrives during a motion (the scale reaches its threshold), the robot must
stop without leaving the path that was verified: the joint positions stay ``q(s)`` for the
path ``q`` of the motion, and only the path speed ``sdot`` is brought to zero as fast as
the joint acceleration limits allow (the fastest braking: at each point the smallest
``sddot`` with ``|q'(s) sddot + q''(s) sdot^2| <= a_max`` for every joint).

:class:`StopPlanner` prepares the path once (``q'``, ``q''`` on a grid ``grid_step``
apart); :meth:`StopPlanner.stop` then integrates ``x = sdot^2`` over the grid (``dx/ds =
2 sddot``, constant ``sddot`` between gridpoints, the TOPP-RA way) from the state at the
event to rest, samples the result every ``knot_period`` and checks every sample against
the limits. It takes a few milliseconds (``benchmarks/pour.py`` prints the figure).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TimingError
from ..model.robot import Robot
from ..timing import PathSpline

__all__ = ["StopPlanner", "Stop", "path_state"]


@dataclass(frozen=True)
class Stop:
    """A braking motion along the path, from the event to rest.

    Attributes:
        t: Times from the event [s].
        s: Path parameter of each sample.
        q: Positions [rad] (N, dof).
        qd: Velocities [rad/s].
        qdd: Accelerations [rad/s^2].
    """

    t: np.ndarray
    s: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    @property
    def duration(self) -> float:
        """Time to rest [s]."""
        return float(self.t[-1])


class StopPlanner:
    """Fastest path-consistent stops on one joint path.

    Args:
        robot: Limits.
        path: The motion's joint path ``q(s)``.
        scale: Fraction of the acceleration limits used for braking, in (0, 1]; the
            default keeps 3 % for the change of ``q'`` and ``q''`` between gridpoints.
        grid_step: Spacing of the integration grid along the path.
        knot_period: Period of the output samples [s].
    """

    def __init__(self, robot: Robot, path: PathSpline, *, scale: float = 0.97,
                 grid_step: float = 0.001, knot_period: float = 0.004,
                 timed: tuple[np.ndarray, ...] | None = None) -> None:
        self.robot = robot
        #: The motion's own knots (t, s, q, qd, qdd), if given: near the end of the path
        #: its own deceleration (at the full limits) is the stop.
        self.timed = timed
        self.path = path
        self.knot_period = knot_period
        self.end = float(path.x[-1])
        self.grid = np.linspace(0.0, self.end, max(3, int(np.ceil(self.end / grid_step)) + 1))
        self.dq = np.ascontiguousarray(path(self.grid, 1))
        self.ddq = np.ascontiguousarray(path(self.grid, 2))
        self.amax = scale * robot.acceleration_limits
        self.vmax = robot.velocity_limits

    def stop(self, s0: float, sd0: float, *, time: float | None = None) -> Stop:
        """Brake from path parameter ``s0`` at path speed ``sd0`` [1/s] to rest.

        Args:
            s0: Path parameter at the event.
            sd0: Path speed at the event [1/s].
            time: Time of the event on the motion [s]: if braking at ``scale`` of the
                limits would pass the end of the path, the motion's own remaining knots
                (which come to rest at the end within the limits) are the stop.

        Raises:
            TimingError: The path cannot be stopped before its end within the limits
                (not for a state of a trajectory timed within the same limits), or a
                sample would break a limit.
        """
        grid, dq, ddq, amax = self.grid, self.dq, self.ddq, self.amax
        i = int(np.searchsorted(grid, s0, side="right")) - 1
        i = min(max(i, 0), grid.size - 2)
        s_list, x_list, u_list = [float(s0)], [float(sd0) ** 2], []
        s, x = float(s0), float(sd0) ** 2
        while x > 0.0:
            if i >= grid.size - 1:
                if self.timed is not None and time is not None:
                    return self._rest_of_motion(time)
                raise TimingError(f"cannot stop before the end of the path (s = {s:.4f})")
            # The smallest sddot every joint allows here: q' u + q'' x within +-amax.
            a, b = dq[i], ddq[i] * x
            with np.errstate(divide="ignore", invalid="ignore"):
                lo = np.where(a > 1e-12, (-amax - b) / a,
                              np.where(a < -1e-12, (amax - b) / a, -np.inf))
            u = float(lo.max())
            if not u < 0.0:
                raise TimingError(f"the path cannot brake at s = {s:.4f} within the limits")
            s_next = float(grid[i + 1])
            x_next = x + 2.0 * u * (s_next - s)
            if x_next <= 0.0:  # rest before the next gridpoint
                s_next = s - x / (2.0 * u)
                x_next = 0.0
            s_list.append(s_next)
            x_list.append(x_next)
            u_list.append(u)
            s, x = s_next, x_next
            i += 1
        return self._sample(np.array(s_list), np.sqrt(np.array(x_list)), np.array(u_list))

    def _rest_of_motion(self, time: float) -> Stop:
        assert self.timed is not None
        t, s, q, qd, qdd = self.timed
        k = int(np.searchsorted(t, time, side="left"))
        return Stop(t[k:] - t[k], s[k:], q[k:], qd[k:], qdd[k:])

    def _sample(self, s: np.ndarray, sd: np.ndarray, u: np.ndarray) -> Stop:
        # Each interval: constant sddot u, from sd[k] to sd[k+1]: dt = (sd1 - sd0) / u.
        dt = (sd[1:] - sd[:-1]) / u
        tk = np.concatenate([[0.0], np.cumsum(dt)])
        t = np.append(np.arange(0.0, tk[-1], self.knot_period), tk[-1])
        k = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, u.size - 1)
        tau = t - tk[k]
        sdt = np.maximum(sd[k] + u[k] * tau, 0.0)
        st = s[k] + sd[k] * tau + 0.5 * u[k] * tau ** 2
        sddt = u[k]
        q = self.path(st)
        qd = self.path(st, 1) * sdt[:, None]
        qdd = self.path(st, 1) * sddt[:, None] + self.path(st, 2) * (sdt ** 2)[:, None]
        qd[-1] = 0.0
        v = float(np.max(np.abs(qd) / self.vmax))
        a = float(np.max(np.abs(qdd) / self.robot.acceleration_limits))
        if not (v <= 1.0 and a <= 1.0):
            raise TimingError(f"a stop sample is at {max(v, a):.4f} of its limit")
        return Stop(t, st, q, qd, qdd)


def path_state(path: PathSpline, s: np.ndarray, qd: np.ndarray, t: np.ndarray,
               time: float) -> tuple[float, float]:
    """Path parameter and path speed [1/s] of a timed path at ``time`` [s] (linear
    between knots; ``sdot = q'(s) . qd / |q'(s)|^2`` at the knots)."""
    k = int(np.clip(np.searchsorted(t, time, side="right") - 1, 0, len(t) - 2))
    f = float(np.clip((time - t[k]) / (t[k + 1] - t[k]), 0.0, 1.0))
    dq = path(s[k:k + 2], 1)
    sd = np.einsum("ij,ij->i", dq, qd[k:k + 2]) / np.maximum(np.einsum("ij,ij->i", dq, dq),
                                                             1e-300)
    return float(s[k] + f * (s[k + 1] - s[k])), float(max(0.0, sd[0] + f * (sd[1] - sd[0])))
