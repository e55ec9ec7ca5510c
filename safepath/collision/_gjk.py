"""Distance lower bounds between two placed convex shapes (numba; GJK's iteration).

The sphere layer (:mod:`safepath.collision._kernels`) uses this for convex hulls (the links of
robots with mesh geometry, e.g. example-robot-data's Panda), where a sphere covering
overestimates the link by up to the covering's cell and leaves every state near an
obstacle undecided.

Soundness does not rest on GJK converging: every value returned is the gap of the two
shapes' projections on one unit direction ``n``, ``min_{a,b} n·(a − b)``, computed from
the exact support functions (a hull's support is the maximum over its vertices, the very
points coal's hull is made of). Such a gap is a lower bound on the distance for *any*
``n``; GJK's simplex only steers ``n`` towards the one that makes the bound tight. A
degenerate simplex can only stop the search early, giving a looser bound.

numba's disk cache tracks only the file of the function it compiles: the kernels of
:mod:`safepath.collision._kernels` that call (and inline) these helpers keep their cached code
when only this file changes. After editing it in a source checkout, delete
``safepath/collision/__pycache__/*.nb*`` (an installed copy compiles afresh). Like the
helpers there, these are compiled without numba's reference counting (see
:mod:`safepath.collision._kernels`): no allocation, no array returned.

The two shapes are read as the rest of the layer reads its data, through the accessors
of :mod:`safepath.collision._records`: placed in the call's scratch as shapes A and B,
each a record of its world rotation, position and dimensions and its kind and hull
vertex rows (vertices in the shape's own frame, with their edges, in the checker's
buffers). Shape kinds are those of :mod:`safepath.collision._layout` (box, cylinder,
sphere, capsule) and the hull. A search takes the checker's buffers, the scratch and
the pair (whose last direction and support hints it starts from): a handful of
arguments, as every array passed costs a numba call ~10 ns in reference counts and
descriptors, and the searches run millions of times a second.
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit
from ..model._primitives import support_point
from ._layout import (
    ENV_BOX,
    ENV_BOX_ONLY_OUTER,
    HULL,
)
from ._records import (
    A,
    B,
    hull_edges,
    hull_neighbour,
    hull_vertex,
    pair_hints,
    pair_warm,
    placed_dims,
    placed_hull,
    placed_kind,
    placed_position,
    placed_rotation,
    simplex,
)

#: How these are compiled (see the module doc).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")

# The box kinds: safepath.collision._layout's codes (the shape table's, and the kernels'
# box about an object); every other kind but the hull is measured by
# safepath.model._primitives.
BOX, BOX_ONLY_OUTER = ENV_BOX, ENV_BOX_ONLY_OUTER


@_inlined
def table_kind(kind):
    """The shape table's kind a kernel kind is measured as by
    :mod:`safepath.model._primitives`: the box about an object is a box."""
    return BOX if kind == BOX_ONLY_OUTER else kind

#: Absolute tolerance [m]: the search stops once the bound is this close to the distance
#: of the current simplex (an upper bound).
TOL = 2e-4
MAX_ITER = 32


@_inlined
def climb(fb, ib, v0, v1, start, lx, ly, lz):
    """The vertex (row) of the hull at vertex rows ``v0:v1`` farthest along (lx, ly,
    lz): steepest ascent over the hull's edges from ``start``. Exact on a convex
    polytope: a vertex that is not farthest has an edge along which the direction
    strictly increases."""
    g = start if v0 <= start < v1 else v0
    x, y, z = hull_vertex(fb, ib, g)
    best = x * lx + y * ly + z * lz
    while True:
        nxt = g
        first, end = hull_edges(ib, g)
        for e in range(first, end):
            h = hull_neighbour(ib, e)
            x, y, z = hull_vertex(fb, ib, h)
            s = x * lx + y * ly + z * lz
            if s > best:
                best, nxt = s, h
        if nxt == g:
            return g
        g = nxt


@_inlined
def support(fb, ib, wf, wi, s, start, nx, ny, nz):
    """World point (x, y, z) farthest along (nx, ny, nz) (not necessarily unit) of
    placed shape ``s`` (A or B, see the module doc), and for a hull the vertex row (the
    next search's ``start``), else -1."""
    R = placed_rotation(wf, s)  # noqa: N806
    # Direction in the shape's frame: R^T n.
    lx = R.r00 * nx + R.r10 * ny + R.r20 * nz
    ly = R.r01 * nx + R.r11 * ny + R.r21 * nz
    lz = R.r02 * nx + R.r12 * ny + R.r22 * nz
    kind = placed_kind(wi, s)
    a, b, c = placed_dims(wf, s)
    x = y = z = 0.0
    found = -1
    if kind == HULL:
        v0, v1 = placed_hull(wi, s)
        found = climb(fb, ib, v0, v1, start, lx, ly, lz)
        x, y, z = hull_vertex(fb, ib, found)
    else:
        x, y, z = support_point(table_kind(kind), a, b, c, lx, ly, lz)
    px, py, pz = placed_position(wf, s)
    return (R.r00 * x + R.r01 * y + R.r02 * z + px, R.r10 * x + R.r11 * y + R.r12 * z + py,
            R.r20 * x + R.r21 * y + R.r22 * z + pz, found)


@_inlined
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@_helper
def _triangle(S, i, j, k, v):  # noqa: N803
    """Closest point to the origin of triangle S[i], S[j], S[k] into ``v``; returns a
    bit mask (1 << i ...) of the vertices that span it (Ericson, Real-Time Collision
    Detection 5.1.5, with p = 0)."""
    a0, a1, a2 = S[i, 0], S[i, 1], S[i, 2]
    ab0, ab1, ab2 = S[j, 0] - a0, S[j, 1] - a1, S[j, 2] - a2
    ac0, ac1, ac2 = S[k, 0] - a0, S[k, 1] - a1, S[k, 2] - a2
    d1 = -(ab0 * a0 + ab1 * a1 + ab2 * a2)
    d2 = -(ac0 * a0 + ac1 * a1 + ac2 * a2)
    if d1 <= 0.0 and d2 <= 0.0:
        v[0], v[1], v[2] = a0, a1, a2
        return 1 << i
    d3 = -(ab0 * S[j, 0] + ab1 * S[j, 1] + ab2 * S[j, 2])
    d4 = -(ac0 * S[j, 0] + ac1 * S[j, 1] + ac2 * S[j, 2])
    if d3 >= 0.0 and d4 <= d3:
        v[0], v[1], v[2] = S[j, 0], S[j, 1], S[j, 2]
        return 1 << j
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        v[0], v[1], v[2] = a0 + t * ab0, a1 + t * ab1, a2 + t * ab2
        return (1 << i) | (1 << j)
    d5 = -(ab0 * S[k, 0] + ab1 * S[k, 1] + ab2 * S[k, 2])
    d6 = -(ac0 * S[k, 0] + ac1 * S[k, 1] + ac2 * S[k, 2])
    if d6 >= 0.0 and d5 <= d6:
        v[0], v[1], v[2] = S[k, 0], S[k, 1], S[k, 2]
        return 1 << k
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        v[0], v[1], v[2] = a0 + t * ac0, a1 + t * ac1, a2 + t * ac2
        return (1 << i) | (1 << k)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        for r in range(3):
            v[r] = S[j, r] + t * (S[k, r] - S[j, r])
        return (1 << j) | (1 << k)
    den = va + vb + vc
    if den <= 0.0:  # degenerate triangle: keep its first edge's answer
        v[0], v[1], v[2] = a0, a1, a2
        return 1 << i
    sv, sw = vb / den, vc / den
    v[0], v[1], v[2] = a0 + ab0 * sv + ac0 * sw, a1 + ab1 * sv + ac1 * sw, a2 + ab2 * sv + ac2 * sw
    return (1 << i) | (1 << j) | (1 << k)


@_inlined
def _origin_outside(S, i, j, k, o):  # noqa: N803
    """Whether the origin and S[o] lie strictly on opposite sides of plane (i, j, k)."""
    ab0, ab1, ab2 = S[j, 0] - S[i, 0], S[j, 1] - S[i, 1], S[j, 2] - S[i, 2]
    ac0, ac1, ac2 = S[k, 0] - S[i, 0], S[k, 1] - S[i, 1], S[k, 2] - S[i, 2]
    n0, n1, n2 = ab1 * ac2 - ab2 * ac1, ab2 * ac0 - ab0 * ac2, ab0 * ac1 - ab1 * ac0
    s_origin = -(S[i, 0] * n0 + S[i, 1] * n1 + S[i, 2] * n2)
    s_other = (S[o, 0] - S[i, 0]) * n0 + (S[o, 1] - S[i, 1]) * n1 + (S[o, 2] - S[i, 2]) * n2
    return s_origin * s_other < 0.0


@_inlined
def _closest_on_segment(S, v):  # noqa: N803
    """Closest point ``v`` of the segment S[0], S[1] to the origin; S is reduced in place
    to the vertices that span it. Returns their count."""
    e0, e1, e2 = S[1, 0] - S[0, 0], S[1, 1] - S[0, 1], S[1, 2] - S[0, 2]
    ee = e0 * e0 + e1 * e1 + e2 * e2
    t = -(S[0, 0] * e0 + S[0, 1] * e1 + S[0, 2] * e2) / ee if ee > 0.0 else 0.0
    if t <= 0.0:
        v[0], v[1], v[2] = S[0, 0], S[0, 1], S[0, 2]
        return 1
    if t >= 1.0:
        S[0, 0], S[0, 1], S[0, 2] = S[1, 0], S[1, 1], S[1, 2]
        v[0], v[1], v[2] = S[0, 0], S[0, 1], S[0, 2]
        return 1
    v[0], v[1], v[2] = S[0, 0] + t * e0, S[0, 1] + t * e1, S[0, 2] + t * e2
    return 2


@_inlined
def _closest_on_tetrahedron(S, v, tmp):  # noqa: N803
    """Closest point ``v`` of the tetrahedron S[0:4] to the origin, over the faces that
    the origin lies outside of; returns the bit mask of the vertices that span it (0: the
    origin is inside, ``v`` untouched)."""
    mask = 0
    best = 1e300
    faces = ((0, 1, 2, 3), (0, 2, 3, 1), (0, 3, 1, 2), (1, 3, 2, 0))
    for f in faces:
        if _origin_outside(S, f[0], f[1], f[2], f[3]):
            m = _triangle(S, f[0], f[1], f[2], tmp)
            dd = _dot(tmp, tmp)
            if dd < best:
                best = dd
                mask = m
                v[0], v[1], v[2] = tmp[0], tmp[1], tmp[2]
    return mask


@_inlined
def _keep(S, n, mask):  # noqa: N803
    """Reduce S[:n] in place to the vertices in ``mask`` (in order); returns their count."""
    out = 0
    for r in range(n):
        if mask & (1 << r):
            if out != r:
                S[out, 0], S[out, 1], S[out, 2] = S[r, 0], S[r, 1], S[r, 2]
            out += 1
    return out


@_inlined
def _closest(S, n, v, tmp):  # noqa: N803
    """Closest point ``v`` of the simplex S[:n] to the origin; S is reduced in place to
    the vertices that span it. Returns the new count (4: the origin is inside)."""
    if n == 1:
        v[0], v[1], v[2] = S[0, 0], S[0, 1], S[0, 2]
        return 1
    if n == 2:
        return _closest_on_segment(S, v)
    if n == 3:
        mask = _triangle(S, 0, 1, 2, v)
    else:
        mask = _closest_on_tetrahedron(S, v, tmp)
        if mask == 0:
            v[:] = 0.0
            return 4
    return _keep(S, n, mask)


@_inlined
def _first_direction(wf, v, warm):
    """GJK's first search direction ``v``: ``warm`` (the pair's last one), else the line
    between the placed shapes' centres, else x."""
    v[0], v[1], v[2] = warm[0], warm[1], warm[2]
    if _dot(v, v) < 1e-18:
        ax, ay, az = placed_position(wf, A)
        bx, by, bz = placed_position(wf, B)
        v[0], v[1], v[2] = ax - bx, ay - by, az - bz
        if _dot(v, v) < 1e-18:
            v[0] = 1.0


@_inlined
def _difference_support(fb, ib, wf, wi, hint, v):
    """The support point of A - B towards -v (A's towards -v, B's towards v; ``hint``
    updated), as (x, y, z): both searches' step."""
    ax, ay, az, hint[0] = support(fb, ib, wf, wi, A, hint[0], -v[0], -v[1], -v[2])
    bx, by, bz, hint[1] = support(fb, ib, wf, wi, B, hint[1], v[0], v[1], v[2])
    return ax - bx, ay - by, az - bz


@_helper
def distance_lower_bound(fb, ib, wf, wi, k, low, high):
    """A lower bound [m] on the distance between the shapes A and B placed in the scratch
    (negative or zero when they may touch), within :data:`TOL` of the true distance when
    GJK converges.

    The search also stops once the bound reaches ``high`` (enough for the caller) or the
    distance is known to be at most ``low`` (no bound above ``low`` exists).

    Pair ``k``'s last direction (``_records.pair_warm``) is the first search direction
    (all zero: the centre line), overwritten with the direction that gave the bound; its
    hints (``_records.pair_hints``), the hull vertices where the support searches of A
    and B start (updated). GJK's simplex (``_records.simplex``) is scratch.
    """
    S, v, tmp = simplex(wf)  # noqa: N806
    warm, hint = pair_warm(wf, wi, k), pair_hints(wi, k)
    _first_direction(wf, v, warm)
    lb = -1e300
    ub = 1e300
    n = 0
    for _ in range(MAX_ITER):
        vn = math.sqrt(_dot(v, v))
        if vn < 1e-12:
            break
        w0, w1, w2 = _difference_support(fb, ib, wf, wi, hint, v)
        gap = (v[0] * w0 + v[1] * w1 + v[2] * w2) / vn
        if gap > lb:
            lb = gap
            warm[0], warm[1], warm[2] = v[0] / vn, v[1] / vn, v[2] / vn
        if ub - lb <= TOL or lb >= high:
            break
        S[n, 0], S[n, 1], S[n, 2] = w0, w1, w2
        n = _closest(S, n + 1, v, tmp)
        if n == 4:
            break
        ub = min(ub, math.sqrt(_dot(v, v)))
        if ub <= low:
            break
    return lb


@_inlined
def _depth_inside(S):  # noqa: N803
    """How far [m] the origin lies inside the tetrahedron S[0:4] (which holds it): its
    smallest distance to a face plane; 0 for a degenerate tetrahedron."""
    depth = 1e300
    faces = ((0, 1, 2, 3), (0, 2, 3, 1), (0, 3, 1, 2), (1, 3, 2, 0))
    for f in faces:
        i, j, k, o = f[0], f[1], f[2], f[3]
        ab0, ab1, ab2 = S[j, 0] - S[i, 0], S[j, 1] - S[i, 1], S[j, 2] - S[i, 2]
        ac0, ac1, ac2 = S[k, 0] - S[i, 0], S[k, 1] - S[i, 1], S[k, 2] - S[i, 2]
        n0, n1, n2 = ab1 * ac2 - ab2 * ac1, ab2 * ac0 - ab0 * ac2, ab0 * ac1 - ab1 * ac0
        nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if nn < 1e-300:
            return 0.0
        # The face's normal away from the opposite vertex: the origin's depth is S[i]'s
        # height along it.
        if (S[o, 0] - S[i, 0]) * n0 + (S[o, 1] - S[i, 1]) * n1 + (S[o, 2] - S[i, 2]) * n2 > 0.0:
            nn = -nn
        d = (S[i, 0] * n0 + S[i, 1] * n1 + S[i, 2] * n2) / nn
        if d < depth:
            depth = d
    return max(depth, 0.0)


@_helper
def distance_upper_bound(fb, ib, wf, wi, k, goal):
    """An upper bound [m] on the signed distance between the shapes A and B placed in the
    scratch (negative: they overlap, at least that deep), searched until it is below
    ``goal`` or GJK shows no bound below ``goal`` exists (then some bound at least
    ``goal`` is returned).

    Every point GJK's simplex holds is a point of the shapes' difference A - B (each
    from the exact support functions), so the distance of the simplex's closest point to
    the origin bounds the shapes' distance from above; a tetrahedron holding the origin
    lies inside A - B, and the origin's depth in it bounds the overlap from below.
    Arguments and scratch as :func:`distance_lower_bound`.
    """
    S, v, tmp = simplex(wf)  # noqa: N806
    warm, hint = pair_warm(wf, wi, k), pair_hints(wi, k)
    _first_direction(wf, v, warm)
    ub = 1e300
    n = 0
    for _ in range(MAX_ITER):
        vn = math.sqrt(_dot(v, v))
        if vn < 1e-12:
            break
        w0, w1, w2 = _difference_support(fb, ib, wf, wi, hint, v)
        if (v[0] * w0 + v[1] * w1 + v[2] * w2) / vn >= goal:
            return max(ub, goal)  # a lower bound of at least goal: no proof below it
        S[n, 0], S[n, 1], S[n, 2] = w0, w1, w2
        n = _closest(S, n + 1, v, tmp)
        if n == 4:
            return -_depth_inside(S)
        ub = min(ub, math.sqrt(_dot(v, v)))
        if ub < goal:
            return ub
    return ub


def hull_tables(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A convex shape's hull as :func:`support` reads it: its vertices (the extreme
    points, rows [m]), and its edges as neighbour lists (``ptr`` (vertices + 1), ``idx``:
    row g's neighbours are ``idx[ptr[g]:ptr[g + 1]]``, rows of the vertex array)."""
    from scipy.spatial import ConvexHull

    points = np.asarray(points, dtype=float)
    hull = ConvexHull(points)
    row = {int(i): r for r, i in enumerate(hull.vertices)}
    neighbours: list[set[int]] = [set() for _ in hull.vertices]
    for tri in hull.simplices:
        a, b, c = (row[int(i)] for i in tri)
        neighbours[a] |= {b, c}
        neighbours[b] |= {a, c}
        neighbours[c] |= {a, b}
    ptr = np.zeros(len(neighbours) + 1, dtype=np.int64)
    ptr[1:] = np.cumsum([len(n) for n in neighbours])
    idx = np.array([j for n in neighbours for j in sorted(n)], dtype=np.int64)
    return np.ascontiguousarray(points[hull.vertices]), ptr, idx
