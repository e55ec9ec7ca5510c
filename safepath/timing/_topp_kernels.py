"""The numba kernels of TOPP-RA (:mod:`safepath.timing._topp`): the backward and forward
passes, the spline slopes' tridiagonal solve, the smoothed knots and the jerk
smoothing's window.

Compiled ahead of time (:mod:`safepath._aot`), else by numba when this module is first
imported; :func:`safepath.timing._topp.compiled_kernels` imports it on the first timing,
so that importing :mod:`safepath.timing` imports no numba. The backward pass's steps are
helpers inlined into it (``inline="always"``): the same operations, bit for bit.
"""

from __future__ import annotations

import numpy as np

from .._aot import njit
from ..model._joinkernel import _larger, piece_of

__all__ = ["backward", "fill_grid", "forward", "jerk_rows", "jerk_shift", "knots",
           "tridiagonal"]

_inlined = njit(cache=True, nogil=True, inline="always")


@njit(cache=True, nogil=True)
def backward(delta, xmax, a, b, c, f, lo, hi):
    """Controllable sets ``[lo_i, hi_i]``; returns -1, or the first stage found empty.

    The rows' limits ``c`` hold scaled by ``f`` (per gridpoint): on interval ``i`` the
    first half of its rows (the limits at ``s_i``) by ``f[i]``, the second by ``f[i+1]``.

    Each row ``|a u + b x| <= c`` is an upper and a lower bound on ``u``; so is the next
    set, ``lo_{i+1} <= x + 2 delta u <= hi_{i+1}``. Every pair of an upper and a lower bound
    gives ``e x <= f``. For two rows (``a, c >= 0`` once a row's sign is flipped so that
    ``a >= 0``) the pair taken either way gives ``|e| x <= f`` and ``-|e| x <= f`` with
    ``f >= 0``: only the upper bound on ``x`` counts. Bounds are kept as fractions and
    compared cross-multiplied; one division per stage. ``xmax`` is the velocity bound on
    ``x``, already capped (:data:`safepath.timing._topp.X_CAP`).
    """
    n = xmax.size
    an = np.empty(a.shape[1])
    bn = np.empty(a.shape[1])
    cn = np.empty(a.shape[1])
    lo[n - 1] = 0.0
    hi[n - 1] = 0.0
    for i in range(n - 2, -1, -1):
        if not (xmax[i] >= 0.0) or not _rows_with_a_up(a, b, c, f, i, an, bn, cn):  # NaN
            return i
        k_lo = lo[i + 1]
        k_hi = hi[i + 1]
        x_lo, x_hi = _stage_set(2.0 * delta[i], xmax[i], an, bn, cn, k_lo, k_hi)
        if k_hi < k_lo or not (x_hi >= 0.0):
            return i
        x_hi = _rounded_point(x_lo, x_hi)
        if x_hi < x_lo:
            return i
        lo[i] = x_lo
        hi[i] = x_hi
    if lo[0] > 1e-12:  # the start at rest is not controllable
        return 0
    return -1


@_inlined
def _rows_with_a_up(a, b, c, f, i, an, bn, cn):
    """Stage ``i``'s rows with their sign flipped so that ``a >= 0`` into ``an``, ``bn``,
    and their limits scaled (:func:`_limit`) into ``cn``; False when a row's limit is
    negative (no ``u`` meets it) or a row is not finite."""
    for p in range(a.shape[1]):
        if a[i, p] >= 0.0:
            an[p] = a[i, p]
            bn[p] = b[i, p]
        else:
            an[p] = -a[i, p]
            bn[p] = -b[i, p]
        cn[p] = _limit(c, f, i, p)
        if not (cn[p] >= 0.0) or an[p] + bn[p] + cn[p] - (an[p] + bn[p] + cn[p]) != 0.0:
            return False
    return True


@_inlined
def _limit(c, f, i, p):
    """Row ``p``'s limit on interval ``i``, scaled by the factor of the gridpoint it holds
    at: ``s_i`` for the first half of the rows, ``s_{i+1}`` for the second."""
    return c[i, p] * f[i] if p < c.shape[1] // 2 else c[i, p] * f[i + 1]


@_inlined
def _stage_set(d2, x_cap, an, bn, cn, k_lo, k_hi):
    """Bounds ``(x_lo, x_hi)`` of the controllable set of a stage (``d2`` twice its
    interval, ``x_cap`` its velocity bound, its rows ``an, bn, cn``, ``[k_lo, k_hi]`` the
    next stage's set): every pair of rows, and every row with the next set."""
    f_hi = x_cap  # x <= f_hi / e_hi
    e_hi = 1.0
    x_lo = 0.0
    for p in range(an.size):
        f_hi, e_hi = _row_pairs(an, bn, cn, p, f_hi, e_hi)
        f_hi, e_hi, x_lo = _row_with_next(d2, an[p], bn[p], cn[p], k_lo, k_hi, f_hi, e_hi,
                                          x_lo)
    return x_lo, f_hi / e_hi


@_inlined
def _row_pairs(an, bn, cn, p, f_hi, e_hi):
    """The tightest upper bound ``f_hi / e_hi`` on ``x`` after pairing row ``p`` with each
    later row."""
    ap = an[p]
    bp = bn[p]
    cp = cn[p]
    for q in range(p + 1, an.size):
        e = abs(an[q] * bp - ap * bn[q])
        f = ap * cn[q] + an[q] * cp
        if e > 0.0 and f * e_hi < f_hi * e:
            f_hi = f
            e_hi = e
    return f_hi, e_hi


@_inlined
def _row_with_next(d2, ap, bp, cp, k_lo, k_hi, f_hi, e_hi, x_lo):
    """Row ``(ap, bp, cp)`` with the next set ``[k_lo, k_hi]``: ``e > 0`` bounds ``x``
    above (through ``k_lo``), ``e < 0`` above (through ``k_hi``) and below (through
    ``k_lo``); returns the bounds ``(f_hi, e_hi, x_lo)`` tightened."""
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
    return f_hi, e_hi, x_lo


@_inlined
def _rounded_point(x_lo, x_hi):
    """``x_hi``, or ``x_lo`` when the set is one point that rounding left inverted
    (``x_hi`` below ``x_lo`` by at most 1e-12 relative)."""
    if x_hi < x_lo and x_hi >= x_lo - 1e-12 * max(1.0, x_lo):
        return x_lo
    return x_hi


@njit(cache=True, nogil=True)
def forward(delta, xmax, a, b, c, f, lo, hi, x):
    """Greedy forward pass: the largest controllable ``x_{i+1}`` from ``x_i`` (the rows'
    limits scaled by ``f`` as in :func:`backward`)."""
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
                u = min(u, (_limit(c, f, i, p) - bp * xi) / ap)
        nxt = xi + d2 * u
        x[i + 1] = min(max(nxt, lo[i + 1]), hi[i + 1])
    x[n - 1] = 0.0


@njit(cache=True, nogil=True)
def knots(t, tp, grid, sd, u, S1, S2, tau_a, tau_b, breaks, coef, path_s, path_sd,  # noqa: N803
          path_sdd, q, qd, qdd):
    """The smoothed motion at the increasing times ``t`` [s]: the profile (times ``tp``,
    ``grid``, speeds ``sd``, accelerations ``u``, integrals ``S1``, ``S2``) averaged over
    ``tau_a`` then ``tau_b`` (:mod:`safepath.timing._smooth`), the path parameter, its
    speed and acceleration written to ``path_s``, ``path_sd``, ``path_sdd``, and the
    positions, velocities and accelerations along the spline (``breaks``; coefficients
    (pieces, 4, dof) of ``y + m x + c2 x^2 + c3 x^3``) to ``q``, ``qd``, ``qdd``: one pass
    for :func:`safepath.timing._smooth.evaluate` and the spline's jet at once."""
    n = t.size
    dof = q.shape[1]
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
        lo = piece_of(breaks, s)
        x = s - breaks[lo]
        for j in range(dof):
            q[i, j], d1, d2 = _cubic(coef, lo, j, x)
            qd[i, j] = d1 * v
            qdd[i, j] = d2 * v * v + d1 * a


@njit(cache=True, nogil=True)
def tridiagonal(dl, d, du, b):
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


@_inlined
def _shift_fits(f, m, dt):
    """Whether no row of ``f`` (dof, n) changes by more than ``m dt`` over ``m`` columns:
    the largest change of each block of :data:`_SHIFT_BLOCK` columns (a loop the compiler
    vectorises), then the next block only while none is over."""
    dof, n = f.shape
    if m >= n:
        return True
    bound = m * dt
    for j in range(dof):
        row = f[j]
        for b in range(0, n - m, _SHIFT_BLOCK):
            worst = 0.0
            for i in range(b, min(b + _SHIFT_BLOCK, n - m)):
                worst = max(worst, abs(row[i + m] - row[i]))
            if worst > bound:
                return False
    return True


#: Columns :func:`_shift_fits` compares at a time before it may stop.
_SHIFT_BLOCK = 64


@_inlined
def _piece_after(breaks, x, i, k):
    """:func:`~safepath.model._joinkernel.piece_of` of ``x[i]``, walking on from piece
    ``k`` (that of ``x[i - 1]``) when ``x`` has not decreased since, else by bisection:
    the same piece, in a few steps along increasing values."""
    if i == 0 or not x[i] >= x[i - 1]:
        return piece_of(breaks, x[i])
    return _piece_at(breaks, x[i], k)


@njit(cache=True, nogil=True)
def evaluate(tp, grid, sdp, up, t, s, sd, u):
    """Path parameter, speed and acceleration of the profile (times ``tp``, gridpoints
    ``grid``, speeds ``sdp``, accelerations ``up``) at the times ``t``, into ``s``, ``sd``,
    ``u``: :func:`safepath.timing._topp.evaluate`, the same sums in the same order (and
    numpy's ``maximum``/``minimum``: the first argument when they are equal)."""
    last = up.size - 1
    k = 0
    for i in range(t.size):
        k = min(_piece_after(tp, t, i, k), last)
        dt = t[i] - tp[k]
        s_i = grid[k] + dt * sdp[k] + 0.5 * dt * dt * up[k]
        sd_i = sdp[k] + dt * up[k]
        s_i = s_i if (s_i >= grid[0] or s_i != s_i) else grid[0]
        s[i] = s_i if (s_i <= grid[-1] or s_i != s_i) else grid[-1]
        sd[i] = sd_i if (sd_i >= 0.0 or sd_i != sd_i) else 0.0
        u[i] = up[k]
    if t.size and t[t.size - 1] >= tp[tp.size - 1]:
        s[t.size - 1] = grid[grid.size - 1]
        sd[t.size - 1] = 0.0


@njit(cache=True, nogil=True)
def jet(breaks, coef, s, q, dq, ddq):
    """Values, first and second derivatives of the cubic pieces ``coef`` (pieces, 4, d:
    ``y, m, c2, c3`` in the offset from each piece's start ``breaks``) at the points ``s``
    into ``q``, ``dq``, ``ddq`` (len(s), d): :meth:`safepath.timing.CubicPath.jet`, the
    same sums in the same order."""
    for k in range(s.size):
        i = piece_of(breaks, s[k])
        t = s[k] - breaks[i]
        for j in range(coef.shape[2]):
            q[k, j], dq[k, j], ddq[k, j] = _cubic(coef, i, j, t)


@_inlined
def _cubic(coef, i, j, x):
    """Value, first and second derivative of piece ``i`` of joint ``j`` of the cubic
    pieces ``coef`` (``y + m x + c2 x^2 + c3 x^3``) at the offset ``x`` into it."""
    y, m, c2, c3 = coef[i, 0, j], coef[i, 1, j], coef[i, 2, j], coef[i, 3, j]
    return (y + x * (m + x * (c2 + x * c3)), m + x * (2.0 * c2 + 3.0 * x * c3),
            2.0 * c2 + 6.0 * x * c3)


@njit(cache=True, nogil=True)
def tighten(g_lo, g_hi, acc, xs, t_acc, t_x, f_acc, f_x):
    """Scale ``f_acc`` and ``f_x`` (in place) at every gridpoint by the smallest ``acc``
    and ``xs`` of the windows ``[g_lo[w], g_hi[w])`` over it (1 where none); ``t_acc``,
    ``t_x`` are scratch of ones, as long as ``f_acc``."""
    for w in range(g_lo.size):
        for g in range(g_lo[w], g_hi[w]):
            t_acc[g] = min(t_acc[g], acc[w])
            t_x[g] = min(t_x[g], xs[w])
    for g in range(f_acc.size):
        f_acc[g] *= t_acc[g]
        f_x[g] *= t_x[g]


@njit(cache=True, nogil=True)
def jerk_rows(tp, grid_p, sdp, up, dt, s_way, jmax_seg, grid, dq, ddq, inverse, f):
    """Each joint's acceleration along TOPP-RA's profile (times ``tp``, gridpoints
    ``grid_p``, speeds ``sdp``, accelerations ``up``) every ``dt`` [s] from 0 to before its
    end (:func:`evaluate` there), over the jerk limit of the segment (bounded by
    ``s_way``) it is in, into columns 1.. of ``f`` (dof, samples + 2; columns 0 and
    ``samples + 1``: at rest, 0); the path's tangent ``dq`` and curvature ``ddq`` linear
    between the gridpoints ``grid``; ``inverse`` (segments x dof) is scratch for the jerk
    limits' inverses (a product, not a division, per sample and joint: within a rounding
    of the quotient, and the same windows on the 75 seeded via paths of five arms and the
    bundled cells tried). :func:`safepath.timing.path_timing._jerk_window`'s sums, one
    sample at a time, each joint's along a row (:func:`jerk_shift` reads them so)."""
    dof = dq.shape[1]
    n = f.shape[1] - 2
    for j in range(dof):
        f[j, 0] = 0.0
        f[j, n + 1] = 0.0
    for r in range(jmax_seg.shape[0]):
        for j in range(dof):
            inverse[r * dof + j] = 1.0 / jmax_seg[r, j]
    last = up.size - 1
    k = seg = g = 0
    s_prev = -np.inf
    for i in range(n):
        # The profile at t = i dt (as evaluate): the times increase, so its piece walks on.
        ti = i * dt
        k = min(_piece_at(tp, ti, k), last)
        d = ti - tp[k]
        s_i = grid_p[k] + d * sdp[k] + 0.5 * d * d * up[k]
        sd_i = sdp[k] + d * up[k]
        s_i = s_i if (s_i >= grid_p[0] or s_i != s_i) else grid_p[0]
        s_i = s_i if (s_i <= grid_p[-1] or s_i != s_i) else grid_p[-1]
        sd_i = sd_i if (sd_i >= 0.0 or sd_i != sd_i) else 0.0
        if i == n - 1 and ti >= tp[tp.size - 1]:
            s_i, sd_i = grid_p[grid_p.size - 1], 0.0
        seg = _piece_walk(s_way, s_i, s_prev, seg)
        g = _piece_walk(grid, s_i, s_prev, g)
        s_prev = s_i
        w = (s_i - grid[g]) / (grid[g + 1] - grid[g])
        x = sd_i * sd_i
        u = up[k]
        for j in range(dof):
            ps = dq[g, j] + w * (dq[g + 1, j] - dq[g, j])
            pss = ddq[g, j] + w * (ddq[g + 1, j] - ddq[g, j])
            f[j, i + 1] = (ps * u + pss * x) * inverse[seg * dof + j]


@_inlined
def _piece_at(breaks, x, k):
    """The last piece ``k' >= k`` of ``breaks`` whose start is at or before ``x`` (the
    first piece when none), walking on from ``k``: the walk of :func:`_piece_after` and
    :func:`_piece_walk` along increasing values."""
    while k + 2 < breaks.size and breaks[k + 1] <= x:
        k += 1
    return k


@_inlined
def _piece_walk(breaks, x, x_prev, k):
    """:func:`~safepath.model._joinkernel.piece_of` of ``x``, walking on from piece ``k``
    (that of ``x_prev``) when ``x`` has not decreased since, else by bisection
    (:func:`_piece_after` for one value at a time)."""
    if not x >= x_prev:
        return piece_of(breaks, x)
    return _piece_at(breaks, x, k)


@njit(cache=True, nogil=True)
def jerk_shift(f, dt):
    """The fewest columns ``m >= 1`` over which no row of ``f`` (dof, n) changes by more
    than ``m dt``, by bisection from ``ceil(2 max|f| / dt)`` (or ``n``, the whole: it then
    fits by definition); :func:`safepath.timing.path_timing._jerk_window`'s search."""
    n = f.shape[1]
    peak = 0.0
    for j in range(f.shape[0]):
        for i in range(n):
            peak = max(peak, abs(f[j, i]))
    hi = max(1, int(np.ceil(2.0 * peak / dt)))
    lo = 1
    if not _shift_fits(f, hi, dt):
        hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if _shift_fits(f, mid, dt):
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(cache=True, nogil=True)
def fill_grid(breaks, counts, grid):
    """Piece ``p`` of ``breaks`` cut evenly into ``counts[p]`` parts: the parts' starts
    into ``grid`` in order (``sum(counts)``; the caller appends the end), as
    :func:`safepath.timing._path_limits.gridpoints` sums them."""
    i = 0
    for p in range(counts.size):
        start, width, count = breaks[p], breaks[p + 1] - breaks[p], counts[p]
        for j in range(count):
            grid[i] = start + width * (j / count)
            i += 1


@njit(cache=True, nogil=True)
def grid_peaks(grid, breaks, coef, dq, vlim, jden, v_peak, j_peak):  # noqa: N803
    """Per gridpoint (increasing ``grid``): the largest ``|q'| / vlim`` over the joints
    into ``v_peak``, and the largest ``|q'''| / jden``, ``|q'''|`` the larger of the cubic
    pieces' (``breaks``, ``coef`` (pieces, 4, dof)) on both sides of the gridpoint (one on
    a breakpoint also ends the piece before), into ``j_peak``; the pieces found walking
    along the grid. NaN where a value is (as numpy's ``max``)."""
    last = coef.shape[0] - 1
    dof = dq.shape[1]
    k = -1  # the last break at or before the gridpoint
    for i in range(grid.size):
        x = grid[i]
        while k + 1 < breaks.size and breaks[k + 1] <= x:
            k += 1
        after = min(max(k, 0), last)
        before = min(max(k - 1 if (k >= 0 and breaks[k] == x) else k, 0), last)
        v = -np.inf
        j = -np.inf
        for d in range(dof):
            v = _larger(v, abs(dq[i, d]) / vlim[d])
            d3 = 6.0 * _larger(abs(coef[after, 3, d]), abs(coef[before, 3, d]))
            j = _larger(j, d3 / jden[d])
        v_peak[i] = v
        j_peak[i] = j


@njit(cache=True, nogil=True)
def acceleration_rows(grid, dq, ddq, alim, a, b, c):
    """:func:`safepath.timing._topp.acceleration_rows` into ``a``, ``b``, ``c`` (N, 2 dof):
    the same sums."""
    dof = dq.shape[1]
    for i in range(grid.size - 1):
        delta = grid[i + 1] - grid[i]
        for d in range(dof):
            a[i, d] = dq[i, d]
            a[i, dof + d] = dq[i + 1, d] + 2.0 * delta * ddq[i + 1, d]
            b[i, d] = ddq[i, d]
            b[i, dof + d] = ddq[i + 1, d]
            c[i, d] = alim[i, d]
            c[i, dof + d] = alim[i + 1, d]
