"""The shape table: every layer's knowledge of a collision shape kind, in one place.

Each kind (``box``, ``cylinder``, ``sphere``, ``capsule``) has one :class:`ShapeKind` row:
its name and ``scene.yaml`` keys, its integer code in the kernels' buffers (the sphere
layer's and the monitor's), its parameter layout there (three half-dimensions), its
bounding radius, how it becomes a coal, python-fcl or MuJoCo object, and its geometry in
numpy: the spheres that fit it (the sphere layer's), points whose hull encloses it (a
locked joint's travel shape) and a triangle mesh of its surface (the page's drawing). The
layers read this table instead of dispatching on the kind themselves; what is left to each
kind is its distance code: the planner's kernels' in :mod:`safepath.model._primitives`,
the release check's own in :mod:`safepath.verify._distance`.

Adding a kind: a row here, and its distance code in those two (see
``docs/architecture.md``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._solids import SLACK, Spheres, box_corners, box_mesh, cell_grid, revolve

__all__ = ["ShapeKind", "SHAPES", "BOX", "CYLINDER", "SPHERE", "CAPSULE", "shape_kind",
           "from_coal", "from_code"]

#: Kernel codes of the kinds (compile-time constants of the numba kernels).
BOX, CYLINDER, SPHERE, CAPSULE = 0, 1, 2, 3


def _radius_length_half(size: tuple[float, ...]) -> np.ndarray:
    return np.array([size[0], size[1] / 2, 0.0])


def _radius_length_size(half: np.ndarray) -> tuple[float, ...]:
    return float(half[0]), float(2 * half[1])


@dataclass(frozen=True)
class ShapeKind:
    """One shape kind: a row of the shape table.

    Attributes:
        name: The kind's name in ``scene.yaml`` and :class:`~safepath.model.scene.Shape`.
        code: Its integer code in the kernels' buffers.
        keys: Its size keys in ``scene.yaml``, in the order of ``Shape.size``.
        size_names: The names of the entries of ``Shape.size`` (in messages).
        coal: The coal class it becomes, built from ``Shape.size`` as is.
        fcl: The python-fcl class it becomes, built from ``Shape.size`` as is.
        mujoco: Its MuJoCo geom type.
        half: ``Shape.size`` [m] -> the kernels' three parameters [m] (box: half sides;
            cylinder, capsule: radius, half length, 0; sphere: radius, 0, 0).
        size: The kernels' parameters [m] -> ``Shape.size`` [m].
        mujoco_params: How many of the kernels' parameters are MuJoCo's ``size``.
        bounding_radius: ``Shape.size`` [m] -> radius of a sphere about the shape's
            origin that holds it [m].
        holding_radius: The kernels' parameters [m] -> the same radius [m].
        coal_half: A coal object of this kind -> the kernels' parameters [m].
        sphere_fit: The kernels' parameters [m] and the largest cell edge of a covering
            grid [m] -> spheres in the shape's frame: outer ones that together enclose
            it (every point of the shape in one), inner ones inside it.
        enclosing_points: The kernels' parameters [m] -> points (n, 3) [m] whose convex
            hull encloses the shape, in its frame.
        mesh: The kernels' parameters [m] -> ``(vertices [m], faces)`` of a closed
            triangle mesh of its surface, vertices on it, faces turned outwards.
    """

    name: str
    code: int
    keys: tuple[str, ...]
    size_names: tuple[str, ...]
    coal: str
    fcl: str
    mujoco: str
    half: Callable[[tuple[float, ...]], np.ndarray]
    size: Callable[[np.ndarray], tuple[float, ...]]
    mujoco_params: int
    bounding_radius: Callable[[tuple[float, ...]], float]
    holding_radius: Callable[[np.ndarray], float]
    coal_half: Callable[[Any], np.ndarray]
    sphere_fit: Callable[[np.ndarray, float], Spheres]
    enclosing_points: Callable[[np.ndarray], np.ndarray]
    mesh: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

    def to_coal(self, size: tuple[float, ...]) -> Any:
        """The coal geometry of a shape of this kind and ``size`` [m]."""
        import coal

        return getattr(coal, self.coal)(*size)

    def to_fcl(self, size: tuple[float, ...]) -> Any:
        """The python-fcl geometry of a shape of this kind and ``size`` [m]."""
        import fcl

        return getattr(fcl, self.fcl)(*(float(v) for v in size))

    def mujoco_size(self, size: tuple[float, ...]) -> np.ndarray:
        """MuJoCo's ``size`` attribute of a geom of this kind and ``size`` [m]."""
        return self.half(size)[:self.mujoco_params]


# Each kind's geometry, in the kernels' parameters (``half``).

def _box_fit(h: np.ndarray, cell: float) -> Spheres:
    """Outer: the spheres circumscribing the cells of a grid over the box; inner: balls
    of the smallest half side, spread along it."""
    centers, half = cell_grid(-h, h, cell)
    radius = float(np.linalg.norm(half)) + SLACK
    r_in = float(h.min())
    span = h - r_in
    counts = np.maximum(1, np.ceil(2 * span / max(r_in, 1e-9)).astype(int) + 1)
    axes = [np.linspace(-span[i], span[i], counts[i]) if span[i] > 0 else np.zeros(1)
            for i in range(3)]
    inner = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return (centers, np.full(len(centers), radius), inner,
            np.full(len(inner), r_in - SLACK))


def _sphere_fit(h: np.ndarray, cell: float) -> Spheres:
    r = float(h[0])
    c = np.zeros((1, 3))
    return c, np.array([r + SLACK]), c, np.array([max(r - SLACK, 0.0)])


def _round_fit(R: float, hl: float, cell: float, *, capsule: bool) -> Spheres:  # noqa: N803
    """Cylinder or capsule along z (radius ``R``, half length ``hl`` [m]): thin ones by
    spheres on the axis, others by the grid's cells that meet them; inner: balls on the
    axis."""
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
        centers, half = cell_grid(lo, hi, cell)
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
    r_in = R if capsule else min(R, hl)
    span = reach - r_in if capsule else hl - r_in
    m = max(1, int(np.ceil(2 * span / max(r_in, 1e-9))) + 1) if span > 0 else 1
    z_in = np.linspace(-span, span, m) if span > 0 else np.zeros(1)
    inner = np.column_stack([np.zeros(m), np.zeros(m), z_in])
    return centers, radii, inner, np.full(m, r_in - SLACK)


def _round_points(h: np.ndarray, *, capsule: bool) -> np.ndarray:
    """A prism of 24 sides circumscribing the cylinder (a capsule: its caps too)."""
    n = 24
    r = float(h[0]) / math.cos(math.pi / n)
    hl = float(h[1]) + (float(h[0]) if capsule else 0.0)
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    ring = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    return np.vstack([np.column_stack([ring, np.full(n, z)]) for z in (-hl, hl)])


def _arc(r: float, z: float, start: float, stop: float, steps: int = 8) -> np.ndarray:
    """Profile points (radius, z) [m] of a circle's arc about (0, z), angles [rad] from
    the +z axis."""
    t = np.linspace(start, stop, steps + 1)
    radius = np.where((t == 0.0) | (t == np.pi), 0.0, r * np.sin(t))  # poles: exactly 0
    return np.column_stack([radius, z + r * np.cos(t)])


def _cylinder_mesh(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    R, hl = float(h[0]), float(h[1])  # noqa: N806
    return revolve([np.array([[0.0, -hl], [R, -hl]]), np.array([[R, -hl], [R, hl]]),
                    np.array([[R, hl], [0.0, hl]])])


def _capsule_mesh(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    R, hl = float(h[0]), float(h[1])  # noqa: N806
    return revolve([np.vstack([_arc(R, -hl, np.pi, np.pi / 2), _arc(R, hl, np.pi / 2, 0.0)])])


#: The shape table, by name (the order of the kernel codes).
SHAPES: dict[str, ShapeKind] = {kind.name: kind for kind in (
    ShapeKind("box", BOX, ("size",), ("x", "y", "z"), "Box", "Box", "box",
              half=lambda s: np.asarray(s, dtype=float) / 2,
              size=lambda h: tuple(float(2 * v) for v in h), mujoco_params=3,
              bounding_radius=lambda s: float(np.linalg.norm(s) / 2),
              holding_radius=lambda h: float(np.linalg.norm(h)),
              coal_half=lambda g: np.asarray(g.halfSide, dtype=float),
              sphere_fit=_box_fit, enclosing_points=box_corners, mesh=box_mesh),
    ShapeKind("cylinder", CYLINDER, ("radius", "length"), ("radius", "length"), "Cylinder",
              "Cylinder", "cylinder", half=_radius_length_half, size=_radius_length_size,
              mujoco_params=2,
              bounding_radius=lambda s: float(np.hypot(s[0], s[1] / 2)),
              holding_radius=lambda h: float(np.hypot(h[0], h[1])),
              coal_half=lambda g: np.array([g.radius, g.halfLength, 0.0]),
              sphere_fit=lambda h, cell: _round_fit(float(h[0]), float(h[1]), cell,
                                                    capsule=False),
              enclosing_points=lambda h: _round_points(h, capsule=False),
              mesh=_cylinder_mesh),
    ShapeKind("sphere", SPHERE, ("radius",), ("radius",), "Sphere", "Sphere", "sphere",
              half=lambda s: np.array([s[0], 0.0, 0.0]), size=lambda h: (float(h[0]),),
              mujoco_params=1, bounding_radius=lambda s: float(s[0]),
              holding_radius=lambda h: float(h[0]),
              coal_half=lambda g: np.array([g.radius, 0.0, 0.0]),
              sphere_fit=_sphere_fit, enclosing_points=lambda h: box_corners(np.full(3, h[0])),
              mesh=lambda h: revolve([_arc(float(h[0]), 0.0, np.pi, 0.0, 16)])),
    ShapeKind("capsule", CAPSULE, ("radius", "length"), ("radius", "length"), "Capsule",
              "Capsule", "capsule", half=_radius_length_half, size=_radius_length_size,
              mujoco_params=2, bounding_radius=lambda s: float(s[0] + s[1] / 2),
              holding_radius=lambda h: float(h[0] + h[1]),
              coal_half=lambda g: np.array([g.radius, g.halfLength, 0.0]),
              sphere_fit=lambda h, cell: _round_fit(float(h[0]), float(h[1]), cell,
                                                    capsule=True),
              enclosing_points=lambda h: _round_points(h, capsule=True),
              mesh=_capsule_mesh),
)}
_BY_CODE = {kind.code: kind for kind in SHAPES.values()}


def shape_kind(name: str) -> ShapeKind:
    """The table's row of the kind called ``name`` (KeyError if there is none)."""
    return SHAPES[name]


def from_code(code: int) -> ShapeKind:
    """The table's row of the kind with kernel code ``code`` (KeyError if there is none)."""
    return _BY_CODE[code]


def from_coal(geometry: Any) -> tuple[ShapeKind, np.ndarray] | None:
    """The row of a coal primitive's kind and its kernel parameters [m], or None."""
    import coal

    for kind in SHAPES.values():
        if isinstance(geometry, getattr(coal, kind.coal)):
            return kind, kind.coal_half(geometry)
    return None
