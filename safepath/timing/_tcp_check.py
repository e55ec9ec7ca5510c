"""The TCP's speed along timed knots, checked as the robot's controller joins them.

Where a route step limits the TCP's speed, :func:`~safepath.timing.time_path` releases
its knots only once the TCP's speed of their join (``controller.yaml``'s interpolation)
is within every step's limit: :class:`TcpLimits` measures it, screening with the path's
rate estimated on TOPP-RA's grid and measuring by forward kinematics only near a limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.execution import join
from ..model.robot import Robot

__all__ = ["TcpLimits"]


#: Share of its TCP speed limit below which a knot interval's two ends keep its inside
#: unsampled (:meth:`TcpLimits.ratio`).
_TCP_NEAR = 0.95
#: Share of its TCP speed limit below which the estimate of a knot interval's two ends
#: keeps the interval from being measured at all. The estimate (the path's rate from
#: finite differences on a 15 mrad grid, linear in between) was at most 8.6 % off the
#: forward kinematics at the knots over half their limit in the bundled cells' plans.
_TCP_SCREEN = 0.7
#: How far below the largest sampled TCP speed ratio a sample's interval is sampled again,
#: :data:`_TCP_FINER` times as densely (:meth:`TcpLimits.ratio`).
_TCP_REFINE = 1e-3
_TCP_FINER = 8


@dataclass(frozen=True)
class TcpLimits:
    """The TCP speed limits of a path's segments, checked on the knots' executed motion.

    Attributes:
        robot: Kinematics.
        v_seg: Each segment's TCP speed limit [m/s] (inf: none).
        grid: TOPP-RA's gridpoints.
        rate: The TCP's speed per path speed there, estimated [m/rad].
        samples: Knot intervals are cut into this many parts (inside the ones near
            their limit, sampled at the cuts as well as at their ends), so that a
            stretch in time samples the same fractions of each interval.
    """

    robot: Robot
    v_seg: np.ndarray
    samples: int
    grid: np.ndarray
    rate: np.ndarray

    def ratio(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
              segment: np.ndarray, s: np.ndarray, sd: np.ndarray) -> float:
        """The largest TCP speed of the knots' join over its limit (the smaller
        of its two knots' segments' limits on each interval); 0 where none limits it.

        The knots lie on the path (``qd = q'(s) sdot``): their TCP speed is the path's
        rate ``|dp/ds|`` times ``sdot`` (``s``, ``sd``), whose estimate on TOPP-RA's grid
        screens out the intervals whose ends are both below :data:`_TCP_SCREEN` of their
        limit; the others are measured by forward kinematics."""
        per_knot = self.v_seg[segment]
        limit = np.minimum(per_knot[:-1], per_knot[1:])
        estimate = np.interp(s, self.grid, self.rate) * sd
        near = np.maximum(estimate[:-1], estimate[1:]) >= _TCP_SCREEN * limit
        at = np.flatnonzero(np.isfinite(limit) & near)
        if at.size == 0:
            return float(np.max(estimate[:-1] / limit, initial=0.0))
        # The knots first: inside an interval whose ends are both below _TCP_NEAR of its
        # limit, the speed could only reach the limit if it bent away from the line
        # between them by that share of it (its second derivative, times the interval
        # squared over 8: kilometres per second cubed for a few milliseconds).
        ends = np.zeros(t.size, dtype=bool)
        ends[at] = ends[at + 1] = True
        knots = np.flatnonzero(ends)
        at_knot = np.zeros(t.size)
        at_knot[knots] = self.robot.tcp_speeds(q[knots], qd[knots])
        ends = np.maximum(at_knot[at], at_knot[at + 1]) / limit[at]
        worst = float(ends.max())
        at = at[ends >= _TCP_NEAR]
        if at.size == 0:
            return worst
        parts = max(2, self.samples)
        sampled = self._sampled(t, q, qd, qdd, at, limit[at], parts)
        worst = max(worst, float(sampled.max()))
        # The largest speed lies between samples: where a sample comes within
        # _TCP_REFINE of the worst, the interval is sampled _TCP_FINER times as densely
        # (a smooth peak's sampling error shrinks with the square of the spacing).
        top = np.flatnonzero(sampled >= worst - _TCP_REFINE) // (parts - 1)  # sorted
        if top.size == 0:  # the worst is at a knot
            return worst
        top = top[np.concatenate([[True], top[1:] != top[:-1]])]
        finer = self._sampled(t, q, qd, qdd, at[top], limit[at][top], _TCP_FINER * parts)
        return max(worst, float(finer.max()))

    def _sampled(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                 at: np.ndarray, limit: np.ndarray, parts: int) -> np.ndarray:
        """The TCP's speed over its limit inside knot intervals ``at`` (their limits
        ``limit``), each cut into ``parts`` (the cuts sampled): (len(at) * (parts - 1),),
        interval by interval."""
        frac = np.linspace(0.0, 1.0, parts + 1)[1:-1]
        times = (t[at, None] + (t[at + 1] - t[at])[:, None] * frac).ravel()
        p, v, _, _ = join(t, q, qd, qdd, times, interpolation=self.robot.controller.interpolation)
        return self.robot.tcp_speeds(p, v) / np.repeat(limit, frac.size)
