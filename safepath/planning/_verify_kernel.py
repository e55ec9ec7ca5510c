"""The verifier's numba kernel: a lower bound on the distance between two placed convex
shapes, its own forward kinematics, and the walk along the grid.

Imported lazily by ``_verify_bounds`` (numba takes a while to import); compiled once and
cached on disk. One module on purpose: numba's disk cache tracks only the file of the
function it compiles, so a walk compiled here never runs with stale geometry helpers
from another file. Plain loops, no ``np.dot`` or ``@``. The geometric helpers take floats
and tuples of floats only, and the array work of the walk sits in closures inside
:func:`certify`: a numba helper that takes arrays pays their reference counting on every
call, which costs more than most of these helpers' work. The small helpers that take
placed shapes (:func:`support`, :func:`gap`, ...) are inlined where they are called
(numba's ``inline="always"``): a call copies both shapes' 17 floats and the hull tables
onto the stack, which cost more than the helper's own arithmetic (the walk took ~12 %
less time inlined). Inlining changes no operation, so no result.

The walk is compiled without numba's reference counting (``_nrt=False``): it allocates
nothing, its scratch and output buffers come from the caller, and a reference count on
every array it touches cost ~8 % of its time. :func:`certify` is the entry point that
calls it (an ahead-of-time build compiles entry points with reference counting, their
callees as they are declared). The walk returns when its output buffers are full, with
the place to resume from.

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

The shape table has one row per shape (the bodies', then the environment objects'):
kind (0 box, 1 sphere, 2 cylinder, 3 capsule, 4 hull), three parameters (box half
extents; radius; radius and half length; a hull's first row in the vertex table and its
count), the centre in the geometry frame, and the radius of a sphere about the centre
that holds the shape. The vertex table holds the hulls' vertices about their centres,
in their geometry frames; with it go, per vertex row, the rows of its neighbours along
the hull's edges (where they start in the neighbour table, and that table): a hull's
support climbs them instead of scanning every vertex.
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit

#: How every function here but the entry points is compiled (see the module doc).
_kernel = njit(cache=True, _nrt=False)
#: How the small helpers that take placed shapes are compiled: inlined where they are
#: called (see the module doc).
_inline = njit(cache=True, _nrt=False, inline="always")

BOX, SPHERE, CYLINDER, CAPSULE, HULL = 0, 1, 2, 3, 4
#: A step's search for the first sample its bound does not certify stops once it has that
#: sample within a 1/APPROX share of the step (the step then ends at the last sample it
#: knows certified): pinning it down to the sample costs more motion probes than the
#: few extra bounds save.
APPROX = 3
REVOLUTE, PRISMATIC = 1, 2
#: Columns of the shape table.
KIND, PAR, CENTRE, RADIUS = 0, 1, 4, 7

# A placed shape is a tuple of 17 floats: kind, three parameters (box half extents;
# radius; radius and half length), the radius of a sphere about the centre that holds
# it, its centre in the world (3), its rotation in the world (9, row-major; column j is
# the shape's axis j).


@_inline
def _dots(S: tuple, n0: float, n1: float, n2: float) -> tuple[float, float, float]:
    """n along each of the shape's axes."""
    return (n0 * S[8] + n1 * S[11] + n2 * S[14], n0 * S[9] + n1 * S[12] + n2 * S[15],
            n0 * S[10] + n1 * S[13] + n2 * S[16])


@_inline
def _axis(S: tuple, j: int) -> tuple[float, float, float]:
    """The shape's axis j in the world."""
    if j == 0:
        return S[8], S[11], S[14]
    if j == 1:
        return S[9], S[12], S[15]
    return S[10], S[13], S[16]


@_kernel
def _hull_top(S: tuple, H: tuple, a0: float, a1: float, a2: float) -> tuple[float, int]:
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
    V, ptr, nbr, start = H
    first = int(S[1])
    k = start[first]
    best = V[k, 0] * a0 + V[k, 1] * a1 + V[k, 2] * a2
    while True:
        top = k
        for e in range(ptr[k], ptr[k + 1]):
            j = nbr[e]
            x = V[j, 0] * a0 + V[j, 1] * a1 + V[j, 2] * a2
            if x > best:
                best, top = x, j
        if top == k:
            start[first] = k
            return best, k
        k = top


@_inline
def support(S: tuple, H: tuple, n0: float, n1: float, n2: float) -> float:
    """How far the shape's projection on the unit axis n reaches beyond its centre along
    n [m] (half its width, but for a hull: ``H`` holds the hulls' vertices about their
    centres in their own frames (rows), per vertex row where its neighbours start in
    the neighbour rows, those rows, and per hull (at its first row) the vertex its
    last climb ended at, updated)."""
    a0, a1, a2 = _dots(S, n0, n1, n2)
    kind = int(S[0])
    if kind == HULL:
        return _hull_top(S, H, a0, a1, a2)[0]  # type: ignore[no-any-return]
    if kind == BOX:
        return S[1] * abs(a0) + S[2] * abs(a1) + S[3] * abs(a2)  # type: ignore[no-any-return]
    if kind == SPHERE:
        return S[1]  # type: ignore[no-any-return]
    u = abs(a2)
    if kind == CYLINDER:
        return S[2] * u + S[1] * math.sqrt(max(0.0, 1.0 - u * u))  # type: ignore[no-any-return]
    return S[2] * u + S[1]  # type: ignore[no-any-return]


@_inline
def _support_point(S: tuple, H: tuple, n0: float, n1: float, n2: float
                   ) -> tuple[float, float, float]:
    """A point of the shape furthest along n: GJK's search only, the bounds use
    :func:`support`."""
    x0, x1, x2 = S[5], S[6], S[7]
    a0, a1, a2 = _dots(S, n0, n1, n2)
    kind = int(S[0])
    if kind == HULL:
        V = H[0]
        k = _hull_top(S, H, a0, a1, a2)[1]
        for j in range(3):
            c0, c1, c2 = _axis(S, j)
            x0, x1, x2 = x0 + V[k, j] * c0, x1 + V[k, j] * c1, x2 + V[k, j] * c2
        return x0, x1, x2
    if kind == BOX:
        for j, a in ((0, a0), (1, a1), (2, a2)):
            h = S[1 + j] if a >= 0.0 else -S[1 + j]
            c0, c1, c2 = _axis(S, j)
            x0, x1, x2 = x0 + h * c0, x1 + h * c1, x2 + h * c2
        return x0, x1, x2
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if kind == SPHERE:
        r = S[1] / norm
        return x0 + r * n0, x1 + r * n1, x2 + r * n2
    c0, c1, c2 = _axis(S, 2)
    h = S[2] if a2 >= 0.0 else -S[2]
    x0, x1, x2 = x0 + h * c0, x1 + h * c1, x2 + h * c2
    if kind == CAPSULE:
        r = S[1] / norm
        return x0 + r * n0, x1 + r * n1, x2 + r * n2
    r0, r1, r2 = n0 - a2 * c0, n1 - a2 * c1, n2 - a2 * c2
    radial = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if radial > 1e-12 * norm:
        r = S[1] / radial
        x0, x1, x2 = x0 + r * r0, x1 + r * r1, x2 + r * r2
    return x0, x1, x2


@_inline
def gap(Sa: tuple, Sb: tuple, H: tuple, n0: float, n1: float, n2: float) -> float:
    """Gap between the shapes' projections on the unit axis n [m]."""
    d0, d1, d2 = Sb[5] - Sa[5], Sb[6] - Sa[6], Sb[7] - Sa[7]
    along = n0 * d0 + n1 * d1 + n2 * d2
    if along < 0.0:  # B lies behind A along n: measure along -n
        n0, n1, n2, along = -n0, -n1, -n2, -along
    return (along - support(Sa, H, n0, n1, n2)  # type: ignore[no-any-return]
            - support(Sb, H, -n0, -n1, -n2))


@_inline
def sphere_bound(Sa: tuple, Sb: tuple) -> tuple[float, float, float, float]:
    """Distance between the bounding spheres [m] (never above the gap along the line
    between the centres), and that line's direction."""
    d0, d1, d2 = Sb[5] - Sa[5], Sb[6] - Sa[6], Sb[7] - Sa[7]
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dist < 1e-12:
        return dist - Sa[4] - Sb[4], 0.0, 0.0, 1.0
    return dist - Sa[4] - Sb[4], d0 / dist, d1 / dist, d2 / dist


@_inline
def _own_axes(S: tuple) -> tuple[int, int]:
    """The shape's axes worth trying: (first, count)."""
    kind = int(S[0])
    if kind == BOX:
        return 0, 3
    if kind == SPHERE or kind == HULL:  # a hull's frame axes are nothing special
        return 0, 0
    return 2, 1


@_kernel
def axis_bound(Sa: tuple, Sb: tuple, H: tuple) -> tuple[float, float, float, float]:
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


@_kernel
def gjk_bound(Sa: tuple, Sb: tuple, H: tuple, best: float, w0: float, w1: float,
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
    d0, d1, d2 = Sb[5] - Sa[5], Sb[6] - Sa[6], Sb[7] - Sa[7]
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
        closest, keep_mask = np.inf, 0
        for mask in range(1, 1 << count):
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
                    continue
                x0 += l1 * e[0, 0] + l2 * e[1, 0] + l3 * e[2, 0]
                x1 += l1 * e[0, 1] + l2 * e[1, 1] + l3 * e[2, 1]
                x2 += l1 * e[0, 2] + l2 * e[1, 2] + l3 * e[2, 2]
            norm2 = x0 * x0 + x1 * x1 + x2 * x2
            if norm2 < closest:
                closest, keep_mask = norm2, mask
                v0, v1, v2 = x0, x1, x2
        kept = 0
        for i in range(count):
            if keep_mask >> i & 1:
                for c in range(3):
                    W[kept, c] = W[i, c]
                kept += 1
        count = kept
        if count == 4:
            break  # the origin is inside: overlapping
    return best, upper, b0, b1, b2


@njit(cache=True)
def grid(q: np.ndarray, weights: np.ndarray, resolution: float
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cut the knots ``q`` (knots x dof) so that no body moves more than ``resolution``
    [m] between two samples, the bodies' motion weights being ``weights`` (bodies x
    dof): a knot interval whose weighted step reaches n resolutions gets n samples.

    Returns:
        (knot of every sample, fraction of its interval, |dq| into every knot (0 at the
        first), its accumulated sum): see ``_verify_bounds.Grid``.
    """
    knots, dof = q.shape
    step = np.empty((knots, dof))
    cum = np.empty((knots, dof))
    cuts = np.ones(knots, dtype=np.int64)
    total = 1
    for v in range(dof):
        step[0, v] = 0.0
        cum[0, v] = 0.0
    for k in range(1, knots):
        for v in range(dof):
            step[k, v] = abs(q[k, v] - q[k - 1, v])
            cum[k, v] = cum[k - 1, v] + step[k, v]
        most = 0.0
        for b in range(weights.shape[0]):
            moved = 0.0
            for v in range(dof):
                moved += step[k, v] * weights[b, v]
            most = max(most, moved)
        cuts[k] = max(int(math.ceil(most / resolution)), 1)
        total += cuts[k]
    knot_of = np.empty(total, dtype=np.int64)
    frac = np.empty(total)
    knot_of[0], frac[0] = 0, 1.0
    s = 1
    for k in range(1, knots):
        for i in range(1, cuts[k] + 1):
            knot_of[s], frac[s] = k, i / cuts[k]
            s += 1
    return knot_of, frac, step, cum


@_kernel
def _basis(x: float, y: float, z: float) -> int:
    """0, 1 or 2 if (x, y, z) is the unit x, y or z axis, else -1."""
    if y == 0.0 and z == 0.0 and x == 1.0:
        return 0
    if x == 0.0 and z == 0.0 and y == 1.0:
        return 1
    if x == 0.0 and y == 0.0 and z == 1.0:
        return 2
    return -1


@_kernel
def _motion(kind: int, value: float, x: float, y: float, z: float
            ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """A joint's own rotation (row-major): about the unit axis (x, y, z) by ``value``
    [rad] (Rodrigues), or none for a prismatic joint."""
    if kind == PRISMATIC:
        return 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    co, si = math.cos(value), math.sin(value)
    t = 1.0 - co
    return (co + t * x * x, t * x * y - si * z, t * x * z + si * y,
            t * x * y + si * z, co + t * y * y, t * y * z - si * x,
            t * x * z - si * y, t * y * z + si * x, co + t * z * z)


@_kernel
def _turned(p0: float, p1: float, p2: float, along: int, co: float, si: float
            ) -> tuple[float, float, float]:
    """A row (p0, p1, p2) of a joint's placement times its turn about its own axis
    ``along`` (0, 1 or 2) by the angle of cosine ``co`` and sine ``si``: the other two
    columns turn into each other."""
    if along == 0:
        return p0, p1 * co + p2 * si, p2 * co - p1 * si
    if along == 1:
        return p0 * co - p2 * si, p1, p2 * co + p0 * si
    return p0 * co + p1 * si, p1 * co - p0 * si, p2


@_kernel
def _placed_row(p0: float, p1: float, p2: float, p3: float, r00: float, r01: float,
                r02: float, r10: float, r11: float, r12: float, r20: float, r21: float,
                r22: float, t0: float, t1: float, t2: float
                ) -> tuple[float, float, float, float]:
    """A row (p0, p1, p2, p3) of a joint's placement times its motion (rotation r,
    row-major, and shift t)."""
    return (p0 * r00 + p1 * r10 + p2 * r20, p0 * r01 + p1 * r11 + p2 * r21,
            p0 * r02 + p1 * r12 + p2 * r22, p0 * t0 + p1 * t1 + p2 * t2 + p3)


@_kernel
def _pose_row(a0: float, a1: float, a2: float, a3: float, m00: float, m01: float,
              m02: float, m03: float, m10: float, m11: float, m12: float, m13: float,
              m20: float, m21: float, m22: float, m23: float
              ) -> tuple[float, float, float, float]:
    """A row (a0, a1, a2, a3) of a pose times the pose m (3 x 4, row-major)."""
    return (a0 * m00 + a1 * m10 + a2 * m20, a0 * m01 + a1 * m11 + a2 * m21,
            a0 * m02 + a1 * m12 + a2 * m22, a0 * m03 + a1 * m13 + a2 * m23 + a3)


@njit(cache=True)
def certify(todo: np.ndarray, first: np.ndarray, stop: np.ndarray, theta: np.ndarray,
            grid: tuple, kin: tuple, cache: tuple, pairs: tuple, world: tuple, memory: tuple,
            params: tuple, scratch: tuple, t0: int, s0: int) -> tuple[int, int, int]:
    """Walk every pair in ``todo`` along its stretch of the grid with the lower bound
    (see :func:`_walk`, which it calls).

    The joints' accumulated motion and upstream turning are interpolated to every sample
    here, once per walk: a step's search reads them for every joint at every probe
    (three probes per step, on average), and did the same interpolation each time."""
    cum, step, cum_turn, step_turn, qk, knot_of, frac = grid
    at, at_turn = _accumulated(cum, step, knot_of, frac), _accumulated(cum_turn, step_turn,
                                                                       knot_of, frac)
    return _walk(todo, first, stop, theta,  # type: ignore[no-any-return]
                 (at, at_turn, qk, knot_of, frac), kin, cache, pairs, world, memory, params,
                 scratch, t0, s0)


@njit(cache=True)
def _accumulated(cum: np.ndarray, step: np.ndarray, knot_of: np.ndarray, frac: np.ndarray
                 ) -> np.ndarray:
    """The accumulated sum ``cum`` (knots x dof) of the steps ``step`` into every knot,
    at every sample (samples x dof; zero at the first knot's): the same expression the
    walk evaluated at each probe, so the same numbers."""
    out = np.empty((knot_of.size, cum.shape[1]))
    for s in range(knot_of.size):
        k = knot_of[s]
        for v in range(cum.shape[1]):
            out[s, v] = 0.0 if k == 0 else cum[k - 1, v] + frac[s] * step[k, v]
    return out


@_kernel
def _walk(todo: np.ndarray, first: np.ndarray, stop: np.ndarray, theta: np.ndarray,
          grid: tuple, kin: tuple, cache: tuple, pairs: tuple, world: tuple, memory: tuple,
          params: tuple, scratch: tuple, t0: int, s0: int) -> tuple[int, int, int]:
    """Walk every pair in ``todo`` along its stretch of the grid with the lower bound.

    At a sample whose bound exceeds the pair's threshold, the samples until the bound
    on how much the pair's gap (along the bound's axis) can have changed reaches the
    excess are certified; a sample whose bound does not exceed it is returned, for FCL,
    and the walk goes on at the next sample.

    Args:
        todo: Pairs to walk, in this order (a pair may come more than once, for
            stretches apart).
        first, stop: The stretch of the grid each entry of ``todo`` walks: samples
            ``first`` to ``stop`` - 1.
        theta: Threshold of every pair [m].
        grid: (accumulated joint motion |dq| at every sample (samples x dof), the
            same for the turning of the revolute joints upstream of each joint, knot
            positions [rad], knot of every sample, fraction of its interval). Samples
            move linearly between knots.
        kin: (parent, placement (3 x 4), kind, axis, q index) of every joint; (joint,
            placement in it (3 x 4)) of every body; the joint of every velocity index.
        cache: (joint done, joint pose) by sample.
        pairs: (body a, body or environment object b, b is environment, motion weights,
            counts for the clearance) of every pair, and per pair and velocity index
            whether the joint moves body b (else a, or neither: weight 0).
        world: (shape table: the bodies' rows, then the environment objects'; world
            pose of every environment object (3 x 4); the hull tables: vertices,
            neighbour starts, neighbour rows, climbs' starts (see :func:`support`)).
        memory: Per pair, the axis that separated it best at its last full evaluation
            and 1 if there is one, and its last full bound [m]; the bounds evaluated
            (all, with the axes, with GJK); the ceiling (smallest GJK upper bound of a
            clearance pair [m], its pair, its sample). Updated.
        params: (coarse: use the bounding spheres alone above theta + coarse [m];
            fine: refine with GJK below theta + fine [m]; keep: trust a kept axis while
            its gap keeps this share of the last full bound's excess; drop: if not
            negative, a clearance pair's threshold is the ceiling minus drop [m], if
            higher than its own).

        scratch: (chain (joints, int), share, reach_ (dof each), GJK's W (4 x 3), e
            (3 x 3) and idx (4, int); the outputs: pair (int), sample (int) and bound of
            every uncertified couple, as long as the room they have).
        t0, s0: Where to start: the walk of ``todo[t0]`` at sample ``s0`` (0,
            ``first[0]``: from the beginning; else where the last call stopped).

    Returns:
        The number of uncertified (pair, sample) couples written to the outputs (entry
        by entry, samples ascending), and where to resume: (``todo.size``, 0) when the
        walk is done, else the place after the last couple written (the outputs were
        full). A walk resumed there goes on exactly as if it had not stopped.
    """
    at, at_turn, qk, knot_of, frac = grid
    parent, place, kind, axis, iq, m_joint, m_place, joint_of = kin
    jdone, jpose = cache
    pair_a, pair_b, pair_env, weights, tracked, moves_b = pairs
    shp, env_pose, hulls = world
    axes, last, stats, ceiling = memory
    coarse, fine, keep, drop = params
    movers = m_joint.size
    nv = qk.shape[1]
    chain, share, reach_, W, e, idx, out_p, out_s, out_b = scratch
    share[:] = 1.0

    def joint_pose(s: int, j: int) -> None:
        """jpose[s, j] (and its missing ancestors) = parent's pose * placement * the
        joint's own motion (a rotation about its axis or a shift along it). The
        placement times the motion is kept in locals, and the parent's pose read
        before the joint's is written: through arrays, every write to the pose could
        overwrite what the next product reads, and would be read back."""
        count, k = 0, j
        while k > 0 and not jdone[s, k]:
            chain[count] = k
            count += 1
            k = parent[k]
        knot = knot_of[s]
        for c in range(count - 1, -1, -1):
            k = chain[c]
            col = iq[k]
            value = qk[0, col] if knot == 0 else (
                qk[knot - 1, col] + frac[s] * (qk[knot, col] - qk[knot - 1, col]))
            x, y, z = axis[k, 0], axis[k, 1], axis[k, 2]
            p = parent[k]
            along = _basis(x, y, z) if kind[k] != PRISMATIC else -1
            if along >= 0:
                # The usual joints: a turn about the joint's own x, y or z (the general
                # case below, with the zeros left out).
                co, si = math.cos(value), math.sin(value)
                m00, m01, m02 = _turned(place[k, 0, 0], place[k, 0, 1], place[k, 0, 2],
                                        along, co, si)
                m10, m11, m12 = _turned(place[k, 1, 0], place[k, 1, 1], place[k, 1, 2],
                                        along, co, si)
                m20, m21, m22 = _turned(place[k, 2, 0], place[k, 2, 1], place[k, 2, 2],
                                        along, co, si)
                m03, m13, m23 = place[k, 0, 3], place[k, 1, 3], place[k, 2, 3]
            else:
                r00, r01, r02, r10, r11, r12, r20, r21, r22 = _motion(kind[k], value, x, y, z)
                t0, t1, t2 = (x * value, y * value, z * value) if kind[k] == PRISMATIC \
                    else (0.0, 0.0, 0.0)
                m00, m01, m02, m03 = _placed_row(place[k, 0, 0], place[k, 0, 1], place[k, 0, 2],
                                                 place[k, 0, 3], r00, r01, r02, r10, r11, r12,
                                                 r20, r21, r22, t0, t1, t2)
                m10, m11, m12, m13 = _placed_row(place[k, 1, 0], place[k, 1, 1], place[k, 1, 2],
                                                 place[k, 1, 3], r00, r01, r02, r10, r11, r12,
                                                 r20, r21, r22, t0, t1, t2)
                m20, m21, m22, m23 = _placed_row(place[k, 2, 0], place[k, 2, 1], place[k, 2, 2],
                                                 place[k, 2, 3], r00, r01, r02, r10, r11, r12,
                                                 r20, r21, r22, t0, t1, t2)
            if p == 0:
                jpose[s, k, 0, 0], jpose[s, k, 0, 1], jpose[s, k, 0, 2] = m00, m01, m02
                jpose[s, k, 1, 0], jpose[s, k, 1, 1], jpose[s, k, 1, 2] = m10, m11, m12
                jpose[s, k, 2, 0], jpose[s, k, 2, 1], jpose[s, k, 2, 2] = m20, m21, m22
                jpose[s, k, 0, 3], jpose[s, k, 1, 3], jpose[s, k, 2, 3] = m03, m13, m23
            else:
                r0 = _pose_row(jpose[s, p, 0, 0], jpose[s, p, 0, 1], jpose[s, p, 0, 2],
                               jpose[s, p, 0, 3], m00, m01, m02, m03, m10, m11, m12, m13,
                               m20, m21, m22, m23)
                r1 = _pose_row(jpose[s, p, 1, 0], jpose[s, p, 1, 1], jpose[s, p, 1, 2],
                               jpose[s, p, 1, 3], m00, m01, m02, m03, m10, m11, m12, m13,
                               m20, m21, m22, m23)
                r2 = _pose_row(jpose[s, p, 2, 0], jpose[s, p, 2, 1], jpose[s, p, 2, 2],
                               jpose[s, p, 2, 3], m00, m01, m02, m03, m10, m11, m12, m13,
                               m20, m21, m22, m23)
                jpose[s, k, 0, 0], jpose[s, k, 0, 1], jpose[s, k, 0, 2], jpose[s, k, 0, 3] = r0
                jpose[s, k, 1, 0], jpose[s, k, 1, 1], jpose[s, k, 1, 2], jpose[s, k, 1, 3] = r1
                jpose[s, k, 2, 0], jpose[s, k, 2, 1], jpose[s, k, 2, 2], jpose[s, k, 2, 3] = r2
            jdone[s, k] = True

    def placed_body(k: int, s: int, m: int) -> tuple:
        """Shape k placed as body m at sample s: its geometry frame is its joint's pose
        times its placement in the joint frame."""
        j = m_joint[m]
        if j > 0 and not jdone[s, j]:
            joint_pose(s, j)
        p00, p01, p02, p03 = m_place[m, 0, 0], m_place[m, 0, 1], m_place[m, 0, 2], m_place[m, 0, 3]
        p10, p11, p12, p13 = m_place[m, 1, 0], m_place[m, 1, 1], m_place[m, 1, 2], m_place[m, 1, 3]
        p20, p21, p22, p23 = m_place[m, 2, 0], m_place[m, 2, 1], m_place[m, 2, 2], m_place[m, 2, 3]
        if j == 0:
            t0, t1, t2 = (p00, p01, p02, p03), (p10, p11, p12, p13), (p20, p21, p22, p23)
        else:
            t0 = _pose_row(jpose[s, j, 0, 0], jpose[s, j, 0, 1], jpose[s, j, 0, 2],
                           jpose[s, j, 0, 3], p00, p01, p02, p03, p10, p11, p12, p13, p20,
                           p21, p22, p23)
            t1 = _pose_row(jpose[s, j, 1, 0], jpose[s, j, 1, 1], jpose[s, j, 1, 2],
                           jpose[s, j, 1, 3], p00, p01, p02, p03, p10, p11, p12, p13, p20,
                           p21, p22, p23)
            t2 = _pose_row(jpose[s, j, 2, 0], jpose[s, j, 2, 1], jpose[s, j, 2, 2],
                           jpose[s, j, 2, 3], p00, p01, p02, p03, p10, p11, p12, p13, p20,
                           p21, p22, p23)
        c0, c1, c2 = shp[k, CENTRE], shp[k, CENTRE + 1], shp[k, CENTRE + 2]
        return (shp[k, KIND], shp[k, PAR], shp[k, PAR + 1], shp[k, PAR + 2], shp[k, RADIUS],
                t0[3] + t0[0] * c0 + t0[1] * c1 + t0[2] * c2,
                t1[3] + t1[0] * c0 + t1[1] * c1 + t1[2] * c2,
                t2[3] + t2[0] * c0 + t2[1] * c1 + t2[2] * c2,
                t0[0], t0[1], t0[2], t1[0], t1[1], t1[2], t2[0], t2[1], t2[2])

    def placed_env(k: int, b: int) -> tuple:
        """Shape k placed as environment object b."""
        c0, c1, c2 = shp[k, CENTRE], shp[k, CENTRE + 1], shp[k, CENTRE + 2]
        return (shp[k, KIND], shp[k, PAR], shp[k, PAR + 1], shp[k, PAR + 2], shp[k, RADIUS],
                env_pose[b, 0, 3] + env_pose[b, 0, 0] * c0 + env_pose[b, 0, 1] * c1
                + env_pose[b, 0, 2] * c2,
                env_pose[b, 1, 3] + env_pose[b, 1, 0] * c0 + env_pose[b, 1, 1] * c1
                + env_pose[b, 1, 2] * c2,
                env_pose[b, 2, 3] + env_pose[b, 2, 0] * c0 + env_pose[b, 2, 1] * c1
                + env_pose[b, 2, 2] * c2,
                env_pose[b, 0, 0], env_pose[b, 0, 1], env_pose[b, 0, 2],
                env_pose[b, 1, 0], env_pose[b, 1, 1], env_pose[b, 1, 2],
                env_pose[b, 2, 0], env_pose[b, 2, 1], env_pose[b, 2, 2])

    def shapes(p: int, s: int) -> tuple:
        """Pair p's two shapes at sample s."""
        a, b = pair_a[p], pair_b[p]
        if pair_env[p]:
            return placed_body(a, s, a), placed_env(movers + b, b)
        return placed_body(a, s, a), placed_body(b, s, b)

    def set_shares(p: int, s: int, n0: float, n1: float, n2: float, Sa: tuple, Sb: tuple
                   ) -> None:
        """For every joint that moves pair p, at sample s: |n x u| (revolute) or |n . u|
        (prismatic), u being the joint's axis in the world (see ``motion``), and how far
        the points of the body it moves lie from its axis (``reach_``: the body's
        bounding sphere's centre's distance plus its radius; a prismatic joint: its
        weight)."""
        for v in range(nv):
            if weights[p, v] == 0.0:
                continue
            j = joint_of[v]
            along = _basis(axis[j, 0], axis[j, 1], axis[j, 2])
            if along >= 0:  # the pose's own axis: its column
                u0, u1, u2 = jpose[s, j, 0, along], jpose[s, j, 1, along], jpose[s, j, 2, along]
            else:
                u0 = (jpose[s, j, 0, 0] * axis[j, 0] + jpose[s, j, 0, 1] * axis[j, 1]
                      + jpose[s, j, 0, 2] * axis[j, 2])
                u1 = (jpose[s, j, 1, 0] * axis[j, 0] + jpose[s, j, 1, 1] * axis[j, 1]
                      + jpose[s, j, 1, 2] * axis[j, 2])
                u2 = (jpose[s, j, 2, 0] * axis[j, 0] + jpose[s, j, 2, 1] * axis[j, 1]
                      + jpose[s, j, 2, 2] * axis[j, 2])
            if kind[j] == PRISMATIC:
                share[v] = abs(n0 * u0 + n1 * u1 + n2 * u2)
                reach_[v] = weights[p, v]
            else:
                c0, c1, c2 = n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0
                share[v] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
                S = Sb if moves_b[p, v] else Sa
                d0, d1, d2 = (S[5] - jpose[s, j, 0, 3], S[6] - jpose[s, j, 1, 3],
                              S[7] - jpose[s, j, 2, 3])
                c0, c1, c2 = d1 * u2 - d2 * u1, d2 * u0 - d0 * u2, d0 * u1 - d1 * u0
                reach_[v] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) + S[4]

    def motion(p: int, s: int, i: int) -> float:
        """Bound on how much pair p's gap along its axis n can change from sample s to
        i [m]. A revolute joint turning by dq moves a point at r from its axis by at
        most r dq, perpendicular to the axis u, so along n by at most r dq |n x u|;
        while the joints upstream turn by a, u turns by at most a, so |n x u| stays
        below its value at s plus a (and below 1). A prismatic joint moves points
        along u: |n . u| instead. Between two bodies, joints that move
        both leave their distance alone (their weight is zero; taking n in the frame
        they move keeps the argument, and the turning counted is only more).

        r is at most the joint's weight for the body it moves, and at most the body's
        reach from the axis at s (``reach_``) plus what the joints between the two
        have moved its points since (each by its weight times its motion: they change
        the body's distance to the axis, the joints upstream move both alike). Those
        joints come after it in velocity order (a joint's children follow it), so one
        pass from the last joint adds them up, per body."""
        acc = grown_a = grown_b = 0.0
        w_p, b_p, at_i, at_s = weights[p], moves_b[p], at[i], at[s]
        turn_i, turn_s = at_turn[i], at_turn[s]
        for v in range(nv - 1, -1, -1):
            w = w_p[v]
            if w == 0.0:
                continue
            moved = at_i[v] - at_s[v]
            turned = turn_i[v] - turn_s[v]
            if b_p[v]:
                r = min(w, reach_[v] + grown_b)
                grown_b += w * moved
            else:
                r = min(w, reach_[v] + grown_a)
                grown_a += w * moved
            acc += r * min(1.0, share[v] + turned) * moved
        return acc

    def reach(p: int, s: int, end: int, target: float, rate: float) -> tuple[int, float]:
        """A sample after s up to which pair p's gap cannot have changed by target [m]
        (the first at which it can, ``end`` (the end of the stretch walked) if none
        before, or one close before it: see APPROX), and the motion per sample seen on
        the way [m] (the next call's first guess; 0: none). The bound never decreases
        along the grid and grows about linearly: the first probe is where ``rate`` (the
        last call's) says the target is reached (without one, the next sample), each
        next one interpolated from what the last ones found (extrapolated, overshooting
        a little, until the target is bracketed), every third one halves the bracket;
        once the bracket is within a 1/APPROX share of the step, the sample after its
        low end is returned. Invariant: motion(lo) < target; motion(hi) >= target, or
        hi is ``end`` and its motion unknown (inf)."""
        lo, hi, m_lo, m_hi, count = s, end, 0.0, np.inf, 0
        probe = s + 1 if rate <= 0.0 else min(max(s + int(target / rate), s + 1), end - 1)
        while hi - lo > 1:
            m = motion(p, s, probe)
            if m >= target:
                hi, m_hi = probe, m
            else:
                lo, m_lo = probe, m
            count += 1
            if hi - lo <= 1:
                break
            if m_hi != np.inf and (hi - lo) * APPROX <= lo - s:
                return lo + 1, m_lo / (lo - s)
            if m_hi == np.inf:
                slope = m_lo / (lo - s)
                ahead = 2 * (lo - s) if slope <= 0.0 else int(1.1 * (target - m_lo) / slope) + 1
                probe = min(lo + max(ahead, 1), hi - 1)
            elif count % 3 == 0:
                probe = (lo + hi) // 2
            else:
                share_ = (target - m_lo) / (m_hi - m_lo)
                probe = min(max(lo + int(share_ * (hi - lo)), lo + 1), hi - 1)
        if m_hi != np.inf:
            return hi, m_hi / (hi - s)
        return hi, (m_lo / (lo - s) if lo > s else 0.0)

    cap = out_p.size
    count = 0
    for t in range(t0, todo.size):
        p, end = todo[t], stop[t]
        s = s0 if t == t0 else first[t]
        rate = 0.0
        while s < end:
            th = max(theta[p], ceiling[0] - drop) if tracked[p] and drop >= 0.0 else theta[p]
            Sa, Sb = shapes(p, s)
            # The cheap bounds first, the finer ones only where those are not enough.
            # Each is a gap along an axis n, kept for the step.
            bound, n0, n1, n2 = sphere_bound(Sa, Sb)
            stats[0] += 1
            if bound <= th + coarse:
                if axes[p, 3] != 0.0:
                    warm = gap(Sa, Sb, hulls, axes[p, 0], axes[p, 1], axes[p, 2])
                    if warm > bound:
                        bound, n0, n1, n2 = warm, axes[p, 0], axes[p, 1], axes[p, 2]
                # The kept axis is trusted while its gap has not fallen far below the
                # last full bound; else (or without one) the full bound is computed.
                if bound - th < keep * (last[p] - th) or axes[p, 3] == 0.0:
                    full, f0, f1, f2 = axis_bound(Sa, Sb, hulls)
                    stats[1] += 1
                    if full <= th + fine:
                        full, upper, f0, f1, f2 = gjk_bound(Sa, Sb, hulls, full, f0, f1,
                                                            f2, axes[p, 3] != 0.0, W, e,
                                                            idx)
                        stats[2] += 1
                        if tracked[p] and upper < ceiling[0]:
                            ceiling[0], ceiling[1], ceiling[2] = upper, p, s
                    if full >= bound:
                        bound, n0, n1, n2 = full, f0, f1, f2
                    axes[p, 0], axes[p, 1], axes[p, 2], axes[p, 3] = n0, n1, n2, 1.0
                    last[p] = bound
            if bound > th:
                set_shares(p, s, n0, n1, n2, Sa, Sb)
                s, rate = reach(p, s, end, bound - th, rate)
                continue
            out_p[count] = p
            out_s[count] = s
            out_b[count] = bound
            count += 1
            s += 1
            if count == cap:
                return count, t, s
    return count, todo.size, 0
