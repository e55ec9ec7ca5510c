"""Numba kernels of the fast collision layer (see :mod:`safepath.fastcheck`).

Imported lazily: the first import compiles (or loads from numba's on-disk cache).
All data of one checker travels in two flat buffers, ``fb`` (float64) and ``ib`` (int64),
laid out by :func:`safepath.fastcheck.pack` (one call argument each keeps numba's
dispatch cheap: the single-state API is called millions of times by planners).

Status codes: FREE (certainly valid), COLLIDES (certainly in collision or outside the
limits), UNSURE (ask the exact checker).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from ._gjk import HULL, distance_lower_bound

FREE, COLLIDES, UNSURE = 0, 1, 2

# Int header (positions in ib).
H_NJ, H_NG, H_NS, H_NE, H_NP, H_DOF = 0, 1, 2, 3, 4, 5
H_J, H_G, H_S, H_E, H_P, H_W, H_L, H_C = 6, 7, 8, 9, 10, 11, 12, 13
H_JI, H_GI, H_EI, H_PI = 14, 15, 16, 17
H_V = 18  # vertices of hull movers (x, y, z rows, each in its shape's frame)
#: Per pair and joint (ints): bit 1 if the joint moves body a relative to body b (or
#: to the world), bit 2 if it moves b relative to a (joints that carry both: 0).
H_PM = 19
#: Hull edges (ints): per vertex row, where its neighbours start in the H_AI block
#: (rows + 1 entries), and the neighbours' rows.
H_AP, H_AI = 20, 21
#: Radius of a sphere about each environment object's centre that holds it (floats).
H_ER = 22
HEADER = 23
# Constants (fb[ib[H_C] + k]).
C_REFINE, C_FREE_EPS, C_PROOF_EPS = 0, 1, 2

ENV_BOX, ENV_CYLINDER, ENV_SPHERE, ENV_CAPSULE, ENV_BOX_ONLY_OUTER = 0, 1, 2, 3, 4
#: Shape kinds of movers (same codes; HULL: a convex hull, measured by GJK on its
#: vertices; SPHERES_ONLY: no primitive, spheres decide).
SPHERES_ONLY = -1
#: Widths of a mover's rows: floats (bounding centre 3, radius 1, rotation 9, position 3
#: in the joint frame, dimensions 3) and ints (joint, outer start/end, inner start/end,
#: kind, hull vertex start/end).
GW, GIW = 19, 8
JOINT_FIXED, JOINT_REVOLUTE, JOINT_PRISMATIC = 0, 1, 2

#: Scratch arrays of one evaluation (allocated once per kernel call).
#: ``warm`` holds, per pair, the last direction GJK found (the next state's first guess).
Workspace = namedtuple("Workspace", ["Rw", "pw", "tmp", "tmp2", "Ra", "pa", "da", "Rb", "pb",
                                     "db", "axes", "Cw", "bufa", "bufb", "simplex", "sa", "sb",
                                     "gv", "warm", "absu", "DL", "CC", "hint", "budget"])


@njit(cache=True, nogil=True)
def _workspace(ib):
    nj, ng, ns, npairs = ib[H_NJ], ib[H_NG], ib[H_NS], ib[H_NP]
    return Workspace(np.empty((nj, 3, 3)), np.empty((nj, 3)), np.empty(3), np.empty(3),
                     np.empty((3, 3)), np.empty(3), np.empty(3), np.empty((3, 3)),
                     np.empty(3), np.empty(3), np.empty((24, 3)), np.empty((ng, 3)),
                     np.empty((ns, 5)), np.empty((ns, 5)), np.empty((4, 3)), np.empty(3),
                     np.empty(3), np.empty(3), np.zeros((npairs, 3)), np.zeros(ib[H_DOF]),
                     np.zeros((ng, ib[H_DOF])), np.zeros((ng, ib[H_DOF])),
                     np.full((npairs, 2), -1, dtype=np.int64), np.zeros(npairs))


@njit(cache=True, nogil=True)
def _fk(q, fb, ib, Rw, pw):  # noqa: N803
    """World rotation and position of every joint frame at ``q`` into Rw (nj,3,3), pw (nj,3)."""
    nj = ib[H_NJ]
    oj, oji = ib[H_J], ib[H_JI]
    Rw[0, :, :] = 0.0
    Rw[0, 0, 0] = Rw[0, 1, 1] = Rw[0, 2, 2] = 1.0
    pw[0, :] = 0.0
    M = np.empty((3, 3))
    t = np.empty(3)
    for j in range(1, nj):
        base = oj + 15 * j
        parent = ib[oji + 3 * j]
        kind = ib[oji + 3 * j + 1]
        # Local placement (joint placement times the joint's own motion).
        for r in range(3):
            for c in range(3):
                M[r, c] = fb[base + 3 * r + c]
            t[r] = fb[base + 9 + r]
        if kind != JOINT_FIXED:
            x = q[ib[oji + 3 * j + 2]]
            ax, ay, az = fb[base + 12], fb[base + 13], fb[base + 14]
            if kind == JOINT_REVOLUTE:
                c_, s_ = math.cos(x), math.sin(x)
                v = 1.0 - c_
                R00 = c_ + ax * ax * v
                R01 = ax * ay * v - az * s_
                R02 = ax * az * v + ay * s_
                R10 = ay * ax * v + az * s_
                R11 = c_ + ay * ay * v
                R12 = ay * az * v - ax * s_
                R20 = az * ax * v - ay * s_
                R21 = az * ay * v + ax * s_
                R22 = c_ + az * az * v
                for r in range(3):
                    m0, m1, m2 = M[r, 0], M[r, 1], M[r, 2]
                    M[r, 0] = m0 * R00 + m1 * R10 + m2 * R20
                    M[r, 1] = m0 * R01 + m1 * R11 + m2 * R21
                    M[r, 2] = m0 * R02 + m1 * R12 + m2 * R22
            else:
                for r in range(3):
                    t[r] += (M[r, 0] * ax + M[r, 1] * ay + M[r, 2] * az) * x
        for r in range(3):
            pw[j, r] = (Rw[parent, r, 0] * t[0] + Rw[parent, r, 1] * t[1]
                        + Rw[parent, r, 2] * t[2] + pw[parent, r])
            for c in range(3):
                Rw[j, r, c] = (Rw[parent, r, 0] * M[0, c] + Rw[parent, r, 1] * M[1, c]
                               + Rw[parent, r, 2] * M[2, c])


@njit(cache=True, nogil=True, inline="always")
def _world(fb, s, Rj, pj, out):  # noqa: N803
    """World centre of sphere/point at fb[s:s+3] (joint frame) into ``out``."""
    x, y, z = fb[s], fb[s + 1], fb[s + 2]
    for r in range(3):
        out[r] = Rj[r, 0] * x + Rj[r, 1] * y + Rj[r, 2] * z + pj[r]


@njit(cache=True, nogil=True)
def _env_sdist(fb, ib, e, p):  # noqa: N803
    """Signed distance [m] from world point ``p`` to environment object ``e``."""
    return _env_sdist3(fb, ib, e, p[0], p[1], p[2])


@njit(cache=True, nogil=True)
def _env_sdist3(fb, ib, e, px, py, pz):  # noqa: N803
    """Signed distance [m] from world point (px, py, pz) to environment object ``e`` (for
    ENV_BOX_ONLY_OUTER: to a box that encloses it, a lower bound)."""
    base = ib[H_E] + 15 * e
    dx = px - fb[base + 9]
    dy = py - fb[base + 10]
    dz = pz - fb[base + 11]
    # Local coordinates: R^T (p - t).
    x = fb[base + 0] * dx + fb[base + 3] * dy + fb[base + 6] * dz
    y = fb[base + 1] * dx + fb[base + 4] * dy + fb[base + 7] * dz
    z = fb[base + 2] * dx + fb[base + 5] * dy + fb[base + 8] * dz
    a, b, c = fb[base + 12], fb[base + 13], fb[base + 14]
    kind = ib[ib[H_EI] + e]
    if kind == ENV_BOX or kind == ENV_BOX_ONLY_OUTER:
        qx, qy, qz = abs(x) - a, abs(y) - b, abs(z) - c
        ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        return math.sqrt(ox * ox + oy * oy + oz * oz) + min(max(qx, max(qy, qz)), 0.0)
    if kind == ENV_CYLINDER:
        dr = math.sqrt(x * x + y * y) - a
        dzz = abs(z) - b
        o1, o2 = max(dr, 0.0), max(dzz, 0.0)
        return math.sqrt(o1 * o1 + o2 * o2) + min(max(dr, dzz), 0.0)
    if kind == ENV_SPHERE:
        return math.sqrt(x * x + y * y + z * z) - a
    zc = min(max(z, -b), b)
    return math.sqrt(x * x + y * y + (z - zc) * (z - zc)) - a


@njit(cache=True, nogil=True)
def _support(kind, R, d0, d1, d2, nx, ny, nz):  # noqa: N803
    """Half extent [m] of a primitive (rotation ``R``, dimensions d) along unit n."""
    if kind == ENV_BOX or kind == ENV_BOX_ONLY_OUTER:
        return (d0 * abs(R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz)
                + d1 * abs(R[0, 1] * nx + R[1, 1] * ny + R[2, 1] * nz)
                + d2 * abs(R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz))
    if kind == ENV_SPHERE:
        return d0
    c = R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz
    if kind == ENV_CAPSULE:
        return d1 * abs(c) + d0
    return d1 * abs(c) + d0 * math.sqrt(max(0.0, 1.0 - c * c))


@njit(cache=True, nogil=True)
def _primitive_axes(kind, R, axes, n):  # noqa: N803
    """Append a primitive's own axes (box: its three face normals; cylinder, capsule: its
    z axis) to ``axes`` from row ``n``; returns the new row count."""
    if kind == ENV_BOX or kind == ENV_BOX_ONLY_OUTER:
        for c in range(3):
            axes[n, 0], axes[n, 1], axes[n, 2] = R[0, c], R[1, c], R[2, c]
            n += 1
    elif kind == ENV_CYLINDER or kind == ENV_CAPSULE:
        axes[n, 0], axes[n, 1], axes[n, 2] = R[0, 2], R[1, 2], R[2, 2]
        n += 1
    return n


@njit(cache=True, nogil=True)
def _sat_gap(ka, Ra, pa, da, kb, Rb, pb, db, axes):  # noqa: N803
    """Lower bound [m] on the distance of two convex primitives: the largest gap between
    their projections over a set of separating-axis candidates (face normals, primitive
    axes, their cross products, the centre line). For two boxes the 15 axes are complete:
    a bound < 0 then means they intersect."""
    na = _primitive_axes(ka, Ra, axes, 0)
    nb = _primitive_axes(kb, Rb, axes, na)
    n = nb
    for i in range(na):
        for j in range(na, nb):
            x = axes[i, 1] * axes[j, 2] - axes[i, 2] * axes[j, 1]
            y = axes[i, 2] * axes[j, 0] - axes[i, 0] * axes[j, 2]
            z = axes[i, 0] * axes[j, 1] - axes[i, 1] * axes[j, 0]
            norm = math.sqrt(x * x + y * y + z * z)
            if norm > 1e-9:
                axes[n, 0], axes[n, 1], axes[n, 2] = x / norm, y / norm, z / norm
                n += 1
    dx, dy, dz = pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]
    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    if norm > 1e-9:
        axes[n, 0], axes[n, 1], axes[n, 2] = dx / norm, dy / norm, dz / norm
        n += 1
    # Round shapes: the centre line's part across each axis.
    for which in range(2):
        kind = ka if which == 0 else kb
        if kind == ENV_CYLINDER or kind == ENV_CAPSULE:
            R = Ra if which == 0 else Rb
            ax, ay, az = R[0, 2], R[1, 2], R[2, 2]
            t = dx * ax + dy * ay + dz * az
            x, y, z = dx - t * ax, dy - t * ay, dz - t * az
            norm = math.sqrt(x * x + y * y + z * z)
            if norm > 1e-9:
                axes[n, 0], axes[n, 1], axes[n, 2] = x / norm, y / norm, z / norm
                n += 1
    best = -1e300
    for i in range(n):
        x, y, z = axes[i, 0], axes[i, 1], axes[i, 2]
        gap = (abs(dx * x + dy * y + dz * z)
               - _support(ka, Ra, da[0], da[1], da[2], x, y, z)
               - _support(kb, Rb, db[0], db[1], db[2], x, y, z))
        if gap > best:
            best = gap
    return best


@njit(cache=True, nogil=True)
def _mover_frame(fb, ib, m, Rw, pw, R, p):  # noqa: N803
    """World rotation and position of mover ``m``'s primitive into R, p."""
    og = ib[H_G] + GW * m
    j = ib[ib[H_GI] + GIW * m]
    for r in range(3):
        p[r] = (Rw[j, r, 0] * fb[og + 13] + Rw[j, r, 1] * fb[og + 14] + Rw[j, r, 2] * fb[og + 15]
                + pw[j, r])
        for c in range(3):
            R[r, c] = (Rw[j, r, 0] * fb[og + 4 + c] + Rw[j, r, 1] * fb[og + 7 + c]
                       + Rw[j, r, 2] * fb[og + 10 + c])


@njit(cache=True, nogil=True)
def _place_pair(fb, ib, a, b, is_env, ws):  # noqa: N803
    """Place mover ``a``'s shape (ws.Ra, pa, da) and environment object (``is_env``) or
    mover ``b``'s shape (ws.Rb, pb, db) at the state in ``ws``; returns their kinds."""
    og, ogi = ib[H_G], ib[H_GI]
    ka = ib[ogi + GIW * a + 5]
    _mover_frame(fb, ib, a, ws.Rw, ws.pw, ws.Ra, ws.pa)
    for r in range(3):
        ws.da[r] = fb[og + GW * a + 16 + r]
    if is_env == 1:
        oe = ib[H_E] + 15 * b
        kb = ib[ib[H_EI] + b]
        for r in range(3):
            ws.pb[r] = fb[oe + 9 + r]
            ws.db[r] = fb[oe + 12 + r]
            for c in range(3):
                ws.Rb[r, c] = fb[oe + 3 * r + c]
    else:
        kb = ib[ogi + GIW * b + 5]
        _mover_frame(fb, ib, b, ws.Rw, ws.pw, ws.Rb, ws.pb)
        for r in range(3):
            ws.db[r] = fb[og + GW * b + 16 + r]
    return ka, kb


@njit(cache=True, nogil=True)
def _sat_pair(fb, ib, a, b, is_env, ws):  # noqa: N803
    """Separating-axis bound [m] between mover ``a``'s primitive and environment object
    (``is_env``) or mover ``b``'s primitive, at the state placed in ``ws``."""
    ka, kb = _place_pair(fb, ib, a, b, is_env, ws)
    return _sat_gap(ka, ws.Ra, ws.pa, ws.da, kb, ws.Rb, ws.pb, ws.db, ws.axes)


@njit(cache=True, nogil=True)
def _gjk_pair(fb, ib, k, a, b, is_env, ws, low, high):  # noqa: N803
    """GJK's distance lower bound [m] between mover ``a``'s shape and environment object
    or mover ``b``'s (pair ``k``; its last direction warm-starts the search), searched
    until it reaches ``high`` or the distance is known to be at most ``low``."""
    ogi = ib[H_GI]
    ka, kb = _place_pair(fb, ib, a, b, is_env, ws)
    va0, va1 = ib[ogi + GIW * a + 6], ib[ogi + GIW * a + 7]
    vb0 = vb1 = 0
    if is_env == 0:
        vb0, vb1 = ib[ogi + GIW * b + 6], ib[ogi + GIW * b + 7]
    return distance_lower_bound(ka, ws.Ra, ws.pa, ws.da, va0, va1, kb, ws.Rb, ws.pb, ws.db,
                                vb0, vb1, fb, ib[H_V], ib, ib[H_AP], ib[H_AI], ws.hint[k],
                                ws.warm[k], ws.simplex, ws.sa, ws.sb,
                                ws.gv, ws.tmp, low, high)


@njit(cache=True, nogil=True)
def _pair_bound(k, fb, ib, ws, enough):  # noqa: N803
    """Lower bound [m] on the distance of pair ``k`` finer than its bounding spheres
    (placed in ``ws.Cw`` by the caller): the separating-axis bound of two primitives,
    GJK's when one is a hull, or the fine spheres of a body that is no primitive. A bound
    of ``enough`` (beyond the pair's margin) is sufficient for the caller."""
    Rw, pw, tmp, Cw = ws.Rw, ws.pw, ws.tmp, ws.Cw
    op, of = ib[H_PI] + 4 * k, ib[H_P] + k
    a, b, is_env = ib[op], ib[op + 1], ib[op + 2]
    sm = max(fb[of], 0.0)
    og, oS, ogi = ib[H_G], ib[H_S], ib[H_GI]
    ka = ib[ogi + GIW * a + 5]
    kb = ENV_BOX if is_env == 1 else ib[ogi + GIW * b + 5]
    if ka != SPHERES_ONLY and kb != SPHERES_ONLY:
        if ka == HULL or kb == HULL:
            return _gjk_pair(fb, ib, k, a, b, is_env, ws, sm, sm + enough)
        return _sat_pair(fb, ib, a, b, is_env, ws)
    ja = ib[ogi + GIW * a]
    if is_env == 1:
        best = 1e300
        for s in range(ib[ogi + GIW * a + 1], ib[ogi + GIW * a + 2]):
            _world(fb, oS + 4 * s, Rw[ja], pw[ja], tmp)
            d = _env_sdist(fb, ib, b, tmp) - fb[oS + 4 * s + 3]
            if d < best:
                best = d
                if best - sm <= 0.0:
                    return best
        return best
    ra, rb = fb[og + GW * a + 3], fb[og + GW * b + 3]
    cbx, cby, cbz = Cw[b, 0], Cw[b, 1], Cw[b, 2]
    ca0, ca1, ca2 = Cw[a, 0], Cw[a, 1], Cw[a, 2]
    # Two sphere sets: place each once, bound each sphere against the other body's
    # bounding sphere, take one real pair distance as an upper bound, and compare only
    # the spheres whose bound beats it.
    A, B = ws.bufa, ws.bufb
    na = _place_spheres(fb, ib, a, Rw, pw, cbx, cby, cbz, rb, A)
    nb = _place_spheres(fb, ib, b, Rw, pw, ca0, ca1, ca2, ra, B)
    sa = 0
    for i in range(1, na):
        if A[i, 4] < A[sa, 4]:
            sa = i
    sb = 0
    for i in range(1, nb):
        if B[i, 4] < B[sb, 4]:
            sb = i
    best = (math.sqrt((A[sa, 0] - B[sb, 0]) ** 2 + (A[sa, 1] - B[sb, 1]) ** 2
                      + (A[sa, 2] - B[sb, 2]) ** 2) - A[sa, 3] - B[sb, 3])
    for i in range(na):
        if A[i, 4] >= best:
            continue
        for j in range(nb):
            if B[j, 4] >= best:
                continue
            d = (math.sqrt((A[i, 0] - B[j, 0]) ** 2 + (A[i, 1] - B[j, 1]) ** 2
                           + (A[i, 2] - B[j, 2]) ** 2) - A[i, 3] - B[j, 3])
            if d < best:
                best = d
                if best - sm <= 0.0:
                    return best
    return best


@njit(cache=True, nogil=True)
def _place_spheres(fb, ib, m, Rw, pw, ox, oy, oz, orad, out):  # noqa: N803
    """World centres and radii of mover ``m``'s outer spheres into ``out`` rows (x, y, z,
    r, lower bound of the distance to the sphere (ox, oy, oz, orad)); returns the count."""
    oS, ogi = ib[H_S], ib[H_GI]
    j = ib[ogi + GIW * m]
    n = 0
    for s in range(ib[ogi + GIW * m + 1], ib[ogi + GIW * m + 2]):
        x, y, z = fb[oS + 4 * s], fb[oS + 4 * s + 1], fb[oS + 4 * s + 2]
        wx = Rw[j, 0, 0] * x + Rw[j, 0, 1] * y + Rw[j, 0, 2] * z + pw[j, 0]
        wy = Rw[j, 1, 0] * x + Rw[j, 1, 1] * y + Rw[j, 1, 2] * z + pw[j, 1]
        wz = Rw[j, 2, 0] * x + Rw[j, 2, 1] * y + Rw[j, 2, 2] * z + pw[j, 2]
        r = fb[oS + 4 * s + 3]
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = wx, wy, wz, r
        out[n, 4] = math.sqrt((wx - ox) ** 2 + (wy - oy) ** 2 + (wz - oz) ** 2) - r - orad
        n += 1
    return n


@njit(cache=True, nogil=True)
def _pair_collides(k, fb, ib, eps, ws):  # noqa: N803
    """Whether pair ``k`` is certainly closer than its margin: an inner sphere reaches
    that close, or (two boxes, no margin) the complete separating-axis test fails."""
    Rw, pw, tmp, tmp2 = ws.Rw, ws.pw, ws.tmp, ws.tmp2
    op, of = ib[H_PI] + 4 * k, ib[H_P] + k
    a, b, is_env, proof = ib[op], ib[op + 1], ib[op + 2], ib[op + 3]
    if proof == 0:
        return False
    sm = fb[of]
    oS, ogi = ib[H_S], ib[H_GI]
    ja = ib[ogi + GIW * a]
    ka = ib[ogi + GIW * a + 5]
    if is_env == 1:
        if (sm == 0.0 and ka == ENV_BOX and ib[ib[H_EI] + b] == ENV_BOX
                and _sat_pair(fb, ib, a, b, 1, ws) < -eps):
            return True
        for s in range(ib[ogi + GIW * a + 3], ib[ogi + GIW * a + 4]):
            _world(fb, oS + 4 * s, Rw[ja], pw[ja], tmp)
            if _env_sdist(fb, ib, b, tmp) - fb[oS + 4 * s + 3] < sm - eps:
                return True
        return False
    jb = ib[ogi + GIW * b]
    kb = ib[ogi + GIW * b + 5]
    if sm == 0.0 and ka == ENV_BOX and kb == ENV_BOX and _sat_pair(fb, ib, a, b, 0, ws) < -eps:
        return True
    for s in range(ib[ogi + GIW * a + 3], ib[ogi + GIW * a + 4]):
        _world(fb, oS + 4 * s, Rw[ja], pw[ja], tmp)
        rs = fb[oS + 4 * s + 3]
        for t in range(ib[ogi + GIW * b + 3], ib[ogi + GIW * b + 4]):
            _world(fb, oS + 4 * t, Rw[jb], pw[jb], tmp2)
            d = math.sqrt((tmp[0] - tmp2[0]) ** 2 + (tmp[1] - tmp2[1]) ** 2
                          + (tmp[2] - tmp2[2]) ** 2) - rs - fb[oS + 4 * t + 3]
            if d < sm - eps:
                return True
    return False


@njit(cache=True, nogil=True)
def _evaluate(q, fb, ib, ws, rates, want_radius):  # noqa: N803
    """(status, radius) of one state inside the limits. With ``want_radius``, radius is
    the largest ``h`` such that every state ``q + t u`` with ``|t| < h`` is certainly
    valid, ``rates[k]`` bounding how fast pair ``k`` can close per unit ``t``."""
    Rw, pw, Cw = ws.Rw, ws.pw, ws.Cw
    _fk(q, fb, ib, Rw, pw)
    oc = ib[H_C]
    refine, free_eps, proof_eps = fb[oc + C_REFINE], fb[oc + C_FREE_EPS], fb[oc + C_PROOF_EPS]
    if not want_radius:
        refine = 0.0
    og, ogi, op_, of_ = ib[H_G], ib[H_GI], ib[H_PI], ib[H_P]
    # Bounding spheres of the movers, in the world.
    for m in range(ib[H_NG]):
        j = ib[ogi + GIW * m]
        x, y, z = fb[og + GW * m], fb[og + GW * m + 1], fb[og + GW * m + 2]
        for r in range(3):
            Cw[m, r] = Rw[j, r, 0] * x + Rw[j, r, 1] * y + Rw[j, r, 2] * z + pw[j, r]
    if want_radius:
        for m in range(ib[H_NG]):
            _axis_distances(m, fb, ib, Rw, pw, Cw, ws.DL)
    unsure = False
    radius = 1e300
    oe, oer = ib[H_E], ib[H_ER]
    for k in range(ib[H_NP]):
        a, b, is_env = ib[op_ + 4 * k], ib[op_ + 4 * k + 1], ib[op_ + 4 * k + 2]
        sm = max(fb[of_ + k], 0.0)
        if is_env == 1:
            if not want_radius:
                # Broad phase: bounding spheres apart by more than the margin decide the
                # pair (free) without measuring the object.
                dx = Cw[a, 0] - fb[oe + 15 * b + 9]
                dy = Cw[a, 1] - fb[oe + 15 * b + 10]
                dz = Cw[a, 2] - fb[oe + 15 * b + 11]
                reach = fb[og + GW * a + 3] + fb[oer + b] + sm + free_eps
                if dx * dx + dy * dy + dz * dz > reach * reach:
                    continue
            coarse = _env_sdist3(fb, ib, b, Cw[a, 0], Cw[a, 1], Cw[a, 2]) - fb[og + GW * a + 3]
        else:
            dd = ((Cw[a, 0] - Cw[b, 0]) ** 2 + (Cw[a, 1] - Cw[b, 1]) ** 2
                  + (Cw[a, 2] - Cw[b, 2]) ** 2)
            rr = fb[og + GW * a + 3] + fb[og + GW * b + 3]
            if not want_radius and dd > (rr + sm + free_eps) ** 2:
                continue
            coarse = math.sqrt(dd) - rr
        budget = coarse - sm - free_eps
        if budget <= refine:
            budget = max(coarse, _pair_bound(k, fb, ib, ws, refine + free_eps)) - sm - free_eps
        if budget <= 0.0:
            if _pair_collides(k, fb, ib, proof_eps, ws):
                return COLLIDES, 0.0
            unsure = True
            continue
        if want_radius:
            ws.budget[k] = budget
        if want_radius and rates[k] > 0.0:
            h = max(budget / rates[k], _local_radius(k, a, b, budget, ib, ws.DL, ws.CC, ws.absu))
            if h < radius:
                radius = h
    if unsure:
        return UNSURE, 0.0
    return FREE, radius


@njit(cache=True, nogil=True)
def _axis_distances(m, fb, ib, Rw, pw, Cw, DL):  # noqa: N803
    """DL[m, v]: how fast [m per unit of joint v] mover ``m``'s points move when joint
    ``v`` alone moves, at the state placed in Rw, pw, Cw: the distance of its bounding
    sphere from the joint's axis plus its radius (revolute), 1 (prismatic)."""
    oj, oji, og, ogi = ib[H_J], ib[H_JI], ib[H_G], ib[H_GI]
    r_m = fb[og + GW * m + 3]
    j = ib[ogi + GIW * m]
    while j > 0:
        v = ib[oji + 3 * j + 2]
        if ib[oji + 3 * j + 1] == JOINT_PRISMATIC:
            DL[m, v] = 1.0
        else:
            base = oj + 15 * j
            ax, ay, az = fb[base + 12], fb[base + 13], fb[base + 14]
            ux = Rw[j, 0, 0] * ax + Rw[j, 0, 1] * ay + Rw[j, 0, 2] * az
            uy = Rw[j, 1, 0] * ax + Rw[j, 1, 1] * ay + Rw[j, 1, 2] * az
            uz = Rw[j, 2, 0] * ax + Rw[j, 2, 1] * ay + Rw[j, 2, 2] * az
            dx, dy, dz = Cw[m, 0] - pw[j, 0], Cw[m, 1] - pw[j, 1], Cw[m, 2] - pw[j, 2]
            cx, cy, cz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
            DL[m, v] = math.sqrt(cx * cx + cy * cy + cz * cz) + r_m
        j = ib[oji + 3 * j]


@njit(cache=True, nogil=True, inline="always")
def _local_radius(k, a, b, budget, ib, DL, CC, absu):  # noqa: N803
    """A radius (in units of ``t``) within which pair ``k`` cannot close by ``budget`` [m],
    from the bodies' distances to the joint axes at this state (``DL``, see
    ``_axis_distances``), which grow along the segment by at most ``CC`` per unit of
    ``t``: the closing speed is at most A + B |t|, so the radius solves
    A h + B h^2 / 2 = budget. (Passed arrays, not the workspace: a numba call that
    takes the workspace pays the reference counts of all its arrays.)"""
    dof, opm = ib[H_DOF], ib[H_PM] + k * ib[H_DOF]
    A = B = 0.0
    for v in range(dof):
        if absu[v] == 0.0:
            continue
        mask = ib[opm + v]
        if mask & 1:
            A += absu[v] * DL[a, v]
            B += absu[v] * CC[a, v]
        if mask & 2:
            A += absu[v] * DL[b, v]
            B += absu[v] * CC[b, v]
    if A <= 0.0:
        return 0.0
    if B <= 1e-12 * A:
        return budget / A
    return (math.sqrt(A * A + 2.0 * B * budget) - A) / B


@njit(cache=True, nogil=True)
def _within_limits(q, fb, ib):  # noqa: N803
    dof, ol = ib[H_DOF], ib[H_L]
    for i in range(dof):
        if not (fb[ol + i] <= q[i] <= fb[ol + dof + i]):
            return False
    return True


@njit(cache=True, nogil=True)
def classify(q, fb, ib):  # noqa: N803
    """Status of one state: FREE, COLLIDES (or outside the limits) or UNSURE."""
    if not _within_limits(q, fb, ib):
        return COLLIDES
    ws = _workspace(ib)
    status, _ = _evaluate(q, fb, ib, ws, ws.tmp, False)
    return status


@njit(cache=True, nogil=True)
def classify_many(Q, fb, ib, out):  # noqa: N803
    """Status of every row of ``Q`` into ``out``."""
    ws = _workspace(ib)
    for i in range(Q.shape[0]):
        if not _within_limits(Q[i], fb, ib):
            out[i] = COLLIDES
            continue
        out[i], _ = _evaluate(Q[i], fb, ib, ws, ws.tmp, False)


@njit(cache=True, nogil=True)
def _pair_rates(u, fb, ib, ws, rates):  # noqa: N803
    """Per pair, a bound on how fast its two bodies approach per unit of ``t`` along
    the joint-space direction ``u`` [m] (joints that carry both bodies leave their
    distance alone). Also ws.absu = |u| and, per mover and joint, ws.CC: how fast its
    distance to that joint's axis can grow per unit of ``t`` (the joints between the
    two move it, at most by their weights)."""
    dof, ow, oji, ogi = ib[H_DOF], ib[H_W], ib[H_JI], ib[H_GI]
    for v in range(dof):
        ws.absu[v] = abs(u[v])
    for k in range(ib[H_NP]):
        op = ib[H_PI] + 4 * k
        opm = ib[H_PM] + k * dof
        a, b = ib[op], ib[op + 1]
        r = 0.0
        for v in range(dof):
            mask = ib[opm + v]
            w = 0.0
            if mask & 1:
                w += fb[ow + a * dof + v]
            if mask & 2:
                w += fb[ow + b * dof + v]
            r += w * ws.absu[v]
        rates[k] = r
    for m in range(ib[H_NG]):
        acc = 0.0
        j = ib[ogi + GIW * m]
        while j > 0:
            v = ib[oji + 3 * j + 2]
            ws.CC[m, v] = 0.0 if ib[oji + 3 * j + 1] == JOINT_PRISMATIC else acc
            acc += fb[ow + m * dof + v] * ws.absu[v]
            j = ib[oji + 3 * j]


@njit(cache=True, nogil=True)
def certify_polyline(P, n, lo, hi, fb, ib, unsure_seg, unsure_idx, max_unsure):  # noqa: N803
    """Certify the grid states of a joint polyline.

    Segment ``k`` of ``P`` (rows) is cut into ``n[k]`` equal steps; its grid states
    ``lo[k]..hi[k]`` (0 = ``P[k]``, ``n[k]`` = ``P[k+1]``) must be valid. States are
    visited coarse to fine (middle first); a state the spheres prove free certifies
    its neighbours within its clearance radius, a state they cannot decide is written
    to ``unsure_seg/unsure_idx`` for the exact checker. Every endpoint must lie inside
    the limits (the caller checks them; the limit box is convex).

    Returns:
        (status, segment, index, evaluated, unsure): COLLIDES with the colliding grid
        state; UNSURE when ``max_unsure`` undecided states were found (the walk stopped:
        the exact checker should look at those first, a collision is often among them);
        else FREE (no state left but the unsure ones).
    """
    npairs, dof = ib[H_NP], ib[H_DOF]
    ws = _workspace(ib)
    rates = np.empty(npairs)
    u = np.empty(dof)
    qs = np.empty(dof)
    n_unsure = 0
    evaluated = 0
    # Carry: the pair budgets [m] of an evaluated state whose certificate reached the end
    # of its segment, and how much each pair may have closed since (its rate times the
    # path walked, segment by segment): later segments within every budget are
    # certified without an evaluation of their own (short chords of a sampled curve).
    carry = False
    carried = np.empty(npairs)
    spent = np.empty(npairs)
    for k in range(P.shape[0] - 1):
        for j in range(dof):
            u[j] = P[k + 1, j] - P[k, j]
        _pair_rates(u, fb, ib, ws, rates)
        if carry:
            for p in range(npairs):
                spent[p] += rates[p]
                if spent[p] >= carried[p]:
                    carry = False
                    break
            if carry:
                continue
        if hi[k] < lo[k]:
            continue
        nk = n[k]
        first = True
        size = hi[k] - lo[k] + 3
        # FIFO of disjoint, non-empty index ranges still to cover (coarse to fine).
        qlo = np.empty(size, dtype=np.int64)
        qhi = np.empty(size, dtype=np.int64)
        head, tail = 0, 1
        qlo[0], qhi[0] = lo[k], hi[k]
        while head < tail:
            a, b = qlo[head], qhi[head]
            head += 1
            mid = (a + b) // 2
            t = mid / nk
            for j in range(dof):
                qs[j] = P[k, j] + t * u[j]
            status, radius = _evaluate(qs, fb, ib, ws, rates, True)
            evaluated += 1
            if status == COLLIDES:
                return COLLIDES, k, mid, evaluated, n_unsure
            m = 0
            if status == FREE:
                # Grid states with |i - mid| / nk < radius are certified.
                reach = radius * nk * (1.0 - 1e-12)
                m = nk if reach >= nk else max(int(math.ceil(reach)) - 1, 0)
                if first and mid + m >= hi[k]:
                    carry = True
                    for p in range(npairs):
                        carried[p] = ws.budget[p]
                        spent[p] = rates[p] * (nk - mid) / nk
            else:
                unsure_seg[n_unsure] = k
                unsure_idx[n_unsure] = mid
                n_unsure += 1
                if n_unsure >= max_unsure:
                    return UNSURE, k, mid, evaluated, n_unsure
            first = False
            if tail + 2 > size:
                live = tail - head
                qlo[:live] = qlo[head:tail].copy()
                qhi[:live] = qhi[head:tail].copy()
                head, tail = 0, live
            if a <= mid - m - 1:
                qlo[tail], qhi[tail] = a, mid - m - 1
                tail += 1
            if mid + m + 1 <= b:
                qlo[tail], qhi[tail] = mid + m + 1, b
                tail += 1
    return FREE, -1, -1, evaluated, n_unsure
