"""Locked joints (fingers) are the user's to set, and the geometry follows what was set.

Real example-robot-data Panda and the project's Gen3 Lite, real Pinocchio and coal.
"""

from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
import yaml

from safepath import CollisionChecker, ConfigError, Robot, load_cell, load_robot
from safepath.cell import Cell
from safepath.collision.spheres import surface_points

REPO_ROOT = Path(__file__).resolve().parents[1]
GEN3_URDF = REPO_ROOT / "robots" / "gen3_lite" / "gen3_lite.urdf"
FINGERS = ("right_finger_prox_link", "right_finger_dist_link", "left_finger_prox_link",
           "left_finger_dist_link")
MIMICS = {"right_finger_bottom_joint": (1.0, 0.0), "left_finger_bottom_joint": (1.0, 0.0),
          "right_finger_tip_joint": (-0.676, 0.149), "left_finger_tip_joint": (-0.676, 0.149)}


def _full_gen3(opening: float) -> tuple[pin.Model, pin.GeometryModel, np.ndarray]:
    """The Gen3 Lite URDF with every joint movable, fingers at ``opening``."""
    model = pin.buildModelFromUrdf(str(GEN3_URDF))
    geom = pin.buildGeomFromUrdf(model, str(GEN3_URDF), pin.GeometryType.COLLISION)
    q = np.zeros(model.nq)
    for name, (mult, off) in MIMICS.items():
        q[model.joints[model.getJointId(name)].idx_q] = opening * mult + off
    return model, geom, q


def _placements(robot: Robot, q: np.ndarray) -> dict[str, np.ndarray]:
    data = robot.model.createData()
    gdata = robot.collision_model.createData()
    pin.updateGeometryPlacements(robot.model, data, robot.collision_model, gdata, q)
    return {g.name: gdata.oMg[i].homogeneous.copy()
            for i, g in enumerate(robot.collision_model.geometryObjects)}


# ------------------------------------------------------------------------------------------
# The value is an explicit argument, and a wrong one is a typed error
# ------------------------------------------------------------------------------------------
def test_gen3_lite_plans_the_arm_and_locks_the_fingers() -> None:
    robot = load_robot("gen3_lite", locked_joints={"right_finger_bottom_joint": 0.6})
    assert robot.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    values = {j.name: j.value for j in robot.locked_joints}
    assert values == pytest.approx({"left_finger_bottom_joint": 0.6,
                                    "left_finger_tip_joint": -0.676 * 0.6 + 0.149,
                                    "right_finger_bottom_joint": 0.6,
                                    "right_finger_tip_joint": -0.676 * 0.6 + 0.149})
    # Not given: the whole travel, said so.
    assert all(j.value is None for j in load_robot("gen3_lite").locked_joints)
    panda = load_robot("panda", locked_joints={"panda_finger_joint1": 0.04})
    assert panda.dof == 7
    assert {j.name: j.value for j in panda.locked_joints} == {"panda_finger_joint1": 0.04,
                                                             "panda_finger_joint2": 0.04}


@pytest.mark.parametrize(("values", "key", "words"), [
    ({"right_finger_bottom_joint": 0.9}, "locked_joints.right_finger_bottom_joint", "outside"),
    ({"right_finger_bottom_joint": -0.01}, "locked_joints.right_finger_bottom_joint",
     "outside"),
    ({"right_finger_bottom_joint": float("nan")}, "locked_joints.right_finger_bottom_joint",
     "outside"),
    ({"right_finger_bottom_joint": "open"}, "locked_joints.right_finger_bottom_joint",
     "expected a number"),
    ({"left_finger_tip_joint": 0.1}, "locked_joints.left_finger_tip_joint", "mimic"),
    ({"joint_3": 0.1}, "locked_joints.joint_3", "planned"),
    ({"thumb": 0.1}, "locked_joints.thumb", "no joint"),
])
def test_bad_locked_values_are_config_errors(values: dict[str, object], key: str,
                                             words: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_robot("gen3_lite", locked_joints=values)  # type: ignore[arg-type]
    assert info.value.key == key
    assert words in info.value.reason


def test_panda_finger_outside_its_travel_is_an_error() -> None:
    with pytest.raises(ConfigError, match="outside its limits"):
        load_robot("panda", locked_joints={"panda_finger_joint1": 0.05})


def test_a_cell_sets_the_fingers_and_errors_name_its_file(cell_copy: Path) -> None:
    scene = cell_copy / "scene.yaml"
    data = yaml.safe_load(scene.read_text())
    data["robot"] = "gen3_lite"
    data.pop("grasp", None)
    data.pop("allowed_contacts", None)
    data["locked_joints"] = {"right_finger_bottom_joint": 0.3}
    scene.write_text(yaml.safe_dump(data))
    (cell_copy / "poses.yaml").unlink()
    cell = load_cell(cell_copy)
    assert {j.name: j.value for j in cell.robot.locked_joints}[
        "right_finger_bottom_joint"] == 0.3
    data["locked_joints"] = {"right_finger_bottom_joint": 1.2}
    scene.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as info:
        load_cell(cell_copy)
    assert info.value.path == scene
    assert info.value.key == "locked_joints.right_finger_bottom_joint"


# ------------------------------------------------------------------------------------------
# The geometry is where the fingers are, or covers their whole travel
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("opening", [0.0, 0.37, 0.85])
def test_finger_geometry_is_where_the_fingers_are(opening: float) -> None:
    robot = load_robot("gen3_lite", locked_joints={"right_finger_bottom_joint": opening})
    model, geom, q_full = _full_gen3(opening)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(robot.lower, robot.upper)
        for j, name in enumerate(robot.joint_names):
            q_full[model.joints[model.getJointId(name)].idx_q] = q[j]
        data, gdata = model.createData(), geom.createData()
        pin.updateGeometryPlacements(model, data, geom, gdata, q_full)
        truth = {g.name: gdata.oMg[i].homogeneous for i, g in enumerate(geom.geometryObjects)}
        ours = _placements(robot, q)
        assert set(ours) == set(truth)
        for name in truth:
            np.testing.assert_allclose(ours[name], truth[name], atol=1e-9, err_msg=name)


def test_travel_geometry_encloses_the_fingers_at_every_opening() -> None:
    robot = load_robot("gen3_lite")
    model, geom, q_full = _full_gen3(0.0)
    rng = np.random.default_rng(2)
    q = rng.uniform(robot.lower, robot.upper)
    hulls = {n: (g, T) for (n, T), g in zip(_placements(robot, q).items(),
                                            robot.collision_model.geometryObjects,
                                            strict=True)}
    probe = coal.Sphere(1e-9)
    worst = -np.inf
    for opening in np.linspace(0.0, 0.85, 23):
        _, _, q_full = _full_gen3(float(opening))
        for j, name in enumerate(robot.joint_names):
            q_full[model.joints[model.getJointId(name)].idx_q] = q[j]
        data, gdata = model.createData(), geom.createData()
        pin.updateGeometryPlacements(model, data, geom, gdata, q_full)
        for i, g in enumerate(geom.geometryObjects):
            if model.frames[g.parentFrame].name not in FINGERS:
                continue
            hull, T_hull = hulls[g.name]
            assert isinstance(hull.geometry, coal.ConvexBase)
            pts = surface_points(g.geometry, 400, rng)
            T = gdata.oMg[i].homogeneous
            world = pts @ T[:3, :3].T + T[:3, 3]
            local = (world - T_hull[:3, 3]) @ T_hull[:3, :3]
            for p in local[::4]:
                d = coal.distance(hull.geometry, coal.Transform3s(), probe,
                                  coal.Transform3s(np.eye(3), p), coal.DistanceRequest(),
                                  coal.DistanceResult())
                worst = max(worst, d)
    assert worst <= 1e-6, f"a finger point {worst * 1000:.3f} mm outside its travel shape"


@pytest.fixture(scope="module")
def qc_cell() -> Cell:
    return load_cell(REPO_ROOT / "scenes" / "quality_check_cell")


def test_panda_plans_for_closed_fingers_collide_with_open_ones(qc_cell: Cell) -> None:
    """The issue's case: a segment free with the fingers closed is not free once they are
    open; the fingers' whole travel (the default) never calls such a segment free."""
    closed = load_robot("panda", locked_joints={"panda_finger_joint1": 0.0})
    opened = load_robot("panda", locked_joints={"panda_finger_joint1": 0.04})
    travel = load_robot("panda")
    checkers = {k: CollisionChecker(r, qc_cell.scene) for k, r in
                (("closed", closed), ("open", opened), ("travel", travel))}
    rng = np.random.default_rng(3)
    free_closed_hit_open = 0
    for _ in range(4000):
        q0 = rng.uniform(closed.lower, closed.upper)
        q1 = np.clip(q0 + rng.normal(0.0, 0.15, closed.dof), closed.lower, closed.upper)
        ok = {k: c.check_segment(q0, q1).valid for k, c in checkers.items()}
        if ok["closed"] and not ok["open"]:
            free_closed_hit_open += 1
        if ok["travel"]:
            assert ok["open"] and ok["closed"], (q0, q1)
        if free_closed_hit_open >= 3:
            break
    assert free_closed_hit_open >= 3
