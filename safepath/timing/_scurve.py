"""The time-optimal jerk-limited rest-to-rest motion along a straight line, on knots.

Along a straight joint path ``q(s) = q0 + s d`` (``|d| = 1``) every joint's speed,
acceleration and jerk are ``|d_j|`` times the path's, so the joint limits are limits on
the path parameter (``v = min_j vmax_j / |d_j|``, likewise ``a`` and ``j``) and the
optimal motion is the 1-DOF double-S ("7-phase S-curve", Biagiotti & Melchiorri,
*Trajectory Planning for Automatic Machines and Robots*, 2008, sec. 3.4): jerk ``+j``
for ``Tj``, none for ``Ta``, ``-j`` for ``Tj`` (speed ``vp``), a cruise of ``Tv``, and
the mirror image down to rest; ``Ta = 0`` when ``a`` is not reached, ``Tv = 0`` when
``v`` is not.

A controller joins knots by quintics through their position, velocity and acceleration,
and a quintic through two points of one cubic piece *is* that piece; a jerk switch inside
an interval instead makes the quintic's jerk overshoot (by up to 1.37x for a step from 0
to ``j``). So the phases are made whole numbers of one knot period: each duration is
rounded up to a multiple of a period ``dt' <= knot_period`` (the one of many candidates,
whole nanoseconds apart, that lengthens the motion least) and the jerk scaled down so the
motion still ends at ``L``; longer phases only lower the jerk, acceleration and speed
needed (each is ``L`` over a product of the durations). The knots then sample the motion
exactly at its switches, and their quintic join *is* the motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SCurve", "s_curve", "sample"]

_NS = 1_000_000_000
#: Candidate knot periods tried, from ``knot_period`` down to half of it.
_CANDIDATES = 2000


@dataclass(frozen=True)
class SCurve:
    """A double-S motion over ``length`` whose phases are whole numbers of knot periods.

    Attributes:
        length: Path length [path units] (> 0).
        step_ns: Knot period [ns].
        nj: Knot periods of each jerk phase.
        na: Knot periods of each constant-acceleration phase.
        nv: Knot periods of the cruise.
        jerk: Path jerk of the jerk phases [path units/s^3].
    """

    length: float
    step_ns: int
    nj: int
    na: int
    nv: int
    jerk: float

    @property
    def knots(self) -> int:
        """Number of knots (periods + 1)."""
        return 4 * self.nj + 2 * self.na + self.nv + 1


def _phases(length: float, v: float, a: float, j: float) -> tuple[float, float, float]:
    """The optimal ``Tj, Ta, Tv`` [s] of a rest-to-rest double-S over ``length``."""
    def ramp(peak: float) -> tuple[float, float]:  # Tj, Ta reaching the speed ``peak``
        if peak * j >= a * a:
            return a / j, peak / a - a / j
        return float(np.sqrt(peak / j)), 0.0

    tj, ta = ramp(v)
    tv = length / v - (2.0 * tj + ta)
    if tv >= 0.0:
        return tj, ta, tv
    # No cruise: the peak speed vp whose two ramps cover the length, vp (2 Tj + Ta) = L.
    peak = (-a * a / j + float(np.sqrt((a * a / j) ** 2 + 4.0 * a * length))) / 2.0
    if peak * j < a * a:  # the acceleration is not reached either
        peak = (length * float(np.sqrt(j)) / 2.0) ** (2.0 / 3.0)
    tj, ta = ramp(peak)
    return tj, ta, 0.0


def s_curve(length: float, v: float, a: float, j: float, knot_period: float) -> SCurve:
    """The double-S over ``length`` within the path limits ``v, a, j``, its phases whole
    numbers of one knot period of at most ``knot_period`` [s]."""
    tj, ta, tv = _phases(length, v, a, j)
    top = int(round(knot_period * _NS))
    steps = np.linspace(top // 2, top, _CANDIDATES).astype(np.int64)
    steps = steps[np.concatenate([[True], np.diff(steps) != 0])]  # ascending, once each
    dt = steps / _NS
    nj = np.maximum(1, np.ceil(tj / dt - 1e-9)).astype(np.int64)
    na = np.maximum(0, np.ceil(ta / dt - 1e-9)).astype(np.int64)
    nv = np.maximum(0, np.ceil(tv / dt - 1e-9)).astype(np.int64)
    total = (4 * nj + 2 * na + nv) * steps  # [ns]
    best = int(np.argmin(total))  # the first (shortest period) of equal durations
    step = float(dt[best])
    t_j, t_a, t_v = nj[best] * step, na[best] * step, nv[best] * step
    jerk = length / (t_j * (t_j + t_a) * (2.0 * t_j + t_a + t_v))
    return SCurve(float(length), int(steps[best]), int(nj[best]), int(na[best]),
                  int(nv[best]), float(jerk))


def sample(curve: SCurve) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Knot times [s] (whole nanoseconds) and the path parameter, speed and acceleration
    there, exactly at the phase switches."""
    n = curve.knots
    k = np.arange(n, dtype=np.int64)
    dt = curve.step_ns / _NS
    t = k * curve.step_ns / _NS
    # The first half: acceleration phases and half the cruise, by the knot's index from
    # whichever end is nearer (the second half mirrors the first).
    back = np.minimum(k, n - 1 - k)
    s, sd, sdd = _accelerating(back * dt, curve)
    mirrored = k > n - 1 - k
    s = np.where(mirrored, curve.length - s, s)
    sdd = np.where(mirrored, -sdd, sdd)
    s[0], s[-1] = 0.0, curve.length
    return t, s, sd, sdd


def _accelerating(t: np.ndarray, curve: SCurve) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Path parameter, speed and acceleration at times ``t`` from rest, up to the middle
    of the cruise."""
    dt = curve.step_ns / _NS
    jerk = curve.jerk
    tj, ta = curve.nj * dt, curve.na * dt
    t_acc = 2.0 * tj + ta
    peak_a = jerk * tj
    vp = peak_a * (tj + ta)
    s_acc = vp * t_acc / 2.0
    # Phase by phase (the times are multiples of dt: compare knot counts, not floats).
    n = np.rint(t / dt).astype(np.int64)
    rise = n <= curve.nj
    hold = (n > curve.nj) & (n <= curve.nj + curve.na)
    fall = (n > curve.nj + curve.na) & (n <= 2 * curve.nj + curve.na)
    cruise = n > 2 * curve.nj + curve.na
    tau = t - tj  # in the hold
    left = t_acc - t  # to the end of the fall
    sdd = np.select([rise, hold, fall], [jerk * t, np.full_like(t, peak_a), jerk * left], 0.0)
    sd = np.select([rise, hold, fall, cruise],
                   [jerk * t * t / 2.0, jerk * tj * tj / 2.0 + peak_a * tau,
                    vp - jerk * left * left / 2.0, np.full_like(t, vp)])
    s = np.select([rise, hold, fall, cruise],
                  [jerk * t ** 3 / 6.0,
                   jerk * tj ** 3 / 6.0 + jerk * tj * tj / 2.0 * tau + peak_a * tau * tau / 2.0,
                   s_acc - vp * left + jerk * left ** 3 / 6.0,
                   s_acc + vp * (t - t_acc)])
    return s, sd, sdd
