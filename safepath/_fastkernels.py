"""Numba kernels of the fast collision layer (see :mod:`safepath.fastcheck`).

Imported lazily: the first import compiles (or loads from numba's on-disk cache).
All data of one checker travels in two flat buffers, ``fb`` (float64) and ``ib`` (int64),
laid out by :func:`safepath.fastcheck.pack` (one call argument each keeps numba's
dispatch cheap: the single-state API is called millions of times by planners).

Status codes: FREE (certainly valid), COLLIDES (certainly in collision or outside the
limits), UNSURE (ask the exact checker).

Reference counts: only the entry points (``classify``, ``classify_many``,
``certify_polyline``, ``certify_segment`` and the ``_workspace`` they allocate) are
compiled with numba's reference counting; every helper below them (and those of
:mod:`safepath._gjk`) is compiled without it (``_nrt=False``): they allocate nothing and
return no arrays, and the counts numba keeps on every array a helper is passed or slices
took ~20 % of a planner's time on the Panda (``perf``: NRT_incref / NRT_decref). Such a
helper must keep to that: no array allocation, no array returned, no array-to-array slice
assignment.
"""

from __future__ import annotations

import math

import numpy as np

from ._aot import njit
from ._gjk import HULL, distance_lower_bound, distance_upper_bound

#: How the helpers are compiled (see the module doc).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")

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
#: The checker's displacement weights (floats, dof): a joint step dq moves no point of
#: the robot (or held object) more than sum(w |dq|) [m].
H_DW = 23
#: Per pair and joint (floats, pairs x dof): how fast the joint can close the pair [m per
#: unit of the joint]: body a's weight where H_PM has bit 1, plus body b's where it has
#: bit 2 (added in that order, as the masks would), else 0.
H_PW = 24
HEADER = 25
# Constants (fb[ib[H_C] + k]); C_RES: the checker's resolution [m].
C_REFINE, C_FREE_EPS, C_PROOF_EPS, C_RES = 0, 1, 2, 3
#: Status of a segment whose start (index 0) or end (index 1) is outside the limits.
OUTSIDE = 3

ENV_BOX, ENV_CYLINDER, ENV_SPHERE, ENV_CAPSULE, ENV_BOX_ONLY_OUTER = 0, 1, 2, 3, 4
#: Shape kinds of movers (same codes; HULL: a convex hull, measured by GJK on its
#: vertices; SPHERES_ONLY: no primitive, spheres decide).
SPHERES_ONLY = -1
#: Widths of a mover's rows: floats (bounding centre 3, radius 1, rotation 9, position 3
#: in the joint frame, dimensions 3) and ints (joint, outer start/end, inner start/end,
#: kind, hull vertex start/end).
GW, GIW = 19, 8
JOINT_FIXED, JOINT_REVOLUTE, JOINT_PRISMATIC = 0, 1, 2

#: Scratch of one kernel call: the joint frames ``Rw`` (nj, 3, 3) and ``pw`` (nj, 3), one
#: float buffer ``wf`` and one int buffer ``wi``. Helpers take these four arrays, never a
#: tuple of many: a numba call pays the reference counts (and copies the descriptors) of
#: every array it is passed, ~10 ns each, and the per-pair helpers run millions of times a
#: second. ``wf`` starts with fixed slots (W_*: two 3-vectors, two placed shapes, the
#: separating-axis candidates, GJK's simplex and supports, a local joint placement); the
#: per-checker blocks follow, where ``wi``'s header says (WI_*); ``wi`` then holds, per
#: pair, the hull vertices where GJK's support searches start.
W_TMP, W_TMP2, W_RA, W_PA, W_DA, W_RB, W_PB, W_DB = 0, 3, 6, 15, 18, 21, 30, 33
W_AXES, W_S, W_SA, W_SB, W_GV, W_M, W_T = 36, 108, 120, 123, 126, 129, 138
W_FIXED = 141
#: Blocks of ``wf``: world bounding-sphere centres of the movers (ng, 3); two placed sphere
#: sets (ns, 5) each; per pair, the last direction GJK found (3: the next state's first
#: guess); |u| (dof); per mover and joint, its distance to the joint's axis (DL) and how
#: fast that can grow (CC) (ng, dof); per pair, the polyline walk's ledger: the most
#: clearance budget [m] an evaluated state leaves at the end of the segment being walked
#: (npairs); per pair, the stretch of that segment it is certified along (centre and
#: half-width in units of ``t``; a negative width: none) (npairs, 2); per mover, 1 once
#: its DL row is measured at the state being evaluated, else 0 (ng).
(WI_CW, WI_BUFA, WI_BUFB, WI_WARM, WI_ABSU, WI_DL, WI_CC, WI_BUDGET, WI_CERT, WI_DLOK,
 WI_HINT) = range(11)
WI_HEADER = 11


@njit(cache=True, nogil=True)
def _workspace(ib):
    """Fresh scratch (Rw, pw, wf, wi) for the checker packed in ``ib``."""
    nj, ng, ns, npairs, dof = ib[H_NJ], ib[H_NG], ib[H_NS], ib[H_NP], ib[H_DOF]
    wi = np.empty(WI_HEADER + 2 * npairs, dtype=np.int64)
    sizes = (3 * ng, 5 * ns, 5 * ns, 3 * npairs, dof, ng * dof, ng * dof, npairs,
             2 * npairs, ng)
    o = W_FIXED
    for i in range(10):
        wi[i] = o
        o += sizes[i]
    wi[WI_HINT] = WI_HEADER
    wi[WI_HEADER:] = -1
    wf = np.empty(o)  # written before read, but for these blocks:
    wf[wi[WI_WARM]:wi[WI_WARM] + 3 * npairs] = 0.0  # no direction yet
    wf[wi[WI_DL]:wi[WI_BUDGET]] = 0.0  # DL, CC of joints that do not move a mover
    return np.empty((nj, 3, 3)), np.empty((nj, 3)), wf, wi


@_helper
def _fk(q, fb, ib, Rw, pw, wf):  # noqa: N803
    """World rotation and position of every joint frame at ``q`` into Rw (nj,3,3), pw (nj,3)."""
    nj = ib[H_NJ]
    oj, oji = ib[H_J], ib[H_JI]
    Rw[0, :, :] = 0.0
    Rw[0, 0, 0] = Rw[0, 1, 1] = Rw[0, 2, 2] = 1.0
    pw[0, :] = 0.0
    M, t = W_M, W_T  # the local placement, rows of M at wf[M + 3 r]
    for j in range(1, nj):
        base = oj + 15 * j
        parent = ib[oji + 3 * j]
        kind = ib[oji + 3 * j + 1]
        # Local placement (joint placement times the joint's own motion).
        for r in range(3):
            for c in range(3):
                wf[M + 3 * r + c] = fb[base + 3 * r + c]
            wf[t + r] = fb[base + 9 + r]
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
                    m0, m1, m2 = wf[M + 3 * r], wf[M + 3 * r + 1], wf[M + 3 * r + 2]
                    wf[M + 3 * r] = m0 * R00 + m1 * R10 + m2 * R20
                    wf[M + 3 * r + 1] = m0 * R01 + m1 * R11 + m2 * R21
                    wf[M + 3 * r + 2] = m0 * R02 + m1 * R12 + m2 * R22
            else:
                for r in range(3):
                    wf[t + r] += (wf[M + 3 * r] * ax + wf[M + 3 * r + 1] * ay
                                  + wf[M + 3 * r + 2] * az) * x
        for r in range(3):
            pw[j, r] = (Rw[parent, r, 0] * wf[t] + Rw[parent, r, 1] * wf[t + 1]
                        + Rw[parent, r, 2] * wf[t + 2] + pw[parent, r])
            for c in range(3):
                Rw[j, r, c] = (Rw[parent, r, 0] * wf[M + c] + Rw[parent, r, 1] * wf[M + 3 + c]
                               + Rw[parent, r, 2] * wf[M + 6 + c])


@_inlined
def _world(fb, s, Rw, pw, j, wf, o):  # noqa: N803
    """World centre of the sphere/point at fb[s:s+3] (frame of joint ``j``) into wf[o:o+3]."""
    x, y, z = fb[s], fb[s + 1], fb[s + 2]
    for r in range(3):
        wf[o + r] = Rw[j, r, 0] * x + Rw[j, r, 1] * y + Rw[j, r, 2] * z + pw[j, r]


@_helper
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


@_inlined
def _support(kind, wf, o, d, nx, ny, nz):  # noqa: N803
    """Half extent [m] along unit n of a primitive placed in ``wf`` (rotation rows at
    wf[o:o+9], dimensions at wf[d:d+3])."""
    if kind == ENV_BOX or kind == ENV_BOX_ONLY_OUTER:
        return (wf[d] * abs(wf[o] * nx + wf[o + 3] * ny + wf[o + 6] * nz)
                + wf[d + 1] * abs(wf[o + 1] * nx + wf[o + 4] * ny + wf[o + 7] * nz)
                + wf[d + 2] * abs(wf[o + 2] * nx + wf[o + 5] * ny + wf[o + 8] * nz))
    if kind == ENV_SPHERE:
        return wf[d]
    c = wf[o + 2] * nx + wf[o + 5] * ny + wf[o + 8] * nz
    if kind == ENV_CAPSULE:
        return wf[d + 1] * abs(c) + wf[d]
    return wf[d + 1] * abs(c) + wf[d] * math.sqrt(max(0.0, 1.0 - c * c))


@_inlined
def _primitive_axes(kind, wf, o, n):  # noqa: N803
    """Append the own axes of the primitive whose rotation is at wf[o:o+9] (box: its three
    face normals; cylinder, capsule: its z axis) to the candidate axes from row ``n``;
    returns the new row count."""
    if kind == ENV_BOX or kind == ENV_BOX_ONLY_OUTER:
        for c in range(3):
            x = W_AXES + 3 * n
            wf[x], wf[x + 1], wf[x + 2] = wf[o + c], wf[o + 3 + c], wf[o + 6 + c]
            n += 1
    elif kind == ENV_CYLINDER or kind == ENV_CAPSULE:
        x = W_AXES + 3 * n
        wf[x], wf[x + 1], wf[x + 2] = wf[o + 2], wf[o + 5], wf[o + 8]
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
    W_RA, W_PA, W_DA; B at W_RB, W_PB, W_DB): the largest gap between their projections
    over a set of separating-axis candidates (face normals, primitive axes, their cross
    products, the centre line). For two boxes the 15 axes are complete: a bound < 0 then
    means they intersect."""
    na = _primitive_axes(ka, wf, W_RA, 0)
    nb = _primitive_axes(kb, wf, W_RB, na)
    n = nb
    for i in range(na):
        oi = W_AXES + 3 * i
        for j in range(na, nb):
            oj = W_AXES + 3 * j
            n = _push_axis(wf, n, wf[oi + 1] * wf[oj + 2] - wf[oi + 2] * wf[oj + 1],
                           wf[oi + 2] * wf[oj] - wf[oi] * wf[oj + 2],
                           wf[oi] * wf[oj + 1] - wf[oi + 1] * wf[oj])
    dx, dy, dz = wf[W_PB] - wf[W_PA], wf[W_PB + 1] - wf[W_PA + 1], wf[W_PB + 2] - wf[W_PA + 2]
    n = _push_axis(wf, n, dx, dy, dz)
    # Round shapes: the centre line's part across each axis.
    for which in range(2):
        kind = ka if which == 0 else kb
        if kind == ENV_CYLINDER or kind == ENV_CAPSULE:
            o = W_RA if which == 0 else W_RB
            ax, ay, az = wf[o + 2], wf[o + 5], wf[o + 8]
            t = dx * ax + dy * ay + dz * az
            n = _push_axis(wf, n, dx - t * ax, dy - t * ay, dz - t * az)
    best = -1e300
    for i in range(n):
        o = W_AXES + 3 * i
        x, y, z = wf[o], wf[o + 1], wf[o + 2]
        gap = (abs(dx * x + dy * y + dz * z)
               - _support(ka, wf, W_RA, W_DA, x, y, z)
               - _support(kb, wf, W_RB, W_DB, x, y, z))
        if gap > best:
            best = gap
    return best


@_inlined
def _mover_frame(fb, ib, m, Rw, pw, wf, oR, op):  # noqa: N803
    """World rotation (rows at wf[oR:oR+9]) and position (wf[op:op+3]) of mover ``m``'s
    primitive."""
    og = ib[H_G] + GW * m
    j = ib[ib[H_GI] + GIW * m]
    for r in range(3):
        wf[op + r] = (Rw[j, r, 0] * fb[og + 13] + Rw[j, r, 1] * fb[og + 14]
                      + Rw[j, r, 2] * fb[og + 15] + pw[j, r])
        for c in range(3):
            wf[oR + 3 * r + c] = (Rw[j, r, 0] * fb[og + 4 + c] + Rw[j, r, 1] * fb[og + 7 + c]
                                  + Rw[j, r, 2] * fb[og + 10 + c])


@_helper
def _place_pair(fb, ib, a, b, is_env, Rw, pw, wf):  # noqa: N803
    """Place mover ``a``'s shape (W_RA, W_PA, W_DA) and environment object (``is_env``) or
    mover ``b``'s shape (W_RB, W_PB, W_DB) in ``wf`` at the state of Rw, pw; returns their
    kinds."""
    og, ogi = ib[H_G], ib[H_GI]
    ka = ib[ogi + GIW * a + 5]
    _mover_frame(fb, ib, a, Rw, pw, wf, W_RA, W_PA)
    for r in range(3):
        wf[W_DA + r] = fb[og + GW * a + 16 + r]
    if is_env == 1:
        oe = ib[H_E] + 15 * b
        kb = ib[ib[H_EI] + b]
        for r in range(3):
            wf[W_PB + r] = fb[oe + 9 + r]
            wf[W_DB + r] = fb[oe + 12 + r]
            for c in range(3):
                wf[W_RB + 3 * r + c] = fb[oe + 3 * r + c]
    else:
        kb = ib[ogi + GIW * b + 5]
        _mover_frame(fb, ib, b, Rw, pw, wf, W_RB, W_PB)
        for r in range(3):
            wf[W_DB + r] = fb[og + GW * b + 16 + r]
    return ka, kb


@_helper
def _sat_pair(fb, ib, a, b, is_env, Rw, pw, wf):  # noqa: N803
    """Separating-axis bound [m] between mover ``a``'s primitive and environment object
    (``is_env``) or mover ``b``'s primitive, at the state of Rw, pw."""
    ka, kb = _place_pair(fb, ib, a, b, is_env, Rw, pw, wf)
    return _sat_gap(ka, kb, wf)


@_helper
def _gjk_pair(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, low, high):  # noqa: N803
    """GJK's distance lower bound [m] between mover ``a``'s shape and environment object
    or mover ``b``'s (pair ``k``; its last direction warm-starts the search), searched
    until it reaches ``high`` or the distance is known to be at most ``low``."""
    ogi = ib[H_GI]
    ka, kb = _place_pair(fb, ib, a, b, is_env, Rw, pw, wf)
    va0, va1 = ib[ogi + GIW * a + 6], ib[ogi + GIW * a + 7]
    vb0 = vb1 = 0
    if is_env == 0:
        vb0, vb1 = ib[ogi + GIW * b + 6], ib[ogi + GIW * b + 7]
    ow, oh = wi[WI_WARM] + 3 * k, wi[WI_HINT] + 2 * k
    return distance_lower_bound(ka, wf[W_RA:W_RA + 9].reshape((3, 3)), wf[W_PA:W_PA + 3],
                                wf[W_DA:W_DA + 3], va0, va1, kb,
                                wf[W_RB:W_RB + 9].reshape((3, 3)), wf[W_PB:W_PB + 3],
                                wf[W_DB:W_DB + 3], vb0, vb1, fb, ib[H_V], ib, ib[H_AP],
                                ib[H_AI], wi[oh:oh + 2], wf[ow:ow + 3],
                                wf[W_S:W_S + 12].reshape((4, 3)), wf[W_SA:W_SA + 3],
                                wf[W_SB:W_SB + 3], wf[W_GV:W_GV + 3], wf[W_TMP:W_TMP + 3],
                                low, high)


@_helper
def _gjk_overlap(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, goal):  # noqa: N803
    """GJK's upper bound [m] on the signed distance of pair ``k``'s shapes (negative: they
    overlap at least that deep), searched until it is below ``goal``."""
    ogi = ib[H_GI]
    ka, kb = _place_pair(fb, ib, a, b, is_env, Rw, pw, wf)
    va0, va1 = ib[ogi + GIW * a + 6], ib[ogi + GIW * a + 7]
    vb0 = vb1 = 0
    if is_env == 0:
        vb0, vb1 = ib[ogi + GIW * b + 6], ib[ogi + GIW * b + 7]
    ow, oh = wi[WI_WARM] + 3 * k, wi[WI_HINT] + 2 * k
    return distance_upper_bound(ka, wf[W_RA:W_RA + 9].reshape((3, 3)), wf[W_PA:W_PA + 3],
                                wf[W_DA:W_DA + 3], va0, va1, kb,
                                wf[W_RB:W_RB + 9].reshape((3, 3)), wf[W_PB:W_PB + 3],
                                wf[W_DB:W_DB + 3], vb0, vb1, fb, ib[H_V], ib, ib[H_AP],
                                ib[H_AI], wi[oh:oh + 2], wf[ow:ow + 3],
                                wf[W_S:W_S + 12].reshape((4, 3)), wf[W_SA:W_SA + 3],
                                wf[W_SB:W_SB + 3], wf[W_GV:W_GV + 3], wf[W_TMP:W_TMP + 3],
                                goal)


@_helper
def _pair_bound(k, fb, ib, Rw, pw, wf, wi, enough):  # noqa: N803
    """Lower bound [m] on the distance of pair ``k`` finer than its bounding spheres
    (placed in wf's WI_CW block by the caller): the separating-axis bound of two
    primitives, GJK's when one is a hull, or the fine spheres of a body that is no
    primitive. A bound of ``enough`` (beyond the pair's margin) is sufficient for the
    caller."""
    op, of = ib[H_PI] + 4 * k, ib[H_P] + k
    a, b, is_env = ib[op], ib[op + 1], ib[op + 2]
    sm = max(fb[of], 0.0)
    og, oS, ogi = ib[H_G], ib[H_S], ib[H_GI]
    ka = ib[ogi + GIW * a + 5]
    kb = ENV_BOX if is_env == 1 else ib[ogi + GIW * b + 5]
    if ka != SPHERES_ONLY and kb != SPHERES_ONLY:
        if ka == HULL or kb == HULL:
            return _gjk_pair(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, sm, sm + enough)
        return _sat_pair(fb, ib, a, b, is_env, Rw, pw, wf)
    ja = ib[ogi + GIW * a]
    if is_env == 1:
        best = 1e300
        for s in range(ib[ogi + GIW * a + 1], ib[ogi + GIW * a + 2]):
            _world(fb, oS + 4 * s, Rw, pw, ja, wf, W_TMP)
            d = (_env_sdist3(fb, ib, b, wf[W_TMP], wf[W_TMP + 1], wf[W_TMP + 2])
                 - fb[oS + 4 * s + 3])
            if d < best:
                best = d
                if best - sm <= 0.0:
                    return best
        return best
    ra, rb = fb[og + GW * a + 3], fb[og + GW * b + 3]
    ocw = wi[WI_CW]
    cbx, cby, cbz = wf[ocw + 3 * b], wf[ocw + 3 * b + 1], wf[ocw + 3 * b + 2]
    ca0, ca1, ca2 = wf[ocw + 3 * a], wf[ocw + 3 * a + 1], wf[ocw + 3 * a + 2]
    # Two sphere sets: place each once, bound each sphere against the other body's
    # bounding sphere, take one real pair distance as an upper bound, and compare only
    # the spheres whose bound beats it.
    A, B = wi[WI_BUFA], wi[WI_BUFB]  # rows of 5 in wf
    na = _place_spheres(fb, ib, a, Rw, pw, cbx, cby, cbz, rb, wf, A)
    nb = _place_spheres(fb, ib, b, Rw, pw, ca0, ca1, ca2, ra, wf, B)
    sa = 0
    for i in range(1, na):
        if wf[A + 5 * i + 4] < wf[A + 5 * sa + 4]:
            sa = i
    sb = 0
    for i in range(1, nb):
        if wf[B + 5 * i + 4] < wf[B + 5 * sb + 4]:
            sb = i
    i0, j0 = A + 5 * sa, B + 5 * sb
    best = (math.sqrt((wf[i0] - wf[j0]) ** 2 + (wf[i0 + 1] - wf[j0 + 1]) ** 2
                      + (wf[i0 + 2] - wf[j0 + 2]) ** 2) - wf[i0 + 3] - wf[j0 + 3])
    for i in range(na):
        i0 = A + 5 * i
        if wf[i0 + 4] >= best:
            continue
        for j in range(nb):
            j0 = B + 5 * j
            if wf[j0 + 4] >= best:
                continue
            d = (math.sqrt((wf[i0] - wf[j0]) ** 2 + (wf[i0 + 1] - wf[j0 + 1]) ** 2
                           + (wf[i0 + 2] - wf[j0 + 2]) ** 2) - wf[i0 + 3] - wf[j0 + 3])
            if d < best:
                best = d
                if best - sm <= 0.0:
                    return best
    return best


@_helper
def _place_spheres(fb, ib, m, Rw, pw, ox, oy, oz, orad, wf, out):  # noqa: N803
    """World centres and radii of mover ``m``'s outer spheres into rows of 5 of ``wf`` from
    ``out`` (x, y, z, r, lower bound of the distance to the sphere (ox, oy, oz, orad));
    returns the count."""
    oS, ogi = ib[H_S], ib[H_GI]
    j = ib[ogi + GIW * m]
    n = 0
    for s in range(ib[ogi + GIW * m + 1], ib[ogi + GIW * m + 2]):
        x, y, z = fb[oS + 4 * s], fb[oS + 4 * s + 1], fb[oS + 4 * s + 2]
        wx = Rw[j, 0, 0] * x + Rw[j, 0, 1] * y + Rw[j, 0, 2] * z + pw[j, 0]
        wy = Rw[j, 1, 0] * x + Rw[j, 1, 1] * y + Rw[j, 1, 2] * z + pw[j, 1]
        wz = Rw[j, 2, 0] * x + Rw[j, 2, 1] * y + Rw[j, 2, 2] * z + pw[j, 2]
        r = fb[oS + 4 * s + 3]
        o = out + 5 * n
        wf[o], wf[o + 1], wf[o + 2], wf[o + 3] = wx, wy, wz, r
        wf[o + 4] = math.sqrt((wx - ox) ** 2 + (wy - oy) ** 2 + (wz - oz) ** 2) - r - orad
        n += 1
    return n


@_helper
def _pair_collides(k, fb, ib, eps, Rw, pw, wf, wi):  # noqa: N803
    """Whether pair ``k`` is certainly closer than its margin: an inner sphere reaches
    that close, (two boxes, no margin) the complete separating-axis test fails, or (two
    exact shapes: primitives or convex hulls) GJK's upper bound on their signed distance
    is below it."""
    op, of = ib[H_PI] + 4 * k, ib[H_P] + k
    a, b, is_env, proof = ib[op], ib[op + 1], ib[op + 2], ib[op + 3]
    if proof == 0:
        return False
    sm = fb[of]
    oS, ogi = ib[H_S], ib[H_GI]
    ja = ib[ogi + GIW * a]
    ka = ib[ogi + GIW * a + 5]
    t1, t2 = W_TMP, W_TMP2
    if is_env == 1:
        if (sm == 0.0 and ka == ENV_BOX and ib[ib[H_EI] + b] == ENV_BOX
                and _sat_pair(fb, ib, a, b, 1, Rw, pw, wf) < -eps):
            return True
        for s in range(ib[ogi + GIW * a + 3], ib[ogi + GIW * a + 4]):
            _world(fb, oS + 4 * s, Rw, pw, ja, wf, t1)
            if (_env_sdist3(fb, ib, b, wf[t1], wf[t1 + 1], wf[t1 + 2]) - fb[oS + 4 * s + 3]
                    < sm - eps):
                return True
        # An object measured by the box around it (ENV_BOX_ONLY_OUTER) proves nothing.
        return (ka != SPHERES_ONLY and ib[ib[H_EI] + b] != ENV_BOX_ONLY_OUTER
                and _gjk_overlap(fb, ib, k, a, b, 1, Rw, pw, wf, wi, sm - eps) < sm - eps)
    jb = ib[ogi + GIW * b]
    kb = ib[ogi + GIW * b + 5]
    if (sm == 0.0 and ka == ENV_BOX and kb == ENV_BOX
            and _sat_pair(fb, ib, a, b, 0, Rw, pw, wf) < -eps):
        return True
    for s in range(ib[ogi + GIW * a + 3], ib[ogi + GIW * a + 4]):
        _world(fb, oS + 4 * s, Rw, pw, ja, wf, t1)
        rs = fb[oS + 4 * s + 3]
        for t in range(ib[ogi + GIW * b + 3], ib[ogi + GIW * b + 4]):
            _world(fb, oS + 4 * t, Rw, pw, jb, wf, t2)
            d = math.sqrt((wf[t1] - wf[t2]) ** 2 + (wf[t1 + 1] - wf[t2 + 1]) ** 2
                          + (wf[t1 + 2] - wf[t2 + 2]) ** 2) - rs - fb[oS + 4 * t + 3]
            if d < sm - eps:
                return True
    return (ka != SPHERES_ONLY and kb != SPHERES_ONLY
            and _gjk_overlap(fb, ib, k, a, b, 0, Rw, pw, wf, wi, sm - eps) < sm - eps)


@_helper
def _evaluate(q, fb, ib, Rw, pw, wf, wi, rates, want_radius, need, t):  # noqa: N803
    """(status, radius) of one state inside the limits. With ``want_radius``, ``q`` is
    the state at ``t`` of a segment walked along ``u`` and radius is the largest ``h``
    such that every state ``q + t' u`` with ``|t'| < h`` is certainly valid,
    ``rates[k]`` bounding how fast pair ``k`` can close per unit ``t`` (and wf's
    WI_ABSU block filled by ``_pair_rates``, WI_CC by ``_axis_growth``), or some radius
    of at least ``need`` when that is all the caller can use: pairs whose closing-rate
    radius reaches ``need`` skip the finer local radius, and a pair is not evaluated at
    all when the stretch an earlier state of the segment certified for it (wf's WI_CERT
    block, which this updates) covers ``need`` either side of ``t``."""
    _fk(q, fb, ib, Rw, pw, wf)
    oc = ib[H_C]
    refine, free_eps, proof_eps = fb[oc + C_REFINE], fb[oc + C_FREE_EPS], fb[oc + C_PROOF_EPS]
    if not want_radius:
        refine = 0.0
    og, ogi, op_, of_ = ib[H_G], ib[H_GI], ib[H_PI], ib[H_P]
    ocw, obud = wi[WI_CW], wi[WI_BUDGET]
    odl, occ, oabs = wi[WI_DL], wi[WI_CC], wi[WI_ABSU]
    # Bounding spheres of the movers, in the world.
    for m in range(ib[H_NG]):
        j = ib[ogi + GIW * m]
        x, y, z = fb[og + GW * m], fb[og + GW * m + 1], fb[og + GW * m + 2]
        for r in range(3):
            wf[ocw + 3 * m + r] = (Rw[j, r, 0] * x + Rw[j, r, 1] * y + Rw[j, r, 2] * z
                                   + pw[j, r])
    odlok = wi[WI_DLOK]
    if want_radius:
        for m in range(ib[H_NG]):  # measured when a pair first needs them
            wf[odlok + m] = 0.0
    unsure = False
    radius = 1e300
    oe, oer, ocert = ib[H_E], ib[H_ER], wi[WI_CERT]
    for k in range(ib[H_NP]):
        if want_radius:
            # Free for every state within ``need`` of this one: its bound is no limit.
            c, w = wf[ocert + 2 * k], wf[ocert + 2 * k + 1]
            if t - need > c - w and t + need < c + w:
                if need < radius:
                    radius = need
                continue
        a, b, is_env = ib[op_ + 4 * k], ib[op_ + 4 * k + 1], ib[op_ + 4 * k + 2]
        sm = max(fb[of_ + k], 0.0)
        cax, cay, caz = wf[ocw + 3 * a], wf[ocw + 3 * a + 1], wf[ocw + 3 * a + 2]
        if is_env == 1:
            if not want_radius:
                # Broad phase: bounding spheres apart by more than the margin decide the
                # pair (free) without measuring the object.
                dx = cax - fb[oe + 15 * b + 9]
                dy = cay - fb[oe + 15 * b + 10]
                dz = caz - fb[oe + 15 * b + 11]
                reach = fb[og + GW * a + 3] + fb[oer + b] + sm + free_eps
                if dx * dx + dy * dy + dz * dz > reach * reach:
                    continue
            coarse = _env_sdist3(fb, ib, b, cax, cay, caz) - fb[og + GW * a + 3]
        else:
            dd = ((cax - wf[ocw + 3 * b]) ** 2 + (cay - wf[ocw + 3 * b + 1]) ** 2
                  + (caz - wf[ocw + 3 * b + 2]) ** 2)
            rr = fb[og + GW * a + 3] + fb[og + GW * b + 3]
            if not want_radius and dd > (rr + sm + free_eps) ** 2:
                continue
            coarse = math.sqrt(dd) - rr
        budget = coarse - sm - free_eps
        if budget <= refine:
            budget = max(coarse, _pair_bound(k, fb, ib, Rw, pw, wf, wi,
                                             refine + free_eps)) - sm - free_eps
        if budget <= 0.0:
            if _pair_collides(k, fb, ib, proof_eps, Rw, pw, wf, wi):
                return COLLIDES, 0.0
            unsure = True
            continue
        if not want_radius:
            continue
        left = budget - rates[k] * (1.0 - t)  # at the segment's end
        if left > wf[obud + k]:
            wf[obud + k] = left
        h = 1e300  # a pair the segment does not move stays free along all of it
        if rates[k] > 0.0:
            h = budget / rates[k]
            if h < need:
                if wf[odlok + a] == 0.0:
                    _axis_distances(a, fb, ib, Rw, pw, wf, ocw, odl)
                    wf[odlok + a] = 1.0
                if is_env == 0 and wf[odlok + b] == 0.0:
                    _axis_distances(b, fb, ib, Rw, pw, wf, ocw, odl)
                    wf[odlok + b] = 1.0
                h = max(h, _local_radius(k, a, b, budget, ib, wf, odl, occ, oabs))
            if h < radius:
                radius = h
        wf[ocert + 2 * k] = t
        wf[ocert + 2 * k + 1] = h * (1.0 - 1e-12)
    if unsure:
        return UNSURE, 0.0
    return FREE, radius


@_inlined
def _axis_distances(m, fb, ib, Rw, pw, wf, ocw, odl):  # noqa: N803
    """DL[m, v] (wf from ``odl``, rows of dof): how fast [m per unit of joint v] mover
    ``m``'s points move when joint ``v`` alone moves, at the state placed in Rw, pw and
    the bounding centres (wf from ``ocw``): the distance of its bounding sphere from the
    joint's axis plus its radius (revolute), 1 (prismatic)."""
    oj, oji, og, ogi = ib[H_J], ib[H_JI], ib[H_G], ib[H_GI]
    dof = ib[H_DOF]
    r_m = fb[og + GW * m + 3]
    j = ib[ogi + GIW * m]
    while j > 0:
        v = ib[oji + 3 * j + 2]
        if ib[oji + 3 * j + 1] == JOINT_PRISMATIC:
            wf[odl + m * dof + v] = 1.0
        else:
            base = oj + 15 * j
            ax, ay, az = fb[base + 12], fb[base + 13], fb[base + 14]
            ux = Rw[j, 0, 0] * ax + Rw[j, 0, 1] * ay + Rw[j, 0, 2] * az
            uy = Rw[j, 1, 0] * ax + Rw[j, 1, 1] * ay + Rw[j, 1, 2] * az
            uz = Rw[j, 2, 0] * ax + Rw[j, 2, 1] * ay + Rw[j, 2, 2] * az
            dx = wf[ocw + 3 * m] - pw[j, 0]
            dy = wf[ocw + 3 * m + 1] - pw[j, 1]
            dz = wf[ocw + 3 * m + 2] - pw[j, 2]
            cx, cy, cz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
            wf[odl + m * dof + v] = math.sqrt(cx * cx + cy * cy + cz * cz) + r_m
        j = ib[oji + 3 * j]


@_inlined
def _local_radius(k, a, b, budget, ib, wf, odl, occ, oabs):  # noqa: N803
    """A radius (in units of ``t``) within which pair ``k`` cannot close by ``budget`` [m],
    from the bodies' distances to the joint axes at this state (DL, see
    ``_axis_distances``), which grow along the segment by at most CC per unit of ``t``
    (wf from ``odl``, ``occ``; |u| from ``oabs``): the closing speed is at most
    A + B |t|, so the radius solves A h + B h^2 / 2 = budget."""
    dof, opm = ib[H_DOF], ib[H_PM] + k * ib[H_DOF]
    A = B = 0.0
    for v in range(dof):
        au = wf[oabs + v]
        if au == 0.0:
            continue
        mask = ib[opm + v]
        if mask & 1:
            A += au * wf[odl + a * dof + v]
            B += au * wf[occ + a * dof + v]
        if mask & 2:
            A += au * wf[odl + b * dof + v]
            B += au * wf[occ + b * dof + v]
    if A <= 0.0:
        return 0.0
    if B <= 1e-12 * A:
        return budget / A
    return (math.sqrt(A * A + 2.0 * B * budget) - A) / B


@_helper
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
    Rw, pw, wf, wi = _workspace(ib)
    status, _ = _evaluate(q, fb, ib, Rw, pw, wf, wi, wf, False, 0.0, 0.0)
    return status


@njit(cache=True, nogil=True)
def classify_many(Q, fb, ib, out):  # noqa: N803
    """Status of every row of ``Q`` into ``out``."""
    Rw, pw, wf, wi = _workspace(ib)
    for i in range(Q.shape[0]):
        if not _within_limits(Q[i], fb, ib):
            out[i] = COLLIDES
            continue
        out[i], _ = _evaluate(Q[i], fb, ib, Rw, pw, wf, wi, wf, False, 0.0, 0.0)


@_helper
def _pair_rates(u, fb, ib, wf, wi, rates):  # noqa: N803
    """Per pair, a bound on how fast its two bodies approach per unit of ``t`` along
    the joint-space direction ``u`` [m] (joints that carry both bodies leave their
    distance alone: their H_PW weight is 0). Also wf's WI_ABSU block = |u|."""
    dof, opw = ib[H_DOF], ib[H_PW]
    oabs = wi[WI_ABSU]
    for v in range(dof):
        wf[oabs + v] = abs(u[v])
    for k in range(ib[H_NP]):
        row = opw + k * dof
        r = 0.0
        for v in range(dof):
            r += fb[row + v] * wf[oabs + v]
        rates[k] = r


@_helper
def _axis_growth(fb, ib, wf, wi):  # noqa: N803
    """Per mover and joint, wf's WI_CC block: how fast the mover's distance to that
    joint's axis can grow per unit of ``t`` along the direction whose |u| is in the
    WI_ABSU block (the joints between the two move it, at most by their weights).
    Only an evaluation with a radius reads it."""
    dof, ow, oji, ogi = ib[H_DOF], ib[H_W], ib[H_JI], ib[H_GI]
    oabs, occ = wi[WI_ABSU], wi[WI_CC]
    for m in range(ib[H_NG]):
        acc = 0.0
        j = ib[ogi + GIW * m]
        while j > 0:
            v = ib[oji + 3 * j + 2]
            wf[occ + m * dof + v] = 0.0 if ib[oji + 3 * j + 1] == JOINT_PRISMATIC else acc
            acc += fb[ow + m * dof + v] * wf[oabs + v]
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
    Rw, pw, wf, wi = _workspace(ib)
    obud, ocert = wi[WI_BUDGET], wi[WI_CERT]
    rates = np.empty(npairs)
    u = np.empty(dof)
    qs = np.empty(dof)
    n_unsure = 0
    evaluated = 0
    # The ledger (wf's WI_BUDGET block): per pair, the most clearance budget [m] left at
    # the start of the segment by any state evaluated before it (its budget less what
    # the path since may have closed: the pair's rate times the path walked, segment by
    # segment), none (<= 0) yet. A pair within its budget over a whole segment is not
    # evaluated there; a segment within every pair's is certified without an evaluation
    # (short chords of a sampled curve).
    for p in range(npairs):
        wf[obud + p] = -1.0
    # FIFO of disjoint, non-empty index ranges still to cover (coarse to fine), made once
    # for the longest segment: a segment's live ranges and the two it adds fit in it.
    room = 3
    for k in range(P.shape[0] - 1):
        room = max(room, hi[k] - lo[k] + 3)
    qlo = np.empty(room, dtype=np.int64)
    qhi = np.empty(room, dtype=np.int64)
    for k in range(P.shape[0] - 1):
        for j in range(dof):
            u[j] = P[k + 1, j] - P[k, j]
        _pair_rates(u, fb, ib, wf, wi, rates)
        whole = hi[k] < lo[k]  # no state of this segment to check
        if not whole:
            whole = True
            for p in range(npairs):
                if wf[obud + p] - rates[p] <= 0.0:
                    whole = False
                    break
        if whole:
            for p in range(npairs):
                wf[obud + p] -= rates[p]
            continue
        # Each pair starts certified from the segment's start as far as its budget
        # lasts; the ledger becomes what that budget leaves at the segment's end (the
        # evaluations below raise it).
        for p in range(npairs):
            left = wf[obud + p]
            width = -1.0
            if left > 0.0:
                width = 1e300 if rates[p] == 0.0 else left / rates[p] * (1.0 - 1e-12)
            wf[ocert + 2 * p] = 0.0
            wf[ocert + 2 * p + 1] = width
            wf[obud + p] = left - rates[p]
        _axis_growth(fb, ib, wf, wi)  # for this segment's evaluations
        nk = n[k]
        head, tail = 0, 1
        qlo[0], qhi[0] = lo[k], hi[k]
        while head < tail:
            a, b = qlo[head], qhi[head]
            head += 1
            mid = (a + b) // 2
            t = mid / nk
            for j in range(dof):
                qs[j] = P[k, j] + t * u[j]
            # A radius covering the rest of [a, b] is all this walk can use.
            need = (max(mid - a, b - mid) + 0.5) / nk
            status, radius = _evaluate(qs, fb, ib, Rw, pw, wf, wi, rates, True, need, t)
            evaluated += 1
            if status == COLLIDES:
                return COLLIDES, k, mid, evaluated, n_unsure
            m = 0
            if status == FREE:
                # Grid states with |i - mid| / nk < radius are certified.
                reach = radius * nk * (1.0 - 1e-12)
                m = nk if reach >= nk else max(int(math.ceil(reach)) - 1, 0)
            else:
                unsure_seg[n_unsure] = k
                unsure_idx[n_unsure] = mid
                n_unsure += 1
                if n_unsure >= max_unsure:
                    return UNSURE, k, mid, evaluated, n_unsure
            if tail + 2 > room:
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


@njit(cache=True, nogil=True)
def certify_segment(q0, q1, fb, ib, skip_start, skip_end, unsure_idx):  # noqa: N803
    """One straight segment, as :func:`certify_polyline` walks it, with what its caller
    would otherwise do in Python around it (the planners' edge check: ~60 % of its time
    went there): the limits at both ends, the grid count from the displacement weights
    and the resolution, states 0 (unless ``skip_start``) to n (n - 1 with ``skip_end``).
    The walk stops once it has left ``len(unsure_idx)`` states undecided, their grid
    indices written there in the order found.

    Returns:
        (status, index, evaluated, unsure, n): OUTSIDE with index 0 (start) or 1 (end);
        COLLIDES with the colliding grid index; UNSURE or FREE as certify_polyline, with
        ``unsure`` undecided states found (FREE: all of them; UNSURE: the walk stopped).
    """
    if not _within_limits(q0, fb, ib):
        return OUTSIDE, 0, 0, 0, 0
    if not _within_limits(q1, fb, ib):
        return OUTSIDE, 1, 0, 0, 0
    dof, odw = ib[H_DOF], ib[H_DW]
    bound = 0.0
    for j in range(dof):
        bound += fb[odw + j] * abs(q1[j] - q0[j])
    n = max(1, int(math.ceil(bound / fb[ib[H_C] + C_RES])))
    P = np.empty((2, dof))
    for j in range(dof):
        P[0, j], P[1, j] = q0[j], q1[j]
    counts = np.full(1, n, dtype=np.int64)
    lo = np.full(1, 1 if skip_start else 0, dtype=np.int64)
    hi = np.full(1, n - 1 if skip_end else n, dtype=np.int64)
    seg = np.empty(max(unsure_idx.shape[0], 1), dtype=np.int64)
    status, _, i, evaluated, unsure = certify_polyline(P, counts, lo, hi, fb, ib, seg,
                                                       unsure_idx, unsure_idx.shape[0])
    return status, i, evaluated, unsure, n
