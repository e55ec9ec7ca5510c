"""Time-optimal path parameterisation by reachability analysis (TOPP-RA), numba-compiled.

Pham & Pham, "A new approach to time-optimal path parameterization based on reachability
analysis", IEEE T-RO 34(3), 2018. On a grid ``s_0 < ... < s_N`` along the path the state is
``x = sdot^2`` and the control ``u = sddot``, constant on each grid interval, so that
``x_{i+1} = x_i + 2 (s_{i+1} - s_i) u_i``. The constraints are

* joint velocity at each gridpoint, ``|q'_j(s_i)| sqrt(x_i) <= v_ij``, as a bound on ``x_i``;
* joint acceleration ``|q'_j(s) u + q''_j(s) x| <= a_j(s)`` in the *interpolation*
  discretisation (as the ``toppra`` library uses it): on interval ``i`` the limits hold
  at ``s_i`` with ``(u_i, x_i)`` and at ``s_{i+1}`` with ``(u_i, x_{i+1})``, i.e. at both
  ends of the constant-acceleration piece that :func:`parametrize` produces.

A backward pass computes the controllable sets ``K_i`` (the ``x_i`` from which the end is
reached at rest); each is the projection on ``x`` of a 2-D polygon in ``(u, x)``, found
exactly by eliminating ``u`` (Fourier-Motzkin: every pair of an upper and a lower bound
on ``u`` gives a bound on ``x``). A forward pass then takes, at each gridpoint, the
largest ``u`` that keeps ``x_{i+1}`` controllable.

The two passes are compiled ahead of time (:mod:`safepath._aot`), or else with numba on
first use (and cached on disk); numba is imported then, not when this module is imported.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model._knots import interval_index

__all__ = ["Profile", "acceleration_rows", "compiled_kernels", "evaluate", "parametrize",
           "solve"]

#: Largest squared path speed [1/s^2] where no joint limits it (a joint path at rest).
X_CAP = 1e12

_lock = threading.Lock()
_compiled: dict[str, Callable[..., Any]] = {}


@dataclass(frozen=True)
class Profile:
    """A time-optimal speed profile along the grid.

    Attributes:
        grid: Path parameter of the gridpoints (N+1,).
        sd: Path speed at the gridpoints (N+1,) [1/s].
        t: Time at the gridpoints (N+1,) [s].
        u: Path acceleration on each grid interval (N,) [1/s^2].
    """

    grid: np.ndarray
    sd: np.ndarray
    t: np.ndarray
    u: np.ndarray

    @property
    def duration(self) -> float:
        """Time from the first to the last gridpoint [s]."""
        return float(self.t[-1])


def acceleration_rows(grid: np.ndarray, dq: np.ndarray, ddq: np.ndarray, alim: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint acceleration limits of each grid interval, interpolation discretisation.

    Args:
        grid: Gridpoints (N+1,).
        dq: Path tangent ``q'(s)`` at the gridpoints (N+1, dof).
        ddq: Path curvature ``q''(s)`` at the gridpoints (N+1, dof).
        alim: Acceleration limits at the gridpoints (N+1, dof) [rad/s^2].

    Returns:
        ``a, b, c`` of shape (N, 2 dof): on interval ``i``, ``|a u_i + b x_i| <= c`` row-wise
        (first the limits at ``s_i``, then those at ``s_{i+1}`` with ``x_{i+1}`` expanded).
    """
    delta = np.diff(grid)[:, None]
    a = np.hstack([dq[:-1], dq[1:] + 2.0 * delta * ddq[1:]])
    b = np.hstack([ddq[:-1], ddq[1:]])
    c = np.hstack([alim[:-1], alim[1:]])
    return a, b, c


def solve(grid: np.ndarray, xmax: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
          ) -> np.ndarray | None:
    """The time-optimal rest-to-rest squared path speeds at the gridpoints.

    Args:
        grid: Gridpoints (N+1,), strictly increasing.
        xmax: Bound on ``x = sdot^2`` at each gridpoint (N+1,) (velocity limits).
        a, b, c: Rows ``|a u_i + b x_i| <= c`` of each interval (N, m), ``c > 0``
            (from :func:`acceleration_rows`).

    Returns:
        ``x`` at the gridpoints (N+1,), or None when no timing exists: the controllable
        sets are empty, the inputs are not finite, or the path would have to rest over
        a whole grid interval (which takes forever).
    """
    kernels = compiled_kernels()
    delta = np.ascontiguousarray(np.diff(grid), dtype=np.float64)
    args = [np.ascontiguousarray(v, dtype=np.float64) for v in (xmax, a, b, c)]
    if not all(np.isfinite(v).all() for v in (delta, *args)):
        return None
    lo = np.empty(grid.size)
    hi = np.empty(grid.size)
    if kernels["backward"](delta, *args, lo, hi) >= 0:
        return None
    x = np.empty(grid.size)
    kernels["forward"](delta, *args, lo, hi, x)
    if not np.all(x[:-1] + x[1:] > 0.0):
        return None
    return x


def parametrize(grid: np.ndarray, x: np.ndarray) -> Profile:
    """Constant path acceleration on each grid interval (toppra's ``ParametrizeConstAccel``).

    The path speed goes linearly in time from ``sqrt(x_i)`` to ``sqrt(x_{i+1})`` while ``s``
    goes from ``s_i`` to ``s_{i+1}``.
    """
    sd = np.sqrt(x)
    delta = np.diff(grid)
    t = np.concatenate([[0.0], np.cumsum(2.0 * delta / (sd[:-1] + sd[1:]))])
    u = (x[1:] - x[:-1]) / (2.0 * delta)
    return Profile(grid, sd, t, u)


def evaluate(profile: Profile, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Path parameter, speed and acceleration at times ``t`` [s] in [0, duration].

    The last time is taken as the end of the path (at rest), exactly.
    """
    k = interval_index(profile.t, t, profile.u.size)
    dt = t - profile.t[k]
    u = profile.u[k]
    sd0 = profile.sd[k]
    s = profile.grid[k] + dt * sd0 + 0.5 * dt * dt * u
    sd = sd0 + dt * u
    s = np.clip(s, profile.grid[0], profile.grid[-1])
    sd = np.maximum(sd, 0.0)
    if t.size and t[-1] >= profile.t[-1]:
        s[-1], sd[-1] = profile.grid[-1], 0.0
    return s, sd, u


# -- kernels (plain Python, compiled by numba in compiled_kernels) -------------------------

def _backward(delta: np.ndarray, xmax: np.ndarray, a: np.ndarray, b: np.ndarray,
              c: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> int:
    """Controllable sets ``[lo_i, hi_i]``; returns -1, or the first stage found empty.

    Each row ``|a u + b x| <= c`` is an upper and a lower bound on ``u``; so is the next
    set, ``lo_{i+1} <= x + 2 delta u <= hi_{i+1}``. Every pair of an upper and a lower bound
    gives ``e x <= f``. For two rows (``a, c >= 0`` once a row's sign is flipped so that
    ``a >= 0``) the pair taken either way gives ``|e| x <= f`` and ``-|e| x <= f`` with
    ``f >= 0``: only the upper bound on ``x`` counts. Bounds are kept as fractions and
    compared cross-multiplied; one division per stage.
    """
    n = xmax.size
    m = a.shape[1]
    an = np.empty(m)
    bn = np.empty(m)
    lo[n - 1] = 0.0
    hi[n - 1] = 0.0
    for i in range(n - 2, -1, -1):
        if not (xmax[i] >= 0.0):  # also NaN
            return i
        for p in range(m):
            if a[i, p] >= 0.0:
                an[p] = a[i, p]
                bn[p] = b[i, p]
            else:
                an[p] = -a[i, p]
                bn[p] = -b[i, p]
            if not (c[i, p] >= 0.0):
                return i
        d2 = 2.0 * delta[i]
        k_lo = lo[i + 1]
        k_hi = hi[i + 1]
        f_hi = min(xmax[i], X_CAP)  # x <= f_hi / e_hi
        e_hi = 1.0
        x_lo = 0.0
        for p in range(m):
            ap = an[p]
            bp = bn[p]
            cp = c[i, p]
            for q in range(p + 1, m):
                e = abs(an[q] * bp - ap * bn[q])
                f = ap * c[i, q] + an[q] * cp
                if e > 0.0 and f * e_hi < f_hi * e:
                    f_hi = f
                    e_hi = e
            # Row p with the next set: e > 0 bounds x above (through lo_{i+1}), e < 0
            # above (through hi_{i+1}) and below (through lo_{i+1}).
            e = d2 * bp - ap
            if e > 0.0:
                f = d2 * cp - ap * k_lo
                if f * e_hi < f_hi * e:
                    f_hi = f
                    e_hi = e
            elif e < 0.0:
                f = d2 * cp + ap * k_hi
                if f * e_hi < -f_hi * e:
                    f_hi = f
                    e_hi = -e
                x_lo = max(x_lo, (d2 * cp - ap * k_lo) / e)
        x_hi = f_hi / e_hi
        if k_hi < k_lo or not (x_hi >= 0.0):
            return i
        if x_hi < x_lo:
            # A set reduced to one point may come out inverted by rounding.
            if x_hi >= x_lo - 1e-12 * max(1.0, x_lo):
                x_hi = x_lo
            else:
                return i
        lo[i] = x_lo
        hi[i] = x_hi
    if lo[0] > 1e-12:  # the start at rest is not controllable
        return 0
    return -1


def _forward(delta: np.ndarray, xmax: np.ndarray, a: np.ndarray, b: np.ndarray,
             c: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             x: np.ndarray) -> None:
    """Greedy forward pass: the largest controllable ``x_{i+1}`` from ``x_i``."""
    n = xmax.size
    m = a.shape[1]
    x[0] = 0.0
    for i in range(n - 1):
        xi = x[i]
        d2 = 2.0 * delta[i]
        u = (hi[i + 1] - xi) / d2
        for p in range(m):
            ap = abs(a[i, p])
            if ap > 0.0:
                bp = b[i, p] if a[i, p] > 0.0 else -b[i, p]
                u = min(u, (c[i, p] - bp * xi) / ap)
        nxt = xi + d2 * u
        x[i + 1] = min(max(nxt, lo[i + 1]), hi[i + 1])
    x[n - 1] = 0.0


def _knots(t: np.ndarray, tp: np.ndarray, grid: np.ndarray, sd: np.ndarray, u: np.ndarray,
           S1: np.ndarray, S2: np.ndarray, tau_a: float, tau_b: float,  # noqa: N803
           breaks: np.ndarray, coef: np.ndarray, path_s: np.ndarray, path_sd: np.ndarray,
           path_sdd: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
    """The smoothed motion at the increasing times ``t`` [s]: the profile (times ``tp``,
    ``grid``, speeds ``sd``, accelerations ``u``, integrals ``S1``, ``S2``) averaged over
    ``tau_a`` then ``tau_b`` (:mod:`safepath.timing._smooth`), the path parameter, its
    speed and acceleration written to ``path_s``, ``path_sd``, ``path_sdd``, and the
    positions, velocities and accelerations along the spline (``breaks``; coefficients
    (pieces, 4, dof) of ``y + m x + c2 x^2 + c3 x^3``) to ``q``, ``qd``, ``qdd``: one pass
    for :func:`safepath.timing._smooth.evaluate` and the spline's jet at once."""
    n = t.size
    dof = q.shape[1]
    pieces = breaks.size - 1
    intervals = u.size
    length = grid[intervals]
    t_end = tp[intervals]
    end = t_end + tau_a + tau_b
    # The average is a second difference of the second integral: at t, t - tau_a,
    # t - tau_b and t - tau_a - tau_b, with these signs; each shift walks the profile's
    # intervals forward (the times increase).
    shift = np.array([0.0, tau_a, tau_b, tau_a + tau_b])
    sign = np.array([1.0, -1.0, -1.0, 1.0])
    at = np.zeros(4, dtype=np.int64)
    acc = np.zeros(3)
    for i in range(n):
        ti = t[i]
        acc[:] = 0.0
        for r in range(4):
            tau = ti - shift[r]
            if tau <= 0.0:
                continue
            if tau >= t_end:  # at rest at the end of the path
                d = tau - t_end
                acc[0] += sign[r] * (S2[intervals] + S1[intervals] * d + length * d * d / 2.0)
                acc[1] += sign[r] * (S1[intervals] + length * d)
                acc[2] += sign[r] * length
                continue
            k = at[r]
            while k + 1 < intervals and tp[k + 1] <= tau:
                k += 1
            at[r] = k
            d = tau - tp[k]
            d2 = d * d
            d3 = d2 * d
            sk, vk, uk, s1 = grid[k], sd[k], u[k], S1[k]
            acc[0] += sign[r] * (S2[k] + s1 * d + sk * d2 / 2.0 + vk * d3 / 6.0
                                 + uk * d3 * d / 24.0)
            acc[1] += sign[r] * (s1 + sk * d + vk * d2 / 2.0 + uk * d3 / 6.0)
            acc[2] += sign[r] * (sk + vk * d + uk * d2 / 2.0)
        w = tau_a * tau_b
        s = min(max(acc[0] / w, 0.0), length)
        v = max(acc[1] / w, 0.0)
        a = acc[2] / w
        if ti >= end:
            s, v, a = length, 0.0, 0.0
        if ti <= 0.0:
            s, v, a = 0.0, 0.0, 0.0
        path_s[i] = s
        path_sd[i] = v
        path_sdd[i] = a
        # The spline piece of s (bisection; the ends' pieces extend).
        lo, hi = 0, pieces
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if breaks[mid] <= s:
                lo = mid
            else:
                hi = mid
        x = s - breaks[lo]
        for j in range(dof):
            y, m, c2, c3 = coef[lo, 0, j], coef[lo, 1, j], coef[lo, 2, j], coef[lo, 3, j]
            q[i, j] = y + x * (m + x * (c2 + x * c3))
            d1 = m + x * (2.0 * c2 + 3.0 * x * c3)
            d2 = 2.0 * c2 + 6.0 * x * c3
            qd[i, j] = d1 * v
            qdd[i, j] = d2 * v * v + d1 * a


def _tridiagonal(dl: np.ndarray, d: np.ndarray, du: np.ndarray, b: np.ndarray) -> int:
    """Solve the tridiagonal system (sub-diagonal ``dl``, diagonal ``d``, super-diagonal
    ``du``, n >= 3) for the right-hand sides ``b`` (n, k) in place, as LAPACK's ``dgtsv``
    does it (Gaussian elimination with partial pivoting), operation for operation: the
    spline slopes' solve (:func:`safepath.timing._spline.solve_tridiagonal`). All four
    arrays are overwritten; ``b`` holds the solution.

    Returns:
        0, or 1 + the row of a zero pivot (a singular system; ``b`` is then garbage).
    """
    n, k = d.size, b.shape[1]
    for i in range(n - 1):
        if abs(d[i]) >= abs(dl[i]):
            if d[i] == 0.0:
                return i + 1
            fact = dl[i] / d[i]
            d[i + 1] = d[i + 1] - fact * du[i]
            for c in range(k):
                b[i + 1, c] = b[i + 1, c] - fact * b[i, c]
            if i < n - 2:
                dl[i] = 0.0
        else:  # interchange rows i and i + 1
            fact = d[i] / dl[i]
            d[i] = dl[i]
            temp = d[i + 1]
            d[i + 1] = du[i] - fact * temp
            if i < n - 2:
                dl[i] = du[i + 1]
                du[i + 1] = -fact * dl[i]
            du[i] = temp
            for c in range(k):
                row = b[i, c]
                b[i, c] = b[i + 1, c]
                b[i + 1, c] = row - fact * b[i + 1, c]
    if d[n - 1] == 0.0:
        return n
    for c in range(k):
        b[n - 1, c] = b[n - 1, c] / d[n - 1]
        b[n - 2, c] = (b[n - 2, c] - du[n - 2] * b[n - 1, c]) / d[n - 2]
    for i in range(n - 3, -1, -1):
        for c in range(k):
            b[i, c] = (b[i, c] - du[i] * b[i + 1, c] - dl[i] * b[i + 2, c]) / d[i]
    return 0


def compiled_kernels() -> dict[str, Callable[..., Any]]:
    """The compiled passes: ahead of time, else numba's (compiled, or loaded from numba's
    cache, once); see :mod:`safepath._aot`."""
    with _lock:
        if not _compiled:
            from .._aot import njit

            _compiled["backward"] = njit(cache=True, nogil=True)(_backward)
            _compiled["forward"] = njit(cache=True, nogil=True)(_forward)
            _compiled["tridiagonal"] = njit(cache=True, nogil=True)(_tridiagonal)
            _compiled["knots"] = njit(cache=True, nogil=True)(_knots)
        return _compiled
