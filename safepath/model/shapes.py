"""The shape table: every layer's knowledge of a collision shape kind, in one place.

Each kind (``box``, ``cylinder``, ``sphere``, ``capsule``) has one :class:`ShapeKind` row:
its name and ``scene.yaml`` keys, its integer code in the kernels' buffers (the sphere
layer's and the monitor's), its parameter layout there (three half-dimensions), its
bounding radius, and how it becomes a coal, python-fcl or MuJoCo object. The layers read
this table instead of dispatching on the kind themselves; what is left to each kind is its
distance code (:mod:`safepath.collision._pair_tests`).

Adding a kind: a row here, and its distance code there (see ``docs/architecture.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

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


#: The shape table, by name (the order of the kernel codes).
SHAPES: dict[str, ShapeKind] = {kind.name: kind for kind in (
    ShapeKind("box", BOX, ("size",), ("x", "y", "z"), "Box", "Box", "box",
              half=lambda s: np.asarray(s, dtype=float) / 2,
              size=lambda h: tuple(float(2 * v) for v in h), mujoco_params=3,
              bounding_radius=lambda s: float(np.linalg.norm(s) / 2),
              holding_radius=lambda h: float(np.linalg.norm(h)),
              coal_half=lambda g: np.asarray(g.halfSide, dtype=float)),
    ShapeKind("cylinder", CYLINDER, ("radius", "length"), ("radius", "length"), "Cylinder",
              "Cylinder", "cylinder", half=_radius_length_half, size=_radius_length_size,
              mujoco_params=2,
              bounding_radius=lambda s: float(np.hypot(s[0], s[1] / 2)),
              holding_radius=lambda h: float(np.hypot(h[0], h[1])),
              coal_half=lambda g: np.array([g.radius, g.halfLength, 0.0])),
    ShapeKind("sphere", SPHERE, ("radius",), ("radius",), "Sphere", "Sphere", "sphere",
              half=lambda s: np.array([s[0], 0.0, 0.0]), size=lambda h: (float(h[0]),),
              mujoco_params=1, bounding_radius=lambda s: float(s[0]),
              holding_radius=lambda h: float(h[0]),
              coal_half=lambda g: np.array([g.radius, 0.0, 0.0])),
    ShapeKind("capsule", CAPSULE, ("radius", "length"), ("radius", "length"), "Capsule",
              "Capsule", "capsule", half=_radius_length_half, size=_radius_length_size,
              mujoco_params=2, bounding_radius=lambda s: float(s[0] + s[1] / 2),
              holding_radius=lambda h: float(h[0] + h[1]),
              coal_half=lambda g: np.array([g.radius, g.halfLength, 0.0])),
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
