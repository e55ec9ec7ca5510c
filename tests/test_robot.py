"""Robots: the Ned3 Pro folder, robots by name (UR5, Panda), kinematics, limits, errors."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

import safepath
from safepath import (
    CollisionChecker,
    ConfigError,
    FrameNotFound,
    InputError,
    PoseError,
    Robot,
    RobotNotFound,
    load_robot,
    robot_names,
)

NED_DIR = Path(__file__).resolve().parents[1] / "robots" / "ned3pro"

# TCP (Gripper 1) positions at the taught poses [m], robot base frame, as computed with
# Niryo's reference URDF (numbers from /work/shared/reference/README.md, 1 mm rounding).
REFERENCE_TCP = {
    "grip": (0.205, -0.007, 0.095),
    "high1": (0.256, -0.004, 0.305),
    "high2": (-0.004, 0.244, 0.290),
    "low1": (0.044, 0.229, 0.077),
    "safe": (0.041, 0.424, 0.095),
    "unsafe": (-0.432, 0.101, 0.003),
}


# ------------------------------------------------------------------------------------------
# The Ned3 Pro
# ------------------------------------------------------------------------------------------
def test_ned3pro_facts(robot: Robot) -> None:
    assert robot.name == "ned3pro"
    assert robot.dof == 6
    assert robot.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    assert robot.tcp_frame == "tcp"
    assert np.all(robot.lower < robot.upper)
    # Niryo's MoveIt motor profile (the URDF's velocity values are placeholders).
    np.testing.assert_allclose(robot.velocity_limits, [2.45, 1.047, 1.5, 4.076, 3.357, 5.036])
    np.testing.assert_allclose(robot.acceleration_limits,
                               [4.363, 2.18, 4.363, 29.96, 26.215, 39.323])
    assert robot.tool is not None
    assert robot.tool.tool_id == 11
    assert set(robot.tool.contact_links) == {"mors_1", "mors_2", "base_gripper_1"}
    assert 0 <= robot.tool.closed_width < robot.tool.open_width
    for link in robot.tool.contact_links:
        assert link in robot.link_names


def test_load_by_name_folder_and_yaml_path_agree(robot: Robot) -> None:
    for ref in ("ned3pro", NED_DIR, NED_DIR / "robot.yaml", str(NED_DIR)):
        other = load_robot(ref)
        assert other.joint_names == robot.joint_names
        np.testing.assert_array_equal(other.lower, robot.lower)
        np.testing.assert_array_equal(other.upper, robot.upper)
        assert other.allowed_self_pairs == robot.allowed_self_pairs


def test_acceleration_override() -> None:
    acc = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert load_robot("ned3pro", acceleration_limits=acc).acceleration_limits.tolist() == acc


@pytest.mark.parametrize("acc", [[1.0, 2.0], [1.0, 2.0, 3.0, 4.0, 5.0, -6.0],
                                 [1.0, 2.0, 3.0, 4.0, 5.0, float("nan")]])
def test_bad_acceleration_override(acc: list[float]) -> None:
    with pytest.raises(ConfigError, match="acceleration_limits"):
        load_robot("ned3pro", acceleration_limits=acc)


@pytest.mark.parametrize("pose", sorted(REFERENCE_TCP))
def test_tcp_at_taught_poses_matches_reference(cell, robot: Robot, pose: str) -> None:
    tcp = robot.tcp_position(cell.pose(pose))
    np.testing.assert_allclose(tcp, REFERENCE_TCP[pose], atol=1.0e-3)
    # At the taught poses tool_link +x (Gripper 1's approach axis) points down.
    x_axis = robot.frame_pose(cell.pose(pose), "tool_link").rotation[:, 0]
    assert x_axis[2] < -0.98


def test_tcp_is_0_1135_m_along_tool_link_x(robot: Robot) -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(robot.lower, robot.upper)
        tool = robot.frame_pose(q, "tool_link")
        tcp = robot.frame_pose(q)
        np.testing.assert_allclose(tcp.translation,
                                   tool.translation + 0.1135 * tool.rotation[:, 0], atol=1e-12)
        np.testing.assert_allclose(robot.tcp_position(q), tcp.translation)


def test_frame_pose_matches_finite_differences_of_joint_1(robot: Robot) -> None:
    # joint_1 turns about the world z axis through the base: the TCP moves on a circle.
    q = np.array([0.3, -0.4, 0.2, 0.1, -0.5, 0.2])
    p0 = robot.tcp_position(q)
    dq = np.zeros(6)
    dq[0] = 0.25
    p1 = robot.tcp_position(q + dq)
    rot = pin.rpy.rpyToMatrix(0.0, 0.0, 0.25)
    np.testing.assert_allclose(p1, rot @ p0, atol=1e-12)


@pytest.mark.parametrize("name", ["ned3pro", "gen3_lite", "panda", "kinova"])
def test_tcp_positions_and_speeds_are_pinocchios(name: str, monkeypatch) -> None:
    """The compiled pass over the chain to the TCP gives Pinocchio's TCP positions and
    linear speeds (world frame) of each row, to rounding; so does the fallback for a chain
    the kernel cannot follow (here: made to have none)."""
    robot = safepath.load_robot(name)
    rng = np.random.default_rng(3)
    q_path = rng.uniform(np.maximum(robot.lower, -4.0), np.minimum(robot.upper, 4.0),
                         (25, robot.dof))
    qd_path = rng.normal(0.0, 1.0, (25, robot.dof))
    model, data, fid = robot.model, robot.model.createData(), robot.tcp_frame_id
    world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    want_p, want_v = [], []
    for q, qd in zip(q_path, qd_path, strict=True):
        pin.forwardKinematics(model, data, q, qd)
        want_p.append(pin.updateFramePlacement(model, data, fid).translation.copy())
        want_v.append(np.linalg.norm(pin.getFrameVelocity(model, data, fid, world).linear))
    assert robot.tcp_chain() is not None
    for kernel in (True, False):
        if not kernel:
            monkeypatch.setattr(robot, "tcp_chain", lambda: None)
        got_p, got_v = robot.tcp_positions(q_path), robot.tcp_speeds(q_path, qd_path)
        assert got_p.shape == (25, 3) and got_v.shape == (25,)
        np.testing.assert_allclose(got_p, want_p, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(got_v, want_v, rtol=1e-12, atol=1e-12)
    # And the speed is the positions' rate along a joint motion (finite differences).
    h = 1e-6
    rates = (robot.tcp_positions(q_path + h * qd_path)
             - robot.tcp_positions(q_path - h * qd_path)) / (2 * h)
    np.testing.assert_allclose(np.linalg.norm(rates, axis=1), want_v, rtol=1e-6, atol=1e-8)


def test_unknown_frame_lists_frames(robot: Robot) -> None:
    with pytest.raises(FrameNotFound) as info:
        robot.frame_pose(np.zeros(6), "gripper_tip")
    assert info.value.name == "gripper_tip"
    assert "tcp" in info.value.frames
    assert "did you mean" in str(info.value)  # the closest names, not all 30 frames


def test_limits_and_joint_vector_validation(robot: Robot) -> None:
    q = np.zeros(6)
    assert robot.limit_violation(q) is None
    assert robot.limit_violation(robot.lower.copy()) is None  # limits are inclusive
    assert robot.limit_violation(robot.upper.copy()) is None
    q[2] = robot.upper[2] + 0.01
    msg = robot.limit_violation(q)
    assert msg is not None and "joint_3" in msg
    assert not robot.within_limits(q)
    assert robot.within_limits(q, tol=0.02)

    with pytest.raises(PoseError, match="joint_3") as info:
        robot.as_joint_vector(q, name="crash")
    assert info.value.key == "crash"
    np.testing.assert_array_equal(robot.as_joint_vector(q, check_limits=False), q)
    with pytest.raises(PoseError, match="expected 6 joint values, got 5"):
        robot.as_joint_vector([0.0] * 5)
    with pytest.raises(PoseError, match="joint_2 is not finite"):
        robot.as_joint_vector([0.0, np.nan, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(PoseError, match="not a vector of numbers"):
        robot.as_joint_vector(["a", 0, 0, 0, 0, 0])


def test_allowed_self_pairs_are_link_pairs(robot: Robot) -> None:
    links = set(robot.link_names)
    assert robot.allowed_self_pairs
    for a, b in robot.allowed_self_pairs:
        assert a in links and b in links and a < b
    # Parent/child links are never checked against each other.
    assert ("arm_link", "shoulder_link") in robot.allowed_self_pairs
    # The gripper against the base is a real risk: it must stay checked.
    assert ("base_gripper_1", "base_link") not in robot.allowed_self_pairs


# ------------------------------------------------------------------------------------------
# Robot files: every bad input is a typed error naming file and key
# ------------------------------------------------------------------------------------------
def _robot_folder(tmp_path: Path, **changes: object) -> Path:
    folder = tmp_path / "robot"
    folder.mkdir()
    for name in ("ned3pro.urdf", "allowed_collisions.yaml"):
        shutil.copy2(NED_DIR / name, folder / name)
    spec = yaml.safe_load((NED_DIR / "robot.yaml").read_text())
    for key, value in changes.items():
        if value is None:
            spec.pop(key, None)
        else:
            spec[key] = value
    (folder / "robot.yaml").write_text(yaml.safe_dump(spec))
    return folder


def test_robot_folder_copy_loads(tmp_path: Path) -> None:
    robot = load_robot(_robot_folder(tmp_path))
    assert robot.dof == 6 and robot.allowed_self_pairs == load_robot("ned3pro").allowed_self_pairs


def test_missing_urdf(tmp_path: Path) -> None:
    folder = _robot_folder(tmp_path, urdf="missing.urdf")
    with pytest.raises(ConfigError, match="missing.urdf") as info:
        load_robot(folder)
    assert info.value.path == folder / "robot.yaml"
    assert info.value.key == "urdf"
    assert str(folder / "robot.yaml") in str(info.value)


def test_missing_mesh_names_the_urdf_and_the_mesh(tmp_path: Path) -> None:
    folder = tmp_path / "meshy"
    folder.mkdir()
    (folder / "r.urdf").write_text(
        '<robot name="r"><link name="base"/><link name="l1"><collision><geometry>'
        '<mesh filename="package://nowhere/missing.stl"/></geometry></collision></link>'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint>'
        '<link name="tcp"/><joint name="jt" type="fixed"><parent link="l1"/>'
        '<child link="tcp"/></joint></robot>')
    (folder / "robot.yaml").write_text(yaml.safe_dump({
        "name": "meshy", "urdf": "r.urdf", "joints": ["j1"], "velocity_limits": [1.0],
        "acceleration_limits": [1.0], "tcp_frame": "tcp"}))
    with pytest.raises(ConfigError, match="missing.stl") as info:
        load_robot(folder)
    assert info.value.path == folder / "r.urdf"


@pytest.mark.parametrize(
    ("changes", "key", "error"),
    [
        ({"velocity_limits": [1.0] * 5}, "velocity_limits", ConfigError),
        ({"acceleration_limits": [1.0, 1.0, 1.0, 1.0, 1.0, -1.0]}, "acceleration_limits",
         ConfigError),
        ({"joints": ["joint_1", "joint_2"]}, "joints", ConfigError),
        ({"tcp_frame": "nowhere"}, "tcp_frame", FrameNotFound),
        ({"name": None}, "name", ConfigError),
        ({"tool": {"name": "g", "id": 11, "contact_links": ["claw"], "open_width": 0.03,
                   "closed_width": 0.0}}, "tool.contact_links", FrameNotFound),
        ({"tool": {"name": "g", "id": 11, "contact_links": ["mors_1"], "open_width": -0.03,
                   "closed_width": 0.0}}, "tool.open_width", ConfigError),
    ],
)
def test_bad_robot_yaml(tmp_path: Path, changes: dict, key: str,
                       error: type[InputError]) -> None:
    folder = _robot_folder(tmp_path, **changes)
    with pytest.raises(error) as info:
        load_robot(folder)
    assert info.value.path == folder / "robot.yaml"
    assert info.value.key is not None and info.value.key.startswith(key)


def test_malformed_robot_yaml(tmp_path: Path) -> None:
    folder = _robot_folder(tmp_path)
    (folder / "robot.yaml").write_text("name: ned3pro\njoints: [joint_1, joint_2\n")
    with pytest.raises(ConfigError, match="malformed YAML") as info:
        load_robot(folder)
    assert str(folder / "robot.yaml") in str(info.value)


def test_allowed_collisions_with_unknown_link(tmp_path: Path) -> None:
    folder = _robot_folder(tmp_path)
    (folder / "allowed_collisions.yaml").write_text(
        "pairs:\n  - {links: [arm_link, ghost_link], reason: never}\n")
    with pytest.raises(FrameNotFound) as info:
        load_robot(folder)
    assert info.value.path == folder / "allowed_collisions.yaml"
    assert info.value.key == "pairs[0].links"


def test_unknown_robot_name_lists_known_ones() -> None:
    with pytest.raises(RobotNotFound) as info:
        load_robot("ned9000")
    err = info.value
    assert isinstance(err, InputError)
    assert err.name == "ned9000"
    assert {"ned3pro", "ur5", "panda"} <= set(err.known)
    assert "ned3pro" in str(err)  # the closest name, not the 75 known ones
    assert "panda" not in str(err)
    assert {"ned3pro", "ur5", "panda"} <= set(robot_names())


def test_a_misspelt_robot_gets_the_closest_name() -> None:
    with pytest.raises(RobotNotFound) as info:
        load_robot("ur55")
    assert "did you mean 'ur5'" in str(info.value)
    assert len(str(info.value)) < 120, str(info.value)
    with pytest.raises(RobotNotFound) as info:
        load_robot("zzzz")
    assert "75" in str(info.value) or "known" in str(info.value)
    assert len(str(info.value)) < 300, str(info.value)


def test_folder_without_robot_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no robot.yaml") as info:
        load_robot(tmp_path)
    assert info.value.path == tmp_path


# ------------------------------------------------------------------------------------------
# Robots of example-robot-data, through the same API
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def panda() -> Robot:
    return load_robot("panda")


@pytest.mark.parametrize(("name", "dof"), [("ur5", 6), ("panda", 7)])
def test_robots_by_name(name: str, dof: int) -> None:
    # The Panda's fingers closed: at the home pose below, open fingers touch panda_link5
    # (and so does their whole travel, the default: see tests/test_locked_joints.py).
    robot = load_robot(name, locked_joints={"panda_finger_joint1": 0.0} if name == "panda"
                       else None)
    assert robot.dof == dof == len(robot.joint_names)
    assert robot.source is None
    for arr in (robot.velocity_limits, robot.acceleration_limits):
        assert arr.shape == (dof,) and np.all(np.isfinite(arr)) and np.all(arr > 0)
    assert np.all(robot.lower < robot.upper)
    checker = CollisionChecker(robot)
    assert checker.pairs
    q_home = np.clip(np.zeros(dof), robot.lower, robot.upper)
    assert checker.is_valid(q_home)
    assert checker.check(q_home).valid
    assert checker.segment_is_valid(q_home, q_home + 0.05 * (robot.upper - q_home))


def test_panda_folded_self_collision(panda: Robot) -> None:
    checker = CollisionChecker(panda)
    # Shoulder pitched fully forward, elbow folded: the hand comes back onto link 1.
    q = np.array([0.0, -1.7, 0.0, -3.0, 0.0, 0.0, 0.0])
    assert panda.within_limits(q)
    assert not checker.is_valid(q)
    report = checker.check(q)
    assert not report.valid and report.within_limits
    links = set(panda.link_names)
    assert all(a in links and b in links for a, b in report.collisions)
    assert ("panda_link1", "panda_hand") in report.collisions
    assert checker.clearance(q) == (float("inf"), None)  # no environment


def _hull_halfspaces(convex) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals and offsets of a coal convex hull's triangles (n.x <= d)."""
    points = np.asarray(convex.points())
    centre = points.mean(axis=0)
    normals, offsets = [], []
    for i in range(convex.num_polygons):
        tri = convex.polygons(i)
        a, b, c = (points[tri[k]] for k in range(3))
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-15:
            continue
        n /= norm
        if n @ (centre - a) > 0:
            n = -n
        normals.append(n)
        offsets.append(n @ a)
    return np.array(normals), np.array(offsets)


def test_panda_meshes_are_replaced_by_enclosing_convex_hulls(panda: Robot) -> None:
    import coal

    trimesh = pytest.importorskip("trimesh")
    checked = 0
    for geom in panda.collision_model.geometryObjects:
        if Path(geom.meshPath).suffix.lower() not in (".stl", ".dae", ".obj"):
            continue  # a primitive (the fingers are boxes): nothing to replace
        assert isinstance(geom.geometry, coal.ConvexBase), geom.name
        mesh = trimesh.load(geom.meshPath, force="mesh")
        vertices = np.asarray(mesh.vertices) * np.asarray(geom.meshScale)
        normals, offsets = _hull_halfspaces(geom.geometry)
        size = float(np.ptp(vertices, axis=0).max())
        outside = vertices @ normals.T - offsets
        assert outside.max() <= 1e-6 * size, (geom.name, outside.max())
        # And the hull is tight: its corners are vertices of the mesh.
        hull = np.asarray(geom.geometry.points())
        nearest = np.min(np.linalg.norm(hull[:, None, :] - vertices[None, :, :], axis=2), axis=1)
        assert nearest.max() <= 1e-6 * size, geom.name
        checked += 1
    assert checked >= 8


def test_the_limits_are_one_record_replaced_whole_never_changed_in_place() -> None:
    """Issue 37: a robot's velocity, acceleration and jerk limits are one read-only
    MotionLimits record; assigning an array replaces the record (checked), writing into
    one is refused."""
    robot = safepath.load_robot("ned3pro")
    before = robot.motion_limits
    with pytest.raises(ValueError):
        robot.velocity_limits[0] = 100.0
    with pytest.raises(ValueError):
        robot.motion_limits.jerk[2] = 1.0
    robot.velocity_limits = robot.velocity_limits * 0.5
    assert robot.motion_limits is not before
    np.testing.assert_array_equal(robot.velocity_limits, before.velocity * 0.5)
    np.testing.assert_array_equal(robot.jerk_limits, before.jerk)
    with pytest.raises(safepath.ConfigError) as info:
        robot.acceleration_limits = [1.0, 2.0]
    assert info.value.key == "acceleration_limits"
    with pytest.raises(safepath.ConfigError) as info:
        robot.jerk_limits = np.full(robot.dof, np.nan)
    assert info.value.key == "jerk_limits"
    with pytest.raises(safepath.ConfigError) as info:
        robot.motion_limits = safepath.MotionLimits([1.0], [1.0], [1.0])
    assert info.value.key == "motion_limits"
    robot.motion_limits = before
    assert robot.motion_limits == before
