"""Any robot, faithfully (issue 28): a hand-written URDF arm loads and plans with or
without a robot folder, any robot holds an object through a tool of its own, velocity
limits can be given, continuous joints are planned without position limits, and robots that
are not fixed-base arms (floating bases, grippers planned as arm joints) are refused or
locked, saying so.

The arm is ``tests/data/box_arm``: box and cylinder links that overlap at their joints
and a one-finger gripper on a prismatic joint.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

import safepath
from safepath import (
    Cell,
    CollisionChecker,
    ConfigError,
    FrameNotFound,
    Grasp,
    PoseError,
    RobotNotFound,
    Scene,
    SceneObject,
    Shape,
    ToolSpec,
    load_cell,
    load_robot,
    placement,
)
from safepath.cli import main
from safepath.errors import RobotNotSupported
from safepath.model.robot import adjacent_link_pairs

ARM_DIR = Path(__file__).resolve().parent / "data" / "box_arm"
ARM_URDF = ARM_DIR / "arm.urdf"
ARM_ACC = [4.0, 3.0, 3.0, 6.0]
ARM_JOINTS = ("joint1", "joint2", "joint3", "joint4")
# Two arm configurations on either side of a post in front of the arm [rad].
Q_LEFT = np.array([-1.0, 0.5, 0.8, 0.0])
Q_RIGHT = np.array([1.0, 0.5, 0.8, 0.0])


def _post_scene(robot: str) -> Scene:
    return Scene(name="post", robot=robot, objects=[
        SceneObject("post", Shape("box", (0.1, 0.1, 0.6)), placement((0.45, 0.0, 0.3)))])


def _arm_copy(tmp_path: Path, **changes: object) -> Path:
    folder = tmp_path / "box_arm"
    shutil.copytree(ARM_DIR, folder)
    if changes:
        spec = yaml.safe_load((folder / "robot.yaml").read_text())
        spec.update(changes)
        (folder / "robot.yaml").write_text(yaml.safe_dump(spec))
    return folder


# ------------------------------------------------------------------------------------------
# 1. A hand-written URDF arm
# ------------------------------------------------------------------------------------------
def test_adjacent_links_touch_and_are_skipped_by_default() -> None:
    robot = load_robot(ARM_DIR)  # robot.yaml names no allowed_collisions file
    # The links really touch at their joints: checked, they would collide in every pose.
    unskipped = load_robot(ARM_DIR)
    unskipped.allowed_self_pairs = frozenset()
    assert {("base_link", "link1"), ("link1", "link2")} <= set(
        CollisionChecker(unskipped).check(Q_LEFT).collisions)
    assert {("base_link", "link1"), ("link1", "link2"), ("link2", "link3"),
            ("link3", "link4")} <= robot.allowed_self_pairs
    assert ("base_link", "link2") not in robot.allowed_self_pairs
    assert CollisionChecker(robot).check(Q_LEFT).valid


@pytest.mark.parametrize("reference", [ARM_DIR, ARM_URDF])
def test_the_arm_plans_around_a_post_from_its_folder_or_its_urdf_alone(reference: Path
                                                                       ) -> None:
    robot = load_robot(reference, acceleration_limits=None if reference == ARM_DIR
                       else ARM_ACC)
    assert robot.joint_names == ARM_JOINTS
    assert [j.name for j in robot.locked_joints] == ["finger_joint"]  # the gripper
    np.testing.assert_allclose(robot.velocity_limits, [2.0, 1.5, 1.5, 3.0])  # the URDF's
    np.testing.assert_allclose(robot.acceleration_limits, ARM_ACC)
    np.testing.assert_allclose(robot.upper, [2.9, 2.0, 2.5, 3.0])
    assert robot.tcp_frame == "tool0"
    scene = _post_scene(robot.name)
    assert not CollisionChecker(robot, scene).segment_is_valid(Q_LEFT, Q_RIGHT)
    traj = safepath.plan(robot, scene, Q_LEFT, Q_RIGHT)
    np.testing.assert_allclose(traj.q[0], Q_LEFT, atol=1e-12)
    np.testing.assert_allclose(traj.q[-1], Q_RIGHT, atol=1e-12)
    checker = CollisionChecker(robot, scene)
    assert all(checker.is_valid(q) for q in traj.q)


def test_a_urdf_alone_says_what_it_lacks() -> None:
    with pytest.raises(ConfigError) as info:
        load_robot(ARM_URDF)
    assert info.value.key == "acceleration_limits" and info.value.path == ARM_URDF
    assert "acceleration_limits=[" in str(info.value) and "robot.yaml" in str(info.value)
    with pytest.raises(ConfigError) as info:
        load_robot(ARM_URDF, acceleration_limits=[1.0, 2.0])
    assert info.value.key == "acceleration_limits" and "need 4" in str(info.value)
    with pytest.raises(FrameNotFound) as info:
        load_robot(ARM_URDF, acceleration_limits=ARM_ACC, tcp_frame="tool")
    assert info.value.key == "tcp_frame" and "tool0" in str(info.value)


def test_a_folder_with_only_a_urdf_points_to_the_file(tmp_path: Path) -> None:
    shutil.copy2(ARM_URDF, tmp_path / "arm.urdf")
    with pytest.raises(ConfigError, match="give its file") as info:
        load_robot(tmp_path)
    assert info.value.path == tmp_path and "arm.urdf" in str(info.value)


def test_a_link_without_geometry_is_looked_through(tmp_path: Path) -> None:
    # link2 without a shape: link1 and link3 meet through it, as MoveIt counts them.
    text = ARM_URDF.read_text()
    start = text.index('<link name="link2">')
    end = text.index("</link>", start) + len("</link>")
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(text[:start] + '<link name="link2"/>' + text[end:])
    robot = load_robot(urdf, acceleration_limits=ARM_ACC)
    assert ("link1", "link3") in set(adjacent_link_pairs(robot.model, robot.collision_model))


def test_robot_pairs_wires_its_file_into_robot_yaml(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    folder = _arm_copy(tmp_path)
    assert main(["robot-pairs", str(folder), "--samples", "300"]) == 0
    out = capsys.readouterr().out
    assert f"added `allowed_collisions: allowed_collisions.yaml` to {folder / 'robot.yaml'}" \
        in out
    spec = yaml.safe_load((folder / "robot.yaml").read_text())
    assert spec["allowed_collisions"] == "allowed_collisions.yaml"
    assert "A robot folder without allowed_collisions" in (folder / "robot.yaml").read_text()
    written = yaml.safe_load((folder / "allowed_collisions.yaml").read_text())["pairs"]
    never = {tuple(sorted(p["links"])) for p in written if p["reason"] == "never"}
    assert never and never <= load_robot(folder).allowed_self_pairs
    assert not never & load_robot(ARM_DIR).allowed_self_pairs
    # Run again: the file is named already, robot.yaml is left as it is.
    before = (folder / "robot.yaml").read_text()
    assert main(["robot-pairs", str(folder), "--samples", "300"]) == 0
    assert "added" not in capsys.readouterr().out
    assert (folder / "robot.yaml").read_text() == before


def test_robot_pairs_says_how_to_wire_it_or_why_not(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    folder = _arm_copy(tmp_path)
    before = (folder / "robot.yaml").read_text()
    assert main(["robot-pairs", str(folder), "--samples", "100", "--no-wire"]) == 0
    assert "not read yet: add `allowed_collisions: allowed_collisions.yaml`" in \
        capsys.readouterr().out
    assert (folder / "robot.yaml").read_text() == before
    assert main(["robot-pairs", str(folder / "arm.urdf"), "--samples", "100"]) == 2
    assert "not a robot folder" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------
# 2. Holding an object with any robot
# ------------------------------------------------------------------------------------------
PANDA_HAND = ToolSpec(name="Franka Hand", contact_links=(
    "panda_leftfinger", "panda_rightfinger", "panda_hand"), open_width=0.08, closed_width=0.0)
Q_A = np.array([-0.8, 0.3, 0.0, -2.0, 0.0, 2.3, 0.785])
Q_B = np.array([0.8, 0.3, 0.0, -2.0, 0.0, 2.3, 0.785])


def _held_scene(robot: safepath.Robot, *, radius: float = 0.025,
                tool: ToolSpec | None = None) -> Scene:
    """A cylinder held between the Panda's fingers, and a post between poses a and b."""
    T_world_part = np.array(robot.frame_pose(Q_A).homogeneous)
    return Scene(name="held", robot="panda", objects=[
        SceneObject("post", Shape("box", (0.06, 0.06, 0.3)), placement((0.6, 0.0, 0.15))),
        SceneObject("part", Shape("cylinder", (radius, 0.1)), T_world_part, movable=True)],
        grasp=Grasp("part", np.eye(4), poses=("a", "b")), tool=tool)


@pytest.fixture(scope="module")
def panda() -> safepath.Robot:
    return load_robot("panda", locked_joints={"panda_finger_joint1": 0.02})


def test_the_panda_holds_an_object_with_a_tool_given_in_python(panda: safepath.Robot) -> None:
    with pytest.raises(ConfigError, match="no tool to hold 'part'.*ToolSpec") as info:
        Cell(panda, _held_scene(panda), {"a": Q_A, "b": Q_B})
    assert info.value.key == "grasp"
    held = load_robot("panda", locked_joints={"panda_finger_joint1": 0.02}, tool=PANDA_HAND)
    assert held.tool == PANDA_HAND and held.tool.tool_id is None
    scene = _held_scene(held)
    cell = Cell(held, scene, {"a": Q_A, "b": Q_B})
    assert cell.checker(held=True, at="a").check(Q_A).valid
    traj = safepath.plan(held, scene, Q_A, Q_B, held=True)  # around the post, held
    checker = cell.checker(held=True)
    assert all(checker.is_valid(q) for q in traj.q[:: max(1, len(traj.q) // 50)])
    # The held part is checked against the world: a pin inside it (between the fingers,
    # touching no link) is a collision only while the part is held.
    pin_at = held.frame_pose(Q_A).translation
    pinned = Scene(name="pinned", robot="panda", objects=[
        scene.objects["part"].placed(placement((2.0, 2.0, 0.0))),  # on a far shelf
        SceneObject("pin", Shape("sphere", (0.004,)), placement(pin_at))], grasp=scene.grasp)
    assert CollisionChecker(held, pinned).check(Q_A).valid
    report = CollisionChecker(held, pinned, held="part").check(Q_A)
    assert list(report.collisions) == [("part", "pin")]


def test_a_scene_gives_the_tool_and_checks_widths(panda: safepath.Robot) -> None:
    scene = _held_scene(panda, tool=PANDA_HAND)
    cell = Cell(panda, scene, {"a": Q_A, "b": Q_B})
    assert cell.robot.tool == PANDA_HAND and panda.tool is None  # a copy holds it
    assert cell.robot.model is panda.model
    with pytest.raises(ConfigError, match="grips objects between 0.0 and 80.0 mm"):
        Cell(panda, _held_scene(panda, radius=0.05, tool=PANDA_HAND), {"a": Q_A, "b": Q_B})
    # Without widths the tool holds any object (nothing to check it against).
    links_only = ToolSpec(contact_links=PANDA_HAND.contact_links)
    Cell(panda, _held_scene(panda, radius=0.05, tool=links_only), {"a": Q_A, "b": Q_B})
    with pytest.raises(FrameNotFound) as info:
        Cell(panda, _held_scene(panda, tool=ToolSpec(contact_links=("panda_finger",))),
             {"a": Q_A, "b": Q_B})
    assert info.value.key == "tool.contact_links"


def test_scene_yaml_and_robot_yaml_give_a_tool_without_vendor_fields(tmp_path: Path) -> None:
    cell_dir = tmp_path / "cell"
    cell_dir.mkdir()
    (cell_dir / "scene.yaml").write_text(yaml.safe_dump({
        "name": "held", "robot": "panda", "locked_joints": {"panda_finger_joint1": 0.02},
        "tool": {"contact_links": ["panda_leftfinger", "panda_rightfinger"],
                 "open_width": 0.08, "closed_width": 0.0},
        "objects": {"part": {"shape": "cylinder", "radius": 0.02, "length": 0.1,
                             "xyz": [0.5, 0.0, 0.3], "movable": True}},
        "grasp": {"object": "part", "xyz": [0, 0, 0], "poses": ["a"]}}))
    (cell_dir / "poses.yaml").write_text(f"poses:\n  a: {Q_A.tolist()}\n")
    cell = load_cell(cell_dir)
    assert cell.robot.tool == ToolSpec(contact_links=("panda_leftfinger", "panda_rightfinger"),
                                       open_width=0.08, closed_width=0.0)
    text = (cell_dir / "scene.yaml").read_text()
    (cell_dir / "scene.yaml").write_text(text.replace("open_width", "opn_width"))
    with pytest.raises(ConfigError, match="did you mean 'open_width'") as info:
        load_cell(cell_dir)
    assert info.value.path == cell_dir / "scene.yaml" and info.value.key == "tool.opn_width"
    (cell_dir / "scene.yaml").write_text(text.replace("closed_width: 0.0", "name: hand"))
    with pytest.raises(ConfigError, match="both open_width and closed_width") as info:
        load_cell(cell_dir)
    assert info.value.path == cell_dir / "scene.yaml"
    # robot.yaml: only the contact links.
    folder = _arm_copy(tmp_path, tool={"contact_links": ["finger", "link4"]})
    robot = load_robot(folder)
    assert robot.tool == ToolSpec(contact_links=("finger", "link4"))


# ------------------------------------------------------------------------------------------
# 3. Velocity limits
# ------------------------------------------------------------------------------------------
def test_zero_velocity_limits_say_how_to_give_them() -> None:
    with pytest.raises(ConfigError) as info:
        load_robot("double_pendulum")
    assert info.value.key == "velocity_limits"
    assert "velocity_limits=[" in str(info.value) and "joint1" in str(info.value)
    assert info.value.path is not None and info.value.path.suffix == ".urdf"
    robot = load_robot("double_pendulum", velocity_limits=[2.0, 3.0])
    np.testing.assert_allclose(robot.velocity_limits, [2.0, 3.0])
    np.testing.assert_allclose(robot.acceleration_limits, [4.0, 6.0])  # top speed in 0.5 s
    for bad in ([2.0], [2.0, 0.0], [2.0, float("inf")]):
        with pytest.raises(ConfigError) as info:
            load_robot("double_pendulum", velocity_limits=bad)
        assert info.value.key == "velocity_limits"


def test_velocity_override_of_a_folder_robot() -> None:
    robot = load_robot(ARM_DIR, velocity_limits=[1.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(robot.velocity_limits, 1.0)
    with pytest.raises(ConfigError, match="need 4") as info:
        load_robot(ARM_DIR, velocity_limits=[1.0, -1.0, 1.0, 1.0])
    assert info.value.key == "velocity_limits"


# ------------------------------------------------------------------------------------------
# 4. Continuous joints are planned (without position limits), never refused or dropped
# ------------------------------------------------------------------------------------------
def test_the_jaco_with_continuous_joints_loads() -> None:
    robot = load_robot("kinova")  # formerly RobotNotSupported (tests/test_continuous_joints.py)
    assert robot.dof == 6 and sum(robot.continuous) == 3


@pytest.mark.parametrize("axis", ["0 0 1", "0 0.6 0.8"], ids=["aligned", "unaligned"])
def test_a_continuous_joint_of_an_own_arm_loads(tmp_path: Path, axis: str) -> None:
    """A URDF ``continuous`` joint (no ``lower``/``upper``; about a frame axis or any
    other) loads from the URDF alone and from a robot folder: the same arm, its joint4
    without position limits, the same placements at every angle as the revolute joint
    it was."""
    revolute = ARM_URDF.read_text().replace('<origin xyz="0 0 0.28"/><axis xyz="0 0 1"/>',
                                            f'<origin xyz="0 0 0.28"/><axis xyz="{axis}"/>')
    text = revolute.replace(
        '<joint name="joint4" type="revolute">', '<joint name="joint4" type="continuous">'
    ).replace('<limit lower="-3.0" upper="3.0" velocity="3.0" effort="5"/>\n  </joint>\n'
              '  <link name="link4">', '<limit velocity="3.0" effort="5"/>\n  </joint>\n'
              '  <link name="link4">')
    assert text.count('<limit velocity="3.0" effort="5"/>') == 1 and text.count(axis) >= 1
    (tmp_path / "bounded.urdf").write_text(revolute)
    (tmp_path / "arm.urdf").write_text(text)
    folder = _arm_copy(tmp_path)
    (folder / "arm.urdf").write_text(text)
    bounded = load_robot(tmp_path / "bounded.urdf", acceleration_limits=ARM_ACC)
    for robot in (load_robot(tmp_path / "arm.urdf", acceleration_limits=ARM_ACC),
                  load_robot(folder)):
        assert robot.joint_names == ARM_JOINTS
        assert robot.continuous == (False, False, False, True)
        assert robot.lower[3] == -np.inf and robot.upper[3] == np.inf
        assert robot.velocity_limits[3] == 3.0
        for q4 in (-2.0, 2.5, 2.5 + 2 * np.pi, -9.0):
            q = np.array([0.3, 0.4, 0.5, q4])
            assert robot.limit_violation(q) is None
            np.testing.assert_allclose(
                robot.frame_pose(q).homogeneous,
                bounded.frame_pose(np.array([0.3, 0.4, 0.5, math.remainder(q4, 2 * np.pi)])
                                   ).homogeneous, atol=1e-12)


# ------------------------------------------------------------------------------------------
# 5. Grippers, floating bases, Pinocchio's errors
# ------------------------------------------------------------------------------------------
def test_the_z1_gripper_is_locked_not_planned() -> None:
    z1 = load_robot("z1")
    assert z1.dof == 6 and "jointGripper" not in z1.joint_names
    assert [j.name for j in z1.locked_joints] == ["jointGripper"]
    assert "locked=['jointGripper']" in repr(z1)
    assert z1.tcp_frame not in ("gripperMover",)  # not a link the gripper moves
    z1_open = load_robot("z1", locked_joints={"jointGripper": -0.5})
    assert z1_open.locked_joints[0].value == -0.5


@pytest.mark.parametrize("name", ["anymal", "so100"])
def test_floating_base_robots_are_refused(name: str) -> None:
    with pytest.raises(RobotNotSupported) as info:
        load_robot(name)
    assert info.value.joints == ["root_joint"] and "floating base" in str(info.value)
    assert "load_robot('" in str(info.value)  # how to load its URDF as a fixed-base arm


def test_pinocchio_errors_are_wrapped() -> None:
    with pytest.raises(RobotNotSupported):
        load_robot("so100")
    from example_robot_data.robots_loader import ROBOTS

    urdf = Path(ROBOTS["so100"]().df_path).resolve()
    # Its gripper joint and link share a name, which Pinocchio cannot lock: a ConfigError.
    with pytest.raises(ConfigError, match="Pinocchio cannot lock") as info:
        load_robot(urdf, acceleration_limits=[1.0] * 5)
    assert info.value.path == urdf


# ------------------------------------------------------------------------------------------
# Confusing points
# ------------------------------------------------------------------------------------------
def test_a_missing_poses_file_is_named(tmp_path: Path) -> None:
    folder = tmp_path / "cell"
    folder.mkdir()
    (folder / "scene.yaml").write_text(yaml.safe_dump({
        "name": "c", "robot": "ur5", "objects": {"table": {
            "shape": "box", "size": [1, 1, 0.04], "xyz": [0.3, 0, -0.02]}}}))
    (folder / "routes.yaml").write_text("routes:\n  r: {start: a, steps: [move: b]}\n")
    cell = load_cell(folder)
    for call in (lambda: cell.pose("a"), cell.route_table):
        with pytest.raises(PoseError, match="file not found") as info:
            call()
        assert info.value.path == folder / "poses.yaml"


def test_a_cell_refuses_another_robot_than_its_scenes() -> None:
    ur5 = load_robot("ur5")
    with pytest.raises(ConfigError, match="includes robot 'panda'.*'ur5'") as info:
        Cell(ur5, Scene(name="s", robot="panda", objects=[]), {})
    assert info.value.key == "robot"
    Cell(ur5, Scene(name="s", robot="ur5", objects=[]), {})
    arm = load_robot(ARM_DIR)
    for name in ("box_arm", str(ARM_DIR), "../box_arm"):
        Cell(arm, Scene(name="s", robot=name, objects=[]), {})


def test_a_robot_name_in_another_case_gets_the_right_one() -> None:
    with pytest.raises(RobotNotFound, match="did you mean 'ur5'"):
        load_robot("UR5")


def test_a_bare_urdf_robot_with_a_tool_travels_to_a_worker() -> None:
    import pickle

    tool = ToolSpec(contact_links=("finger", "link4"))
    robot = load_robot(ARM_URDF, acceleration_limits=ARM_ACC, velocity_limits=[1, 1, 1, 1],
                       tool=tool)
    again = pickle.loads(pickle.dumps(robot))  # loaded again from its URDF
    assert again.joint_names == robot.joint_names and again.tool == tool
    np.testing.assert_allclose(again.acceleration_limits, ARM_ACC)
    np.testing.assert_allclose(again.velocity_limits, 1.0)
    assert again.model is not robot.model


def test_plan_applies_the_allowed_contacts_of_the_poses_it_is_told(cell: safepath.Cell
                                                                   ) -> None:
    """plan() between two configurations takes no pose's allowed contacts unless told
    which taught poses they are: down to the plate with the vial held, the vial touches
    the plate at low1 (allowed there) and the line is refused without goal_pose, planned
    and verified with it; a pose the scene never names is refused with a did-you-mean."""
    robot, scene = cell.robot, cell.scene
    high1, low1 = cell.pose("high1"), cell.pose("low1")
    with pytest.raises(safepath.PlanningError, match="vial / test_plate"):
        safepath.plan(robot, scene, high1, low1, kind="line", held=True)
    traj = safepath.plan(robot, scene, high1, low1, kind="line", held=True,
                         start_pose="high1", goal_pose="low1")
    np.testing.assert_allclose(traj.q[-1], low1, atol=1e-9)
    assert traj.info["clearance_bound"] >= 0.0
    with pytest.raises(safepath.ConfigError, match="did you mean 'low1'") as info:
        safepath.plan(robot, scene, high1, low1, goal_pose="lowl")
    assert info.value.key == "goal_pose"
