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

The two passes are numba kernels (:mod:`._topp_kernels`), compiled ahead of time
(:mod:`safepath._aot`), or else with numba on first use (and cached on disk); numba is
imported then, not when this module is imported.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

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
    grid, dq, ddq, alim = (np.ascontiguousarray(x, dtype=np.float64)
                           for x in (grid, dq, ddq, alim))
    shape = (grid.size - 1, 2 * dq.shape[1])
    a, b, c = np.empty(shape), np.empty(shape), np.empty(shape)
    compiled_kernels()["acceleration_rows"](grid, dq, ddq, alim, a, b, c)
    return a, b, c


def solve(grid: np.ndarray, xmax: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray,
          factor: np.ndarray | None = None) -> np.ndarray | None:
    """The time-optimal rest-to-rest squared path speeds at the gridpoints.

    Args:
        grid: Gridpoints (N+1,), strictly increasing.
        xmax: Bound on ``x = sdot^2`` at each gridpoint (N+1,) (velocity limits).
        a, b, c: Rows ``|a u_i + b x_i| <= c`` of each interval (N, m), ``c > 0``
            (from :func:`acceleration_rows`: the limits at ``s_i``, then at ``s_{i+1}``).
        factor: Scale of the limits ``c`` at each gridpoint (N+1,) (1 by default).

    Returns:
        ``x`` at the gridpoints (N+1,), or None when no timing exists: the controllable
        sets are empty, the inputs are not finite, or the path would have to rest over
        a whole grid interval (which takes forever).

    Raises:
        ValueError: ``factor`` not one per gridpoint.
    """
    kernels = compiled_kernels()
    delta = np.ascontiguousarray(np.diff(grid), dtype=np.float64)
    if factor is None:
        factor = np.ones(grid.size)
    elif np.shape(factor) != np.shape(grid):
        raise ValueError(f"factor: one per gridpoint ({grid.size}), got {np.shape(factor)}")
    args = [np.ascontiguousarray(v, dtype=np.float64) for v in (xmax, a, b, c, factor)]
    # (The backward pass refuses a row or a factor that is not finite.)
    if not (np.isfinite(delta).all() and np.isfinite(args[0]).all()):
        return None
    lo = np.empty(grid.size)
    hi = np.empty(grid.size)
    # The velocity bound capped where no joint limits it (the backward pass's f/e bounds
    # stay finite).
    capped = np.minimum(args[0], X_CAP)
    if kernels["backward"](delta, capped, *args[1:], lo, hi) >= 0:
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

    The last time is taken as the end of the path (at rest), exactly. Compiled
    (``_topp_kernels.evaluate``).
    """
    t = np.ascontiguousarray(t, dtype=np.float64)
    s, sd, u = np.empty(t.size), np.empty(t.size), np.empty(t.size)
    compiled_kernels()["evaluate"](*(np.ascontiguousarray(x, dtype=np.float64) for x in (
        profile.t, profile.grid, profile.sd, profile.u)), t, s, sd, u)
    return s, sd, u


def compiled_kernels() -> dict[str, Callable[..., Any]]:
    """The compiled kernels of :mod:`._topp_kernels` by name: ahead of time, else numba's
    (compiled, or loaded from numba's cache, once); see :mod:`safepath._aot`."""
    with _lock:
        if not _compiled:
            from . import _topp_kernels as kernels

            _compiled.update(backward=kernels.backward, forward=kernels.forward,
                             tridiagonal=kernels.tridiagonal, knots=kernels.knots,
                             jerk_rows=kernels.jerk_rows, jerk_shift=kernels.jerk_shift,
                             tighten=kernels.tighten, jet=kernels.jet,
                             evaluate=kernels.evaluate, grid_peaks=kernels.grid_peaks,
                             acceleration_rows=kernels.acceleration_rows,
                             fill_grid=kernels.fill_grid)
        return _compiled
