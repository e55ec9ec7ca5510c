"""Scenes: the robot's surroundings as data (boxes, cylinders, spheres, capsules).

``scene.yaml`` names the robot (it is included, never copied), the objects of the
cell with their placement in the world frame, the default safety margin, the object
the gripper may hold, and the contacts that are allowed on purpose (a vial standing
on its conveyor), each restricted to the taught poses where it happens.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pinocchio as pin

from ._io import as_float, as_str, as_vector, get_key, read_yaml
from .errors import ConfigError

__all__ = ["Shape", "SceneObject", "AllowedContact", "Grasp", "Scene", "load_scene",
           "placement"]

ShapeKind = Literal["box", "cylinder", "sphere", "capsule"]
_SIZE_KEYS: dict[str, tuple[str, ...]] = {
    "box": ("size",),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
    "sphere": ("radius",),
}

#: Alias in ``allowed_contacts`` for the tool's contact links (the gripper jaws).
GRIPPER = "gripper"


@dataclass(frozen=True)
class Shape:
    """A primitive shape, centred on its frame; cylinders and capsules along local z.

    Attributes:
        kind: ``box``, ``cylinder``, ``sphere`` or ``capsule``.
        size: Box edge lengths (x, y, z) [m]; (radius, length) for cylinders and
            capsules [m]; (radius,) for spheres [m].
    """

    kind: ShapeKind
    size: tuple[float, ...]

    def bounding_radius(self) -> float:
        """Radius of a sphere about the shape's origin that holds it [m]."""
        if self.kind == "box":
            return float(np.linalg.norm(self.size) / 2)
        if self.kind == "cylinder":
            return float(np.hypot(self.size[0], self.size[1] / 2))
        if self.kind == "capsule":
            return float(self.size[0] + self.size[1] / 2)
        return float(self.size[0])

    def to_coal(self) -> Any:
        """The coal collision geometry of this shape."""
        import coal

        if self.kind == "box":
            return coal.Box(*self.size)
        if self.kind == "cylinder":
            return coal.Cylinder(self.size[0], self.size[1])
        if self.kind == "capsule":
            return coal.Capsule(self.size[0], self.size[1])
        return coal.Sphere(self.size[0])


@dataclass(frozen=True)
class SceneObject:
    """An object of the cell.

    Attributes:
        name: Unique name.
        shape: Its primitive shape.
        T_world_object: Placement of the object frame in the world [m, rad] (4x4).
        margin: Safety margin the robot keeps from it [m], or None for the scene's.
        movable: Whether the gripper may pick it (it then moves with the TCP).
        color: RGB in [0, 1] for viewers.
    """

    name: str
    shape: Shape
    T_world_object: np.ndarray = field(repr=False)
    margin: float | None = None
    movable: bool = False
    color: tuple[float, float, float] = (0.6, 0.6, 0.6)

    def placed(self, T_world_object: np.ndarray) -> SceneObject:
        """The same object at another placement."""
        return SceneObject(self.name, self.shape, np.array(T_world_object, dtype=float),
                           self.margin, self.movable, self.color)


@dataclass(frozen=True)
class AllowedContact:
    """A contact that is expected and allowed, between two names, at given poses.

    Attributes:
        between: Two names: object names, robot link names, or ``gripper`` (the
            tool's contact links).
        at: Taught poses where the contact happens; the allowance also holds on the
            straight Cartesian lines that arrive at or leave those poses. Empty: never
            applied by pose (only by explicit request).
        max_depth: How deep the two may interpenetrate [m]; None for any depth (jaws
            closing on a vial). A small depth lets a vial stand on its support without
            letting it sink into it.
        reason: Why this contact is expected.
    """

    between: tuple[str, str]
    at: tuple[str, ...] = ()
    max_depth: float | None = None
    reason: str = ""


@dataclass(frozen=True)
class Grasp:
    """How the gripper holds the movable object.

    Attributes:
        object: Name of the movable object.
        T_tcp_object: Placement of the object in the TCP frame when held (4x4).
        poses: Taught poses at which the object may be in the gripper.
    """

    object: str
    T_tcp_object: np.ndarray = field(repr=False)
    poses: tuple[str, ...] = ()


@dataclass(frozen=True)
class Scene:
    """The robot's surroundings.

    Attributes:
        name: Scene name.
        robot: Robot name or folder the scene includes.
        objects: Objects by name (static and movable), at their initial placement.
        margin: Default safety margin [m].
        allowed_contacts: Contacts allowed on purpose.
        grasp: How the movable object is held, if any.
        path: File the scene came from.
    """

    name: str
    robot: str
    objects: Mapping[str, SceneObject]
    margin: float = 0.010
    allowed_contacts: tuple[AllowedContact, ...] = ()
    grasp: Grasp | None = None
    path: Path | None = None

    def static_objects(self) -> list[SceneObject]:
        """Objects that never move."""
        return [o for o in self.objects.values() if not o.movable]

    def margin_for(self, name: str) -> float:
        """Safety margin required from object ``name`` [m]."""
        obj = self.objects.get(name)
        if obj is not None and obj.margin is not None:
            return obj.margin
        return self.margin

    def contacts_at(self, pose: str | None) -> tuple[AllowedContact, ...]:
        """The allowed contacts that apply at taught pose ``pose``."""
        if pose is None:
            return ()
        return tuple(c for c in self.allowed_contacts if pose in c.at)


def placement(xyz: Any, rpy: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform (4x4) from a translation [m] and URDF roll-pitch-yaw [rad]."""
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(*[float(v) for v in rpy])
    T[:3, 3] = np.asarray(xyz, dtype=float)
    return T


def load_scene(path: str | Path) -> Scene:
    """Read ``scene.yaml`` (or a folder holding it).

    Raises:
        ConfigError: Malformed YAML, an unknown shape, a non-positive size, a bad
            placement, a contact naming an unknown object; names file and key.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "scene.yaml"
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping at the top level", path=path)
    name = as_str(get_key(data, "name", path=path), path=path, key="name")
    robot = as_str(get_key(data, "robot", path=path), path=path, key="robot")
    margin = as_float(get_key(data, "margin", path=path, default=0.010), path=path,
                      key="margin", non_negative=True)
    raw_objects = get_key(data, "objects", path=path)
    if not isinstance(raw_objects, dict) or not raw_objects:
        raise ConfigError("expected a non-empty mapping of object names", path=path,
                          key="objects")
    objects = {str(k): _parse_object(str(k), v, path) for k, v in raw_objects.items()}
    contacts = tuple(_parse_contact(i, c, path, objects)
                     for i, c in enumerate(get_key(data, "allowed_contacts", path=path,
                                                   default=[]) or []))
    grasp = None
    if data.get("grasp") is not None:
        grasp = _parse_grasp(data["grasp"], path, objects)
    return Scene(name=name, robot=robot, objects=objects, margin=margin,
                 allowed_contacts=contacts, grasp=grasp, path=path)


def _parse_object(name: str, raw: Any, path: Path) -> SceneObject:
    key = f"objects.{name}"
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key=key)
    kind = as_str(get_key(raw, "shape", path=path, prefix=key), path=path, key=f"{key}.shape")
    if kind not in _SIZE_KEYS:
        raise ConfigError(f"unknown shape '{kind}' (known: {', '.join(_SIZE_KEYS)})",
                          path=path, key=f"{key}.shape")
    if kind == "box":
        size = as_vector(get_key(raw, "size", path=path, prefix=key), 3, path=path,
                         key=f"{key}.size")
        for i, v in enumerate(size):
            if v <= 0:
                raise ConfigError(f"size must be > 0, got {v:g}", path=path,
                                  key=f"{key}.size[{i}]")
    else:
        size = [as_float(get_key(raw, k, path=path, prefix=key), path=path, key=f"{key}.{k}",
                         positive=True) for k in _SIZE_KEYS[kind]]
    xyz = as_vector(get_key(raw, "xyz", path=path, prefix=key), 3, path=path, key=f"{key}.xyz")
    rpy = as_vector(get_key(raw, "rpy", path=path, prefix=key, default=[0.0, 0.0, 0.0]), 3,
                    path=path, key=f"{key}.rpy")
    margin = raw.get("margin")
    if margin is not None:
        margin = as_float(margin, path=path, key=f"{key}.margin", non_negative=True)
    movable = raw.get("movable", False)
    if not isinstance(movable, bool):
        raise ConfigError(f"expected true or false, got {movable!r}", path=path,
                          key=f"{key}.movable")
    color = raw.get("color", [0.6, 0.6, 0.6])
    rgb = as_vector(color, 3, path=path, key=f"{key}.color")
    if any(c < 0 or c > 1 for c in rgb):
        raise ConfigError("colour components must lie in [0, 1]", path=path, key=f"{key}.color")
    unknown = set(raw) - {"shape", "size", "radius", "length", "xyz", "rpy", "margin",
                          "movable", "color", "note"}
    if unknown:
        raise ConfigError(f"unknown key(s) {sorted(unknown)}", path=path, key=key)
    shape = Shape(kind, tuple(size))  # type: ignore[arg-type]  # kind checked above
    return SceneObject(name, shape, placement(xyz, rpy), margin, movable,
                       (rgb[0], rgb[1], rgb[2]))


def _parse_contact(i: int, raw: Any, path: Path, objects: Mapping[str, SceneObject]
                   ) -> AllowedContact:
    key = f"allowed_contacts[{i}]"
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key=key)
    between = get_key(raw, "between", path=path, prefix=key)
    if not (isinstance(between, list) and len(between) == 2
            and all(isinstance(b, str) for b in between)):
        raise ConfigError("expected two names", path=path, key=f"{key}.between")
    if not any(b in objects for b in between):
        raise ConfigError(f"neither of {between} is a scene object", path=path,
                          key=f"{key}.between")
    at = raw.get("at", [])
    if not isinstance(at, list) or not all(isinstance(a, str) for a in at):
        raise ConfigError("expected a list of pose names", path=path, key=f"{key}.at")
    depth = raw.get("max_depth")
    if depth is not None:
        depth = as_float(depth, path=path, key=f"{key}.max_depth", non_negative=True)
    return AllowedContact((between[0], between[1]), tuple(at), depth, str(raw.get("reason", "")))


def _parse_grasp(raw: Any, path: Path, objects: Mapping[str, SceneObject]) -> Grasp:
    obj = as_str(get_key(raw, "object", path=path, prefix="grasp"), path=path, key="grasp.object")
    if obj not in objects:
        raise ConfigError(f"unknown object '{obj}' (objects: {', '.join(objects)})", path=path,
                          key="grasp.object")
    if not objects[obj].movable:
        raise ConfigError(f"object '{obj}' is not movable", path=path, key="grasp.object")
    xyz = as_vector(get_key(raw, "xyz", path=path, prefix="grasp"), 3, path=path,
                    key="grasp.xyz")
    rpy = as_vector(raw.get("rpy", [0.0, 0.0, 0.0]), 3, path=path, key="grasp.rpy")
    poses = raw.get("poses", [])
    if not isinstance(poses, list) or not all(isinstance(p, str) for p in poses):
        raise ConfigError("expected a list of pose names", path=path, key="grasp.poses")
    return Grasp(obj, placement(xyz, rpy), tuple(poses))
