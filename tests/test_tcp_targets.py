"""Cartesian targets (position + quaternion x, y, z, w) in poses.yaml and routes.yaml."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from safepath import ConfigError, load_cell, load_robot
from safepath.cell import load_routes
from safepath.cell.tcp_targets import CartesianTarget, quaternion_matrix

REPO_ROOT = Path(__file__).resolve().parents[1]
POURING = REPO_ROOT / "scenes" / "pouring_cell"


@pytest.fixture()
def pouring_copy(tmp_path: Path) -> Path:
    target = tmp_path / "pouring_cell"
    shutil.copytree(POURING, target)
    return target


def test_quaternions_are_x_y_z_w() -> None:
    # 90 deg about y, written (x, y, z, w) as ROS does: x -> -z, z -> x.
    R = quaternion_matrix([0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)])
    np.testing.assert_allclose(R, pin.utils.rotate("y", math.pi / 2), atol=1e-12)
    q = pin.Quaternion(pin.utils.rotate("z", 0.3) @ pin.utils.rotate("x", -1.1))
    np.testing.assert_allclose(quaternion_matrix([q.x, q.y, q.z, q.w]), q.matrix(), atol=1e-12)


@pytest.mark.parametrize("quat", [[0.5, 0.5, 0.5, 0.9], [0.0, 0.0, 0.0, 0.0],
                                  [float("nan"), 0.0, 0.0, 1.0], [0.0, 1.0, 0.0],
                                  [0.0, 2.0, 0.0, 0.0]])
def test_bad_quaternions_are_refused_not_normalised(quat: list[float]) -> None:
    with pytest.raises(ConfigError):
        quaternion_matrix(quat)
    with pytest.raises(ConfigError):
        CartesianTarget((0.4, 0.0, 0.2), tuple(quat))  # type: ignore[arg-type]


def test_the_seeds_non_unit_quaternion_in_poses_names_file_and_key(pouring_copy: Path
                                                                     ) -> None:
    poses = pouring_copy / "poses.yaml"
    data = yaml.safe_load(poses.read_text())
    data["poses"]["above_cup"]["orientation"] = [0.5, 0.5, 0.5, 0.9]
    poses.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(ConfigError) as info:
        load_cell(pouring_copy)
    assert info.value.path == poses
    assert info.value.key == "poses.above_cup.orientation"
    assert "norm 1.2490" in info.value.reason and "not normalise" in info.value.reason


def test_a_nan_quaternion_in_routes_names_file_and_key(pouring_copy: Path) -> None:
    routes = pouring_copy / "routes.yaml"
    data = yaml.safe_load(routes.read_text())
    data["routes"]["place_cup"]["steps"][1]["line"]["orientation"] = [0.5, float("nan"),
                                                                      0.5, 0.5]
    routes.write_text(yaml.safe_dump(data, sort_keys=False))
    cell = load_cell(pouring_copy)
    with pytest.raises(ConfigError) as info:
        load_routes(routes, poses=list(cell.poses), objects=list(cell.scene.objects))
    assert info.value.path == routes
    assert info.value.key == "routes.place_cup.steps[1].line.orientation"


def test_tcp_poses_are_solved_where_they_are_written() -> None:
    cell = load_cell(POURING)
    raw = yaml.safe_load((POURING / "poses.yaml").read_text())["poses"]
    solved = [name for name, v in raw.items() if isinstance(v, dict)]
    assert solved == ["above_cup", "grasp_cup", "above_bowl"]
    for name in solved:
        T = cell.robot.frame_pose(cell.pose(name))
        np.testing.assert_allclose(T.translation, raw[name]["position"], atol=2e-5)
        R = quaternion_matrix(raw[name]["orientation"])
        assert np.linalg.norm(pin.log3(R.T @ T.rotation)) < 2e-4
    # The brief's upright end_effector_link quaternion names the same TCP orientation.
    ee = CartesianTarget((0.27, -0.2, 0.21), (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)),
                         "end_effector_link")
    T = ee.tcp_pose(cell.robot)
    np.testing.assert_allclose(T.rotation, quaternion_matrix([0.5, 0.5, 0.5, 0.5]),
                               atol=1e-9)
    np.testing.assert_allclose(T.translation, [0.40, -0.2, 0.21], atol=1e-9)


def test_a_frame_that_does_not_move_with_the_tcp_is_refused() -> None:
    robot = load_robot("gen3_lite")
    target = CartesianTarget((0.3, 0.0, 0.3), (0.5, 0.5, 0.5, 0.5), "forearm_link")
    with pytest.raises(ConfigError, match="rigidly"):
        target.tcp_pose(robot)
