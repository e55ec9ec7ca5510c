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
so the excess over the shape's surface is at most about 0.37 of the cell edge; thin
cylinders and capsules are covered by spheres along their axis instead. Works for the
shapes a URDF or a scene gives: boxes, spheres, cylinders, capsules, convex hulls
(example-robot-data meshes are replaced by their hulls) and, through their vertices'
hull, meshes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..files._digest import blake2b

__all__ = ["SphereFit", "fit_spheres", "surface_points"]

#: Radii are grown (outer) or shrunk (inner) by this much [m]: floating-point slack.
SLACK = 1e-6
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

    if isinstance(geometry, coal.Sphere):
        dims: tuple[Any, ...] = (float(geometry.radius),)
    elif isinstance(geometry, coal.Box):
        dims = tuple(float(x) for x in geometry.halfSide)
    elif isinstance(geometry, (coal.Cylinder, coal.Capsule)):
        dims = (float(geometry.radius), float(geometry.halfLength))
    elif isinstance(geometry, (coal.ConvexBase, coal.BVHModelBase)):
        points = np.ascontiguousarray(geometry.points() if isinstance(geometry, coal.ConvexBase)
                                      else geometry.vertices(), dtype=float)
        dims = (points.shape, blake2b(points.tobytes()))
    else:
        dims = (id(geometry),)  # refused by _fit_shape
    return (type(geometry).__name__, *dims, float(cell))


def _fit_shape(geometry: Any, cell: float) -> SphereFit:
    """The fit of :func:`fit_spheres`, made."""
    import coal

    if isinstance(geometry, coal.Sphere):
        r = float(geometry.radius)
        c = np.zeros((1, 3))
        return _fit(c, np.array([r + SLACK]), c, np.array([max(r - SLACK, 0.0)]))
    if isinstance(geometry, coal.Box):
        return _fit_box(np.asarray(geometry.halfSide, dtype=float), cell)
    if isinstance(geometry, coal.Cylinder):
        return _fit_cylinder(float(geometry.radius), float(geometry.halfLength), cell,
                             capsule=False)
    if isinstance(geometry, coal.Capsule):
        return _fit_cylinder(float(geometry.radius), float(geometry.halfLength), cell,
                             capsule=True)
    if isinstance(geometry, coal.ConvexBase):
        return _fit_points(np.asarray(geometry.points(), dtype=float), cell)
    if isinstance(geometry, coal.BVHModelBase):
        return _fit_points(np.asarray(geometry.vertices(), dtype=float), cell)
    raise ValueError(f"no sphere fit for {type(geometry).__name__}")


def _fit(oc: np.ndarray, orad: np.ndarray, ic: np.ndarray, irad: np.ndarray) -> SphereFit:
    keep = irad > 0
    return SphereFit(np.ascontiguousarray(oc, dtype=float), np.asarray(orad, dtype=float),
                     np.ascontiguousarray(ic[keep], dtype=float),
                     np.asarray(irad[keep], dtype=float))


def _grid(lo: np.ndarray, hi: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the cells of a grid over the box [lo, hi], and each cell's half edges."""
    size = hi - lo
    counts = np.maximum(1, np.ceil(size / cell - 1e-9)).astype(int)
    step = size / counts
    axes = [lo[i] + step[i] * (np.arange(counts[i]) + 0.5) for i in range(3)]
    centers = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return centers, step / 2


def _fit_box(h: np.ndarray, cell: float) -> SphereFit:
    centers, half = _grid(-h, h, cell)
    radius = float(np.linalg.norm(half)) + SLACK
    # Inner: balls of the smallest half edge, spread along the box.
    r_in = float(h.min())
    span = h - r_in
    counts = np.maximum(1, np.ceil(2 * span / max(r_in, 1e-9)).astype(int) + 1)
    axes = [np.linspace(-span[i], span[i], counts[i]) if span[i] > 0 else np.zeros(1)
            for i in range(3)]
    inner = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return _fit(centers, np.full(len(centers), radius), inner,
                np.full(len(inner), r_in - SLACK))


def _fit_cylinder(R: float, hl: float, cell: float, *, capsule: bool) -> SphereFit:
    """Cylinder or capsule along z (radius ``R``, half length ``hl`` [m])."""
    reach = hl + (R if capsule else 0.0)
    if R <= cell:
        # Spheres on the axis: a slice of height t is held by sqrt(R^2 + (t/2)^2); a
        # capsule's caps are held by its end balls, which those spheres contain.
        n = max(1, int(np.ceil(2 * hl / cell - 1e-9)))
        t = 2 * hl / n
        z = -hl + t * (np.arange(n) + 0.5)
        centers = np.column_stack([np.zeros(n), np.zeros(n), z])
        radii = np.full(n, np.hypot(R, t / 2) + SLACK)
        if capsule:
            ends = np.array([[0.0, 0.0, -hl], [0.0, 0.0, hl]])
            centers = np.vstack([centers, ends])
            radii = np.concatenate([radii, [R + SLACK, R + SLACK]])
    else:
        lo, hi = np.array([-R, -R, -reach]), np.array([R, R, reach])
        centers, half = _grid(lo, hi, cell)
        # Keep the cells that meet the shape: nearest point of the cell to the axis
        # segment within R.
        near_xy = np.maximum(np.abs(centers[:, :2]) - half[:2], 0.0)
        rho = np.linalg.norm(near_xy, axis=1)
        if capsule:
            dz = np.maximum(np.abs(centers[:, 2]) - half[2] - hl, 0.0)
            keep = np.hypot(rho, dz) <= R
        else:
            keep = rho <= R
        centers = centers[keep]
        radii = np.full(len(centers), float(np.linalg.norm(half)) + SLACK)
    # Inner: balls of radius R (or the half length) on the axis.
    r_in = R if capsule else min(R, hl)
    span = reach - r_in if capsule else hl - r_in
    m = max(1, int(np.ceil(2 * span / max(r_in, 1e-9))) + 1) if span > 0 else 1
    z_in = np.linspace(-span, span, m) if span > 0 else np.zeros(1)
    inner = np.column_stack([np.zeros(m), np.zeros(m), z_in])
    return _fit(centers, radii, inner, np.full(m, r_in - SLACK))


def _fit_points(points: np.ndarray, cell: float) -> SphereFit:
    """The convex hull of ``points`` (a convex shape, or a mesh's vertices)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    normals, offsets = hull.equations[:, :3], hull.equations[:, 3]  # n.x + d <= 0 inside
    lo, hi = points.min(axis=0), points.max(axis=0)
    centers, half = _grid(lo, hi, cell)
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
    enclosure: every one must lie inside the outer spheres)."""
    import coal

    if isinstance(geometry, coal.Sphere):
        v = rng.normal(size=(n, 3))
        return float(geometry.radius) * v / np.linalg.norm(v, axis=1, keepdims=True)
    if isinstance(geometry, coal.Box):
        h = np.asarray(geometry.halfSide, dtype=float)
        p = rng.uniform(-h, h, size=(n, 3))
        axis = rng.integers(3, size=n)
        p[np.arange(n), axis] = h[axis] * rng.choice([-1.0, 1.0], size=n)
        return p
    if isinstance(geometry, (coal.Cylinder, coal.Capsule)):
        R, hl = float(geometry.radius), float(geometry.halfLength)
        phi = rng.uniform(0, 2 * np.pi, size=n)
        side = np.column_stack([R * np.cos(phi), R * np.sin(phi), rng.uniform(-hl, hl, n)])
        cap = rng.random(n) < 0.3
        if isinstance(geometry, coal.Cylinder):
            rr = R * np.sqrt(rng.random(n))
            side[cap] = np.column_stack([rr * np.cos(phi), rr * np.sin(phi),
                                         hl * rng.choice([-1.0, 1.0], size=n)])[cap]
        else:
            v = rng.normal(size=(n, 3))
            v = R * v / np.linalg.norm(v, axis=1, keepdims=True)
            v[:, 2] += np.sign(v[:, 2]) * hl
            side[cap] = v[cap]
        return side
    if isinstance(geometry, (coal.ConvexBase, coal.BVHModelBase)):
        pts = np.asarray(geometry.points() if isinstance(geometry, coal.ConvexBase)
                         else geometry.vertices(), dtype=float)
        from scipy.spatial import ConvexHull

        hull = ConvexHull(pts)
        tri = hull.simplices[rng.integers(len(hull.simplices), size=n)]
        w = rng.dirichlet(np.ones(3), size=n)
        return np.einsum("nk,nkd->nd", w, pts[tri])
    raise ValueError(f"no surface sampler for {type(geometry).__name__}")
