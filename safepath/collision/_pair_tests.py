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
from ._gjk import HULL, distance_lower_bound, distance_upper_bound, table_kind
from ._layout import (
    ENV_BOX,
    ENV_BOX_ONLY_OUTER,
    SPHERES_ONLY,
)
from ._placement import _mover_frame, _place_spheres, _sphere_world
from ._records import (
    A,
    B,
    axis,
    bound_centre,
    env_dims,
    env_kind,
    env_position,
    env_rotation,
    inner_spheres,
    mover_dims,
    mover_hull,
    mover_joint,
    mover_kind,
    mover_radius,
    outer_spheres,
    pair,
    pair_margin,
    place,
    placed_axis,
    placed_dims,
    placed_position,
    placed_rotation_start,
    placed_sphere,
    placed_sphere_bound,
    set_axis,
    sphere_radius,
)

#: How the helpers are compiled (see :mod:`safepath.collision._kernels`).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_helper
def _env_sdist3(fb, ib, e, px, py, pz):  # noqa: N803
    """Signed distance [m] from world point (px, py, pz) to environment object ``e`` (for
    ENV_BOX_ONLY_OUTER: to a box that encloses it, a lower bound)."""
    R = env_rotation(fb, ib, e)  # noqa: N806
    tx, ty, tz = env_position(fb, ib, e)
    dx = px - tx
    dy = py - ty
    dz = pz - tz
    # Local coordinates: R^T (p - t).
    x = R.r00 * dx + R.r10 * dy + R.r20 * dz
    y = R.r01 * dx + R.r11 * dy + R.r21 * dz
    z = R.r02 * dx + R.r12 * dy + R.r22 * dz
    a, b, c = env_dims(fb, ib, e)
    kind = env_kind(ib, e)
    return signed_distance(table_kind(kind), a, b, c, x, y, z)


@_inlined
def _support(kind, s, d0, d1, d2, wf, nx, ny, nz):  # noqa: N803
    """Half extent [m] along unit n of the primitive placed as shape ``s`` (A or B), of
    dimensions (d0, d1, d2)."""
    return extent(table_kind(kind), d0, d1, d2, wf,
                  placed_rotation_start(s), nx, ny, nz)


@_inlined
def _primitive_axes(kind, s, wf, n):  # noqa: N803
    """Append the own axes of the primitive placed as shape ``s`` (box: its three face
    normals; cylinder, capsule: its z axis) to the candidate axes from row ``n``; returns
    the new row count."""
    first, count = own_axes(table_kind(kind))
    if count == 3:  # columns first .. first + 2, unrolled
        for c in range(3):
            x, y, z = placed_axis(wf, s, first + c)
            set_axis(wf, n, x, y, z)
            n += 1
    elif count == 1:
        x, y, z = placed_axis(wf, s, first)
        set_axis(wf, n, x, y, z)
        n += 1
    return n


@_inlined
def _push_axis(wf, n, x, y, z):  # noqa: N803
    """Append (x, y, z) normalised to the candidate axes unless it is ~0; the row count."""
    norm = math.sqrt(x * x + y * y + z * z)
    if norm > 1e-9:
        set_axis(wf, n, x / norm, y / norm, z / norm)
        n += 1
    return n


@_helper
def _sat_gap(ka, kb, wf):  # noqa: N803
    """Lower bound [m] on the distance of the two convex primitives placed in ``wf`` (A
    and B): the largest gap between their projections over a set of separating-axis
    candidates (face normals, primitive axes, their cross products, the centre line).
    For two boxes the 15 axes are complete: a bound < 0 then means they intersect."""
    na = _primitive_axes(ka, A, wf, 0)
    nb = _primitive_axes(kb, B, wf, na)
    n = nb
    for i in range(na):
        ix, iy, iz = axis(wf, i)
        for j in range(na, nb):
            jx, jy, jz = axis(wf, j)
            n = _push_axis(wf, n, iy * jz - iz * jy, iz * jx - ix * jz, ix * jy - iy * jx)
    pax, pay, paz = placed_position(wf, A)
    pbx, pby, pbz = placed_position(wf, B)
    dx, dy, dz = pbx - pax, pby - pay, pbz - paz
    n = _push_axis(wf, n, dx, dy, dz)
    # Round shapes: the centre line's part across each axis.
    for which in range(2):
        kind = ka if which == 0 else kb
        if round_about_z(kind):
            ax, ay, az = placed_axis(wf, which, 2)
            t = dx * ax + dy * ay + dz * az
            n = _push_axis(wf, n, dx - t * ax, dy - t * ay, dz - t * az)
    a0, a1, a2 = placed_dims(wf, A)
    b0, b1, b2 = placed_dims(wf, B)
    best = -1e300
    for i in range(n):
        x, y, z = axis(wf, i)
        gap = (abs(dx * x + dy * y + dz * z)
               - _support(ka, A, a0, a1, a2, wf, x, y, z)
               - _support(kb, B, b0, b1, b2, wf, x, y, z))
        if gap > best:
            best = gap
    return best


@_inlined
def _place_mover(fb, ib, m, Rw, pw, wf, wi, s):  # noqa: N803
    """Place mover ``m``'s shape as placed shape ``s`` (A or B: its world rotation,
    position, dimensions, kind and hull rows) at the state of Rw, pw; returns its kind."""
    R, px, py, pz = _mover_frame(fb, ib, m, Rw, pw)  # noqa: N806
    d0, d1, d2 = mover_dims(fb, ib, m)
    kind = mover_kind(ib, m)
    h0, h1 = mover_hull(ib, m)
    place(wf, wi, s, R, px, py, pz, d0, d1, d2, kind, h0, h1)
    return kind


@_helper
def _place_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi):  # noqa: N803
    """Place mover ``a``'s shape (A) and environment object (``is_env``) or mover ``b``'s
    shape (B) in the scratch at the state of Rw, pw; returns their kinds."""
    ka = _place_mover(fb, ib, a, Rw, pw, wf, wi, A)
    if is_env == 0:
        return ka, _place_mover(fb, ib, b, Rw, pw, wf, wi, B)
    kb = env_kind(ib, b)
    px, py, pz = env_position(fb, ib, b)
    d0, d1, d2 = env_dims(fb, ib, b)
    place(wf, wi, B, env_rotation(fb, ib, b), px, py, pz, d0, d1, d2, kb, 0, 0)
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
    (placed in the scratch by the caller): the separating-axis bound of two primitives,
    GJK's when one is a hull, or the fine spheres of a body that is no primitive. A
    bound of ``enough`` (beyond the pair's margin) is sufficient for the caller."""
    a, b, is_env, _ = pair(ib, k)
    sm = max(pair_margin(fb, ib, k), 0.0)
    ka = mover_kind(ib, a)
    kb = ENV_BOX if is_env == 1 else mover_kind(ib, b)
    if ka != SPHERES_ONLY and kb != SPHERES_ONLY:
        if ka == HULL or kb == HULL:
            return _gjk_pair(fb, ib, k, a, b, is_env, Rw, pw, wf, wi, sm, sm + enough)
        return _sat_pair(fb, ib, a, b, is_env, Rw, pw, wf, wi)
    if is_env == 1:
        return _spheres_to_object(fb, ib, a, b, sm, Rw, pw)
    return _sphere_sets(fb, ib, a, b, sm, Rw, pw, wf, wi)


@_inlined
def _spheres_to_object(fb, ib, a, e, sm, Rw, pw):  # noqa: N803
    """Lower bound [m] on the distance of mover ``a``'s outer spheres to environment
    object ``e``; the first one found within the margin ``sm``, if any."""
    ja = mover_joint(ib, a)
    best = 1e300
    first, end = outer_spheres(ib, a)
    for s in range(first, end):
        x, y, z = _sphere_world(fb, ib, s, Rw, pw, ja)
        d = _env_sdist3(fb, ib, e, x, y, z) - sphere_radius(fb, ib, s)
        if d < best:
            best = d
            if best - sm <= 0.0:
                return best
    return best


@_inlined
def _nearest(wf, wi, which, n):
    """The sphere of the ``n`` of placed set ``which`` whose distance bound to the other
    body is the smallest (the first such)."""
    best = 0
    for i in range(1, n):
        if placed_sphere_bound(wf, wi, which, i) < placed_sphere_bound(wf, wi, which, best):
            best = i
    return best


@_inlined
def _sphere_gap(wf, wi, i, j):
    """Distance [m] between sphere ``i`` of placed set A and sphere ``j`` of set B."""
    x0, y0, z0, r0 = placed_sphere(wf, wi, A, i)
    x1, y1, z1, r1 = placed_sphere(wf, wi, B, j)
    return math.sqrt((x0 - x1) ** 2 + (y0 - y1) ** 2 + (z0 - z1) ** 2) - r0 - r1


@_inlined
def _sphere_sets(fb, ib, a, b, sm, Rw, pw, wf, wi):  # noqa: N803
    """Lower bound [m] on the distance of movers ``a`` and ``b``'s outer sphere sets
    (their bounding spheres' world centres placed by the caller); the first pair of
    spheres found within the margin ``sm``, if any."""
    ra, rb = mover_radius(fb, ib, a), mover_radius(fb, ib, b)
    cbx, cby, cbz = bound_centre(wf, wi, b)
    ca0, ca1, ca2 = bound_centre(wf, wi, a)
    # Two sphere sets: place each once, bound each sphere against the other body's
    # bounding sphere, take one real pair distance as an upper bound, and compare only
    # the spheres whose bound beats it.
    na = _place_spheres(fb, ib, a, Rw, pw, cbx, cby, cbz, rb, wf, wi, A)
    nb = _place_spheres(fb, ib, b, Rw, pw, ca0, ca1, ca2, ra, wf, wi, B)
    best = _sphere_gap(wf, wi, _nearest(wf, wi, A, na), _nearest(wf, wi, B, nb))
    for i in range(na):
        if placed_sphere_bound(wf, wi, A, i) >= best:
            continue
        for j in range(nb):
            if placed_sphere_bound(wf, wi, B, j) >= best:
                continue
            d = _sphere_gap(wf, wi, i, j)
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
    if _proof_without_gjk(k, fb, ib, eps, Rw, pw, wf, wi):
        return True
    a, b, is_env, proof = pair(ib, k)
    if proof == 0:
        return False
    sm = pair_margin(fb, ib, k)
    ka = mover_kind(ib, a)
    if is_env == 1:
        # An object measured by the box around it (ENV_BOX_ONLY_OUTER) proves nothing.
        return (ka != SPHERES_ONLY and env_kind(ib, b) != ENV_BOX_ONLY_OUTER
                and _gjk_overlap(fb, ib, k, a, b, 1, Rw, pw, wf, wi, sm - eps) < sm - eps)
    return (ka != SPHERES_ONLY and mover_kind(ib, b) != SPHERES_ONLY
            and _gjk_overlap(fb, ib, k, a, b, 0, Rw, pw, wf, wi, sm - eps) < sm - eps)


@_helper
def _proof_without_gjk(k, fb, ib, eps, Rw, pw, wf, wi):  # noqa: N803
    """The proofs of :func:`_pair_collides` that leave nothing behind in the scratch
    (GJK's, which update the pair's search hints, excepted): an inner sphere within the
    margin, or (two boxes, no margin) the complete separating-axis test failing."""
    a, b, is_env, proof = pair(ib, k)
    if proof == 0:
        return False
    sm = pair_margin(fb, ib, k)
    ja, ka = mover_joint(ib, a), mover_kind(ib, a)
    if is_env == 1:
        if (sm == 0.0 and ka == ENV_BOX and env_kind(ib, b) == ENV_BOX
                and _sat_pair(fb, ib, a, b, 1, Rw, pw, wf, wi) < -eps):
            return True
        first, end = inner_spheres(ib, a)
        for s in range(first, end):
            x, y, z = _sphere_world(fb, ib, s, Rw, pw, ja)
            if _env_sdist3(fb, ib, b, x, y, z) - sphere_radius(fb, ib, s) < sm - eps:
                return True
        return False
    jb, kb = mover_joint(ib, b), mover_kind(ib, b)
    if (sm == 0.0 and ka == ENV_BOX and kb == ENV_BOX
            and _sat_pair(fb, ib, a, b, 0, Rw, pw, wf, wi) < -eps):
        return True
    return _inner_spheres_meet(fb, ib, a, ja, b, jb, Rw, pw, sm - eps)


@_inlined
def _inner_spheres_meet(fb, ib, a, ja, b, jb, Rw, pw, within):  # noqa: N803
    """Whether an inner sphere of mover ``a`` (carried by joint ``ja``) and one of mover
    ``b`` (joint ``jb``) lie closer than ``within`` [m]."""
    a0, a1 = inner_spheres(ib, a)
    b0, b1 = inner_spheres(ib, b)
    for s in range(a0, a1):
        x0, y0, z0 = _sphere_world(fb, ib, s, Rw, pw, ja)
        rs = sphere_radius(fb, ib, s)
        for t in range(b0, b1):
            x1, y1, z1 = _sphere_world(fb, ib, t, Rw, pw, jb)
            d = (math.sqrt((x0 - x1) ** 2 + (y0 - y1) ** 2 + (z0 - z1) ** 2) - rs
                 - sphere_radius(fb, ib, t))
            if d < within:
                return True
    return False
