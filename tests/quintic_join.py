"""The motion a trajectory controller executes from a goal's points, written for the tests
independently of safepath: ros2_control's joint_trajectory_controller joins consecutive
points carrying position, velocity and acceleration with a quintic per joint."""

from __future__ import annotations

import numpy as np


def quintic_peaks(t: np.ndarray, P: np.ndarray, V: np.ndarray, A: np.ndarray,  # noqa: N803
                   rate: float = 1000.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per joint, max |v|, |a|, |j| of the quintic join sampled at >= ``rate`` Hz (every
    interval at the same number of evenly spaced instants, ends included)."""
    T = np.diff(t)[:, None, None]  # noqa: N806
    m = max(2, int(np.ceil(T.max() * rate)) + 1)
    s = T * np.linspace(0.0, 1.0, m)[None, None, :]
    p0, v0, a0 = P[:-1, :, None], V[:-1, :, None], A[:-1, :, None]
    h = P[1:, :, None] - p0 - v0 * T - a0 * T * T / 2
    dv = V[1:, :, None] - v0 - a0 * T
    da = A[1:, :, None] - a0
    c3 = (10 * h - 4 * dv * T + da * T * T / 2) / T ** 3
    c4 = (-15 * h + 7 * dv * T - da * T * T) / T ** 4
    c5 = (6 * h - 3 * dv * T + da * T * T / 2) / T ** 5
    v = v0 + a0 * s + 3 * c3 * s ** 2 + 4 * c4 * s ** 3 + 5 * c5 * s ** 4
    a = a0 + 6 * c3 * s + 12 * c4 * s ** 2 + 20 * c5 * s ** 3
    j = 6 * c3 + 24 * c4 * s + 60 * c5 * s ** 2
    return tuple(np.abs(x).max(axis=(0, 2)) for x in (v, a, j))  # type: ignore[return-value]


def quintic_state(t: np.ndarray, P: np.ndarray, V: np.ndarray, A: np.ndarray,  # noqa: N803
                  at: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of the quintic join at time ``at`` (held at the
    ends: the last point with zero velocity and acceleration after it)."""
    if at <= t[0]:
        return P[0], V[0], A[0]
    if at >= t[-1]:
        return P[-1], 0 * V[-1], 0 * A[-1]
    i = int(np.clip(np.searchsorted(t, at, side="right") - 1, 0, t.size - 2))
    T, s = t[i + 1] - t[i], at - t[i]  # noqa: N806
    p0, v0, a0 = P[i], V[i], A[i]
    h = P[i + 1] - p0 - v0 * T - a0 * T * T / 2
    dv = V[i + 1] - v0 - a0 * T
    da = A[i + 1] - a0
    c3 = (10 * h - 4 * dv * T + da * T * T / 2) / T ** 3
    c4 = (-15 * h + 7 * dv * T - da * T * T) / T ** 4
    c5 = (6 * h - 3 * dv * T + da * T * T / 2) / T ** 5
    p = p0 + v0 * s + a0 * s * s / 2 + c3 * s ** 3 + c4 * s ** 4 + c5 * s ** 5
    v = v0 + a0 * s + 3 * c3 * s ** 2 + 4 * c4 * s ** 3 + 5 * c5 * s ** 4
    a = a0 + 6 * c3 * s + 12 * c4 * s ** 2 + 20 * c5 * s ** 3
    return p, v, a
