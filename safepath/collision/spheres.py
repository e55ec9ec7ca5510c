"""Spheres fitted to collision shapes: outer sets that enclose a shape, inner sets inside it.

The fast layer of the collision checker (:mod:`safepath.collision.layer`) answers most state
queries with spheres instead of exact shapes. Its answers stay exact because

* an **outer** set encloses the shape (every point of the shape lies in some sphere),
  so a distance between outer sets is a lower bound of the true distance: "farther
  than the margin" is then certain;
* an **inner** set lies inside the shape, so an inner sphere that reaches into an
  obstacle proves a collision.

Everything else ("not sure") goes to the exact coal check. Shapes are covered by a grid
of cells: each cell that meets the shape becomes the sphere circumscribing the cell,
so the excess over the shape's surface is at most about 0.37 of the cell edge. Works for
the shapes a URDF or a scene gives: every kind of the shape table
(:mod:`safepath.model.shapes`; each row fits its own kind, thin cylinders and capsules by
spheres along their axis), convex hulls (example-robot-data meshes are replaced by their
hulls) and, through their vertices' hull, meshes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..files._digest import blake2b
from ..model._solids import SLACK, cell_grid
from ..model.shapes import from_coal

__all__ = ["SphereFit", "fit_spheres", "surface_points"]

#: Inner spheres kept for a convex hull (the deepest ones).
MAX_INNER = 8


@dataclass(frozen=True)
class SphereFit:
    """Spheres about one shape, in the shape's own frame.

    Attributes:
        outer_centers: Centres of spheres that together enclose the shape [m] (n, 3).
        outer_radii: Their radii [m] (n,).
        inner_centers: Centres of spheres inside the shape [m] (m, 3) (may be empty).
        inner_radii: Their radii [m] (m,).
    """

    outer_centers: np.ndarray
    outer_radii: np.ndarray
    inner_centers: np.ndarray
    inner_radii: np.ndarray

    @property
    def bounding(self) -> tuple[np.ndarray, float]:
        """One sphere that holds every outer sphere (centre [m], radius [m])."""
        lo = (self.outer_centers - self.outer_radii[:, None]).min(axis=0)
        hi = (self.outer_centers + self.outer_radii[:, None]).max(axis=0)
        c = 0.5 * (lo + hi)
        r = float(np.max(np.linalg.norm(self.outer_centers - c, axis=1) + self.outer_radii))
        return c, r + SLACK

    def transformed(self, T: np.ndarray) -> SphereFit:
        """The same spheres in another frame (``T`` maps shape to that frame, 4x4)."""
        R, p = T[:3, :3], T[:3, 3]
        return SphereFit(self.outer_centers @ R.T + p, self.outer_radii,
                         self.inner_centers @ R.T + p, self.inner_radii)


#: Fits made in this process, by what they are made from (see :func:`fit_spheres`).
_FITS: dict[tuple[Any, ...], SphereFit] = {}
#: Most fits kept (the oldest goes first): the robots' and held objects' shapes.
_FITS_KEPT = 512


def fit_spheres(geometry: Any, *, cell: float = 0.015) -> SphereFit:
    """Outer and inner spheres for a coal geometry.

    A fit depends on nothing but the shape's kind, its dimensions (a hull's or mesh's
    points) and ``cell``: it is made once per process for each (every checker of a robot
    fits the same links; the runtime planner builds checkers whenever the scene
    changes) and handed out again, its arrays read-only.

    Args:
        geometry: ``coal.Box``, ``Sphere``, ``Cylinder``, ``Capsule``, ``ConvexBase`` or a
            mesh (``BVHModelBase``, covered through the hull of its vertices).
        cell: Largest cell edge of the covering grid [m]; smaller is tighter and slower.

    Raises:
        ValueError: A geometry of another kind (the checker then keeps it exact).
    """
    key = _fit_key(geometry, cell)
    fit = _FITS.get(key)
    if fit is None:
        fit = _fit_shape(geometry, cell)
        for array in (fit.outer_centers, fit.outer_radii, fit.inner_centers, fit.inner_radii):
            array.setflags(write=False)
        if len(_FITS) >= _FITS_KEPT:
            _FITS.pop(next(iter(_FITS)), None)
        _FITS[key] = fit
    return fit


def _fit_key(geometry: Any, cell: float) -> tuple[Any, ...]:
    """What a fit is made from: the shape's kind and dimensions (a digest of a hull's or
    mesh's points), and the cell."""
    import coal

    primitive = from_coal(geometry)
    if primitive is not None:
        dims: tuple[Any, ...] = tuple(float(x) for x in primitive[1])
    elif isinstance(geometry, (coal.ConvexBase, coal.BVHModelBase)):
        points = _points(geometry)
        dims = (points.shape, blake2b(points.tobytes()))
    else:
        dims = (id(geometry),)  # refused by _fit_shape
    return (type(geometry).__name__, *dims, float(cell))


def _points(geometry: Any) -> np.ndarray:
    """A coal convex hull's points or a mesh's vertices [m] (n, 3)."""
    import coal

    return np.ascontiguousarray(geometry.points() if isinstance(geometry, coal.ConvexBase)
                                else geometry.vertices(), dtype=float)


def _fit_shape(geometry: Any, cell: float) -> SphereFit:
    """The fit of :func:`fit_spheres`, made: a kind of the shape table fits itself."""
    import coal

    primitive = from_coal(geometry)
    if primitive is not None:
        kind, half = primitive
        return _fit(*kind.sphere_fit(half, cell))
    if isinstance(geometry, (coal.ConvexBase, coal.BVHModelBase)):
        return _fit_points(_points(geometry), cell)
    raise ValueError(f"no sphere fit for {type(geometry).__name__}")


def _fit(oc: np.ndarray, orad: np.ndarray, ic: np.ndarray, irad: np.ndarray) -> SphereFit:
    keep = irad > 0
    return SphereFit(np.ascontiguousarray(oc, dtype=float), np.asarray(orad, dtype=float),
                     np.ascontiguousarray(ic[keep], dtype=float),
                     np.asarray(irad[keep], dtype=float))


def _fit_points(points: np.ndarray, cell: float) -> SphereFit:
    """The convex hull of ``points`` (a convex shape, or a mesh's vertices)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    normals, offsets = hull.equations[:, :3], hull.equations[:, 3]  # n.x + d <= 0 inside
    lo, hi = points.min(axis=0), points.max(axis=0)
    centers, half = cell_grid(lo, hi, cell)
    rho = float(np.linalg.norm(half))
    signed = centers @ normals.T + offsets  # per facet, > 0 outside
    # A cell that holds a hull point x has n.c + d <= n.x + d + |c - x| <= rho for every
    # facet, so keeping those cells keeps every cell that meets the hull.
    keep = np.all(signed <= rho, axis=1)
    outer = centers[keep]
    depth = -signed.max(axis=1)  # distance to the nearest facet plane, inside > 0
    # Inner: the deepest cell centres, each the ball to its nearest facet (a few suffice).
    deepest = np.argsort(-depth, kind="stable")[:MAX_INNER]
    deepest = deepest[depth[deepest] > 0]
    return _fit(outer, np.full(len(outer), rho + SLACK), centers[deepest],
                depth[deepest] - SLACK)


def surface_points(geometry: Any, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points on the surface of a coal geometry, in its frame [m] (for tests of
    enclosure: every one must lie inside the outer spheres).

    A kind of the shape table: the points of its surface nearest to probes drawn in a box
    a quarter larger than the one around it, as coal measures them (its distance is signed:
    a probe inside has its nearest surface point too), so the sample knows nothing of the
    table's geometry; a hull or mesh: points on its hull's triangles.
    """
    import coal

    if from_coal(geometry) is not None:
        geometry.computeLocalAABB()
        lo, hi = np.asarray(geometry.aabb_local.min_), np.asarray(geometry.aabb_local.max_)
        middle, half = (lo + hi) / 2, 1.25 * (hi - lo) / 2
        dot, at, out = coal.Sphere(0.0), coal.Transform3s(), np.empty((n, 3))
        for i, probe in enumerate(rng.uniform(middle - half, middle + half, size=(n, 3))):
            result = coal.DistanceResult()
            coal.distance(geometry, at, dot, coal.Transform3s(np.eye(3), probe),
                          coal.DistanceRequest(), result)
            out[i] = result.getNearestPoint1()
        return out
    if isinstance(geometry, (coal.ConvexBase, coal.BVHModelBase)):
        from scipy.spatial import ConvexHull

        pts = _points(geometry)
        hull = ConvexHull(pts)
        tri = hull.simplices[rng.integers(len(hull.simplices), size=n)]
        w = rng.dirichlet(np.ones(3), size=n)
        return np.einsum("nk,nkd->nd", w, pts[tri])
    raise ValueError(f"no surface sampler for {type(geometry).__name__}")
