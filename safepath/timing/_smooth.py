"""A jerk-limited time scaling of a path from a TOPP-RA profile: two moving averages.

TOPP-RA's profile ``s0(t)`` has a piecewise-constant path acceleration ``u0``: the joint
accelerations jump between gridpoints (infinite jerk), and a controller's quintic join of
points sampled from it overshoots the acceleration limits. Averaging the profile over a
moving window of ``tau_a`` and then of ``tau_b`` seconds (Biagiotti & Melchiorri's FIR
trajectory filters, applied to the path parameter) gives

    s(t) = (1 / (tau_a tau_b)) int_0^tau_b int_0^tau_a s0(t - x - y) dx dy,

whose path jerk ``s'''`` is at most ``|du0| / tau_a`` (a jump of ``u0`` spread over
``tau_a``) and whose jerk is itself continuous (spread over ``tau_b``), so the quintic
join of points a few milliseconds apart follows it closely. The motion stays on the path
(only ``s(t)`` changes), starts and ends at rest, and lasts ``tau_a + tau_b`` longer than
the profile. Speeds and accelerations are averages of the profile's, so they keep within
its limits where the limits change slowly along the path; where they do not, the caller
tightens the limits there and solves again (:func:`safepath.timing.time_path`).

Everything is exact: ``s0`` is piecewise quadratic in time, so its first and second
integrals are piecewise cubic and quartic, and the double average is a second difference
of the second integral (:func:`evaluate`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._path_limits import PathSpline, jet
from ._topp import Profile, compiled_kernels

__all__ = ["Smoothed", "smooth", "evaluate", "along"]


@dataclass(frozen=True)
class Smoothed:
    """A TOPP-RA profile and the widths of its two moving averages.

    Attributes:
        profile: The profile (gridpoints, speeds, times, path accelerations).
        tau_a: Width of the first average [s] (bounds the path jerk).
        tau_b: Width of the second average [s] (makes the jerk continuous).
        S1: First integral of ``s0`` at the gridpoints' times.
        S2: Second integral of ``s0`` at the gridpoints' times.
    """

    profile: Profile
    tau_a: float
    tau_b: float
    S1: np.ndarray  # noqa: N815
    S2: np.ndarray  # noqa: N815

    @property
    def duration(self) -> float:
        """Duration of the smoothed motion [s]."""
        return self.profile.duration + self.tau_a + self.tau_b


def smooth(profile: Profile, tau_a: float, tau_b: float) -> Smoothed:
    """The profile with its integrals prepared for :func:`evaluate`."""
    p = profile
    dt = np.diff(p.t)
    s, v, u = p.grid[:-1], p.sd[:-1], p.u
    S1 = np.concatenate([[0.0], np.cumsum(s * dt + v * dt ** 2 / 2 + u * dt ** 3 / 6)])  # noqa: N806
    S1k = S1[:-1]  # noqa: N806
    S2 = np.concatenate([[0.0], np.cumsum(S1k * dt + s * dt ** 2 / 2 + v * dt ** 3 / 6  # noqa: N806
                                          + u * dt ** 4 / 24)])
    return Smoothed(profile, float(tau_a), float(tau_b), S1, S2)


def _integrals(sm: Smoothed, t: np.ndarray) -> np.ndarray:
    """``S2, S1, s0, sd0`` at times ``t`` (4, len(t)), the profile extended at rest
    before 0 and after its end."""
    p = sm.profile
    T0 = p.t[-1]  # noqa: N806
    L = p.grid[-1]  # noqa: N806
    out = np.zeros((4, t.size))
    inside = (t > 0.0) & (t < T0)
    ti = t[inside]
    # (np.clip checks its arguments' types on every call.)
    k = np.minimum(np.maximum(np.searchsorted(p.t, ti, side="right") - 1, 0), p.u.size - 1)
    tau = ti - p.t[k]
    s, v, u, s1 = p.grid[k], p.sd[k], p.u[k], sm.S1[k]
    tau2, tau3 = tau ** 2, tau ** 3  # each power once (the same values in every row)
    out[0, inside] = sm.S2[k] + s1 * tau + s * tau2 / 2 + v * tau3 / 6 + u * tau ** 4 / 24
    out[1, inside] = s1 + s * tau + v * tau2 / 2 + u * tau3 / 6
    out[2, inside] = s + v * tau + u * tau2 / 2
    out[3, inside] = v + u * tau
    after = t >= T0
    d = t[after] - T0
    out[0, after] = sm.S2[-1] + sm.S1[-1] * d + L * d ** 2 / 2
    out[1, after] = sm.S1[-1] + L * d
    out[2, after] = L
    return out


def evaluate(sm: Smoothed, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Path parameter, speed, acceleration and jerk of the smoothed motion at ``t`` [s].

    Returns:
        ``s, sd, sdd, sddd`` at ``t`` (the last time in ``t`` at or past the end is the
        end of the path at rest, exactly).
    """
    t = np.asarray(t, dtype=float)
    a, b = sm.tau_a, sm.tau_b
    n = t.size
    out = _integrals(sm, np.concatenate([t, t - a, t - b, t - a - b]))
    acc = (out[:, :n] - out[:, n:2 * n] - out[:, 2 * n:3 * n] + out[:, 3 * n:]) / (a * b)
    s, sd, sdd, sddd = acc[0], acc[1], acc[2], acc[3]
    end = sm.duration
    L = sm.profile.grid[-1]  # noqa: N806
    s = np.minimum(np.maximum(s, 0.0), L)
    sd = np.maximum(sd, 0.0)
    done = t >= end
    s[done], sd[done], sdd[done], sddd[done] = L, 0.0, 0.0, 0.0
    start = t <= 0.0
    s[start], sd[start], sdd[start], sddd[start] = 0.0, 0.0, 0.0, 0.0
    return s, sd, sdd, sddd



def along(sm: Smoothed, path: PathSpline, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """The smoothed motion at the increasing times ``t`` [s] along ``path``.

    Returns:
        ``s, sd, sdd`` (path parameter, speed, acceleration) and the joint positions,
        velocities and accelerations ``q, qd, qdd`` (len(t), dof): :func:`evaluate` and
        the chain rule, in one compiled pass where the path is a
        :class:`~safepath.timing.CubicPath`.
    """
    coef = getattr(path, "coefficients", None)
    if coef is None:
        s, sd, sdd, _ = evaluate(sm, t)
        q, ps, pss = jet(path, s)
        return s, sd, sdd, q, ps * sd[:, None], pss * (sd ** 2)[:, None] + ps * sdd[:, None]
    p = sm.profile
    n, dof = t.size, coef.shape[2]
    s, sd, sdd = np.empty(n), np.empty(n), np.empty(n)
    q, qd, qdd = np.empty((n, dof)), np.empty((n, dof)), np.empty((n, dof))
    compiled_kernels()["knots"](np.ascontiguousarray(t, dtype=np.float64), p.t, p.grid, p.sd,
                                p.u, sm.S1, sm.S2, sm.tau_a, sm.tau_b, path.x, coef, s, sd,
                                sdd, q, qd, qdd)
    return s, sd, sdd, q, qd, qdd
