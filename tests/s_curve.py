"""The time-optimal jerk-limited rest-to-rest move along a straight joint line, written
for the tests and benchmarks independently of safepath (``safepath.timing._scurve`` is
what it checks)."""

from __future__ import annotations

import numpy as np


def s_curve_time(delta: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray
                 ) -> float:
    """Time-optimal rest-to-rest duration of a straight joint move under velocity,
    acceleration and jerk limits [s] (the 7-phase S-curve along the line)."""
    d = np.abs(np.asarray(delta, dtype=float))
    moving = d > 1e-12
    v, a, j = (float(np.min(x[moving] / d[moving])) for x in (vmax, amax, jmax))

    def ramp(peak: float) -> float:  # time from rest to the speed ``peak``
        return peak / a + a / j if peak * j >= a * a else 2.0 * np.sqrt(peak / j)

    if v * ramp(v) <= 1.0:  # cruises
        return 1.0 / v + ramp(v)
    lo, hi = 0.0, v
    for _ in range(200):  # the peak speed whose ramps cover the whole move
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if mid * ramp(mid) < 1.0 else (lo, mid)
    return 2.0 * ramp(lo)
