"""Scenes: the bundled cell's geometry agrees with its taught poses; bad scene files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yaml

from safepath import (
    Cell,
    ConfigError,
    PoseError,
    RobotNotFound,
    Scene,
    SceneObject,
    Shape,
    load_cell,
    load_scene,
    placement,
)

#: Where the held vial is put down at each release pose: the support it stands on.
SUPPORTS = {"grip": "qc_conveyor", "low1": "test_plate", "safe": "packaging_conveyor",
            "unsafe": "reject_bin"}


def _top(obj: SceneObject) -> float:
    assert obj.shape.kind == "box"
    return float(obj.T_world_object[2, 3] + obj.shape.size[2] / 2)


def _lowest_point(T_world_object: np.ndarray, shape: Shape) -> float:
    """Lowest z of a cylinder (axis along local z) placed at ``T_world_object`` [m]."""
    radius, length = shape.size
    axis_z = abs(T_world_object[2, 2])
    return float(T_world_object[2, 3] - axis_z * length / 2
                 - radius * np.sqrt(max(0.0, 1.0 - axis_z**2)))


def _held_vial(cell: Cell, pose: str) -> np.ndarray:
    assert cell.scene.grasp is not None
    T_world_tcp = cell.robot.frame_pose(cell.pose(pose)).homogeneous
    return T_world_tcp @ cell.scene.grasp.T_tcp_object


# ------------------------------------------------------------------------------------------
# The bundled cell
# ------------------------------------------------------------------------------------------
def test_bundled_scene(cell: Cell) -> None:
    scene = cell.scene
    assert scene.name == "quality_check_cell" and scene.robot == "ned3pro"
    assert scene.margin == pytest.approx(0.010)
    assert {"table", "qc_conveyor", "test_plate", "camera_post", "camera",
            "packaging_conveyor", "reject_bin", "vial"} <= set(scene.objects)
    assert [o.name for o in scene.objects.values() if o.movable] == ["vial"]
    assert "vial" not in [o.name for o in scene.static_objects()]
    assert _top(scene.objects["table"]) == pytest.approx(0.0)
    assert scene.margin_for("vial") == pytest.approx(0.005)
    assert scene.margin_for("qc_conveyor") == pytest.approx(0.010)
    assert scene.margin_for("not_an_object") == pytest.approx(0.010)
    assert scene.grasp is not None and scene.grasp.object == "vial"
    assert set(scene.grasp.poses) == set(cell.poses)
    for obj in scene.objects.values():
        T = obj.T_world_object
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
        assert all(s > 0 for s in obj.shape.size)


def test_vial_rests_where_the_grip_pose_holds_it(cell: Cell) -> None:
    # The resting vial was placed by the grasp at the grip pose: same placement.
    T_rest = cell.scene.objects["vial"].T_world_object
    T_held = _held_vial(cell, "grip")
    np.testing.assert_allclose(T_held[:3, 3], T_rest[:3, 3], atol=1e-4)
    np.testing.assert_allclose(T_held[:3, :3], T_rest[:3, :3], atol=1e-4)


@pytest.mark.parametrize("pose", sorted(SUPPORTS))
def test_held_vial_stands_on_its_support(cell: Cell, pose: str) -> None:
    support = cell.scene.objects[SUPPORTS[pose]]
    T_vial = _held_vial(cell, pose)
    vial = cell.scene.objects["vial"]
    # The support's top is where the held vial's lowest point is at that pose.
    assert _lowest_point(T_vial, vial.shape) == pytest.approx(_top(support), abs=1e-4)
    # And the vial stands inside the support's footprint.
    half = np.asarray(support.shape.size[:2]) / 2
    local = np.linalg.inv(support.T_world_object) @ np.append(T_vial[:3, 3], 1.0)
    assert np.all(np.abs(local[:2]) < half - vial.shape.size[0])
    # The allowed contact between vial and support applies exactly there.
    contacts = [c for c in cell.scene.allowed_contacts
                if set(c.between) == {"vial", support.name}]
    assert len(contacts) == 1 and contacts[0].at == (pose,)
    assert contacts[0].max_depth is not None and contacts[0].max_depth <= 0.001


def test_vial_is_held_upright_between_the_jaws(cell: Cell) -> None:
    assert cell.scene.grasp is not None
    T = cell.scene.grasp.T_tcp_object
    np.testing.assert_allclose(T[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)  # axis on TCP x
    np.testing.assert_allclose(T[:3, 3], [-0.015, 0.0, 0.0])
    tool = cell.robot.tool
    assert tool is not None
    assert tool.closed_width < 2 * cell.scene.objects["vial"].shape.size[0] < tool.open_width


def test_allowed_contacts_by_pose(cell: Cell) -> None:
    scene = cell.scene
    at_grip = {frozenset(c.between) for c in scene.contacts_at("grip")}
    assert at_grip == {frozenset({"vial", "qc_conveyor"}), frozenset({"vial", "gripper"})}
    assert scene.contacts_at("high1") == ()
    assert scene.contacts_at(None) == ()
    jaws = [c for c in scene.allowed_contacts if "gripper" in c.between]
    assert len(jaws) == 1 and jaws[0].max_depth is None
    assert "high1" not in jaws[0].at and "high2" not in jaws[0].at


# ------------------------------------------------------------------------------------------
# Shapes and placements
# ------------------------------------------------------------------------------------------
def test_placement() -> None:
    T = placement([1.0, 2.0, 3.0], [0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(T @ [1.0, 0.0, 0.0, 1.0], [1.0, 3.0, 3.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])
    # URDF roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll).
    r, p, y = 0.3, -0.2, 1.1
    expected = (pin.utils.rotate("z", y) @ pin.utils.rotate("y", p) @ pin.utils.rotate("x", r))
    np.testing.assert_allclose(placement([0, 0, 0], [r, p, y])[:3, :3], expected, atol=1e-12)
    T = placement([0.1, 0.2, 0.3])
    np.testing.assert_array_equal(T[:3, :3], np.eye(3))
    np.testing.assert_array_equal(T[:3, 3], [0.1, 0.2, 0.3])


@pytest.mark.parametrize(
    ("shape", "radius"),
    [
        (Shape("box", (0.2, 0.4, 0.4)), 0.3),
        (Shape("cylinder", (0.3, 0.8)), 0.5),
        (Shape("capsule", (0.1, 0.4)), 0.3),
        (Shape("sphere", (0.25,)), 0.25),
    ],
)
def test_shape_bounding_radius_and_coal(shape: Shape, radius: float) -> None:
    assert shape.bounding_radius() == pytest.approx(radius)
    geom = shape.to_coal()
    geom.computeLocalAABB()
    corner = np.maximum(np.abs(geom.aabb_local.min_), np.abs(geom.aabb_local.max_))
    # The coal shape lies inside the bounding sphere (its AABB half-extents do too).
    assert np.all(corner <= radius + 1e-9)
    assert np.max(corner) == pytest.approx(
        {"box": 0.2, "cylinder": 0.4, "capsule": 0.3, "sphere": 0.25}[shape.kind])


# ------------------------------------------------------------------------------------------
# Bad scene files: typed errors naming file and key
# ------------------------------------------------------------------------------------------
def _scene_data(cell_dir: Path) -> dict[str, Any]:
    data = yaml.safe_load((cell_dir / "scene.yaml").read_text())
    assert isinstance(data, dict)
    return data


def _write_scene(folder: Path, data: dict[str, Any]) -> Path:
    path = folder / "scene.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _edit(key_path: str, value: Any) -> Any:
    def apply(data: dict[str, Any]) -> None:
        *parents, last = key_path.split(".")
        node: Any = data
        for part in parents:
            node = node[int(part)] if isinstance(node, list) else node[part]
        if isinstance(node, list):
            node[int(last)] = value
        elif value is None:
            del node[last]
        else:
            node[last] = value
    return apply


@pytest.mark.parametrize(
    ("edit", "key", "match"),
    [
        (_edit("objects.camera.size", [0.04, -0.03, 0.03]), "objects.camera.size[1]",
         "must be > 0"),
        (_edit("objects.camera_post.radius", -0.012), "objects.camera_post.radius", "> 0"),
        (_edit("objects.camera_post.length", 0), "objects.camera_post.length", "> 0"),
        (_edit("objects.camera.shape", "cone"), "objects.camera.shape", "unknown shape 'cone'"),
        (_edit("objects.camera.size", [0.04, 0.03]), "objects.camera.size", "expected 3"),
        (_edit("objects.camera.xyz", None), "objects.camera.xyz", "missing key"),
        (_edit("objects.camera.xyz", [0.0, 0.0, float("nan")]), "objects.camera.xyz[2]",
         "not finite"),
        (_edit("objects.camera.xyz", [0.0, "up", 0.0]), "objects.camera.xyz[1]",
         "expected a number"),
        (_edit("objects.camera.color", [2.0, 0.0, 0.0]), "objects.camera.color", "colour"),
        (_edit("objects.camera.movable", "yes"), "objects.camera.movable", "true or false"),
        (_edit("objects.camera.weight", 1.0), "objects.camera.weight", "unknown key"),
        (_edit("objects.camera.margin", -0.01), "objects.camera.margin", ">= 0"),
        (_edit("margin", -0.01), "margin", ">= 0"),
        (_edit("objects", {}), "objects", "non-empty"),
        (_edit("name", None), "name", "missing key"),
        (_edit("grasp.object", "camera"), "grasp.object", "not movable"),
        (_edit("grasp.object", "flask"), "grasp.object", "unknown object 'flask'"),
        (_edit("allowed_contacts.0.between", ["flask", "gripper"]),
         "allowed_contacts[0].between", "neither"),
        (_edit("allowed_contacts.0.max_depth", -1.0), "allowed_contacts[0].max_depth", ">= 0"),
        # Unknown keys at every level, each naming the closest known key.
        (_edit("margn", 0.05), "margn", "did you mean 'margin'"),
        (_edit("allowed_contact", []), "allowed_contact", "did you mean 'allowed_contacts'"),
        (_edit("allowed_contacts.0.depth", 0.001), "allowed_contacts[0].depth",
         "did you mean 'max_depth'"),
        (_edit("grasp.pose", ["grip"]), "grasp.pose", "did you mean 'poses'"),
        (_edit("objects.camera.colour", [1, 0, 0]), "objects.camera.colour",
         "did you mean 'color'"),
        (_edit("objects.camera_post.size", [0.1, 0.1, 0.1]), "objects.camera_post.size",
         "has no 'size'"),
    ],
)
def test_bad_scene(tmp_path: Path, cell_dir: Path, edit: Any, key: str, match: str) -> None:
    data = _scene_data(cell_dir)
    edit(data)
    path = _write_scene(tmp_path, data)
    with pytest.raises(ConfigError, match=match) as info:
        load_scene(path)
    assert info.value.path == path
    assert info.value.key == key
    assert str(path) in str(info.value) and f"key '{key}'" in str(info.value)


def test_malformed_scene_yaml(tmp_path: Path) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text("name: x\nobjects:\n  table: {shape: box, size: [1, 1, 1]\n")
    with pytest.raises(ConfigError, match="malformed YAML at line") as info:
        load_scene(tmp_path)  # a folder holding scene.yaml works too
    assert info.value.path == path


def test_missing_scene_folder(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="scene folder not found") as info:
        load_cell(tmp_path / "no_such_cell")
    assert info.value.path == tmp_path / "no_such_cell"


def test_folder_without_scene_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="file not found") as info:
        load_cell(tmp_path)
    assert info.value.path == tmp_path / "scene.yaml"


def test_unknown_robot_in_scene(cell_copy: Path, cell_dir: Path) -> None:
    data = _scene_data(cell_dir)
    data["robot"] = "ned9000"
    _write_scene(cell_copy, data)
    with pytest.raises(RobotNotFound, match="ned9000") as info:
        load_cell(cell_copy)
    assert "ned3pro" in info.value.known


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (_edit("grasp.poses", ["grip", "nowhere"]), "grasp.poses"),
        (_edit("allowed_contacts.1.at", ["low2"]), "allowed_contacts[1].at"),
    ],
)
def test_scene_naming_an_unknown_pose(cell_copy: Path, cell_dir: Path, edit: Any,
                                      key: str) -> None:
    data = _scene_data(cell_dir)
    edit(data)
    path = _write_scene(cell_copy, data)
    with pytest.raises(ConfigError, match="unknown pose") as info:
        load_cell(cell_copy)
    assert info.value.path == path and info.value.key == key


def test_vial_too_wide_for_the_gripper(cell_copy: Path, cell_dir: Path) -> None:
    data = _scene_data(cell_dir)
    data["objects"]["vial"]["radius"] = 0.030
    path = _write_scene(cell_copy, data)
    with pytest.raises(ConfigError, match="60.0 mm wide") as info:
        load_cell(cell_copy)
    assert info.value.path == path and info.value.key == "objects.vial"


def test_bad_poses_file_of_a_cell_is_a_pose_error(cell_copy: Path) -> None:
    (cell_copy / "poses.yaml").write_text("poses:\n  grip: [0, 0, 0\n")
    with pytest.raises(PoseError, match="malformed YAML") as info:
        load_cell(cell_copy)
    assert info.value.path == cell_copy / "poses.yaml"


def test_scene_in_code_matches_scene_from_file(cell: Cell) -> None:
    camera = cell.scene.objects["camera"]
    same = SceneObject("camera", Shape("box", (0.040, 0.030, 0.030)),
                       placement([0.050, 0.300, 0.150]))
    np.testing.assert_allclose(same.T_world_object, camera.T_world_object)
    assert same.shape == camera.shape
    moved = camera.placed(placement([0.0, 0.0, 1.0]))
    assert moved.T_world_object[2, 3] == 1.0 and camera.T_world_object[2, 3] == 0.150
    scene = Scene(name="s", robot="ned3pro", objects={"camera": same})
    assert scene.margin == pytest.approx(0.010) and scene.grasp is None
