"""Robots and scenes are data folders: every one of them is complete and loads."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import yaml

from safepath import load_cell, load_robot, load_routes, robot_names
from safepath.description.robot_folder import ROBOTS_DIR

REPO_ROOT = Path(__file__).resolve().parents[1]
ALL_ROBOT_DIRS = sorted(p for p in (REPO_ROOT / "robots").iterdir() if p.is_dir())
#: Full robot descriptions (URDF, limits, pairs).
ROBOT_DIRS = [p for p in ALL_ROBOT_DIRS if (p / "robot.yaml").exists()]
#: Controller settings for an example-robot-data arm of the folder's name.
CONTROLLER_ONLY_DIRS = [p for p in ALL_ROBOT_DIRS if not (p / "robot.yaml").exists()]
SCENE_DIRS = sorted(p for p in (REPO_ROOT / "scenes").iterdir() if p.is_dir())
REFERENCE = REPO_ROOT.parent / "shared" / "reference"


def test_there_are_data_folders() -> None:
    assert [p.name for p in ROBOT_DIRS] == sorted(p.name for p in ROBOT_DIRS)
    assert "ned3pro" in [p.name for p in ROBOT_DIRS]
    assert "quality_check_cell" in [p.name for p in SCENE_DIRS]
    assert ROBOTS_DIR.resolve() == (REPO_ROOT / "robots").resolve()


@pytest.mark.parametrize("folder", ROBOT_DIRS, ids=lambda p: p.name)
def test_robot_folder_is_complete(folder: Path) -> None:
    for name in ("robot.yaml", "README.md", "LICENSE", "CHANGELOG.md",
                 "allowed_collisions.yaml"):
        assert (folder / name).is_file(), f"{folder.name}/{name} is missing"
        assert (folder / name).stat().st_size > 0, f"{folder.name}/{name} is empty"
    spec = yaml.safe_load((folder / "robot.yaml").read_text())
    assert spec["name"] == folder.name
    assert (folder / spec["urdf"]).is_file(), f"{folder.name}: URDF {spec['urdf']} is missing"
    assert spec.get("allowed_collisions") == "allowed_collisions.yaml"
    readme = (folder / "README.md").read_text()
    assert "Provenance" in readme or "provenance" in readme


@pytest.mark.parametrize("folder", ROBOT_DIRS, ids=lambda p: p.name)
def test_robot_folder_loads_with_its_allowed_collisions(folder: Path) -> None:
    robot = load_robot(folder)
    assert robot.source == folder / "robot.yaml"
    pairs = yaml.safe_load((folder / "allowed_collisions.yaml").read_text())
    assert pairs["robot"] == robot.name
    listed = {tuple(sorted(entry["links"])) for entry in pairs["pairs"]}
    assert {e["reason"] for e in pairs["pairs"]} <= {"adjacent", "never", "always"}
    assert listed == set(robot.allowed_self_pairs)
    # The same robot by name.
    assert load_robot(folder.name).joint_names == robot.joint_names


@pytest.mark.parametrize("folder", SCENE_DIRS, ids=lambda p: p.name)
def test_scene_folder_is_complete_and_loads(folder: Path) -> None:
    for name in ("scene.yaml", "poses.yaml", "README.md"):
        assert (folder / name).is_file(), f"{folder.name}/{name} is missing"
    cell = load_cell(folder)
    assert cell.scene.name == folder.name
    assert cell.poses, "a cell without taught poses"
    assert cell.poses_path == folder / "poses.yaml"
    # The scene includes its robot by name (robots/<name>), never a copy.
    assert not list(folder.glob("*.urdf"))
    assert (ROBOTS_DIR / cell.scene.robot).is_dir() or (folder / cell.scene.robot).is_dir()
    if (folder / "routes.yaml").exists():
        routes = load_routes(folder / "routes.yaml", poses=list(cell.poses),
                             objects=list(cell.scene.objects))
        assert routes
        for route in routes.values():
            assert route.steps


def test_bundled_cell_routes() -> None:
    cell = load_cell(REPO_ROOT / "scenes" / "quality_check_cell")
    routes = load_routes(cell.folder, poses=list(cell.poses), objects=list(cell.scene.objects))
    assert set(routes) == {"phase1", "phase2_safe", "phase2_unsafe"}
    assert routes["phase2_safe"].after == routes["phase2_unsafe"].after == "phase1"


@pytest.mark.parametrize("folder", CONTROLLER_ONLY_DIRS, ids=lambda p: p.name)
def test_controller_only_folder_is_complete_and_loads(folder: Path) -> None:
    for name in ("controller.yaml", "README.md", "LICENSE", "CHANGELOG.md"):
        assert (folder / name).is_file(), f"{folder.name}/{name} is missing"
    assert "Provenance" in (folder / "README.md").read_text()
    assert folder.name in robot_names()
    robot = load_robot(folder.name)
    assert robot.controller.source is not None
    assert robot.controller.source.resolve() == (folder / "controller.yaml").resolve()
    assert robot.controller.joint_names == robot.joint_names
    assert load_robot(folder).controller == robot.controller


def test_every_full_robot_with_a_controller_file_loads_it() -> None:
    for folder in ROBOT_DIRS:
        robot = load_robot(folder)
        if (folder / "controller.yaml").exists():
            assert robot.controller.source == folder / "controller.yaml"
            assert sorted(robot.controller.joint_names) == sorted(robot.joint_names)


def _digests(root: Path) -> dict[str, Path]:
    return {hashlib.sha256(p.read_bytes()).hexdigest(): p
            for p in root.rglob("*") if p.is_file()}


@pytest.mark.skipif(not REFERENCE.is_dir(), reason="no /work/shared/reference next to the repo")
def test_no_reference_file_is_copied_into_the_data_folders() -> None:
    reference = _digests(REFERENCE)
    ours = {**_digests(REPO_ROOT / "robots"), **_digests(REPO_ROOT / "scenes")}
    copied = sorted(str(p.relative_to(REPO_ROOT)) for h, p in ours.items() if h in reference)
    assert copied == []
