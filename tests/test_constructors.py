"""Objects built in Python are checked where the bad value enters, with the YAML path's errors.

Each case was accepted before and surfaced later as a misleading error (a
``VerificationError`` for a negative box size, a false collision list for a NaN
placement, numpy's broadcasting error for a goal of the wrong length, an
``OverflowError`` for a zero speed).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from safepath import (
    AllowedContact,
    Cell,
    ConfigError,
    Grasp,
    PoseError,
    Route,
    Scene,
    SceneObject,
    Shape,
    Step,
    Target,
    placement,
)
from safepath.errors import unknown_name


@pytest.mark.parametrize(("kind", "size", "key", "words"), [
    ("box", (0.15, -0.15, 0.3), "size[1]", "> 0"),
    ("box", (0.15, 0.3), "size", "3 sizes"),
    ("box", (0.1, math.nan, 0.1), "size[1]", "not finite"),
    ("cylinder", (0.1,), "size", "radius, length"),
    ("sphere", (0.0,), "size[0]", "> 0"),
    ("capsule", (0.1, "long"), "size[1]", "expected a number"),
    ("cone", (0.1, 0.2), "kind", "unknown shape 'cone'"),
    ("bax", (0.1, 0.2, 0.3), "kind", "did you mean 'box'"),
])
def test_shape_refuses_bad_sizes(kind: str, size: Any, key: str, words: str) -> None:
    with pytest.raises(ConfigError, match=words) as info:
        Shape(kind, size)  # type: ignore[arg-type]
    assert info.value.key == key


def test_shape_keeps_floats() -> None:
    shape = Shape("box", [1, 2, 3])  # type: ignore[arg-type]
    assert shape.size == (1.0, 2.0, 3.0) and all(type(v) is float for v in shape.size)


@pytest.mark.parametrize(("xyz", "rpy", "key"), [
    ((0.0, math.nan, 0.0), (0.0, 0.0, 0.0), "xyz"),
    ((0.0, 0.0, 0.0), (0.0, math.inf, 0.0), "rpy"),
    ((0.0, 0.0), (0.0, 0.0, 0.0), "xyz"),
    ("here", (0.0, 0.0, 0.0), "xyz"),
])
def test_placement_refuses_nan_and_bad_lengths(xyz: Any, rpy: Any, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        placement(xyz, rpy)
    assert info.value.key == key


def test_scene_object_refuses_bad_transforms_and_values() -> None:
    box = Shape("box", (0.1, 0.1, 0.1))
    T = np.eye(4)
    T[1, 3] = math.nan
    with pytest.raises(ConfigError, match="non-finite") as info:
        SceneObject("crate", box, T)
    assert info.value.key == "objects.crate.T_world_object"
    sheared = np.eye(4)
    sheared[0, 1] = 0.5
    with pytest.raises(ConfigError, match="not a rigid transform"):
        SceneObject("crate", box, sheared)
    with pytest.raises(ConfigError, match="4x4"):
        SceneObject("crate", box, np.eye(3))
    with pytest.raises(ConfigError) as info:
        SceneObject("crate", box, np.eye(4), margin=-0.01)
    assert info.value.key == "objects.crate.margin"
    with pytest.raises(ConfigError) as info:
        SceneObject("crate", box, np.eye(4), color=(2.0, 0.0, 0.0))
    assert info.value.key == "objects.crate.color"
    with pytest.raises(ConfigError):
        SceneObject("crate", (0.1, 0.1, 0.1), np.eye(4))  # type: ignore[arg-type]
    ok = SceneObject("crate", box, placement((0.5, 0, 0.05)))
    moved = ok.placed(placement((0.6, 0, 0.05)))
    assert moved.T_world_object[0, 3] == 0.6 and moved.shape is box


def _scene(**changes: Any) -> Scene:
    objects = [SceneObject("table", Shape("box", (1.0, 1.0, 0.02)), placement((0.4, 0, -0.011))),
               SceneObject("can", Shape("cylinder", (0.03, 0.1)), placement((0.5, 0, 0.05)),
                           movable=True)]
    fields: dict[str, Any] = {"name": "t", "robot": "ur5", "objects": objects}
    fields.update(changes)
    return Scene(**fields)


def test_scene_checks_its_parts() -> None:
    scene = _scene()
    assert list(scene.objects) == ["table", "can"]  # a list is keyed by the objects' names
    with pytest.raises(ConfigError, match=">= 0") as info:
        _scene(margin=-0.01)
    assert info.value.key == "margin"
    with pytest.raises(ConfigError, match="neither") as info:
        _scene(allowed_contacts=(AllowedContact(("cup", "gripper"), ("a",)),))
    assert info.value.key == "allowed_contacts[0].between"
    with pytest.raises(ConfigError, match="did you mean 'can'") as info:
        _scene(grasp=Grasp("cans", np.eye(4)))
    assert info.value.key == "grasp.object"
    with pytest.raises(ConfigError, match="not movable"):
        _scene(grasp=Grasp("table", np.eye(4)))
    with pytest.raises(ConfigError) as info:
        AllowedContact(("can",), ())  # type: ignore[arg-type]
    assert info.value.key == "between"
    with pytest.raises(ConfigError) as info:
        AllowedContact(("can", "table"), max_depth=-1.0)
    assert info.value.key == "max_depth"
    with pytest.raises(ConfigError) as info:
        _scene(objects={"desk": SceneObject("table", Shape("sphere", (0.1,)), np.eye(4))})
    assert info.value.key == "objects.desk"


@pytest.mark.parametrize(("build", "key", "words"), [
    (lambda: Step("move", Target("b"), speed=0), "speed", "(0, 1]"),
    (lambda: Step("move", Target("b"), speed=1.5), "speed", "(0, 1]"),
    (lambda: Step("move", Target("b"), speed=math.nan), "speed", "(0, 1]"),
    (lambda: Step("line", Target("b"), tcp_speed=0.0), "tcp_speed", "> 0"),
    (lambda: Step("move", None), "target", "needs a Target"),
    (lambda: Step("open", Target("b")), "target", "no target"),
    (lambda: Step("jump", Target("b")), "kind", "unknown step kind"),
    (lambda: Step("move", Target("b"), stop="yes"), "stop", "True or False"),
    (lambda: Step("line", Target("b"), via=True), "via", "never stops"),
    (lambda: Step("move", Target("b"), stop=True, via=True), "via", "never stops"),
    (lambda: Target("b", (0.0, math.nan, 0.0)), "offset", "finite"),
    (lambda: Target(None), "offset", "non-zero"),
    (lambda: Route("r", "a", ()), "steps", "non-empty"),
    (lambda: Route("", "a", (Step("move", Target("b")),)), "name", "non-empty"),
])
def test_route_parts_refuse_bad_values(build: Any, key: str, words: str) -> None:
    with pytest.raises(ConfigError, match=words.replace("(", r"\(").replace("]", r"\]")) as info:
        build()
    assert info.value.key == key


def test_cell_checks_poses_and_routes(robot: Any, cell: Cell) -> None:
    q = cell.pose("high1")
    with pytest.raises(PoseError, match="expected 6 joint values") as info:
        Cell(robot, cell.scene, {**cell.poses, "extra": q[:5]})
    assert info.value.key == "extra"
    with pytest.raises(PoseError, match="not finite"):
        Cell(robot, cell.scene, {**cell.poses, "extra": [math.nan] * 6})
    with pytest.raises(PoseError, match="outside its limits"):
        Cell(robot, cell.scene, {**cell.poses, "extra": q + [10, 0, 0, 0, 0, 0]})
    with pytest.raises(PoseError, match="not a valid pose name"):
        Cell(robot, cell.scene, {**cell.poses, "9 lives": q})
    with pytest.raises(ConfigError, match="unknown pose 'low1'") as info:
        Cell(robot, cell.scene, {k: v for k, v in cell.poses.items() if k != "low1"})
    assert info.value.key in ("grasp.poses", "allowed_contacts[1].at")
    bad_route = Route("r", "high1", (Step("move", Target("hihg2")),))
    with pytest.raises(ConfigError, match="did you mean 'high2'") as info:
        Cell(robot, cell.scene, cell.poses, routes={"r": bad_route})
    assert info.value.key == "routes.r.steps[0].move"
    with pytest.raises(ConfigError, match="named 'r'"):
        Cell(robot, cell.scene, cell.poses, routes={"other": bad_route})
    loop = {"a": Route("a", "high1", (Step("move", Target("high2")),), after="b"),
            "b": Route("b", "high2", (Step("move", Target("high1")),), after="a")}
    with pytest.raises(ConfigError, match="cycle"):
        Cell(robot, cell.scene, cell.poses, routes=loop)
    fine = Cell(robot, cell.scene, {k: list(v) for k, v in cell.poses.items()},
                routes={"r": Route("r", "high1", (Step("move", Target("high2")),))})
    assert isinstance(fine.poses["high1"], np.ndarray) and fine.folder is None
    assert list(fine.route_table()) == ["r"]
    with pytest.raises(ConfigError, match="no routes"):
        Cell(robot, cell.scene, cell.poses).route_table()


def test_unknown_name_wording() -> None:
    assert unknown_name("robot", "ur55", ["panda", "ur5", "ur10"]) == (
        "unknown robot 'ur55' (did you mean 'ur5'?)")
    assert unknown_name("pose", "zz", ["a", "b"]) == "unknown pose 'zz' (known: a, b)"
    many = [f"name{i}" for i in range(75)]
    text = unknown_name("robot", "qqq", many)
    assert text.startswith("unknown robot 'qqq' (75 known, e.g. ") and len(text) < 200


@pytest.mark.parametrize(("text", "key", "words"), [
    ("rutes: {}\n", "rutes", "did you mean 'routes'"),
    ("defaults: {sped: 0.5}\nroutes: {r: {start: a, steps: [move: b]}}\n", "defaults.sped",
     "did you mean 'speed'"),
    ("routes: {r: {start: a, aftr: q, steps: [move: b]}}\n", "routes.r.aftr",
     "did you mean 'after'"),
    ("routes: {r: {start: a, steps: [{line: {up: 0.05, pose: a}}]}}\n",
     "routes.r.steps[0].line.pose", "unknown key 'pose'"),
    ("routes: {r: {start: a, steps: [{line: {pose: a, ofset: [0, 0, 1]}}]}}\n",
     "routes.r.steps[0].line.ofset", "did you mean 'offset'"),
])
def test_routes_file_refuses_unknown_keys_at_every_level(tmp_path: Any, text: str, key: str,
                                                         words: str) -> None:
    from safepath import load_routes

    path = tmp_path / "routes.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=words) as info:
        load_routes(path, poses=["a", "b"], objects=[])
    assert info.value.key == key and info.value.path == path


def test_robot_and_controller_files_refuse_unknown_keys(tmp_path: Any) -> None:
    import shutil

    from safepath import load_robot
    from safepath.description.robot_folder import ROBOTS_DIR

    folder = tmp_path / "arm"
    shutil.copytree(ROBOTS_DIR / "ned3pro", folder)
    spec = folder / "robot.yaml"
    original = spec.read_text()
    spec.write_text(original.replace("velocity_limits:", "velocty_limits:"))
    with pytest.raises(ConfigError, match="did you mean 'velocity_limits'") as info:
        load_robot(folder)
    assert info.value.key == "velocty_limits" and info.value.path == spec
    spec.write_text(original.replace("  open_width:", "  open_widht:"))
    with pytest.raises(ConfigError, match="did you mean 'open_width'") as info:
        load_robot(folder)
    assert info.value.key == "tool.open_widht"
    spec.write_text(original)
    controller = folder / "controller.yaml"
    text = controller.read_text()
    controller.write_text(text.replace("goal_tolerance:", "goal_tolerence:"))
    with pytest.raises(ConfigError, match="did you mean 'goal_tolerance'") as info:
        load_robot(folder)
    assert info.value.path == controller
    controller.write_text(text.replace("joint_names: [joint_1,", "joint_names: [joint_0,"))
    with pytest.raises(ConfigError, match="not the robot's") as info:
        load_robot(folder)
    assert info.value.key == "joint_names"
    controller.write_text(text.replace("period: 0.04", "period: 0"))
    with pytest.raises(ConfigError, match="> 0") as info:
        load_robot(folder)
    assert info.value.key == "period"
    controller.write_text(text)
    robot = load_robot(folder)
    assert robot.controller.source == controller and robot.reference == str(folder.resolve())


def test_every_option_class_is_keyword_only() -> None:
    """Options are built by name only (``PlannerOptions(seed=3)``): a positional call would
    silently shift meaning when a field is added. Every ``*Options`` dataclass of the
    library is found by walking its modules, so a new one is covered too."""
    import dataclasses
    import importlib
    import pkgutil

    import safepath

    found = {}
    for info in pkgutil.walk_packages(safepath.__path__, "safepath."):
        if info.name.startswith("safepath._aot"):
            continue  # the kernels' ahead-of-time build, not the library's API
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (name.endswith("Options") and isinstance(value, type)
                    and dataclasses.is_dataclass(value) and value.__module__ == info.name):
                found[f"{info.name}.{name}"] = value
    assert len(found) >= 10, sorted(found)
    positional = [name for name, cls in found.items()
                  if any(f.init and not f.kw_only for f in dataclasses.fields(cls))]
    assert positional == []
    with pytest.raises(TypeError):
        safepath.PlannerOptions("rrtconnect")  # type: ignore[misc]
