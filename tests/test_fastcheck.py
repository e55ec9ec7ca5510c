"""The sphere layer: its spheres enclose the real shapes, and it never contradicts coal.

Enclosure is checked on sampled surface points of every collision shape of the Ned3 Pro,
the Gen3 Lite (fingers over their whole travel), the Panda and the UR5 (example-robot-data
convex hulls included) and of the held vial.
Agreement is checked on random states (uniform in the limits, and close around the
taught poses where the robot is near the cell): a state the layer calls free is free for
coal, and a state it calls colliding collides for coal, with and without margins.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from safepath import CheckOptions, CollisionChecker, load_cell, load_robot
from safepath.cell import Cell
from safepath.collision import COLLIDES, FREE, UNSURE
from safepath.collision.spheres import fit_spheres, surface_points
from safepath.model.robot import Robot

ROBOTS = ["ned3pro", "gen3_lite", "panda", "ur5"]


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_cell("scenes/quality_check_cell")


def _inside_any(points: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Whether each point lies in at least one sphere (64 points at a time: a fit has
    thousands of spheres, and the whole points x spheres array would not stay in cache)."""
    out = np.empty(len(points), dtype=bool)
    for k in range(0, len(points), 64):
        d = np.linalg.norm(points[k:k + 64, None, :] - centers[None, :, :], axis=2)
        out[k:k + 64] = np.any(d <= radii[None, :], axis=1)
    return out


def _assert_enclosed(geometry: object, rng: np.random.Generator, label: str) -> None:
    """Sampled surface points of a shape, and points between them and its centroid (inside
    a convex body), all lie in its outer spheres."""
    fit = fit_spheres(geometry)
    pts = surface_points(geometry, 4000, rng)
    inside = _inside_any(pts, fit.outer_centers, fit.outer_radii)
    assert inside.all(), f"{label}: {np.sum(~inside)} surface points outside"
    c = pts.mean(axis=0)
    inner = c + (pts - c) * rng.random((len(pts), 1))
    assert _inside_any(inner, fit.outer_centers, fit.outer_radii).all(), label


@pytest.mark.parametrize("name", ROBOTS)
def test_outer_spheres_enclose_every_shape(name: str) -> None:
    robot = load_robot(name)
    rng = np.random.default_rng(7)
    for geom in robot.collision_model.geometryObjects:
        _assert_enclosed(geom.geometry, rng, f"{name}/{geom.name}")


def test_a_fit_is_made_once_per_shape_and_never_handed_to_another(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Fits are kept per process by what they are made of (kind, dimensions, a hull's
    points, the cell): the same shape gets the same (read-only) fit, a shape that differs
    in any of those gets its own, equal to one made afresh, and enclosed."""
    import coal

    from safepath.collision import spheres

    box = coal.Box(0.1, 0.2, 0.3)
    first = fit_spheres(box)
    assert fit_spheres(coal.Box(0.1, 0.2, 0.3)) is first
    assert not first.outer_radii.flags.writeable
    rng = np.random.default_rng(2)
    points = rng.normal(size=(40, 3)) * 0.05
    moved = points.copy()
    moved[np.argmax(np.linalg.norm(points, axis=1))] *= 1.5  # a vertex of the hull moves

    def hull(pts: np.ndarray) -> object:
        vec = coal.StdVec_Vec3s()
        for p in pts:
            vec.append(p)
        return coal.Convex.convexHull(vec, False, "")

    variants = [coal.Box(0.1, 0.2, 0.31), coal.Box(0.3, 0.2, 0.1), coal.Cylinder(0.1, 0.6),
                coal.Capsule(0.1, 0.6), hull(points), hull(moved)]
    fits = [fit_spheres(g) for g in variants]
    assert fit_spheres(box, cell=0.01) is not first
    for g, fit in zip(variants, fits, strict=True):
        assert fit is not first
        with monkeypatch.context() as patch:
            patch.setattr(spheres, "_FITS", {})  # nothing kept: made afresh
            fresh = fit_spheres(g, cell=0.015)
        np.testing.assert_array_equal(fit.outer_centers, fresh.outer_centers)
        np.testing.assert_array_equal(fit.outer_radii, fresh.outer_radii)
        _assert_enclosed(g, rng, type(g).__name__)
    assert fits[-1] is not fits[-2]


def test_held_vial_is_enclosed(cell: Cell) -> None:
    _assert_enclosed(cell.scene.objects["vial"].shape.to_coal(), np.random.default_rng(3),
                     "vial")


@pytest.mark.parametrize("name", ROBOTS)
def test_inner_spheres_lie_inside_their_shape(name: str) -> None:
    import coal

    robot = load_robot(name)
    rng = np.random.default_rng(11)
    for geom in robot.collision_model.geometryObjects:
        fit = fit_spheres(geom.geometry)
        if not len(fit.inner_radii):
            continue
        v = rng.normal(size=(500, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        which = rng.integers(len(fit.inner_radii), size=500)
        pts = fit.inner_centers[which] + v * fit.inner_radii[which, None]
        probe = coal.Sphere(1e-9)
        for p in pts[:200]:
            req, res = coal.DistanceRequest(), coal.DistanceResult()
            d = coal.distance(geom.geometry, coal.Transform3s(), probe,
                              coal.Transform3s(np.eye(3), p), req, res)
            assert d <= 1e-6, f"{name}/{geom.name}: inner sphere point {d * 1000:.3f} mm outside"


def test_kernel_kinematics_match_pinocchio(cell: Cell) -> None:
    """The planner's kernels' one forward kinematics (the sphere layer's and the lines'
    IK's), over every joint of the robot's joint table, against Pinocchio."""
    from safepath.model._fk_kernel import joint_frames
    from safepath.model._joint_table import WORLD, joint_table

    for robot in (cell.robot, load_robot("panda")):
        model = robot.model
        jf, ji = joint_table(model, range(model.njoints),
                             [WORLD, *(int(model.parents[j]) for j in range(1, model.njoints))])
        Rw, pw = np.empty((model.njoints, 3, 3)), np.empty((model.njoints, 3))
        data = model.createData()
        for q in np.random.default_rng(0).uniform(robot.lower, robot.upper, (50, robot.dof)):
            joint_frames(q, jf, ji, Rw, pw)
            pin.forwardKinematics(model, data, q)
            for j in range(1, model.njoints):
                np.testing.assert_allclose(Rw[j], data.oMi[j].rotation, atol=1e-12)
                np.testing.assert_allclose(pw[j], data.oMi[j].translation, atol=1e-12)


def _states(robot: Robot, poses: list[np.ndarray], n: int, rng: np.random.Generator
            ) -> np.ndarray:
    """Half uniform in the limits, half close around the given poses (near the cell)."""
    uniform = rng.uniform(robot.lower, robot.upper, size=(n // 2, robot.dof))
    base = np.asarray(poses)[rng.integers(len(poses), size=n - n // 2)]
    near = np.clip(base + rng.normal(0.0, 0.15, size=base.shape), robot.lower, robot.upper)
    return np.vstack([uniform, near])


def _disagreements(fast: CollisionChecker, exact: CollisionChecker, Q: np.ndarray  # noqa: N803
                   ) -> tuple[int, int, np.ndarray]:
    layer = fast.layer
    assert layer is not None
    status = layer.classify_many(Q)
    truth = np.array([exact.is_valid(q) for q in Q])
    false_free = int(np.sum((status == FREE) & ~truth))
    false_collide = int(np.sum((status == COLLIDES) & truth))
    return false_free, false_collide, status


@pytest.mark.parametrize(("held", "margin", "n"), [(False, True, 60_000), (True, True, 30_000),
                                                    (True, False, 10_000)])
def test_layer_never_contradicts_coal_in_the_cell(cell: Cell, held: bool, margin: bool,
                                                  n: int) -> None:
    options = CheckOptions(enforce_margin=margin)
    fast = cell.checker(held=held, options=options)
    exact = cell.checker(held=held, options=CheckOptions(enforce_margin=margin, fast=False))
    Q = _states(cell.robot, list(cell.poses.values()), n, np.random.default_rng(n))  # noqa: N806
    false_free, false_collide, status = _disagreements(fast, exact, Q)
    assert false_free == 0 and false_collide == 0
    # And it is worth having: most states are decided without coal.
    assert np.mean(status == UNSURE) < 0.2
    # is_valid (layer, then coal for the unsure) answers exactly as coal alone.
    sample = Q[:2000]
    assert [fast.is_valid(q) for q in sample] == [exact.is_valid(q) for q in sample]


@pytest.mark.parametrize("name", ["gen3_lite", "panda", "ur5"])
def test_layer_never_contradicts_coal_for_other_robots(cell: Cell, name: str) -> None:
    # The cell's objects around another arm: convex-hull links (example-robot-data).
    robot = load_robot(name)
    options = CheckOptions(enforce_margin=True)
    fast = CollisionChecker(robot, cell.scene, options=options)
    exact = CollisionChecker(robot, cell.scene,
                             options=CheckOptions(enforce_margin=True, fast=False))
    rng = np.random.default_rng(5)
    Q = rng.uniform(robot.lower, robot.upper, size=(10_000, robot.dof))  # noqa: N806
    false_free, false_collide, _ = _disagreements(fast, exact, Q)
    assert false_free == 0 and false_collide == 0


def test_segments_answer_as_the_exact_grid(cell: Cell) -> None:
    # Every grid state of a segment is either certified free or checked by coal, so a
    # segment is valid for the layer exactly when all its 2 mm grid states are.
    options = CheckOptions(enforce_margin=True)
    fast = cell.checker(held=True, options=options)
    exact = cell.checker(held=True, options=CheckOptions(enforce_margin=True, fast=False))
    rng = np.random.default_rng(2)
    Q = _states(cell.robot, list(cell.poses.values()), 600, rng)  # noqa: N806
    agree = valid = 0
    for q0, q1 in zip(Q[::2], Q[1::2], strict=True):
        a = fast.check_segment(q0, q1)
        b = exact.check_segment(q0, q1)
        assert a.valid == b.valid
        agree += 1
        valid += a.valid
        if a.valid:
            assert a.checked <= b.checked
    assert agree == 300 and 0 < valid < 300


@pytest.fixture(scope="module")
def panda_cell(tmp_path_factory: pytest.TempPathFactory) -> Cell:
    """The Panda problem set's table scene (benchmarks/peers), written as a cell."""
    import importlib.util
    import json
    import sys
    from pathlib import Path

    peers = Path(__file__).resolve().parents[1] / "benchmarks" / "peers"
    spec = importlib.util.spec_from_file_location("peer_problems", peers / "problems.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    problems = json.loads((peers / "panda_problems.json").read_text())
    return load_cell(module.write_panda_cell(problems, tmp_path_factory.mktemp("panda")))


def test_panda_segments_answer_as_the_exact_grid(panda_cell: Cell) -> None:
    """Hull links (GJK bounds) and the per-state axis-distance radii: a Panda segment
    among obstacles is certified exactly when coal finds all its grid states free."""
    fast = CollisionChecker(panda_cell.robot, panda_cell.scene)
    exact = CollisionChecker(panda_cell.robot, panda_cell.scene,
                             options=CheckOptions(fast=False))
    poses = np.array(list(panda_cell.poses.values()))
    rng = np.random.default_rng(4)
    valid = 0
    for _ in range(150):
        q0, q1 = poses[rng.integers(len(poses), size=2)]
        q1 = q0 + rng.uniform(0.1, 0.9) * (q1 - q0) + rng.normal(0.0, 0.05, len(q0))
        q1 = np.clip(q1, panda_cell.robot.lower, panda_cell.robot.upper)
        a = fast.check_segment(q0, q1, details=False)
        assert a.valid == exact.check_segment(q0, q1, details=False).valid
        valid += a.valid
    assert 10 < valid < 140


@pytest.mark.parametrize("robot", ["ned3pro", "panda"])
def test_polylines_of_short_chords_answer_as_the_exact_grid(cell: Cell, panda_cell: Cell,
                                                             robot: str) -> None:
    """Sampled curves (many short chords, as the smoothed paths are checked): a state's
    certificate carried along the following chords never certifies a colliding one."""
    the_cell = cell if robot == "ned3pro" else panda_cell
    fast = CollisionChecker(the_cell.robot, the_cell.scene)
    exact = CollisionChecker(the_cell.robot, the_cell.scene, options=CheckOptions(fast=False))
    poses = np.array(list(the_cell.poses.values()))
    rng = np.random.default_rng(8)
    valid = 0
    for _ in range(60):
        a, b, c = poses[rng.integers(len(poses), size=3)]
        s = np.linspace(0.0, 1.0, int(rng.integers(20, 120)))[:, None]
        curve = (1 - s) ** 2 * a + 2 * s * (1 - s) * (c + rng.normal(0.0, 0.3, len(a))) \
            + s ** 2 * b  # a quadratic Bezier curve through the joint space
        curve = np.clip(curve, the_cell.robot.lower, the_cell.robot.upper)
        verdict = fast.check_path(curve, details=False).valid
        assert verdict == exact.check_path(curve, details=False).valid
        valid += verdict
    assert 5 < valid < 55


def test_pair_weights_are_the_mask_sums_of_the_bodies_weights(cell: Cell,
                                                             panda_cell: Cell) -> None:
    """The packed per-pair weights (what a joint step can close each pair by) are body a's
    weights where the pair's mask has bit 1 plus body b's where it has bit 2, for robot
    pairs, environment pairs and the held object's pairs."""
    from safepath.collision._probe import pair_tables

    checkers = [cell.checker(), cell.checker(held=True),
                CollisionChecker(panda_cell.robot, panda_cell.scene)]
    for checker in checkers:
        layer = checker.layer
        assert layer is not None
        W, pairs, masks, got = pair_tables(layer.F, layer.I)  # noqa: N806
        dof = W.shape[1]
        kinds = set()
        for k, (a, b, env, _) in enumerate(pairs):
            kinds.add(bool(env))
            for v in range(dof):
                want = 0.0
                if masks[k, v] & 1:
                    want += W[a, v]
                if masks[k, v] & 2:
                    assert not env
                    want += W[b, v]
                assert got[k, v] == want, (k, v)
        assert kinds == {True, False}
        assert (got > 0).any() and (got == 0).any()


def test_one_call_segments_report_as_the_polyline_walk(cell: Cell, panda_cell: Cell) -> None:
    """check_segment's one-call way (limits, grid count and walk inside the kernel) reports
    what the general polyline walk reports: verdict, states evaluated, where it fails,
    for every choice of checked ends; an end outside the limits is named. The planners'
    segment_is_valid gives the same verdict."""
    # The held vial's allowed contacts leave states to coal (no proof below a negative
    # margin): the way where coal checks what the one call left undecided.
    checkers = [(cell, CollisionChecker(cell.robot, cell.scene)), (cell, cell.checker(held=True)),
                (panda_cell, CollisionChecker(panda_cell.robot, panda_cell.scene))]
    outcomes = set()
    for the_cell, checker in checkers:
        robot = the_cell.robot
        poses = np.array(list(the_cell.poses.values()))
        rng = np.random.default_rng(11)
        for trial in range(60):
            q0, q1 = poses[rng.integers(len(poses), size=2)]
            q1 = q0 + rng.uniform(0.05, 1.0) * (q1 - q0) + rng.normal(0.0, 0.05, len(q0))
            q1 = np.clip(q1, robot.lower, robot.upper)
            if trial % 10 == 9:  # an end beyond a limit
                q1[trial % len(q1)] = robot.upper[trial % len(q1)] + 0.01
            n = checker.segment_states(q0, q1)
            for ends, start in ((True, None), (False, None), (False, True), (True, False)):
                a = checker.check_segment(q0, q1, check_ends=ends, check_start=start,
                                          details=False)
                if start is None:  # the planners' edge check: the verdict alone
                    assert checker.segment_is_valid(q0, q1, check_ends=ends) == a.valid
                if trial % 10 == 9:
                    assert not a.valid and a.fraction == 1.0 and a.limit_violation
                    outcomes.add("outside")
                    continue
                lo, hi = (0, n) if ends else (1, n - 1)
                lo = 1 if start is False else (0 if start else lo)
                # The same grid states, walked as a polyline.
                b = checker.check_path([q0, q1], details=False, check_start=lo == 0,
                                       check_end=hi == n)
                assert (a.valid, a.checked, a.fraction) == (b.valid, b.checked, b.fraction)
                if not a.valid:
                    np.testing.assert_array_equal(a.q, b.q)
                outcomes.add("valid" if a.valid else "collides")
                # States the walk left to coal (found in one walk, not walked again).
                found = np.empty(4, dtype=np.int64)
                status, _, _, unsure, _ = checker.layer.certify_segment(
                    q0, q1, lo == 1, hi == n - 1, found)
                if unsure:
                    outcomes.add(f"undecided, then {'valid' if a.valid else 'collides'}")
    assert outcomes == {"valid", "collides", "outside", "undecided, then collides",
                        "undecided, then valid"}


def _layer_of(robot: Robot, cell: Cell) -> tuple[np.ndarray, np.ndarray]:
    layer = CollisionChecker(robot, cell.scene, held="vial").layer
    assert layer is not None
    return layer.F, layer.I


def _afresh(robot: Robot, cell: Cell) -> tuple[np.ndarray, np.ndarray]:
    robot.derived.forget()  # nothing kept: everything made from the shapes again
    return _layer_of(robot, cell)


def test_checkers_of_a_robot_share_its_part_and_see_it_change() -> None:
    """What a checker builds from the robot's shapes alone is made once per robot and
    shared read-only: a checker built with it packs the same buffers as one built
    afresh. Moving a geometry, changing a limit or giving the robot a new collision model
    makes it again."""
    own = load_cell("scenes/quality_check_cell")  # its robot is changed below
    robot = own.robot
    first = CollisionChecker(robot, own.scene, held="vial")
    second = CollisionChecker(robot, own.scene)
    assert first.layer is not None and second.layer is not None
    assert second.layer.fits[0] is first.layer.fits[0]
    assert not first.layer.fits[0].outer_centers.flags.writeable
    assert len(first.geometry_model.collisionPairs) == len(first.pairs)
    F, I_ = _layer_of(robot, own)
    fresh = _afresh(robot, own)
    np.testing.assert_array_equal(fresh[0], F)
    np.testing.assert_array_equal(fresh[1], I_)

    def changed(what: str) -> None:
        before = _layer_of(robot, own)
        assert not np.array_equal(before[0], F), what
        after = _afresh(robot, own)
        np.testing.assert_array_equal(after[0], before[0], err_msg=what)
        np.testing.assert_array_equal(after[1], before[1], err_msg=what)

    geom = robot.collision_model.geometryObjects[3]
    placement = geom.placement.copy()
    geom.placement = pin.SE3(placement.rotation, placement.translation + [0.0, 0.0, 0.05])
    assert np.allclose(robot.collision_model.geometryObjects[3].placement.translation,
                       placement.translation + [0.0, 0.0, 0.05])
    changed("a geometry moved in place")
    robot.collision_model.geometryObjects[3].placement = placement
    robot.upper = robot.upper - 0.1
    changed("upper limits")
    robot.upper = robot.upper + 0.1
    import coal

    bigger = robot.collision_model.copy()
    bigger.geometryObjects[3].geometry = coal.Sphere(0.2)
    robot.collision_model = bigger
    changed("a new collision model")


@pytest.mark.parametrize("helical", [False, True])
def test_a_helical_joint_leaves_the_checker_exact(helical: bool) -> None:
    """The layer's motion bounds know a joint's turn or its slide, not both: a robot with
    a helical joint gets no sphere layer (every check exact), one without gets it."""
    import coal

    model = pin.Model()
    kind = (pin.JointModelHelicalUnaligned(np.array([0.0, 0.0, 1.0]), 0.05) if helical
            else pin.JointModelRevoluteUnaligned(np.array([0.0, 0.0, 1.0])))
    j1 = model.addJoint(0, kind, pin.SE3.Identity(), "j1", np.array([10.0]), np.array([1.0]),
                        np.array([-3.0]), np.array([3.0]))
    j2 = model.addJoint(j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])),
                        "j2", np.array([10.0]), np.array([1.0]), np.array([-3.0]),
                        np.array([3.0]))
    for j, name in ((j1, "l1"), (j2, "l2")):
        model.addFrame(pin.Frame(name, j, pin.SE3.Identity(), pin.FrameType.BODY))
    model.addFrame(pin.Frame("tcp", j2, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2])),
                             pin.FrameType.OP_FRAME))
    geometry = pin.GeometryModel()
    for j, name in ((j1, "l1"), (j2, "l2")):
        geometry.addGeometryObject(pin.GeometryObject(
            f"{name}_box", model.getFrameId(name), j, pin.SE3(np.eye(3), np.array([0, 0, 0.1])),
            coal.Box(0.05, 0.05, 0.2)))
    robot = Robot(name="screw" if helical else "turn", model=model, collision_model=geometry,
                  visual_model=None, velocity_limits=np.ones(2), acceleration_limits=np.ones(2),
                  tcp_frame="tcp")
    checker = CollisionChecker(robot)
    assert (checker.layer is None) is helical
    assert checker.is_valid(np.array([0.5, 0.3]))


def _edge_of_collision(exact: CollisionChecker, q0: np.ndarray, q1: np.ndarray,
                       shift: np.ndarray, steps: int = 14
                       ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The segment q0 -> q1 (invalid for coal) moved by s * shift (s = 1: valid), bisected
    on s to the edge of its collision: (just valid, just invalid) segments."""
    lo, hi = 1.0, 0.0  # valid at lo, invalid at hi
    for _ in range(steps):
        s = 0.5 * (lo + hi)
        if exact.check_segment(q0 + s * shift, q1 + s * shift, details=False).valid:
            lo = s
        else:
            hi = s
    return (q0 + lo * shift, q1 + lo * shift), (q0 + hi * shift, q1 + hi * shift)


def test_panda_segments_grazing_an_obstacle_are_refused(panda_cell: Cell) -> None:
    """Segments moved to the edge of a collision (bisected with coal): the one just past
    it collides at a few grid states between states the layer certifies with their radii,
    and is refused (or left to coal), the one just short of it is never refused. Also
    with a layer that refines no pair while walking (``refine=0``): every binding pair's
    finer bound is then measured after the walk's first pass, near the obstacle too."""
    from safepath.collision import SphereLayer
    from safepath.collision.options import LayerOptions

    robot = panda_cell.robot
    fast = CollisionChecker(robot, panda_cell.scene)
    exact = CollisionChecker(robot, panda_cell.scene, options=CheckOptions(fast=False))
    coarse = SphereLayer(fast.layer_source(), LayerOptions(refine=0.0))
    poses = np.array(list(panda_cell.poses.values()))
    rng = np.random.default_rng(21)
    grazed = 0
    for _ in range(400):
        q0, q1 = poses[rng.integers(len(poses), size=2)]
        shift = rng.normal(0.0, 0.3, robot.dof)
        ends = (q0, q1, q0 + shift, q1 + shift)
        if (any(not exact.is_valid(q) for q in ends)
                or exact.check_segment(q0, q1, details=False).valid
                or not exact.check_segment(ends[2], ends[3], details=False).valid):
            continue
        valid, invalid = _edge_of_collision(exact, q0, q1, shift)
        assert fast.check_segment(*valid, details=False).valid
        assert fast.segment_is_valid(*valid)
        assert not fast.check_segment(*invalid, details=False).valid
        assert not fast.segment_is_valid(*invalid)
        for layer in (fast.layer, coarse):
            assert layer is not None
            found = np.empty(8, dtype=np.int64)
            status, _, _, unsure, _ = layer.certify_segment(*invalid, False, False, found)
            assert status != FREE or unsure > 0  # refused, or left to coal
            assert layer.certify_segment(*valid, False, False, found)[0] != COLLIDES
        grazed += 1
        if grazed == 8:
            break
    assert grazed == 8


def test_the_pair_that_collided_last_changes_no_answer(panda_cell: Cell) -> None:
    """The layer remembers the pair whose collision it proved last and tries that proof
    first at the next state it evaluates: a walk answers the same (status, grid index,
    states evaluated, the states left to coal) whichever pair is remembered, or none, and
    so does a single state."""
    from safepath.collision._probe import last_collision, pair_tables

    layer = CollisionChecker(panda_cell.robot, panda_cell.scene).layer
    assert layer is not None
    segment, classify = layer.kernel("certify_segment"), layer.kernel("classify")
    poses = np.array(list(panda_cell.poses.values()))
    rng = np.random.default_rng(13)
    pairs = rng.choice(len(pair_tables(layer.F, layer.I).pairs), size=4, replace=False)
    remembered = set()

    def answers(q0: np.ndarray, q1: np.ndarray, last: int) -> tuple:
        table = layer.I.copy()
        slot = last_collision(table)
        slot[0] = last
        found = np.empty(4, dtype=np.int64)
        walk = segment(q0, q1, layer.F, table, False, False, found)
        remembered.add(int(slot[0]))
        slot[0] = last
        return (*walk, *found[:walk[3]], classify(0.5 * (q0 + q1), layer.F, table))

    collided = 0
    for _ in range(40):
        q0, q1 = poses[rng.integers(len(poses), size=2)]
        q1 = np.clip(q0 + rng.uniform(0.2, 1.0) * (q1 - q0) + rng.normal(0.0, 0.1, len(q0)),
                     panda_cell.robot.lower, panda_cell.robot.upper)
        none = answers(q0, q1, -1)
        collided += none[0] == COLLIDES
        for last in [*pairs, *sorted(remembered - {-1})]:
            assert answers(q0, q1, int(last)) == none
    assert collided >= 5 and len(remembered - {-1}) >= 2
