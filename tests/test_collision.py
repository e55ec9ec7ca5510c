"""Collision checking of the bundled cell: taught poses, contacts, self-collision, segments."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from safepath import (
    Cell,
    CheckOptions,
    CollisionChecker,
    ConfigError,
    PoseError,
    Robot,
    Scene,
    SceneObject,
    Shape,
    check_poses,
    load_cell,
    placement,
)
from safepath.kinematics import solve_ik

GRIPPER_LINKS = {"mors_1", "mors_2", "base_gripper_1", "hand_link"}
# Shoulder pitched forward, elbow folded down: the gripper comes back onto the base.
FOLDED = np.array([0.0, -1.55, -0.71, 0.0, -1.5, 0.0])


def _random_states(robot: Robot, n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(robot.lower, robot.upper, size=(n, robot.dof))


# ------------------------------------------------------------------------------------------
# 1. Every taught pose is valid, empty and holding the vial, and keeps the margin
# ------------------------------------------------------------------------------------------
def test_every_taught_pose_is_valid_and_keeps_the_margin(cell: Cell) -> None:
    rows = check_poses(cell)
    assert [(r.pose, r.held) for r in rows] == [
        (name, held) for name in cell.poses for held in (False, True)]
    for row in rows:
        rep = row.report
        assert rep.within_limits and rep.limit_violation is None, row
        assert rep.collisions == (), row
        assert rep.valid and rep.margin_ok, row
        assert rep.clearance >= 0.010, (row.pose, row.held, rep.clearance, rep.closest_pair)
        np.testing.assert_array_equal(rep.q, cell.pose(row.pose))
        # The fast path agrees, even when the margin is enforced as a hard limit.
        checker = cell.checker(held=row.held, at=row.pose,
                               options=CheckOptions(enforce_margin=True))
        assert checker.is_valid(cell.pose(row.pose)), row


@pytest.mark.parametrize("pose", ["grip", "low1", "safe", "unsafe"])
def test_empty_gripper_where_the_vial_was_released(cell: Cell, pose: str) -> None:
    # After "open" the vial stays where the gripper held it, straddled by the open jaws.
    assert cell.scene.grasp is not None
    T_world_vial = cell.robot.frame_pose(cell.pose(pose)).homogeneous @ \
        cell.scene.grasp.T_tcp_object
    checker = CollisionChecker(cell.robot, cell.scene, resting={"vial": T_world_vial},
                               allowed=cell.scene.contacts_at(pose))
    rep = checker.check(cell.pose(pose))
    assert rep.valid and rep.margin_ok, (rep.collisions, rep.margin_violations)
    # Without the contact allowances the jaws are in the vial: the allowance is needed.
    strict = CollisionChecker(cell.robot, cell.scene, resting={"vial": T_world_vial})
    assert {p for p in strict.collisions(cell.pose(pose)) if "vial" in p}


def test_margin_is_reported_and_can_be_enforced(cell: Cell) -> None:
    q = cell.pose("low1")
    base = cell.checker(at="low1").check(q)
    d, pair = base.clearance, base.closest_pair
    assert pair is not None and 0.010 < d < 0.1
    assert cell.checker(at="low1").clearance(q) == (pytest.approx(d), pair)
    wide = cell.checker(at="low1", options=CheckOptions(margin=d + 0.002)).check(q)
    assert wide.valid and not wide.margin_ok
    assert wide.margin_violations[0][0] == pair
    assert wide.margin_violations[0][1] == pytest.approx(d)
    assert wide.margin_violations[0][2] == pytest.approx(d + 0.002)
    # Enforced, the margin becomes a collision at d + 2 mm and not at d - 2 mm: the
    # distance query and the collision query (with security margin) agree.
    hard = cell.checker(at="low1", options=CheckOptions(margin=d + 0.002, enforce_margin=True))
    assert not hard.is_valid(q)
    assert pair in hard.check(q).collisions
    soft = cell.checker(at="low1", options=CheckOptions(margin=d - 0.002, enforce_margin=True))
    assert soft.is_valid(q) and soft.check(q).valid


def test_per_object_margin_overrides_the_scene_default(cell: Cell) -> None:
    q = cell.pose("low1")
    d, pair = cell.checker(at="low1").clearance(q)
    assert pair == ("mors_2", "camera")
    for camera_margin, ok in ((d - 0.001, True), (d + 0.001, False)):
        camera = dataclasses.replace(cell.scene.objects["camera"], margin=camera_margin)
        # Default margin 0: only the camera's own margin can be violated.
        scene = dataclasses.replace(cell.scene, margin=0.0,
                                    objects={**cell.scene.objects, "camera": camera})
        rep = CollisionChecker(cell.robot, scene, allowed=scene.contacts_at("low1")).check(q)
        assert rep.valid and rep.margin_ok == ok
        if not ok:
            assert [(p, m) for p, _, m in rep.margin_violations] == [(pair, camera_margin)]


# ------------------------------------------------------------------------------------------
# 2. A pose pushed into the conveyor names the right pair
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("down", [0.06, 0.07, 0.08])
def test_tcp_pushed_into_the_conveyor(cell: Cell, robot: Robot, down: float) -> None:
    q_grip = cell.pose("grip")
    T = robot.frame_pose(q_grip)
    target = pin.SE3(T.rotation, T.translation - np.array([0.0, 0.0, down]))
    q = solve_ik(robot, target, q_grip)
    assert q is not None
    np.testing.assert_allclose(robot.tcp_position(q), target.translation, atol=1e-4)
    assert robot.within_limits(q)
    for checker in (cell.checker(at="grip"), cell.checker(held=True, at="grip"),
                    CollisionChecker(robot, cell.scene, resting={"vial": None})):
        assert not checker.is_valid(q)
        rep = checker.check(q)
        assert not rep.valid and rep.within_limits
        hits = {a for a, b in rep.collisions if b == "qc_conveyor"}
        assert hits & GRIPPER_LINKS, rep.collisions
        assert rep.clearance < 0
    # With the vial removed, the conveyor is the only thing hit.
    alone = CollisionChecker(robot, cell.scene, resting={"vial": None}).check(q)
    assert {b for _, b in alone.collisions} == {"qc_conveyor"}


def test_joint_move_into_the_conveyor(cell: Cell) -> None:
    # Tilting the shoulder forward from grip drives the gripper down into the belt (the
    # jaw tips are ~29 mm above the TCP: see robots/ned3pro/README.md).
    q = cell.pose("grip").copy()
    q[1] -= 0.35
    rep = CollisionChecker(cell.robot, cell.scene, resting={"vial": None}).check(q)
    assert rep.within_limits
    assert any(a in GRIPPER_LINKS and b == "qc_conveyor" for a, b in rep.collisions)


def test_allowed_contact_depth_is_limited(cell: Cell, robot: Robot) -> None:
    # Holding the vial at grip it stands on the belt (allowed up to 1 mm deep) ...
    checker = cell.checker(held=True, at="grip")
    q_grip = cell.pose("grip")
    assert checker.is_valid(q_grip)
    T = robot.frame_pose(q_grip)

    def lowered(dz: float) -> np.ndarray:
        q = solve_ik(robot, pin.SE3(T.rotation, T.translation - [0.0, 0.0, dz]), q_grip)
        assert q is not None
        return q

    assert checker.is_valid(lowered(0.0005))
    # ... but pushed 3 mm into it, the vial/belt contact is a collision again.
    rep = checker.check(lowered(0.003))
    assert ("vial", "qc_conveyor") in rep.collisions
    # The allowance is tied to its pose: at high1 nothing is allowed.
    assert cell.checker(held=True, at="high1").check(lowered(0.003)).collisions


# ------------------------------------------------------------------------------------------
# 3. Self-collision of a folded arm
# ------------------------------------------------------------------------------------------
def test_folded_arm_self_collision(cell: Cell, robot: Robot) -> None:
    assert robot.within_limits(FOLDED)
    links = set(robot.link_names)
    for checker in (CollisionChecker(robot, None), cell.checker()):
        assert not checker.is_valid(FOLDED)
        rep = checker.check(FOLDED)
        assert not rep.valid and rep.within_limits
        self_pairs = [(a, b) for a, b in rep.collisions if a in links and b in links]
        assert self_pairs
        assert any({a, b} & GRIPPER_LINKS and {a, b} & {"base_link", "shoulder_link"}
                   for a, b in self_pairs), rep.collisions
    only_self = CollisionChecker(robot, None)
    assert all(a in links and b in links for a, b in only_self.check(FOLDED).collisions)
    assert only_self.clearance(FOLDED) == (float("inf"), None)
    # Upright is free.
    assert only_self.is_valid(np.zeros(6))


def test_self_pairs_skip_adjacent_and_allowed_links(cell: Cell, robot: Robot) -> None:
    checker = cell.checker()
    links = set(robot.link_names)
    statics = {o.name for o in cell.scene.objects.values()}
    for a, b in checker.pairs:
        assert not (a in statics and b in statics)  # two fixed objects are never checked
        if a in links and b in links:
            assert a != b
            assert tuple(sorted((a, b))) not in robot.allowed_self_pairs
    assert ("base_link", "table") not in checker.pairs  # both fixed to the world


def test_held_vial_pairs(cell: Cell, robot: Robot) -> None:
    assert robot.tool is not None
    held = cell.checker(held=True)
    vial_pairs = [p for p in held.pairs if "vial" in p]
    partners = {a if b == "vial" else b for a, b in vial_pairs}
    assert not partners & set(robot.tool.contact_links)  # the jaws hold it
    assert {"forearm_link", "qc_conveyor", "test_plate", "base_link"} <= partners
    # The resting vial can be removed from the world.
    assert not [p for p in CollisionChecker(robot, cell.scene, resting={"vial": None}).pairs
                if "vial" in p]


# ------------------------------------------------------------------------------------------
# The fast path answers like the pair-by-pair loop
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("held", [False, True])
@pytest.mark.parametrize("enforce", [False, True])
def test_is_valid_agrees_with_the_full_report(cell: Cell, robot: Robot, held: bool,
                                              enforce: bool) -> None:
    checker = cell.checker(held=held, options=CheckOptions(enforce_margin=enforce))
    rng = np.random.default_rng(1)
    poses = np.array(list(cell.poses.values()))
    near = poses[rng.integers(len(poses), size=150)] + rng.normal(0, 0.15, size=(150, 6))
    states = np.vstack([_random_states(robot, 250, seed=2), np.clip(near, robot.lower,
                                                                    robot.upper)])
    verdicts = []
    for q in states:
        fast = checker.is_valid(q)
        assert fast == checker.check(q).valid, q
        assert fast == (robot.within_limits(q) and not checker.collisions(q)), q
        verdicts.append(fast)
    assert 0.1 < np.mean(verdicts) < 0.95  # both answers occur


def test_clearance_is_the_smallest_distance(cell: Cell, robot: Robot) -> None:
    checker = cell.checker(held=True)
    environment = set(cell.scene.objects) - {"vial"}  # the held vial moves with the robot
    for q in _random_states(robot, 20, seed=3):
        dists = checker.distances(q)
        assert len(dists) > 0
        d, pair = checker.clearance(q)
        assert d == pytest.approx(min(x for _, x in dists), abs=1e-6)
        rep = checker.check(q)
        assert rep.clearance == pytest.approx(d, abs=1e-6) and rep.closest_pair == pair
        env_hits = [p for p in rep.collisions if p[1] in environment]
        assert bool(env_hits) == (d <= 0.0), (d, env_hits)


def test_clearance_is_coal_solved_to_the_nanometre(repo_root: Path) -> None:
    """The reported clearance is the true distance of its pair, to a nanometre: coal's
    default GJK tolerance (1e-6, relative) reported cylinder-box distances of the Gen3 Lite
    up to 12 um too far (13.003678 mm for 13.003666 mm in the pouring twin)."""
    pour = load_cell(repo_root / "scenes" / "pouring_cell")
    checker = pour.checker()
    model, geometry = pour.robot.model, checker.geometry_model
    data, gdata = model.createData(), pin.GeometryData(geometry)
    tight = coal.DistanceRequest()
    tight.gjk_tolerance, tight.gjk_max_iterations = 1e-13, 1000
    worst = 0.0
    for q in _random_states(pour.robot, 40, seed=11):
        d, pair = checker.clearance(q)
        if pair is None or d <= 1e-3:
            continue
        pin.updateGeometryPlacements(model, data, geometry, gdata, q)
        objects = geometry.geometryObjects
        exact = min(coal.distance(objects[p.first].geometry, coal.Transform3s(gdata.oMg[p.first]),
                                  objects[p.second].geometry, coal.Transform3s(gdata.oMg[p.second]),
                                  tight, coal.DistanceResult())
                    for p, names in zip(geometry.collisionPairs, checker.pairs, strict=True)
                    if names == pair)
        worst = max(worst, abs(d - exact))
    assert 0.0 <= worst <= 1e-8, worst


def test_bad_inputs_to_the_checker(cell: Cell, robot: Robot) -> None:
    checker = cell.checker()
    with pytest.raises(PoseError, match="expected 6"):
        checker.check(np.zeros(5))
    with pytest.raises(PoseError, match="not finite"):
        checker.check([0.0, 0.0, np.nan, 0.0, 0.0, 0.0])
    out = np.zeros(6)
    out[1] = 1.0  # joint_2 above its 0.44 rad limit
    rep = checker.check(out)
    assert not rep.within_limits and not rep.valid and "joint_2" in (rep.limit_violation or "")
    assert not checker.is_valid(out)
    with pytest.raises(ConfigError, match="grasp"):
        CollisionChecker(robot, None, held="vial")
    with pytest.raises(ConfigError, match="resolution"):
        CheckOptions(resolution=0.0)
    with pytest.raises(ConfigError, match="margin"):
        CheckOptions(margin=-0.001)
    with pytest.raises(dataclasses.FrozenInstanceError):
        CheckOptions().resolution = 1.0  # type: ignore[misc]


def test_clone_changes_the_world_state(cell: Cell) -> None:
    empty = cell.checker()
    held = empty.clone(held="vial")
    assert held.held == "vial" and empty.held is None
    assert len([p for p in held.pairs if "vial" in p]) != \
        len([p for p in empty.pairs if "vial" in p])


# ------------------------------------------------------------------------------------------
# 4. Segments: a thin plate between two valid poses, and the resolution guarantee
# ------------------------------------------------------------------------------------------
def _plate_across_path(robot: Robot, q0: np.ndarray, q1: np.ndarray, s: float, *,
                       up: float = 0.03, height: float = 0.06) -> SceneObject:
    """A 3 mm plate across the TCP's path at fraction ``s`` of the joint segment."""
    dq = q1 - q0
    tangent = robot.tcp_position(q0 + (s + 0.01) * dq) - robot.tcp_position(q0 + (s - 0.01) * dq)
    yaw = float(np.arctan2(tangent[1], tangent[0]))  # plate normal along the path
    centre = robot.tcp_position(q0 + s * dq) + np.array([0.0, 0.0, up])
    return SceneObject("plate", Shape("box", (0.003, 0.05, height)), placement(centre, (0, 0, yaw)))


@pytest.mark.parametrize("s", [0.23, 0.37, 0.5, 0.61, 0.78])
def test_segment_catches_a_thin_plate(cell: Cell, robot: Robot, s: float) -> None:
    q0, q1 = cell.pose("high1"), cell.pose("high2")
    scene = Scene(name="plate", robot="ned3pro",
                  objects={"plate": _plate_across_path(robot, q0, q1, s)})
    checker = CollisionChecker(robot, scene)
    # Both ends are valid: checking only the end states would miss the plate ...
    assert checker.is_valid(q0) and checker.is_valid(q1)
    ends_only = CollisionChecker(robot, scene, options=CheckOptions(resolution=100.0))
    assert ends_only.segment_states(q0, q1) == 1
    assert ends_only.check_segment(q0, q1).valid
    # ... the segment check does not.
    rep = checker.check_segment(q0, q1)
    assert not rep.valid
    assert rep.collisions and all(b == "plate" for _, b in rep.collisions)
    assert {a for a, _ in rep.collisions} <= GRIPPER_LINKS
    assert rep.fraction is not None and abs(rep.fraction - s) < 0.08
    assert rep.q is not None and "plate" in {b for _, b in checker.collisions(rep.q)}
    np.testing.assert_allclose(rep.q, q0 + rep.fraction * (q1 - q0))
    assert not checker.segment_is_valid(q0, q1)
    assert not checker.check_path([q0, q1]).valid
    assert not checker.check_segment(q1, q0).valid  # either direction


def test_segment_sweeps_the_held_vial(cell: Cell, robot: Robot) -> None:
    # A plate low enough to pass under the jaws, but not under the vial they hold.
    q0, q1 = cell.pose("high1"), cell.pose("high2")
    plate = _plate_across_path(robot, q0, q1, 0.5, up=-0.02, height=0.015)
    scene = dataclasses.replace(cell.scene, objects={**cell.scene.objects, "plate": plate})
    empty = CollisionChecker(robot, scene)
    held = CollisionChecker(robot, scene, held="vial")
    assert empty.check_segment(q0, q1).valid
    assert held.is_valid(q0) and held.is_valid(q1)
    rep = held.check_segment(q0, q1)
    assert not rep.valid and rep.collisions == (("vial", "plate"),)


def test_segment_states_and_counts(cell: Cell) -> None:
    checker = cell.checker(held=True, options=CheckOptions(fast=False))
    q0, q1 = cell.pose("high1"), cell.pose("high2")
    n = checker.segment_states(q0, q1)
    bound = checker.displacement_bound(q0, q1)
    assert bound == pytest.approx(float(checker.displacement_weights @ np.abs(q1 - q0)))
    assert (n - 1) * checker.options.resolution < bound <= n * checker.options.resolution
    rep = checker.check_segment(q0, q1)
    assert rep.valid and rep.checked == n + 1  # every state once, ends included
    assert checker.check_segment(q0, q1, check_ends=False).checked == n - 1
    assert checker.check_segment(q0, q0).checked == 2
    assert checker.segment_states(q0, q0) == 1
    path = checker.check_path([q0, q1, q0])
    assert path.valid and path.checked >= 2 * n


def test_segment_certified_by_clearance_evaluates_few_states(cell: Cell) -> None:
    # The same segment with the sphere layer: open space is certified by clearance, so
    # far fewer states are evaluated than the 2 mm grid has, with the same verdicts.
    fast = cell.checker(held=True)
    exact = cell.checker(held=True, options=CheckOptions(fast=False))
    q0, q1 = cell.pose("high1"), cell.pose("high2")
    n = fast.segment_states(q0, q1)
    rep = fast.check_segment(q0, q1)
    assert rep.valid and 1 <= rep.checked < (n + 1) / 5
    for a, b in [("high1", "high2"), ("grip", "low1"), ("safe", "unsafe"), ("low1", "safe")]:
        qa, qb = cell.pose(a), cell.pose(b)
        assert fast.segment_is_valid(qa, qb) == exact.segment_is_valid(qa, qb), (a, b)


def test_segment_with_an_end_outside_the_limits(cell: Cell, robot: Robot) -> None:
    checker = cell.checker()
    q0 = cell.pose("high1")
    q1 = q0.copy()
    q1[4] = robot.upper[4] + 0.1
    rep = checker.check_segment(q0, q1)
    assert not rep.valid and rep.fraction == 1.0 and "joint_5" in (rep.limit_violation or "")
    rep = checker.check_segment(q1, q0)
    assert not rep.valid and rep.fraction == 0.0


def _bounding_radius(geometry: object) -> float:
    """Radius of a sphere about the geometry's origin that holds it [m] (independent)."""
    if isinstance(geometry, coal.Box):
        return float(np.linalg.norm(geometry.halfSide))
    if isinstance(geometry, coal.Cylinder):
        return float(np.hypot(geometry.radius, geometry.halfLength))
    if isinstance(geometry, coal.Sphere):
        return float(geometry.radius)
    if isinstance(geometry, coal.ConvexBase):
        return float(np.max(np.linalg.norm(np.asarray(geometry.points()), axis=1)))
    raise AssertionError(f"unexpected geometry {type(geometry).__name__}")


@pytest.mark.parametrize("held", [False, True])
def test_resolution_guarantee_with_forward_kinematics(cell: Cell, robot: Robot,
                                                      held: bool) -> None:
    """No point of the robot (or the held vial) moves more than ``resolution`` between
    two consecutive checked states of a segment, measured on the geometry placements."""
    checker = cell.checker(held=held)
    resolution = checker.options.resolution
    model, gmodel = robot.model, checker.geometry_model
    data, gdata = model.createData(), pin.GeometryData(gmodel)
    movers = [k for k, g in enumerate(gmodel.geometryObjects) if g.parentJoint != 0]
    radius = np.array([_bounding_radius(gmodel.geometryObjects[k].geometry) for k in movers])
    assert held == ("vial" in {gmodel.geometryObjects[k].name for k in movers})

    def placements(q: np.ndarray) -> list[pin.SE3]:
        pin.updateGeometryPlacements(model, data, gmodel, gdata, q)
        return [gdata.oMg[k].copy() for k in movers]

    rng = np.random.default_rng(4)
    worst = 0.0
    for i in range(12):
        q0 = rng.uniform(robot.lower, robot.upper)
        if i % 2:  # long random segments and short ones near a state
            q1 = rng.uniform(robot.lower, robot.upper)
        else:
            q1 = np.clip(q0 + rng.normal(0, 0.1, 6), robot.lower, robot.upper)
        n = checker.segment_states(q0, q1)
        states = [q0 + (k / n) * (q1 - q0) for k in range(n + 1)]
        previous = placements(states[0])
        for k in range(1, n + 1):
            current = placements(states[k])
            moves = []
            for j, (a, b) in enumerate(zip(previous, current, strict=True)):
                shift = np.linalg.norm(b.translation - a.translation)
                angle = np.linalg.norm(pin.log3(a.rotation.T @ b.rotation))
                # Any point within the bounding sphere moves at most this far.
                moves.append(shift + angle * radius[j])
            step = max(moves)
            assert step <= checker.displacement_bound(states[k - 1], states[k]) + 1e-9
            assert step <= resolution + 1e-9, (i, k, step)
            worst = max(worst, step)
            previous = current
    # The bound is not absurdly loose either: some step uses a fair share of it.
    assert worst > 0.3 * resolution


def test_check_path_checks_the_last_waypoint(cell: Cell, robot: Robot) -> None:
    # Holding the vial, lower it onto the belt: 1.2 mm deep is beyond the 1 mm allowed.
    checker = cell.checker(held=True, at="grip")
    q_grip = cell.pose("grip")
    T = robot.frame_pose(q_grip)

    def lowered(dz: float) -> np.ndarray:
        q = solve_ik(robot, pin.SE3(T.rotation, T.translation - [0.0, 0.0, dz]), q_grip)
        assert q is not None
        return q

    q_a, q_b, q_c = lowered(-0.06), lowered(-0.03), lowered(0.0012)
    assert checker.is_valid(q_a) and checker.is_valid(q_b)
    assert ("vial", "qc_conveyor") in checker.check(q_c).collisions
    assert not checker.check_segment(q_b, q_c).valid
    assert not checker.check_path([q_b, q_c]).valid
    assert not checker.check_path([q_a, q_b, q_c]).valid


@pytest.mark.parametrize("held", [False, True])
def test_a_few_states_are_judged_one_by_one_as_a_batch_judges_them(
        cell: Cell, robot: Robot, held: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """States the sphere layer leaves to coal: a few go through the broad phase one by
    one, more through a batch pool. Both give the same first collision, where it lies
    and its pairs, and the same count of states checked."""
    from safepath.collision import checker as collision

    checker = cell.checker(held=held)
    states = _random_states(robot, 24, seed=9)
    colliding = [checker.exact_collides(q) for q in states]
    assert any(colliding) and not all(colliding)
    fractions = np.linspace(0.0, 1.0, len(states))
    for start in range(0, len(states), 3):
        batch, where = states[start:], fractions[start:]
        with monkeypatch.context() as patch:
            patch.setattr(collision, "_FEW", len(batch))  # one by one
            few = checker.check_states(batch, where)
            patch.setattr(collision, "_FEW", 0)  # a batch pool
            pooled = checker.check_states(batch, where)
        assert (few.valid, few.checked, few.fraction, few.collisions) == (
            pooled.valid, pooled.checked, pooled.fraction, pooled.collisions)
        first = next((k for k, hit in enumerate(colliding[start:]) if hit), None)
        assert few.checked == (len(batch) if first is None else first + 1)


def test_states_outside_the_limits_or_without_one_fraction_each_are_refused(
        cell: Cell, robot: Robot) -> None:
    """check_states: a state beyond a limit fails before any is checked, where it lies;
    by default the k-th of n states lies at k / (n - 1); fractions must be one per
    state."""
    from safepath import InputError

    checker = cell.checker()
    states = np.vstack([q for q in map(cell.pose, cell.poses) if not checker.exact_collides(q)])
    assert len(states) >= 3
    free = checker.check_states(states)
    assert free.valid and free.checked == len(states)
    beyond = states.copy()
    beyond[2, 0] = robot.upper[0] + 0.01
    report = checker.check_states(beyond)
    assert not report.valid and report.checked == 0 and report.limit_violation
    assert report.fraction == 2 / (len(states) - 1)
    with pytest.raises(InputError, match="fractions"):
        checker.check_states(states, np.zeros(len(states) - 1))
