"""Scenes: the robot's surroundings as data (boxes, cylinders, spheres, capsules).

``scene.yaml`` names the robot (it is included, never copied), the objects of the
cell with their placement in the world frame, the default safety margin, the object
the gripper may hold (and, optionally, the tool that holds it, for a robot whose own
description has none), and the contacts that are allowed on purpose (a vial standing
on its conveyor), each restricted to the taught poses where it happens.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..files._io import as_float, check_names
from .shapes import SHAPES
from .tool import ToolSpec

__all__ = ["Shape", "SceneObject", "AllowedContact", "Grasp", "Scene", "placement", "SIZE_KEYS",
           "DEFAULT_WALL", "DEFAULT_SPILL_ANGLE"]

ShapeKind = Literal["box", "cylinder", "sphere", "capsule"]
#: The size keys of each shape kind, in the order of :attr:`Shape.size`.
SIZE_KEYS: dict[str, tuple[str, ...]] = {name: kind.keys for name, kind in SHAPES.items()}

#: Wall thickness of a receptacle whose scene gives none [m]: a thick-walled bowl's rim, so
#: that a pour is never judged against an opening wider than the real one by more.
DEFAULT_WALL = 0.005
#: Spill angle of a container a pour step tilts whose scene gives none [rad]: a cup full to
#: the brim spills at any tilt.
DEFAULT_SPILL_ANGLE = 0.0
#: Alias in ``allowed_contacts`` for the tool's contact links (the gripper jaws).
GRIPPER = "gripper"



def _number(value: Any, key: str, *, positive: bool = False, non_negative: bool = False
            ) -> float:
    """A finite float from a constructor argument, or a ConfigError naming ``key``."""
    return as_float(value.item() if isinstance(value, np.generic) else value, path=None,
                    key=key, positive=positive, non_negative=non_negative)


def _transform(value: Any, key: str) -> np.ndarray:
    """A finite rigid 4x4 transform (a copy), or a ConfigError naming ``key``."""
    try:
        T = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"expected a 4x4 transform, got {value!r}", key=key) from None
    if T.shape != (4, 4):
        raise ConfigError(f"expected a 4x4 transform, got shape {T.shape}", key=key)
    if not np.all(np.isfinite(T)):
        raise ConfigError("the transform has non-finite entries", key=key)
    R = T[:3, :3]
    if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.isclose(np.linalg.det(R), 1.0,
                                                                       atol=1e-6)
            and np.allclose(T[3], [0.0, 0.0, 0.0, 1.0])):
        raise ConfigError("not a rigid transform (rotation not orthonormal, or last row "
                          "not [0, 0, 0, 1])", key=key)
    return T


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

    def __post_init__(self) -> None:
        if self.kind not in SIZE_KEYS:
            check_names([self.kind], SIZE_KEYS, path=None, key="kind", what="shape")
        names = SHAPES[self.kind].size_names
        try:
            size = tuple(self.size)
        except TypeError:
            raise ConfigError(f"expected {len(names)} sizes ({', '.join(names)}) [m], got "
                              f"{self.size!r}", key="size") from None
        if len(size) != len(names):
            raise ConfigError(f"a {self.kind} needs {len(names)} sizes ({', '.join(names)}) "
                              f"[m], got {len(size)}", key="size")
        object.__setattr__(self, "size", tuple(
            _number(v, f"size[{i}]", positive=True) for i, v in enumerate(size)))

    def bounding_radius(self) -> float:
        """Radius of a sphere about the shape's origin that holds it [m]."""
        return SHAPES[self.kind].bounding_radius(self.size)

    def to_coal(self) -> Any:
        """The coal collision geometry of this shape."""
        return SHAPES[self.kind].to_coal(self.size)


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
        wall: Thickness of its walls at the top [m], as a receptacle a pour lands in
            (``into``): the opening is its top face less this all round. None:
            :data:`DEFAULT_WALL`.
        spill_angle: As a held container (its open end its local +z face), the tilt of
            its axis from the vertical past which its content can reach the rim [rad].
            None: it holds nothing that can pour, unless a pour step tilts it (then
            :data:`DEFAULT_SPILL_ANGLE`).
    """

    name: str
    shape: Shape
    T_world_object: np.ndarray = field(repr=False)
    margin: float | None = None
    movable: bool = False
    color: tuple[float, float, float] = (0.6, 0.6, 0.6)
    wall: float | None = None
    spill_angle: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError(f"expected a non-empty name, got {self.name!r}", key="name")
        where = f"objects.{self.name}"
        if not isinstance(self.shape, Shape):
            raise ConfigError(f"expected a Shape, got {self.shape!r}", key=f"{where}.shape")
        object.__setattr__(self, "T_world_object",
                           _transform(self.T_world_object, f"{where}.T_world_object"))
        if self.margin is not None:
            object.__setattr__(self, "margin", _number(self.margin, f"{where}.margin",
                                                       non_negative=True))
        if not isinstance(self.movable, bool):
            raise ConfigError(f"expected True or False, got {self.movable!r}",
                              key=f"{where}.movable")
        if self.wall is not None:
            object.__setattr__(self, "wall", _number(self.wall, f"{where}.wall",
                                                     non_negative=True))
        if self.spill_angle is not None:
            angle = _number(self.spill_angle, f"{where}.spill_angle", non_negative=True)
            if angle > math.pi:
                raise ConfigError(f"a tilt in [0, pi] [rad], got {angle!r}",
                                  key=f"{where}.spill_angle")
            object.__setattr__(self, "spill_angle", angle)
        rgb = tuple(_number(c, f"{where}.color") for c in self.color)
        if len(rgb) != 3 or any(c < 0 or c > 1 for c in rgb):
            raise ConfigError(f"expected three components in [0, 1], got {self.color!r}",
                              key=f"{where}.color")
        object.__setattr__(self, "color", rgb)

    def placed(self, T_world_object: np.ndarray) -> SceneObject:
        """The same object at another placement."""
        return dataclasses.replace(self, T_world_object=T_world_object)


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

    def __post_init__(self) -> None:
        between = tuple(self.between) if isinstance(self.between, (list, tuple)) else ()
        if len(between) != 2 or not all(isinstance(b, str) and b for b in between):
            raise ConfigError(f"expected two names, got {self.between!r}", key="between")
        object.__setattr__(self, "between", between)
        at = (self.at,) if isinstance(self.at, str) else tuple(self.at)
        if not all(isinstance(a, str) and a for a in at):
            raise ConfigError(f"expected pose names, got {self.at!r}", key="at")
        object.__setattr__(self, "at", at)
        if self.max_depth is not None:
            object.__setattr__(self, "max_depth", _number(self.max_depth, "max_depth",
                                                          non_negative=True))


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

    def __post_init__(self) -> None:
        if not isinstance(self.object, str) or not self.object:
            raise ConfigError(f"expected an object name, got {self.object!r}",
                              key="grasp.object")
        object.__setattr__(self, "T_tcp_object",
                           _transform(self.T_tcp_object, "grasp.T_tcp_object"))
        poses = (self.poses,) if isinstance(self.poses, str) else tuple(self.poses)
        if not all(isinstance(p, str) and p for p in poses):
            raise ConfigError(f"expected pose names, got {self.poses!r}", key="grasp.poses")
        object.__setattr__(self, "poses", poses)


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
        locked_joints: Positions of the robot's locked joints (fingers) in this cell,
            ``{joint: value [rad or m] or "travel"}``; a joint not named covers its whole
            travel (see :func:`safepath.load_robot`).
        tool: The tool on the robot's flange in this cell (its contact links hold the
            grasped object), instead of the robot's own; None: the robot's.
    """

    name: str
    robot: str
    objects: Mapping[str, SceneObject]
    margin: float = 0.010
    allowed_contacts: tuple[AllowedContact, ...] = ()
    grasp: Grasp | None = None
    path: Path | None = None
    locked_joints: Mapping[str, float | str] = field(default_factory=dict)
    tool: ToolSpec | None = None

    def __post_init__(self) -> None:
        where = {"path": self.path}
        if self.tool is not None and not isinstance(self.tool, ToolSpec):
            raise ConfigError(f"expected a safepath.ToolSpec, got {type(self.tool).__name__}",
                              key="tool", **where)
        for key in ("name", "robot"):
            value = getattr(self, key)
            if not isinstance(value, str) or not value:
                raise ConfigError(f"expected a non-empty string, got {value!r}", key=key,
                                  **where)
        if isinstance(self.objects, Mapping):
            items = list(self.objects.items())
        else:  # a sequence of objects: keyed by their names
            items = [(getattr(o, "name", None), o) for o in self.objects]
        objects: dict[str, SceneObject] = {}
        for name, obj in items:
            if not isinstance(obj, SceneObject):
                raise ConfigError(f"expected a SceneObject, got {type(obj).__name__}",
                                  key=f"objects.{name}", **where)
            if obj.name != name or name in objects:
                raise ConfigError(f"object '{obj.name}' is listed under '{name}' or twice",
                                  key=f"objects.{name}", **where)
            objects[name] = obj
        object.__setattr__(self, "objects", objects)
        object.__setattr__(self, "margin", as_float(
            self.margin.item() if isinstance(self.margin, np.generic) else self.margin,
            path=self.path, key="margin", non_negative=True))
        object.__setattr__(self, "allowed_contacts", self._checked_contacts(objects))
        if self.grasp is not None:
            if not isinstance(self.grasp, Grasp):
                raise ConfigError(f"expected a Grasp, got {type(self.grasp).__name__}",
                                  key="grasp", **where)
            check_names([self.grasp.object], objects, path=self.path, key="grasp.object",
                        what="object")
            if not objects[self.grasp.object].movable:
                raise ConfigError(f"object '{self.grasp.object}' is not movable",
                                  key="grasp.object", **where)

    def _checked_contacts(self, objects: Mapping[str, SceneObject]
                          ) -> tuple[AllowedContact, ...]:
        """The allowed contacts as a tuple, each an AllowedContact naming a scene object."""
        contacts = tuple(self.allowed_contacts)
        for i, contact in enumerate(contacts):
            if not isinstance(contact, AllowedContact):
                raise ConfigError(f"expected an AllowedContact, got {type(contact).__name__}",
                                  key=f"allowed_contacts[{i}]", path=self.path)
            if not any(b in objects for b in contact.between):
                raise ConfigError(f"neither of {list(contact.between)} is a scene object",
                                  key=f"allowed_contacts[{i}].between", path=self.path)
        return contacts

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
    """Homogeneous transform (4x4) from a translation [m] and URDF roll-pitch-yaw [rad].

    Raises:
        ConfigError: ``xyz`` or ``rpy`` is not three finite numbers (key ``xyz``/``rpy``).
    """
    values = {}
    for key, raw in (("xyz", xyz), ("rpy", rpy)):
        try:
            v = np.asarray(raw, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ConfigError(f"expected three numbers, got {raw!r}", key=key) from None
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ConfigError(f"expected three finite numbers, got {raw!r}", key=key)
        values[key] = v
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(*[float(v) for v in values["rpy"]])
    T[:3, 3] = values["xyz"]
    return T
