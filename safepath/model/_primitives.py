"""Each kind of the shape table's own geometry, in the shape's frame, for the numba kernels.

The one place a kind's distance code lives for the planner's kernels: the sphere layer's
separating-axis bounds and GJK (:mod:`safepath.collision._pair_tests`,
:mod:`safepath.collision._gjk`) and the monitor's point distances
(:mod:`safepath.monitor._kernels`) call these, inlined, with the shape's kernel
parameters ``a, b, c`` (:attr:`safepath.model.shapes.ShapeKind.half`: a box's half sides;
a cylinder's or capsule's radius and half length along its z axis; a sphere's radius) and
a point or direction already in the shape's frame. The release check keeps its own
(:mod:`safepath.verify._distance`) on purpose: it must not share a fault with the planner
it checks.

Adding a kind: its row in :mod:`safepath.model.shapes`, its branch in each function here,
and the release check's. Importing this module compiles nothing until a kernel that
inlines it is compiled (:mod:`safepath._aot` keys its builds on this file's source).
"""

from __future__ import annotations

import math

from .._aot import njit
from .shapes import BOX, CAPSULE, CYLINDER, SPHERE

__all__ = ["extent", "own_axes", "round_about_z", "signed_distance", "support_point"]

_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_inlined
def signed_distance(kind, a, b, c, x, y, z):
    """Signed distance [m] from the point (x, y, z) [m] of the shape's frame to a shape of
    ``kind`` with parameters ``a, b, c`` [m] (negative inside)."""
    if kind == BOX:
        qx, qy, qz = abs(x) - a, abs(y) - b, abs(z) - c
        ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        return math.sqrt(ox * ox + oy * oy + oz * oz) + min(max(qx, max(qy, qz)), 0.0)
    if kind == CYLINDER:
        dr = math.sqrt(x * x + y * y) - a
        dzz = abs(z) - b
        o1, o2 = max(dr, 0.0), max(dzz, 0.0)
        return math.sqrt(o1 * o1 + o2 * o2) + min(max(dr, dzz), 0.0)
    if kind == SPHERE:
        return math.sqrt(x * x + y * y + z * z) - a
    zc = min(max(z, -b), b)  # a capsule: its axis segment, then the radius
    return math.sqrt(x * x + y * y + (z - zc) * (z - zc)) - a


@_inlined
def extent(kind, a, b, c, rot, o, nx, ny, nz):
    """Half extent [m] of the shape along the unit world direction (nx, ny, nz), its
    rotation in ``rot[o:o + 9]`` (row-major): the largest of its points' projections on
    the direction, from its origin. (The direction is taken into the shape's frame only
    as far as the kind needs it: this runs for every separating-axis candidate.)"""
    if kind == BOX:
        return (a * abs(rot[o] * nx + rot[o + 3] * ny + rot[o + 6] * nz)
                + b * abs(rot[o + 1] * nx + rot[o + 4] * ny + rot[o + 7] * nz)
                + c * abs(rot[o + 2] * nx + rot[o + 5] * ny + rot[o + 8] * nz))
    if kind == SPHERE:
        return a
    lz = rot[o + 2] * nx + rot[o + 5] * ny + rot[o + 8] * nz
    if kind == CAPSULE:
        return b * abs(lz) + a
    return b * abs(lz) + a * math.sqrt(max(0.0, 1.0 - lz * lz))  # a cylinder


@_inlined
def support_point(kind, a, b, c, lx, ly, lz):
    """The shape's point [m] farthest along (lx, ly, lz) (any length) in its frame."""
    x = y = z = 0.0
    if kind == BOX:
        x = a if lx >= 0.0 else -a
        y = b if ly >= 0.0 else -b
        z = c if lz >= 0.0 else -c
        return x, y, z
    norm = math.sqrt(lx * lx + ly * ly + lz * lz)
    if kind == SPHERE:
        if norm > 0.0:
            x, y, z = a * lx / norm, a * ly / norm, a * lz / norm
    elif kind == CAPSULE:
        z = b if lz >= 0.0 else -b
        if norm > 0.0:
            x, y, z = a * lx / norm, a * ly / norm, z + a * lz / norm
    else:  # a cylinder along z: radius a, half length b
        z = b if lz >= 0.0 else -b
        rho = math.sqrt(lx * lx + ly * ly)
        if rho > 0.0:
            x, y = a * lx / rho, a * ly / rho
    return x, y, z


@_inlined
def own_axes(kind):
    """The shape's own separating-axis candidates: the first column of its rotation that
    is one, and how many, 0, 1 or 3 (a box's three face normals, a cylinder's or
    capsule's z axis; a sphere has none)."""
    if kind == BOX:
        return 0, 3
    if kind == CYLINDER or kind == CAPSULE:
        return 2, 1
    return 0, 0


@_inlined
def round_about_z(kind):
    """Whether the shape is round about its z axis (the line between two shapes' centres,
    across that axis, is then a separating-axis candidate)."""
    return kind == CYLINDER or kind == CAPSULE
