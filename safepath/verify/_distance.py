"""The release check's own distance bounds between two placed convex shapes (numba).

Part of the verifier's independent geometry (:mod:`safepath.verify`): it shares no code
with the planner's sphere layer (:mod:`safepath.collision`), on purpose. Plain loops, no
``np.dot`` or ``@``. A placed shape is a :class:`Placed` record (17 floats read by
field name), the hull tables a :class:`Hulls` record; both are ``typing.NamedTuple``
classes, which numba compiles to plain structs. Everything here is compiled without numba's
reference counting (see :mod:`safepath.verify._kernel`). The small helpers that take
placed shapes (:func:`support`, :func:`gap`, ...) and GJK's steps are inlined where they
are called (numba's ``inline="always"``): a call copies both shapes' 17 floats and the
hull tables onto the stack, which cost more than the helper's own arithmetic (the walk
took ~12 % less time inlined). Inlining changes no operation, so no result. Python
callers use :func:`axis_bound_entry` and :func:`gjk_bound_entry`, which take the records
as plain tuples in field order (what the ahead-of-time guards take).

Shapes are convex: boxes, spheres, cylinders and capsules (cylinders and capsules along
their local z), and convex hulls given by their vertices (a mesh link's own hull, as FCL
checks it). The bound is the largest gap between the two shapes'
projections on a few unit axes: the line between the centres, each shape's own axes,
their cross products, the axis that worked at the pair's last evaluation, and GJK's
search directions when those are not enough. Projecting is 1-Lipschitz, so every gap is
at most the distance; when the shapes overlap, a gap is minus their overlap along that
axis, and moving one shape by that overlap separates them, so the gap is also at most
minus the penetration depth. Either way a gap is below the signed distance, whatever the
state of GJK: its directions are only candidates, the gaps use the exact widths
(:func:`support`), never GJK's points.

The shape table has one row per shape (the bodies', then the environment objects'): kind
(BOX, SPHERE, CYLINDER, CAPSULE: :mod:`safepath.model.shapes` codes; HULL), three
parameters (box half extents; radius; radius and half length; a hull's first row in the
vertex table and its count), the centre in the geometry frame, and the radius of a
sphere about the centre that holds the shape. The vertex table holds the hulls' vertices
about their centres, in their geometry frames; with it go, per vertex row, the rows of
its neighbours along the hull's edges (where they start in the neighbour table, and that
table): a hull's support climbs them instead of scanning every vertex.

numba's disk cache tracks only the file of the function it compiles: the walk of
:mod:`safepath.verify._kernel` that calls (and inlines) these keeps its cached code when
only this file changes. After editing it in a source checkout, delete
``safepath/verify/__pycache__/*.nb*`` (an installed copy compiles afresh; the kernels
compiled ahead of time are keyed on every kernel module's source, this one's too).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._aot import njit
from ..model.shapes import BOX, CAPSULE, CYLINDER, SPHERE

#: How every function here is compiled: without numba's reference counting (see
#: :mod:`safepath.verify._kernel`).
_kernel = njit(cache=True, _nrt=False)
#: How the small helpers that take placed shapes are compiled: inlined where they are
#: called (see the module doc).
_inline = njit(cache=True, _nrt=False, inline="always")

#: Shape kinds: the shape table's codes (:mod:`safepath.model.shapes`), and a convex hull.
HULL = -1
#: Columns of the shape table.
KIND, PAR, CENTRE, RADIUS = 0, 1, 4, 7



class Placed(NamedTuple):
    """A shape placed in the world, as the bounds read it (17 floats, read by name).

    Attributes:
        kind: BOX, SPHERE, CYLINDER, CAPSULE or HULL (a float, as the shape table's).
        par0, par1, par2: Its parameters: box half extents; radius; radius and half
            length; a hull's first row in the vertex table and its count [m].
        radius: Radius of a sphere about the centre that holds the shape [m].
        cx, cy, cz: Its centre in the world [m].
        r00, r01, r02, r10, r11, r12, r20, r21, r22: Its rotation in the world
            (row-major; column j is the shape's axis j).
    """

    kind: float
    par0: float
    par1: float
    par2: float
    radius: float
    cx: float
    cy: float
    cz: float
    r00: float
    r01: float
    r02: float
    r10: float
    r11: float
    r12: float
    r20: float
    r21: float
    r22: float


class Hulls(NamedTuple):
    """The hull tables (all rows of the vertex table; see the module doc).

    Attributes:
        vertices: The hulls' vertices about their centres, in their geometry frames
            (rows x 3) [m].
        starts: Per vertex row, where its neighbours start in ``neighbours`` (rows + 1).
        neighbours: The neighbours' rows.
        climb: Per hull, at its first row, the vertex its last climb ended at (updated).
    """

    vertices: np.ndarray
    starts: np.ndarray
    neighbours: np.ndarray
    climb: np.ndarray


@_inline
def _dots(S: Placed, n0: float, n1: float, n2: float) -> tuple[float, float, float]:
    """n along each of the shape's axes."""
    return (n0 * S.r00 + n1 * S.r10 + n2 * S.r20, n0 * S.r01 + n1 * S.r11 + n2 * S.r21,
            n0 * S.r02 + n1 * S.r12 + n2 * S.r22)


@_inline
def _axis(S: Placed, j: int) -> tuple[float, float, float]:
    """The shape's axis j in the world."""
    if j == 0:
        return S.r00, S.r10, S.r20
    if j == 1:
        return S.r01, S.r11, S.r21
    return S.r02, S.r12, S.r22


@_inline
def _par(S: Placed, j: int) -> float:
    """The shape's parameter j (a box's half extent along its axis j)."""
    if j == 0:
        return S.par0
    if j == 1:
        return S.par1
    return S.par2


@_kernel
def _hull_top(S: Placed, H: Hulls, a0: float, a1: float, a2: float) -> tuple[float, int]:
    """The largest of a hull's vertices along a (in its frame), and its row: climbing
    the hull's edges to a better neighbour while there is one, from where its last
    climb ended (kept in ``H``'s start table at the hull's first row: the next
    direction asked of a hull is mostly close to the last one).

    A linear function on a convex polytope that no edge from a vertex increases is at
    its maximum there (the simplex method's argument); the edges are those of the
    hull's triangulated facets, which include every edge of the polytope. So this is
    the maximum over all the vertices from any start (to rounding: a neighbour better
    by less than the rounding of a dot product may be missed, ~1e-16 m), visiting a
    few of them."""
    V, ptr, nbr = H.vertices, H.starts, H.neighbours
    first = int(S.par0)
    k = H.climb[first]
    best = V[k, 0] * a0 + V[k, 1] * a1 + V[k, 2] * a2
    while True:
        top = k
        for e in range(ptr[k], ptr[k + 1]):
            j = nbr[e]
            x = V[j, 0] * a0 + V[j, 1] * a1 + V[j, 2] * a2
            if x > best:
                best, top = x, j
        if top == k:
            H.climb[first] = k
            return best, k
        k = top


@_inline
def support(S: Placed, H: Hulls, n0: float, n1: float, n2: float) -> float:
    """How far the shape's projection on the unit axis n reaches beyond its centre along
    n [m] (half its width, but for a hull: ``H`` holds the hulls' vertices about their
    centres in their own frames (rows), per vertex row where its neighbours start in
    the neighbour rows, those rows, and per hull (at its first row) the vertex its
    last climb ended at, updated)."""
    a0, a1, a2 = _dots(S, n0, n1, n2)
    kind = int(S.kind)
    if kind == HULL:
        return _hull_top(S, H, a0, a1, a2)[0]  # type: ignore[no-any-return]
    if kind == BOX:
        return S.par0 * abs(a0) + S.par1 * abs(a1) + S.par2 * abs(a2)
    if kind == SPHERE:
        return S.par0
    u = abs(a2)
    if kind == CYLINDER:
        return S.par1 * u + S.par0 * math.sqrt(max(0.0, 1.0 - u * u))
    return S.par1 * u + S.par0


@_inline
def _support_point(S: Placed, H: Hulls, n0: float, n1: float, n2: float
                   ) -> tuple[float, float, float]:
    """A point of the shape furthest along n: GJK's search only, the bounds use
    :func:`support`."""
    x0, x1, x2 = S.cx, S.cy, S.cz
    a0, a1, a2 = _dots(S, n0, n1, n2)
    kind = int(S.kind)
    if kind == HULL:
        V = H.vertices
        k = _hull_top(S, H, a0, a1, a2)[1]
        for j in range(3):
            c0, c1, c2 = _axis(S, j)
            x0, x1, x2 = x0 + V[k, j] * c0, x1 + V[k, j] * c1, x2 + V[k, j] * c2
        return x0, x1, x2
    if kind == BOX:
        for j, a in ((0, a0), (1, a1), (2, a2)):
            h = _par(S, j) if a >= 0.0 else -_par(S, j)
            c0, c1, c2 = _axis(S, j)
            x0, x1, x2 = x0 + h * c0, x1 + h * c1, x2 + h * c2
        return x0, x1, x2
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if kind == SPHERE:
        r = S.par0 / norm
        return x0 + r * n0, x1 + r * n1, x2 + r * n2
    c0, c1, c2 = _axis(S, 2)
    h = S.par1 if a2 >= 0.0 else -S.par1
    x0, x1, x2 = x0 + h * c0, x1 + h * c1, x2 + h * c2
    if kind == CAPSULE:
        r = S.par0 / norm
        return x0 + r * n0, x1 + r * n1, x2 + r * n2
    r0, r1, r2 = n0 - a2 * c0, n1 - a2 * c1, n2 - a2 * c2
    radial = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if radial > 1e-12 * norm:
        r = S.par0 / radial
        x0, x1, x2 = x0 + r * r0, x1 + r * r1, x2 + r * r2
    return x0, x1, x2


@_inline
def gap(Sa: Placed, Sb: Placed, H: Hulls, n0: float, n1: float, n2: float) -> float:
    """Gap between the shapes' projections on the unit axis n [m]."""
    d0, d1, d2 = Sb.cx - Sa.cx, Sb.cy - Sa.cy, Sb.cz - Sa.cz
    along = n0 * d0 + n1 * d1 + n2 * d2
    if along < 0.0:  # B lies behind A along n: measure along -n
        n0, n1, n2, along = -n0, -n1, -n2, -along
    return (along - support(Sa, H, n0, n1, n2)  # type: ignore[no-any-return]
            - support(Sb, H, -n0, -n1, -n2))


@_inline
def sphere_bound(Sa: Placed, Sb: Placed) -> tuple[float, float, float, float]:
    """Distance between the bounding spheres [m] (never above the gap along the line
    between the centres), and that line's direction."""
    d0, d1, d2 = Sb.cx - Sa.cx, Sb.cy - Sa.cy, Sb.cz - Sa.cz
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dist < 1e-12:
        return dist - Sa.radius - Sb.radius, 0.0, 0.0, 1.0
    return dist - Sa.radius - Sb.radius, d0 / dist, d1 / dist, d2 / dist


@_inline
def _own_axes(S: Placed) -> tuple[int, int]:
    """The shape's axes worth trying: (first, count)."""
    kind = int(S.kind)
    if kind == BOX:
        return 0, 3
    if kind == SPHERE or kind == HULL:  # a hull's frame axes are nothing special
        return 0, 0
    return 2, 1


@_kernel
def axis_bound(Sa: Placed, Sb: Placed, H: Hulls) -> tuple[float, float, float, float]:
    """The largest gap along the line between the centres, the shapes' own axes and
    their cross products [m] (never below the bounding spheres' distance), and its
    axis."""
    best, b0, b1, b2 = sphere_bound(Sa, Sb)
    g = gap(Sa, Sb, H, b0, b1, b2)  # the line between the centres
    if g > best:
        best = g
    a_first, a_count = _own_axes(Sa)
    b_first, b_count = _own_axes(Sb)
    for i in range(a_first, a_first + a_count):
        n0, n1, n2 = _axis(Sa, i)
        g = gap(Sa, Sb, H, n0, n1, n2)
        if g > best:
            best, b0, b1, b2 = g, n0, n1, n2
    for j in range(b_first, b_first + b_count):
        n0, n1, n2 = _axis(Sb, j)
        g = gap(Sa, Sb, H, n0, n1, n2)
        if g > best:
            best, b0, b1, b2 = g, n0, n1, n2
    for i in range(a_first, a_first + a_count):
        u0, u1, u2 = _axis(Sa, i)
        for j in range(b_first, b_first + b_count):
            v0, v1, v2 = _axis(Sb, j)
            c0, c1, c2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
            norm = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            if norm > 1e-6:
                n0, n1, n2 = c0 / norm, c1 / norm, c2 / norm
                g = gap(Sa, Sb, H, n0, n1, n2)
                if g > best:
                    best, b0, b1, b2 = g, n0, n1, n2
    return best, b0, b1, b2


@_kernel
def _solve(k: int, g00: float, g01: float, g02: float, g11: float, g12: float,
           g22: float, r0: float, r1: float, r2: float
           ) -> tuple[bool, float, float, float]:
    """Solve the symmetric k x k system (k <= 3) G x = r by Cramer's rule; False if it
    is (nearly) singular."""
    if k == 1:
        if g00 <= 1e-30:
            return False, 0.0, 0.0, 0.0
        return True, r0 / g00, 0.0, 0.0
    if k == 2:
        det = g00 * g11 - g01 * g01
        if det <= 1e-14 * g00 * g11:
            return False, 0.0, 0.0, 0.0
        return True, (r0 * g11 - r1 * g01) / det, (g00 * r1 - g01 * r0) / det, 0.0
    c00 = g11 * g22 - g12 * g12
    c01 = g02 * g12 - g01 * g22
    c02 = g01 * g12 - g02 * g11
    det = g00 * c00 + g01 * c01 + g02 * c02
    if det <= 1e-14 * g00 * g11 * g22:
        return False, 0.0, 0.0, 0.0
    c11 = g00 * g22 - g02 * g02
    c12 = g01 * g02 - g00 * g12
    c22 = g00 * g11 - g01 * g01
    return (True, (c00 * r0 + c01 * r1 + c02 * r2) / det,
            (c01 * r0 + c11 * r1 + c12 * r2) / det, (c02 * r0 + c12 * r1 + c22 * r2) / det)


@_inline
def _face_point(W: np.ndarray, e: np.ndarray, idx: np.ndarray, count: int, mask: int
                ) -> tuple[bool, float, float, float]:
    """The point of the simplex's face (its vertices: the bits of ``mask`` among the
    first ``count`` rows of ``W``) closest to the origin, if the origin's projection on
    the face's plane falls inside the face (else False)."""
    k = -1
    for i in range(count):
        if mask >> i & 1:
            k += 1
            idx[k] = i
    i0 = idx[0]
    e[:] = 0.0
    for a in range(k):
        for c in range(3):
            e[a, c] = W[idx[a + 1], c] - W[i0, c]
    x0, x1, x2 = W[i0, 0], W[i0, 1], W[i0, 2]
    if k > 0:
        ok, l1, l2, l3 = _solve(
            k, e[0, 0] * e[0, 0] + e[0, 1] * e[0, 1] + e[0, 2] * e[0, 2],
            e[0, 0] * e[1, 0] + e[0, 1] * e[1, 1] + e[0, 2] * e[1, 2],
            e[0, 0] * e[2, 0] + e[0, 1] * e[2, 1] + e[0, 2] * e[2, 2],
            e[1, 0] * e[1, 0] + e[1, 1] * e[1, 1] + e[1, 2] * e[1, 2],
            e[1, 0] * e[2, 0] + e[1, 1] * e[2, 1] + e[1, 2] * e[2, 2],
            e[2, 0] * e[2, 0] + e[2, 1] * e[2, 1] + e[2, 2] * e[2, 2],
            -(e[0, 0] * x0 + e[0, 1] * x1 + e[0, 2] * x2),
            -(e[1, 0] * x0 + e[1, 1] * x1 + e[1, 2] * x2),
            -(e[2, 0] * x0 + e[2, 1] * x1 + e[2, 2] * x2))
        if not ok or min(l1, l2, l3) < -1e-12 or l1 + l2 + l3 > 1.0 + 1e-12:
            return False, x0, x1, x2
        x0 += l1 * e[0, 0] + l2 * e[1, 0] + l3 * e[2, 0]
        x1 += l1 * e[0, 1] + l2 * e[1, 1] + l3 * e[2, 1]
        x2 += l1 * e[0, 2] + l2 * e[1, 2] + l3 * e[2, 2]
    return True, x0, x1, x2


@_inline
def _closest(W: np.ndarray, e: np.ndarray, idx: np.ndarray, count: int, v0: float,
             v1: float, v2: float) -> tuple[int, float, float, float]:
    """The closest point of the simplex (the first ``count`` rows of ``W``) to the
    origin, and the face it lies on (a mask of its vertices): the smallest of the faces'
    closest points (:func:`_face_point`). (v0, v1, v2) is kept if no face has one."""
    closest, keep_mask = np.inf, 0
    for mask in range(1, 1 << count):
        inside, x0, x1, x2 = _face_point(W, e, idx, count, mask)
        if not inside:
            continue
        norm2 = x0 * x0 + x1 * x1 + x2 * x2
        if norm2 < closest:
            closest, keep_mask = norm2, mask
            v0, v1, v2 = x0, x1, x2
    return keep_mask, v0, v1, v2


@_inline
def _reduce(W: np.ndarray, count: int, keep_mask: int) -> int:
    """Keep the simplex's vertices in ``keep_mask`` (moved to the first rows of ``W``,
    in order); returns how many."""
    kept = 0
    for i in range(count):
        if keep_mask >> i & 1:
            for c in range(3):
                W[kept, c] = W[i, c]
            kept += 1
    return kept


@_kernel
def gjk_bound(Sa: Placed, Sb: Placed, H: Hulls, best: float, w0: float, w1: float,
              w2: float, warm: bool, W: np.ndarray, e: np.ndarray, idx: np.ndarray
              ) -> tuple[float, float, float, float, float]:
    """Raise the lower bound ``best`` [m] with the gaps along GJK's search directions.

    GJK walks the Minkowski difference B - A towards the origin, from its point
    furthest along the axis w if ``warm`` (else from the centres' difference). It stops
    when the bound is within a micrometre of its upper bound (the distance to the
    closest point of its simplex, itself the distance between two points of the
    shapes), when it meets the origin, or after 32 steps. The closest point of the
    simplex is the smallest of its faces' projections that fall inside their face.

    Scratch: ``W`` (4 x 3, the simplex), ``e`` (3 x 3, its edges), ``idx`` (4, int).

    Returns:
        The bound [m], the upper bound [m], and the axis of the bound if GJK raised
        it (else w).
    """
    d0, d1, d2 = Sb.cx - Sa.cx, Sb.cy - Sa.cy, Sb.cz - Sa.cz
    v0, v1, v2 = d0, d1, d2
    b0, b1, b2 = w0, w1, w2
    count = 0
    if warm:
        a0, a1, a2 = _support_point(Sa, H, w0, w1, w2)
        c0, c1, c2 = _support_point(Sb, H, -w0, -w1, -w2)
        v0, v1, v2 = c0 - a0, c1 - a1, c2 - a2
        W[0, 0], W[0, 1], W[0, 2] = v0, v1, v2
        count = 1
    upper = np.inf
    for _ in range(32):
        norm = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        upper = min(upper, norm)
        if norm < 1e-10:
            break  # touching or overlapping: the axis bounds are all there is
        n0, n1, n2 = v0 / norm, v1 / norm, v2 / norm
        g = (n0 * d0 + n1 * d1 + n2 * d2 - support(Sa, H, n0, n1, n2)
             - support(Sb, H, -n0, -n1, -n2))
        if g > best:
            best, b0, b1, b2 = g, n0, n1, n2
        if norm - best < 1e-6:
            break
        a0, a1, a2 = _support_point(Sa, H, n0, n1, n2)
        c0, c1, c2 = _support_point(Sb, H, -n0, -n1, -n2)
        W[count, 0], W[count, 1], W[count, 2] = c0 - a0, c1 - a1, c2 - a2
        count += 1
        # The closest point of the simplex to the origin, and the face it lies on.
        keep_mask, v0, v1, v2 = _closest(W, e, idx, count, v0, v1, v2)
        count = _reduce(W, count, keep_mask)
        if count == 4:
            break  # the origin is inside: overlapping
    return best, upper, b0, b1, b2


@njit(cache=True)
def axis_bound_entry(Sa: tuple, Sb: tuple, H: tuple) -> tuple[float, float, float, float]:
    """:func:`axis_bound` for callers from Python (an entry of the ahead-of-time table,
    whose guards take plain tuples): the placed shapes as tuples in :class:`Placed`'s
    field order, the hull tables in :class:`Hulls`'s."""
    return axis_bound(Placed(*Sa), Placed(*Sb), Hulls(*H))  # type: ignore[no-any-return]


@njit(cache=True)
def gjk_bound_entry(Sa: tuple, Sb: tuple, H: tuple, best: float, w0: float, w1: float,
                    w2: float, warm: bool, W: np.ndarray, e: np.ndarray, idx: np.ndarray
                    ) -> tuple[float, float, float, float, float]:
    """:func:`gjk_bound` for callers from Python (as :func:`axis_bound_entry`)."""
    return gjk_bound(Placed(*Sa), Placed(*Sb), Hulls(*H),  # type: ignore[no-any-return]
                     best, w0, w1, w2, warm, W, e, idx)
