"""Kernels of the sphere layer: the tests of one pair.

Lower bounds on the distance of a pair of shapes at a placed state (signed distances of
points to the scene's primitives, separating axes of two primitives, GJK on convex hulls
through :mod:`safepath.collision._gjk`, fine sphere sets) and the proofs of a collision
(inner spheres, the complete separating-axis test of two boxes, GJK's upper bound), for
:mod:`safepath.collision._kernels`. Compiled without numba's reference counting (see
there): no allocation, no array returned.

numba's disk cache tracks only the file of the function it compiles: the kernels of
:mod:`safepath.collision._kernels` that call (and inline) these helpers keep their cached
code when only this file changes. After editing it in a source checkout, delete
``safepath/collision/__pycache__/*.nb*`` (an installed copy compiles afresh; the kernels
compiled ahead of time are keyed on every kernel module's source).
"""

from __future__ import annotations

import math

from .._aot import njit
from ..model._primitives import extent, own_axes, round_about_z, signed_distance
from ._gjk import HULL, distance_lower_bound, distance_upper_bound
from ._layout import (
    E_DIMS,
    E_POS,
    E_ROT,
    ENV_BOX,
    ENV_BOX_ONLY_OUTER,
    EW,
    G_DIMS,
    G_RADIUS,
    GI_HULL,
    GI_HULL_END,
    GI_INNER,
    GI_INNER_END,
    GI_JOINT,
    GI_KIND,
    GI_OUTER,
    GI_OUTER_END,
    GIW,
    GW,
    H_E,
    H_EI,
    H_G,
    H_GI,
    H_P,
    H_PI,
    H_S,
    PI_A,
    PI_B,
    PI_ENV,
    PI_PROOF,
    PIW,
    PS_BOUND,
    PS_RADIUS,
    PSW,
    S_RADIUS,
    SPHERES_ONLY,
    SW,
    W_A,
    W_AXES,
    W_B,
    W_D,
    W_P,
    W_R,
    W_TMP,
    W_TMP2,
    WI_A,
    WI_B,
    WI_BUFA,
    WI_BUFB,
    WI_CW,
    WS_HULL,
    WS_HULL_END,
    WS_KIND,
)
from ._placement import _mover_frame, _place_spheres, _world

#: How the helpers are compiled (see :mod:`safepath.collision._kernels`).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_helper
def _env_sdist3(fb, ib, e, px, py, pz):  # noqa: N803
    """Signed distance [m] from world point (px, py, pz) to environment object ``e`` (for
    ENV_BOX_ONLY_OUTER: to a box that encloses it, a lower bound)."""
    base = ib[H_E] + EW * e
    o, t, d = base + E_ROT, base + E_POS, base + E_DIMS
    dx = px - fb[t]
    dy = py - fb[t + 1]
    dz = pz - fb[t + 2]
    # Local coordinates: R^T (p - t).
    x = fb[o + 0] * dx + fb[o + 3] * dy + fb[o + 6] * dz
    y = fb[o + 1] * dx + fb[o + 4] * dy + fb[o + 7] * dz
    z = fb[o + 2] * dx + fb[o + 5] * dy + fb[o + 8] * dz
    kind = ib[ib[H_EI] + e]
    return signed_distance(ENV_BOX if kind == ENV_BOX_ONLY_OUTER else kind, fb[d],
                           fb[d + 1], fb[d + 2], x, y, z)


@_inlined
def _support(kind, wf, o, d, nx, ny, nz):  # noqa: N803
    """Half extent [m] along unit n of a primitive placed in ``wf`` (rotation rows at
    wf[o:o+9], dimensions at wf[d:d+3])."""
    return extent(ENV_BOX if kind == ENV_BOX_ONLY_OUTER else kind, wf[d], wf[d + 1],
                  wf[d + 2], wf, o, nx, ny, nz)


@_inlined
def _primitive_axes(kind, wf, o, n):  # noqa: N803
    """Append the own axes of the primitive whose rotation is at wf[o:o+9] (box: its three
    face normals; cylinder, capsule: its z axis) to the candidate axes from row ``n``;
    returns the new row count."""
    first, count = own_axes(ENV_BOX if kind == ENV_BOX_ONLY_OUTER else kind)
    if count == 3:  # columns first .. first + 2, unrolled
        for c in range(3):
            x = W_AXES + 3 * n
            col = first + c
            wf[x], wf[x + 1], wf[x + 2] = wf[o + col], wf[o + 3 + col], wf[o + 6 + col]
            n += 1
    elif count == 1:
        x = W_AXES + 3 * n
        wf[x], wf[x + 1], wf[x + 2] = wf[o + first], wf[o + 3 + first], wf[o + 6 + first]
        n += 1
    return n


@_inlined
def _push_axis(wf, n, x, y, z):  # noqa: N803
    """Append (x, y, z) normalised to the candidate axes unless it is ~0; the row count."""
    norm = math.sqrt(x * x + y * y + z * z)
    if norm > 1e-9:
        o = W_AXES + 3 * n
        wf[o], wf[o + 1], wf[o + 2] = x / norm, y / norm, z / norm
        n += 1
    return n


@_helper
def _sat_gap(ka, kb, wf):  # noqa: N803
    """Lower bound [m] on the distance of the two convex primitives placed in ``wf`` (A at
    slot W_A, B at W_B): the largest gap between their projections
    over a set of separating-axis candidates (face normals, primitive axes, their cross
    products, the centre line). For two boxes the 15 axes are complete: a bound < 0 then
    means they intersect."""
    na = _primitive_axes(ka, wf, W_A + W_R, 0)
    nb = _primitive_axes(kb, wf, W_B + W_R, na)
    n = nb
    for i in range(na):
        oi = W_AXES + 3 * i
        for j in range(na, nb):
            oj = W_AXES + 3 * j
            n = _push_axis(wf, n, wf[oi + 1] * wf[oj + 2] - wf[oi + 2] * wf[oj + 1],
                           wf[oi + 2] * wf[oj] - wf[oi] * wf[oj + 2],
                           wf[oi] * wf[oj + 1] - wf[oi + 1] * wf[oj])
    pa, pb = W_A + W_P, W_B + W_P
    dx, dy, dz = wf[pb] - wf[pa], wf[pb + 1] - wf[pa + 1], wf[pb + 2] - wf[pa + 2]
    n = _push_axis(wf, n, dx, dy, dz)
    # Round shapes: the centre line's part across each axis.
    for which in range(2):
        kind = ka if which == 0 else kb
        if round_about_z(kind):
            o = (W_A if which == 0 else W_B) + W_R
            ax, ay, az = wf[o + 2], wf[o + 5], wf[o + 8]
            t = dx * ax + dy * ay + dz * az
            n = _push_axis(wf, n, dx - t * ax, dy - t * ay, dz - t * az)
    best = -1e300
    for i in range(n):
        o = W_AXES + 3 * i
        x, y, z = wf[o], wf[o + 1], wf[o + 2]
        gap = (abs(dx * x + dy * y + dz * z)
               - _support(ka, wf, W_A + W_R, W_A + W_D, x, y, z)
               - _support(kb, wf, W_B + W_R, W_B + W_D, x, y, z))
        if gap > best:
            best = gap
    return best


@_inlined
def _place_mover(fb, ib, m, Rw, pw, wf, wi, s, si):  # noqa: N803
    """Place mover ``m``'s shape at slot ``s`` of ``wf`` (its world rotation, position,
    dimensions) and ``si`` of ``wi`` (its kind and hull rows) at the state of Rw, pw;
    returns its kind."""
    row = ib[H_GI] + GIW * m
    _mover_frame(fb, ib, m, Rw, pw, wf, s + W_R, s + W_P)
    for r in range(3):
        wf[s + W_D + r] = fb[ib[H_G] + GW * m + G_DIMS + r]
    wi[si + WS_KIND] = ib[row + GI_KIND]
    wi[si + WS_HULL], wi[si + WS_HULL_END] = ib[row + GI_HULL], ib[row + GI_HULL_END]
    return ib[row + GI_KIND]


@_helper
def _place_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi):  # noqa: N803
    """Place mover ``a``'s shape (slots W_A, WI_A) and environment object (``is_env``) or
    mover ``b``'s shape (slots W_B, WI_B) in the scratch at the state of Rw, pw; returns
    their kinds."""
    ka = _place_mover(fb, ib, a, Rw, pw, wf, wi, W_A, WI_A)
    if is_env == 0:
        return ka, _place_mover(fb, ib, b, Rw, pw, wf, wi, W_B, WI_B)
    oe = ib[H_E] + EW * b
    kb = ib[ib[H_EI] + b]
    for r in range(3):
        wf[W_B + W_P + r] = fb[oe + E_POS + r]
        wf[W_B + W_D + r] = fb[oe + E_DIMS + r]
        for c in range(3):
            wf[W_B + W_R + 3 * r + c] = fb[oe + E_ROT + 3 * r + c]
    wi[WI_B + WS_KIND], wi[WI_B + WS_HULL], wi[WI_B + WS_HULL_END] = kb, 0, 0
    return ka, kb


@_helper
def _sat_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi):  # noqa: N803
    """Separating-axis bound [m] between mover ``a``'s primitive and environment object
    (``is_env``) or mover ``b``'s primitive, at the state of Rw, pw."""
    ka, kb = _place_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi)
    return _sat_gap(ka, kb, wf)


@_helper
def _gjk_pair(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, low, high):  # noqa: N803
    """GJK's distance lower bound [m] between mover ``a``'s shape and environment object
    or mover ``b``'s (pair ``k``; its last direction warm-starts the search), searched
    until it reaches ``high`` or the distance is known to be at most ``low``."""
    _place_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi)
    return distance_lower_bound(fb, ib, wf, wi, k, low, high)


@_helper
def _gjk_overlap(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, goal):  # noqa: N803
    """GJK's upper bound [m] on the signed distance of pair ``k``'s shapes (negative: they
    overlap at least that deep), searched until it is below ``goal``."""
    _place_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi)
    return distance_upper_bound(fb, ib, wf, wi, k, goal)


@_helper
def _pair_bound(k, fb, ib, Rw, pw, wf, wi, enough):  # noqa: N803
    """Lower bound [m] on the distance of pair ``k`` finer than its bounding spheres
    (placed in wf's WI_CW block by the caller): the separating-axis bound of two
    primitives, GJK's when one is a hull, or the fine spheres of a body that is no
    primitive. A bound of ``enough`` (beyond the pair's margin) is sufficient for the
    caller."""
    op, of = ib[H_PI] + PIW * k, ib[H_P] + k
    a, b, is_env = ib[op + PI_A], ib[op + PI_B], ib[op + PI_ENV]
    sm = max(fb[of], 0.0)
    ogi = ib[H_GI]
    ka = ib[ogi + GIW * a + GI_KIND]
    kb = ENV_BOX if is_env == 1 else ib[ogi + GIW * b + GI_KIND]
    if ka != SPHERES_ONLY and kb != SPHERES_ONLY:
        if ka == HULL or kb == HULL:
            return _gjk_pair(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, sm, sm + enough)
        return _sat_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi)
    if is_env == 1:
        return _spheres_to_object(fb, ib, a, b, sm, Rw, pw, wf)
    return _sphere_sets(fb, ib, a, b, sm, Rw, pw, wf, wi)


@_inlined
def _spheres_to_object(fb, ib, a, e, sm, Rw, pw, wf):  # noqa: N803
    """Lower bound [m] on the distance of mover ``a``'s outer spheres to environment
    object ``e``; the first one found within the margin ``sm``, if any."""
    oS, ogi = ib[H_S], ib[H_GI]
    ja = ib[ogi + GIW * a + GI_JOINT]
    best = 1e300
    for s in range(ib[ogi + GIW * a + GI_OUTER], ib[ogi + GIW * a + GI_OUTER_END]):
        _world(fb, oS + SW * s, Rw, pw, ja, wf, W_TMP)
        d = (_env_sdist3(fb, ib, e, wf[W_TMP], wf[W_TMP + 1], wf[W_TMP + 2])
             - fb[oS + SW * s + S_RADIUS])
        if d < best:
            best = d
            if best - sm <= 0.0:
                return best
    return best


@_inlined
def _nearest(wf, rows, n):
    """The sphere of the ``n`` placed at wf[rows] (rows of PSW) whose distance bound to the
    other body is the smallest (the first such)."""
    best = 0
    for i in range(1, n):
        if wf[rows + PSW * i + PS_BOUND] < wf[rows + PSW * best + PS_BOUND]:
            best = i
    return best


@_inlined
def _sphere_gap(wf, i0, j0):
    """Distance [m] between the placed spheres at wf[i0] and wf[j0] (rows of PSW)."""
    return (math.sqrt((wf[i0] - wf[j0]) ** 2 + (wf[i0 + 1] - wf[j0 + 1]) ** 2
                      + (wf[i0 + 2] - wf[j0 + 2]) ** 2) - wf[i0 + PS_RADIUS]
            - wf[j0 + PS_RADIUS])


@_inlined
def _sphere_sets(fb, ib, a, b, sm, Rw, pw, wf, wi):  # noqa: N803
    """Lower bound [m] on the distance of movers ``a`` and ``b``'s outer sphere sets
    (their bounding spheres' world centres in wf's WI_CW block); the first pair of
    spheres found within the margin ``sm``, if any."""
    og = ib[H_G]
    ra, rb = fb[og + GW * a + G_RADIUS], fb[og + GW * b + G_RADIUS]
    ocw = wi[WI_CW]
    cbx, cby, cbz = wf[ocw + 3 * b], wf[ocw + 3 * b + 1], wf[ocw + 3 * b + 2]
    ca0, ca1, ca2 = wf[ocw + 3 * a], wf[ocw + 3 * a + 1], wf[ocw + 3 * a + 2]
    # Two sphere sets: place each once, bound each sphere against the other body's
    # bounding sphere, take one real pair distance as an upper bound, and compare only
    # the spheres whose bound beats it.
    A, B = wi[WI_BUFA], wi[WI_BUFB]  # rows of PSW in wf
    na = _place_spheres(fb, ib, a, Rw, pw, cbx, cby, cbz, rb, wf, A)
    nb = _place_spheres(fb, ib, b, Rw, pw, ca0, ca1, ca2, ra, wf, B)
    best = _sphere_gap(wf, A + PSW * _nearest(wf, A, na), B + PSW * _nearest(wf, B, nb))
    for i in range(na):
        i0 = A + PSW * i
        if wf[i0 + PS_BOUND] >= best:
            continue
        for j in range(nb):
            j0 = B + PSW * j
            if wf[j0 + PS_BOUND] >= best:
                continue
            d = _sphere_gap(wf, i0, j0)
            if d < best:
                best = d
                if best - sm <= 0.0:
                    return best
    return best


@_helper
def _pair_collides(k, fb, ib, eps, Rw, pw, wf, wi):  # noqa: N803
    """Whether pair ``k`` is certainly closer than its margin: an inner sphere reaches
    that close, (two boxes, no margin) the complete separating-axis test fails, or (two
    exact shapes: primitives or convex hulls) GJK's upper bound on their signed distance
    is below it."""
    op, of = ib[H_PI] + PIW * k, ib[H_P] + k
    a, b, is_env, proof = ib[op + PI_A], ib[op + PI_B], ib[op + PI_ENV], ib[op + PI_PROOF]
    if proof == 0:
        return False
    sm = fb[of]
    oS, ogi = ib[H_S], ib[H_GI]
    ja = ib[ogi + GIW * a + GI_JOINT]
    ka = ib[ogi + GIW * a + GI_KIND]
    t1, t2 = W_TMP, W_TMP2
    if is_env == 1:
        if (sm == 0.0 and ka == ENV_BOX and ib[ib[H_EI] + b] == ENV_BOX
                and _sat_pair(fb, ib, a, b, 1, Rw, pw, wf, wi) < -eps):
            return True
        for s in range(ib[ogi + GIW * a + GI_INNER], ib[ogi + GIW * a + GI_INNER_END]):
            _world(fb, oS + SW * s, Rw, pw, ja, wf, t1)
            if (_env_sdist3(fb, ib, b, wf[t1], wf[t1 + 1], wf[t1 + 2])
                    - fb[oS + SW * s + S_RADIUS] < sm - eps):
                return True
        # An object measured by the box around it (ENV_BOX_ONLY_OUTER) proves nothing.
        return (ka != SPHERES_ONLY and ib[ib[H_EI] + b] != ENV_BOX_ONLY_OUTER
                and _gjk_overlap(fb, ib, k, a, b, 1, Rw, pw, wf, wi, sm - eps) < sm - eps)
    jb = ib[ogi + GIW * b + GI_JOINT]
    kb = ib[ogi + GIW * b + GI_KIND]
    if (sm == 0.0 and ka == ENV_BOX and kb == ENV_BOX
            and _sat_pair(fb, ib, a, b, 0, Rw, pw, wf, wi) < -eps):
        return True
    for s in range(ib[ogi + GIW * a + GI_INNER], ib[ogi + GIW * a + GI_INNER_END]):
        _world(fb, oS + SW * s, Rw, pw, ja, wf, t1)
        rs = fb[oS + SW * s + S_RADIUS]
        for t in range(ib[ogi + GIW * b + GI_INNER], ib[ogi + GIW * b + GI_INNER_END]):
            _world(fb, oS + SW * t, Rw, pw, jb, wf, t2)
            d = math.sqrt((wf[t1] - wf[t2]) ** 2 + (wf[t1 + 1] - wf[t2 + 1]) ** 2
                          + (wf[t1 + 2] - wf[t2 + 2]) ** 2) - rs - fb[oS + SW * t + S_RADIUS]
            if d < sm - eps:
                return True
    return (ka != SPHERES_ONLY and kb != SPHERES_ONLY
            and _gjk_overlap(fb, ib, k, a, b, 0, Rw, pw, wf, wi, sm - eps) < sm - eps)
