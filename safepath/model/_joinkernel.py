"""The peaks of a quintic join, per interval and joint, and its samples, numba-compiled.

The kernel of :func:`safepath.model.execution.interval_ratios` (see there for what is bounded
and how): the same sums as the numpy version it replaced, one interval and joint at a
time, without the temporary arrays. Compiled ahead of time (:mod:`safepath._aot`), else
by numba on first use. Also the compiled knot lookup, :func:`piece_of`, which the timing's
kernels inline too. Imported lazily (it imports numba where no build of the kernels is
current).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from .._aot import njit
from ._sampling import SAMPLE_SLACK

__all__ = ["compiled_kernels", "peaks", "piece_of", "ratios", "sample"]

_lock = threading.Lock()
_compiled: dict[str, Callable[..., Any]] = {}


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def piece_of(breaks, x):
    """The piece of increasing ``breaks`` (at least two) that holds ``x``, by bisection:
    the last ``lo < breaks.size - 1`` with ``breaks[lo] <= x``, 0 before the first break
    (the end pieces extend); :func:`safepath.model._knots.interval_index` for one value,
    compiled."""
    lo, hi = 0, breaks.size - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if breaks[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _coefficients(q, qd, qdd, k, d, h, i3, i4, i5):
    """``c1 .. c5`` of the quintic ``q[k] + c1 t + ... + c5 t^5`` matching position,
    velocity and acceleration of points ``k`` and ``k + 1`` of joint ``d`` (``h`` the
    interval's length, ``i3``, ``i4``, ``i5`` its inverse third, fourth and fifth
    powers: :func:`_inverse_powers`)."""
    return _quintic(q[k, d], q[k + 1, d], qd[k, d], qd[k + 1, d], qdd[k, d], qdd[k + 1, d],
                    h, i3, i4, i5)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _quintic(p0, p1, v0, v1, acc0, acc1, h, i3, i4, i5):
    """``c1 .. c5`` of the quintic ``p0 + c1 t + ... + c5 t^5`` from position, velocity
    and acceleration ``p0, v0, acc0`` at 0 and ``p1, v1, acc1`` at ``h`` (``i3``, ``i4``,
    ``i5``: the inverse third, fourth and fifth powers of ``h``)."""
    dp = p1 - p0 - v0 * h - acc0 * h * h / 2.0
    dv = v1 - v0 - acc0 * h
    da = acc1 - acc0
    c3 = (10.0 * dp - 4.0 * dv * h + da * h * h / 2.0) * i3
    c4 = (-15.0 * dp + 7.0 * dv * h - da * h * h) * i4
    c5 = (6.0 * dp - 3.0 * dv * h + da * h * h / 2.0) * i5
    return v0, acc0 / 2.0, c3, c4, c5


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _interval_peaks(q, qd, qdd, k, d, m, h, i3, i4, i5):
    """The quintic join's speed bound, peak |a| and peak |j| on interval ``k`` of joint
    ``d`` (see :func:`_peaks`), its speed sampled at ``m`` points where it may peak
    inside; ``h`` is the interval's length, ``i3``, ``i4``, ``i5`` its inverse third,
    fourth and fifth powers (the same for every joint: :func:`_inverse_powers`)."""
    c1, c2, c3, c4, c5 = _coefficients(q, qd, qdd, k, d, h, i3, i4, i5)
    v1, a0, a1, j0, j1 = _ends(c1, c2, c3, c4, c5, h)
    jp = _jerk_peak(c3, c4, c5, h, j0, j1)
    a_lo, a_hi = _acceleration_range(c2, c3, c4, c5, h, a0, a1)
    return _speed_bound(c1, c2, c3, c4, c5, h, m, a_lo, a_hi, jp, v1), \
        max(abs(a_lo), abs(a_hi)), jp


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _ends(c1, c2, c3, c4, c5, h):
    """The quintic's speed at ``h`` and its acceleration and jerk at 0 and ``h``:
    ``v1, a0, a1, j0, j1`` (its speed at 0 is ``c1``)."""
    return (c1 + h * (2.0 * c2 + h * (3.0 * c3 + h * (4.0 * c4 + 5.0 * c5 * h))),
            2.0 * c2, 2.0 * c2 + h * (6.0 * c3 + h * (12.0 * c4 + 20.0 * c5 * h)),
            6.0 * c3, 6.0 * c3 + h * (24.0 * c4 + 60.0 * c5 * h))


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _jerk_peak(c3, c4, c5, h, j0, j1):
    """The quintic's peak |j| on ``[0, h]``: jerk ``6 c3 + 24 c4 t + 60 c5 t^2``, at the
    ends (``j0``, ``j1``: :func:`_ends`) and the vertex."""
    jp = max(abs(j0), abs(j1))
    if c5 != 0.0:
        tv = -24.0 * c4 / (120.0 * c5)
        if 0.0 < tv < h:
            jp = max(jp, abs(6.0 * c3 + tv * (24.0 * c4 + 60.0 * c5 * tv)))
    return jp


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _acceleration_range(c2, c3, c4, c5, h, a0, a1):
    """The quintic's least and largest acceleration on ``[0, h]``:
    ``2 c2 + 6 c3 t + 12 c4 t^2 + 20 c5 t^3`` at the ends (``a0``, ``a1``: :func:`_ends`)
    and where the jerk vanishes."""
    a_lo = min(a0, a1)
    a_hi = max(a0, a1)
    qa, qb, qc = 60.0 * c5, 24.0 * c4, 6.0 * c3
    for r_i in range(2):
        r = -1.0
        if qa != 0.0:
            disc = qb * qb - 4.0 * qa * qc
            if disc >= 0.0:
                sq = math.sqrt(disc)
                r = (-qb + sq) / (2.0 * qa) if r_i == 0 else (-qb - sq) / (2.0 * qa)
        elif r_i == 0 and qb != 0.0:
            r = -qc / qb
        if 0.0 < r < h:
            a = 2.0 * c2 + r * (6.0 * c3 + r * (12.0 * c4 + 20.0 * c5 * r))
            a_lo = min(a_lo, a)
            a_hi = max(a_hi, a)
    return a_lo, a_hi


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _speed_bound(c1, c2, c3, c4, c5, h, m, a_lo, a_hi, jp, v1):
    """A bound of the quintic's |v| on ``[0, h]`` (speed ``c1 + 2 c2 t + 3 c3 t^2 +
    4 c4 t^3 + 5 c5 t^4``, ``v1`` at ``h``; its acceleration between ``a_lo`` and
    ``a_hi``, its peak |j| ``jp``): the larger end where the acceleration keeps its sign,
    else ``m`` samples plus ``jp dt^2 / 8``."""
    vp = max(abs(c1), abs(v1))
    if a_lo < 0.0 < a_hi:  # the speed may peak inside
        dt = h / (m - 1)
        sampled = vp
        for i in range(1, m - 1):
            x = i * dt
            v = c1 + x * (2.0 * c2 + x * (3.0 * c3 + x * (4.0 * c4 + 5.0 * c5 * x)))
            sampled = max(sampled, abs(v))
        vp = max(vp, sampled + jp * dt * dt / 8.0)
    return vp


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _inverse_powers(h):
    """``1 / h^3``, ``1 / h^4``, ``1 / h^5``: one division per interval, not three per
    joint."""
    i1 = 1.0 / h
    i3 = i1 * i1 * i1
    return i3, i3 * i1, i3 * i1 * i1


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _speed_samples(h, rate):
    """How many points the speed of an interval ``h`` [s] long is sampled at where it
    may peak inside: at least ``rate`` per second (to :data:`SAMPLE_SLACK` of a
    spacing), and 4."""
    return max(4, int(math.ceil(h * rate - SAMPLE_SLACK)) + 1)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _larger(best, x):
    """The larger of ``best`` and ``x``, NaN once either is NaN (as numpy's max)."""
    return x if (x > best or x != x) else best


def _peaks(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, rate: float,
           v_out: np.ndarray, a_out: np.ndarray, j_out: np.ndarray) -> None:
    """For the quintic join of points ``(t, q, qd, qdd)``, per interval and joint: a bound
    of |v| (exact at the ends and where the acceleration keeps its sign, sampled at
    ``rate`` elsewhere plus ``|j| dt^2 / 8``), and the exact max |a| and |j|, into the
    outputs (intervals, dof)."""
    n, dof = t.size - 1, q.shape[1]
    for k in range(n):
        h = t[k + 1] - t[k]
        m = _speed_samples(h, rate)
        i3, i4, i5 = _inverse_powers(h)
        for d in range(dof):
            v_out[k, d], a_out[k, d], j_out[k, d] = _interval_peaks(q, qd, qdd, k, d, m, h,
                                                                    i3, i4, i5)


#: Relative margin by which a screening bound (:func:`_screened_peaks`) must fall below its
#: threshold before it stands in for the peak (its rounding differs from the peak's).
_SCREEN_MARGIN = 1.0 + 1e-9


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _cheap_bounds(c1, v1, a0, a1, j0, j1, jp, h, dt):
    """Bounds of the quintic's |v| and |a| on ``[0, h]`` (see :func:`_screened_peaks`):
    the largest Bernstein coefficients of its speed plus ``jp dt^2 / 8`` (``dt`` the
    speed's sample spacing, :func:`_speed_bound`), and of its acceleration, from its ends
    (:func:`_ends`) and peak |j| ``jp``."""
    ap = max(max(abs(a0), abs(a1)), max(abs(a0 + j0 * h / 3.0), abs(a1 - j1 * h / 3.0)))
    vp = max(max(abs(c1), abs(v1)), max(abs(c1 + a0 * h / 4.0), abs(v1 - a1 * h / 4.0)),
             abs(c1 + a0 * h / 2.0 + j0 * h * h / 12.0)) + jp * dt * dt / 8.0
    return vp, ap


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _screened_peaks(c1, c2, c3, c4, c5, h, m, v_below, a_below):
    """The quintic's speed bound, peak |a| and peak |j| on ``[0, h]`` as
    :func:`_interval_peaks` gives them, except that a speed or acceleration whose cheap
    bound lies below ``v_below`` or ``a_below`` is that bound instead (it is at least the
    true peak).

    The cheap bounds are the largest Bernstein coefficients of the speed (a quartic) and
    the acceleration (a cubic) on the interval: a polynomial on an interval lies within
    its Bernstein coefficients. The speed's adds ``|j| dt^2 / 8``, so that it is at least
    the sampled bound of :func:`_speed_bound` too."""
    v1, a0, a1, j0, j1 = _ends(c1, c2, c3, c4, c5, h)
    jp = _jerk_peak(c3, c4, c5, h, j0, j1)
    vp, ap = _cheap_bounds(c1, v1, a0, a1, j0, j1, jp, h, h / (m - 1))
    a_exact = not ap * _SCREEN_MARGIN < a_below
    v_exact = not vp * _SCREEN_MARGIN < v_below
    if a_exact or v_exact:
        a_lo, a_hi = _acceleration_range(c2, c3, c4, c5, h, a0, a1)
        if a_exact:
            ap = max(abs(a_lo), abs(a_hi))
        if v_exact:
            vp = _speed_bound(c1, c2, c3, c4, c5, h, m, a_lo, a_hi, jp, v1)
    return vp, ap, jp


def _ratios(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, rate: float,
            at: np.ndarray, row: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
            jmax: np.ndarray, exact_from: float, v_out: np.ndarray, a_out: np.ndarray,
            j_out: np.ndarray) -> None:
    """Per interval ``at[i]``, the largest ratio over the joints of the quintic join's speed
    bound, peak |a| and peak |j| (:func:`_peaks`) to the limits of row ``row[at[i]]`` of
    ``vmax``, ``amax``, ``jmax`` (rows, dof), into the outputs (len(at),); NaN where an
    input of the interval is not finite. A speed or acceleration ratio whose cheap bound
    lies below ``exact_from`` is that bound (:func:`_screened_peaks`): every ratio of
    ``exact_from`` or more is the peaks' own."""
    dof = q.shape[1]
    for i in range(at.size):
        k = at[i]
        h = t[k + 1] - t[k]
        m = _speed_samples(h, rate)
        i3, i4, i5 = _inverse_powers(h)
        r = row[k]
        rv = ra = rj = -np.inf
        inputs = h  # finite iff every input of the interval is
        for d in range(dof):
            inputs += q[k, d] + q[k + 1, d] + qd[k, d] + qd[k + 1, d] + qdd[k, d] + qdd[k + 1, d]
            c1, c2, c3, c4, c5 = _coefficients(q, qd, qdd, k, d, h, i3, i4, i5)
            vp, ap, jp = _screened_peaks(c1, c2, c3, c4, c5, h, m, exact_from * vmax[r, d],
                                         exact_from * amax[r, d])
            rv = _larger(rv, vp / vmax[r, d])
            ra = _larger(ra, ap / amax[r, d])
            rj = _larger(rj, jp / jmax[r, d])
        if inputs - inputs != 0.0:  # a NaN or an infinity among them
            rv = ra = rj = np.nan
        v_out[i], a_out[i], j_out[i] = rv, ra, rj


#: Intervals the screening pass (:func:`_screen`) takes at a time: their points, limits,
#: lengths and ratios fit its scratch (:data:`_SCRATCH` rows of ``(dof, _BLOCK + 1)``,
#: about 110 kB for seven joints).
_BLOCK = 128
_SCRATCH = 15


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _screen_joint(n, q, qd, qdd, vl, al, hs, i3s, i4s, i5s, dts, exact_from, rv, ra, rj, jl,
                  flag):
    """The cheap bounds' speed and acceleration ratios and the jerk ratio of ``n``
    intervals of one joint, from its points ``q, qd, qdd``, the intervals' limits and their
    lengths ``hs``, inverse powers ``i3s, i4s, i5s`` and speed sample spacings ``dts``
    (:func:`_interval_terms`), into ``rv, ra, rj``; ``flag`` 1.0 where a bound may not
    stand in for the peak (:func:`_screened_peaks`), else 0.0. One straight loop that the
    compiler vectorises: numpy's divisions (``np.true_divide``, no zero test)."""
    for k in range(n):
        h, i3, i4, i5 = hs[k], i3s[k], i4s[k], i5s[k]
        c1, c2, c3, c4, c5 = _quintic(q[k], q[k + 1], qd[k], qd[k + 1], qdd[k], qdd[k + 1],
                                      h, i3, i4, i5)
        v1, a0, a1, j0, j1 = _ends(c1, c2, c3, c4, c5, h)
        # _jerk_peak's vertex, chosen without a branch.
        jp = max(abs(j0), abs(j1))
        tv = np.true_divide(-24.0 * c4, 120.0 * c5)
        jv = abs(6.0 * c3 + tv * (24.0 * c4 + 60.0 * c5 * tv))
        if c5 != 0.0 and 0.0 < tv and tv < h and jv > jp:
            jp = jv
        vp, ap = _cheap_bounds(c1, v1, a0, a1, j0, j1, jp, h, dts[k])
        screened = vp * _SCREEN_MARGIN < exact_from * vl[k] and \
            ap * _SCREEN_MARGIN < exact_from * al[k]
        flag[k] = 0.0 if screened else 1.0
        rv[k] = np.true_divide(vp, vl[k])
        ra[k] = np.true_divide(ap, al[k])
        rj[k] = np.true_divide(jp, jl[k])


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _interval_terms(t, k0, n, rate, scratch):
    """Of intervals ``k0 .. k0 + n``, what every joint's bounds use (:func:`_screen_joint`),
    into ``scratch`` rows 10-14 (of joint 0): the lengths ``h``, ``1 / h^3``, ``1 / h^4``,
    ``1 / h^5`` and the spacing of ``m`` speed samples (:func:`_interval_peaks`), once per
    interval rather than per joint."""
    for k in range(n):
        h = t[k0 + k + 1] - t[k0 + k]
        m = _speed_samples(h, rate)
        i1 = np.true_divide(1.0, h)
        i3 = i1 * i1 * i1
        scratch[10, 0, k] = h
        scratch[11, 0, k] = i3
        scratch[12, 0, k] = i3 * i1
        scratch[13, 0, k] = i3 * i1 * i1
        scratch[14, 0, k] = np.true_divide(h, float(m - 1))


def _screen(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, rate: float,
            row: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray,
            exact_from: float, v_out: np.ndarray, a_out: np.ndarray, j_out: np.ndarray,
            scratch: np.ndarray) -> None:
    """:func:`_ratios` of every interval, bit for bit, faster: :data:`_BLOCK` intervals at
    a time, their points and limits transposed into ``scratch`` (:data:`_SCRATCH`, dof,
    ``_BLOCK + 1``) beside their lengths' terms (:func:`_interval_terms`), each joint's
    bounds along the intervals in one vectorised loop
    (:func:`_screen_joint`), then, where a bound may not stand in, the peaks of
    :func:`_ratios` (:func:`_screened_peaks`), and the largest ratio over the joints."""
    n_all, dof = t.size - 1, q.shape[1]
    for k0 in range(0, n_all, _BLOCK):
        n = min(_BLOCK, n_all - k0)
        _interval_terms(t, k0, n, rate, scratch)
        for d in range(dof):
            for k in range(n + 1):
                scratch[0, d, k] = q[k0 + k, d]
                scratch[1, d, k] = qd[k0 + k, d]
                scratch[2, d, k] = qdd[k0 + k, d]
            for k in range(n):
                r = row[k0 + k]
                scratch[3, d, k] = vmax[r, d]
                scratch[4, d, k] = amax[r, d]
                scratch[5, d, k] = jmax[r, d]
            _screen_joint(n, scratch[0, d], scratch[1, d], scratch[2, d], scratch[3, d],
                          scratch[4, d], scratch[10, 0], scratch[11, 0], scratch[12, 0],
                          scratch[13, 0], scratch[14, 0], exact_from, scratch[6, d],
                          scratch[7, d], scratch[8, d], scratch[5, d], scratch[9, d])
        for d in range(dof):  # the exact peaks where a bound may not stand in
            for k in range(n):
                if scratch[9, d, k] != 0.0:
                    kk, r = k0 + k, row[k0 + k]
                    h = t[kk + 1] - t[kk]
                    m = _speed_samples(h, rate)
                    i3, i4, i5 = _inverse_powers(h)
                    c1, c2, c3, c4, c5 = _coefficients(q, qd, qdd, kk, d, h, i3, i4, i5)
                    vp, ap, jp = _screened_peaks(c1, c2, c3, c4, c5, h, m,
                                                 exact_from * vmax[r, d],
                                                 exact_from * amax[r, d])
                    scratch[6, d, k] = vp / vmax[r, d]
                    scratch[7, d, k] = ap / amax[r, d]
                    scratch[8, d, k] = jp / jmax[r, d]
        _block_ratios(t, k0, n, dof, scratch, v_out, a_out, j_out)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _block_ratios(t, k0, n, dof, scratch, v_out, a_out, j_out):
    """The largest ratio over the joints of the block's intervals (``scratch`` rows 6-8,
    :func:`_screen`) into the outputs from ``k0``, NaN where an input is not finite: the
    sums and comparisons of :func:`_ratios`, along the intervals."""
    for k in range(n):
        v_out[k0 + k] = a_out[k0 + k] = j_out[k0 + k] = -np.inf
        scratch[9, 0, k] = t[k0 + k + 1] - t[k0 + k]  # the inputs' sum, from h
    for d in range(dof):
        p, v, a = scratch[0, d], scratch[1, d], scratch[2, d]
        rv, ra, rj, inputs = scratch[6, d], scratch[7, d], scratch[8, d], scratch[9, 0]
        for k in range(n):
            inputs[k] += p[k] + p[k + 1] + v[k] + v[k + 1] + a[k] + a[k + 1]
            v_out[k0 + k] = _larger(v_out[k0 + k], rv[k])
            a_out[k0 + k] = _larger(a_out[k0 + k], ra[k])
            j_out[k0 + k] = _larger(j_out[k0 + k], rj[k])
    for k in range(n):
        x = scratch[9, 0, k]
        if x - x != 0.0:  # a NaN or an infinity among them
            v_out[k0 + k] = a_out[k0 + k] = j_out[k0 + k] = np.nan


def _sample(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
            times: np.ndarray, p_out: np.ndarray, v_out: np.ndarray, a_out: np.ndarray
            ) -> None:
    """Position, velocity and acceleration of the quintic join of points ``(t, q, qd,
    qdd)`` (at least two) at ``times``, clamped to the ends (the end points themselves
    there), into the outputs (len(times), dof)."""
    n, dof = t.size, q.shape[1]
    for i in range(times.size):
        x = times[i]
        if x <= t[0] or x >= t[n - 1]:
            e = 0 if x <= t[0] else n - 1
            for d in range(dof):
                p_out[i, d], v_out[i, d], a_out[i, d] = q[e, d], qd[e, d], qdd[e, d]
            continue
        lo = piece_of(t, x)  # t[lo] <= x < t[lo + 1]
        h, s = t[lo + 1] - t[lo], x - t[lo]
        for d in range(dof):
            v0, acc0 = qd[lo, d], qdd[lo, d]
            dp = q[lo + 1, d] - q[lo, d] - v0 * h - acc0 * h * h / 2.0
            dv = qd[lo + 1, d] - v0 - acc0 * h
            da = qdd[lo + 1, d] - acc0
            c3 = (10.0 * dp - 4.0 * dv * h + da * h * h / 2.0) / h ** 3
            c4 = (-15.0 * dp + 7.0 * dv * h - da * h * h) / h ** 4
            c5 = (6.0 * dp - 3.0 * dv * h + da * h * h / 2.0) / h ** 5
            p_out[i, d] = q[lo, d] + s * (v0 + s * (acc0 / 2.0 + s * (c3 + s * (c4 + c5 * s))))
            v_out[i, d] = v0 + s * (acc0 + s * (3.0 * c3 + s * (4.0 * c4 + 5.0 * c5 * s)))
            a_out[i, d] = acc0 + s * (6.0 * c3 + s * (12.0 * c4 + 20.0 * c5 * s))


def sample(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
           times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of the quintic join of the points at ``times``
    (clamped to the ends), each (len(times), dof); what
    :func:`safepath.model.execution.join` gives, compiled (equal to rounding)."""
    t, q, qd, qdd = (np.ascontiguousarray(x, dtype=np.float64) for x in (t, q, qd, qdd))
    times = np.ascontiguousarray(np.atleast_1d(times), dtype=np.float64)
    shape = (times.size, q.shape[1])
    if t.size == 1:
        return (np.repeat(q, times.size, 0), np.repeat(qd, times.size, 0),
                np.repeat(qdd, times.size, 0))
    p, v, a = np.empty(shape), np.empty(shape), np.empty(shape)
    compiled_kernels()["sample"](t, q, qd, qdd, times, p, v, a)
    return p, v, a


def peaks(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, rate: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed bound, acceleration and jerk peaks of the quintic join of the points, per
    interval and joint (see :func:`_peaks`)."""
    kernel = compiled_kernels()["peaks"]
    t, q, qd, qdd = (np.ascontiguousarray(x, dtype=np.float64) for x in (t, q, qd, qdd))
    shape = (t.size - 1, q.shape[1])
    v, a, j = np.empty(shape), np.empty(shape), np.empty(shape)
    kernel(t, q, qd, qdd, float(rate), v, a, j)
    return v, a, j


def ratios(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, rate: float,
           row: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray,
           exact_from: float = 0.0, at: np.ndarray | None = None) -> np.ndarray:
    """Per interval (those listed in ``at``, else all), the largest speed, acceleration and
    jerk ratio of the quintic join of the points to the limits of row ``row[k]`` of
    ``vmax``, ``amax``, ``jmax`` (rows of one array, (3, intervals)); speed and
    acceleration ratios below ``exact_from`` may be bounds of them (see :func:`_ratios`);
    ``at`` is not checked (see :meth:`safepath.model.interpolation.Interpolation.ratios`).
    Every interval with an ``exact_from`` over 0: the vectorised pass (:func:`_screen`),
    the same ratios bit for bit."""
    t, q, qd, qdd, vmax, amax, jmax = (np.ascontiguousarray(x, dtype=np.float64)
                                       for x in (t, q, qd, qdd, vmax, amax, jmax))
    row = np.ascontiguousarray(row, dtype=np.int64)
    if at is None and exact_from > 0.0:
        out = np.empty((3, max(t.size - 1, 0)))
        if t.size > 1:
            compiled_kernels()["screen"](t, q, qd, qdd, float(rate), row, vmax, amax, jmax,
                                         float(exact_from), out[0], out[1], out[2],
                                         np.empty((_SCRATCH, q.shape[1], _BLOCK + 1)))
        return out
    at = np.arange(t.size - 1, dtype=np.int64) if at is None else \
        np.ascontiguousarray(at, dtype=np.int64)
    out = np.empty((3, at.size))
    compiled_kernels()["ratios"](t, q, qd, qdd, float(rate), at, row, vmax, amax, jmax,
                                 float(exact_from), out[0], out[1], out[2])
    return out


def compiled_kernels() -> dict[str, Callable[..., Any]]:
    """The compiled kernel: ahead of time, else numba's (compiled, or loaded from numba's
    cache, once); see :mod:`safepath._aot`."""
    with _lock:
        if not _compiled:
            from .._aot import njit

            _compiled["peaks"] = njit(cache=True, nogil=True)(_peaks)
            _compiled["sample"] = njit(cache=True, nogil=True)(_sample)
            _compiled["ratios"] = njit(cache=True, nogil=True)(_ratios)
            _compiled["screen"] = njit(cache=True, nogil=True)(_screen)
        return _compiled
