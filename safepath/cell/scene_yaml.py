"""Reading ``scene.yaml``: every key checked, the unknown ones refused by their closest name.

The fields of each level are listed in ``docs/your_own_robot_and_cell.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from ..files._io import (
    as_float,
    as_str,
    as_vector,
    check_keys,
    check_names,
    get_key,
    read_mapping,
)
from ..model.scene import SIZE_KEYS, AllowedContact, Grasp, Scene, SceneObject, Shape, placement
from ..model.shapes import SHAPES
from ..model.tool import read_tool

__all__ = ["load_scene"]

_SCENE_KEYS = ("name", "robot", "margin", "objects", "grasp", "allowed_contacts", "note",
               "locked_joints", "tool")
_OBJECT_KEYS = ("shape", "size", "radius", "length", "xyz", "rpy", "margin", "movable",
                "color", "note", "wall", "spill_angle")
_CONTACT_KEYS = ("between", "at", "max_depth", "reason")
_GRASP_KEYS = ("object", "xyz", "rpy", "poses")


def load_scene(path: str | Path) -> Scene:
    """Read ``scene.yaml`` (or a folder holding it).

    Raises:
        ConfigError: Malformed YAML, an unknown shape, a non-positive size, a bad
            placement, a contact naming an unknown object; names file and key.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "scene.yaml"
    data = read_mapping(path, _SCENE_KEYS)
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
    locked = get_key(data, "locked_joints", path=path, default={}) or {}
    if not isinstance(locked, dict):
        raise ConfigError("expected a mapping {joint: position or 'travel'}", path=path,
                          key="locked_joints")
    tool = None if data.get("tool") is None else read_tool(data["tool"], path=path)
    return Scene(name=name, robot=robot, objects=objects, margin=margin,
                 allowed_contacts=contacts, grasp=grasp, path=path,
                 locked_joints={str(k): v for k, v in locked.items()}, tool=tool)


def _parse_object(name: str, raw: Any, path: Path) -> SceneObject:
    key = f"objects.{name}"
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key=key)
    check_keys(raw, _OBJECT_KEYS, path=path, prefix=key)
    kind = as_str(get_key(raw, "shape", path=path, prefix=key), path=path, key=f"{key}.shape")
    check_names([kind], SIZE_KEYS, path=path, key=f"{key}.shape", what="shape")
    spec = SHAPES[kind]
    if len(spec.keys) < len(spec.size_names):  # one key, a vector (a box's size)
        k = spec.keys[0]
        size = as_vector(get_key(raw, k, path=path, prefix=key), len(spec.size_names),
                         path=path, key=f"{key}.{k}")
        for i, v in enumerate(size):
            if v <= 0:
                raise ConfigError(f"{k} must be > 0, got {v:g}", path=path,
                                  key=f"{key}.{k}[{i}]")
    else:
        size = [as_float(get_key(raw, k, path=path, prefix=key), path=path, key=f"{key}.{k}",
                         positive=True) for k in SIZE_KEYS[kind]]
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
    extra = [k for k in ("size", "radius", "length") if k in raw and k not in SIZE_KEYS[kind]]
    if extra:
        raise ConfigError(f"a {kind} has no '{extra[0]}' (it takes "
                          f"{', '.join(SIZE_KEYS[kind])})", path=path, key=f"{key}.{extra[0]}")
    shape = Shape(kind, tuple(size))  # type: ignore[arg-type]  # kind checked above
    wall, spill = (None if raw.get(k) is None else
                   as_float(raw[k], path=path, key=f"{key}.{k}", non_negative=True)
                   for k in ("wall", "spill_angle"))
    try:
        return SceneObject(name, shape, placement(xyz, rpy), margin, movable,
                           (rgb[0], rgb[1], rgb[2]), wall=wall, spill_angle=spill)
    except ConfigError as exc:
        raise ConfigError(exc.reason, path=path, key=exc.key) from None


def _parse_contact(i: int, raw: Any, path: Path, objects: Mapping[str, SceneObject]
                   ) -> AllowedContact:
    key = f"allowed_contacts[{i}]"
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key=key)
    check_keys(raw, _CONTACT_KEYS, path=path, prefix=key)
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
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key="grasp")
    check_keys(raw, _GRASP_KEYS, path=path, prefix="grasp")
    obj = as_str(get_key(raw, "object", path=path, prefix="grasp"), path=path, key="grasp.object")
    check_names([obj], objects, path=path, key="grasp.object", what="object")
    if not objects[obj].movable:
        raise ConfigError(f"object '{obj}' is not movable", path=path, key="grasp.object")
    xyz = as_vector(get_key(raw, "xyz", path=path, prefix="grasp"), 3, path=path,
                    key="grasp.xyz")
    rpy = as_vector(raw.get("rpy", [0.0, 0.0, 0.0]), 3, path=path, key="grasp.rpy")
    poses = raw.get("poses", [])
    if not isinstance(poses, list) or not all(isinstance(p, str) for p in poses):
        raise ConfigError("expected a list of pose names", path=path, key="grasp.poses")
    return Grasp(obj, placement(xyz, rpy), tuple(poses))
