"""The independent FCL verifier catches what it must: collisions and margin violations.

A timed trajectory that goes straight through the detour cell's post (timed with the
library's own spline and TOPPRA, but never collision-checked) must be rejected with
the pair, the time and the step; a safe trajectory checked against a margin larger
than its clearance must be rejected only when margins are enforced. The verifier
clears most samples with its own conservative bounds: it must find exactly what a
dense FCL check of every grid sample finds, and its bounds must be lower bounds.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import time

import coal
import fcl
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import ConvexHull

from safepath import CheckOptions, ConfigError, VerificationError, plan_cell
from safepath.cell import Cell
from safepath.model.robot import Robot
from safepath.model.scene import AllowedContact, Scene, SceneObject, Shape
from safepath.planning import initial_world
from safepath.timing import TimedPiece, spline_path, time_path
from safepath.verify import (
    Body,
    CheckedPair,
    FclVerifier,
    VerifyResult,
    check_verifiable,
    fcl_shape,
)
from safepath.verify._bodies import robot_bodies
from safepath.verify._bounds import (
    Grid,
    Layer,
    bound_between,
    joint_tables,
    pair_weights,
    shape_spec,
    undominated,
)

from .conftest import Plans, object_released_at

STEP = "3 move high2"


def _straight(cell: Cell, a: str, b: str) -> TimedPiece:
    """The straight joint move a -> b, timed rest to rest, not collision-checked."""
    path, s_way, _ = spline_path([cell.pose(a), cell.pose(b)], 0.06)
    return time_path(cell.robot, path, s_way, scales=[1.0], tcp_speeds=[None])


def _verifier(cell: Cell, **kwargs: object) -> FclVerifier:
    world = initial_world(cell)
    return FclVerifier(cell.robot, cell.scene, held="vial", resting=dict(world.resting),
                       **kwargs)  # type: ignore[arg-type]


def test_a_trajectory_through_the_post_is_rejected(detour_cell: Cell) -> None:
    piece = _straight(detour_cell, "high1", "high2")
    verifier = _verifier(detour_cell)
    with pytest.raises(VerificationError) as info:
        verifier.verify(piece.t, piece.q, piece.qd, steps=[STEP] * len(piece.t))
    err = info.value
    assert err.step == STEP
    assert 0.0 < err.time < float(piece.t[-1])
    assert err.pairs and all("obstacle" in pair for pair in err.pairs)
    assert "obstacle" in str(err) and STEP in str(err) and f"t={err.time:.3f}" in str(err)
    # The rejected state does collide (or breaks the margin) for the planner's checker.
    checker = detour_cell.checker(held=True, options=CheckOptions(enforce_margin=True))
    assert not checker.is_valid(np.asarray(err.q))
    # Before the reported time the motion was accepted: the failure is the first one.
    first = int(np.searchsorted(piece.t, err.time))
    early = _verifier(detour_cell).verify(piece.t[:max(first - 5, 2)],
                                          piece.q[:max(first - 5, 2)],
                                          piece.qd[:max(first - 5, 2)])
    assert early.min_clearance >= 0.0


def test_the_same_motion_is_accepted_without_the_post(bundled_cell: Cell) -> None:
    piece = _straight(bundled_cell, "high1", "high2")
    result = _verifier(bundled_cell).verify(piece.t, piece.q, piece.qd)
    assert result.min_clearance >= bundled_cell.scene.margin
    assert 0 < result.checked <= result.samples
    assert result.closest_pair is not None


def _move_of_phase1(bundled: Plans) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    traj = bundled.trajectories["phase1"]
    sel = traj.step_index == traj.steps.index(STEP)
    return traj.t[sel], traj.q[sel], traj.qd[sel]


def test_a_margin_violation_is_caught_only_when_enforced(bundled: Plans) -> None:
    cell = bundled.cell
    t, q, qd = _move_of_phase1(bundled)
    relaxed = _verifier(cell, margin=0.2, enforce_margin=False).verify(t, q, qd)
    assert relaxed.min_clearance < 0.2  # the margin is not kept ...
    with pytest.raises(VerificationError) as info:  # ... and that is caught when enforced
        _verifier(cell, margin=0.2, enforce_margin=True).verify(t, q, qd,
                                                                 steps=[STEP] * len(t))
    assert info.value.step == STEP and info.value.pairs
    # With the scene's margins the planned move passes, and its clearance is the same.
    strict = _verifier(cell, enforce_margin=True).verify(t, q, qd)
    assert strict.min_clearance >= cell.scene.margin
    assert strict.min_clearance == pytest.approx(relaxed.min_clearance, abs=2e-3)


def test_verifier_and_checker_agree_on_clearance(bundled: Plans) -> None:
    """FCL (verifier) and coal (checker) measure the same closest distance, within 1 mm."""
    cell = bundled.cell
    t, q, qd = _move_of_phase1(bundled)
    result = _verifier(cell, enforce_margin=True).verify(t, q, qd)
    checker = cell.checker(held=True)
    coal_min = min(checker.clearance(qk)[0] for qk in q[::5])
    assert result.min_clearance == pytest.approx(coal_min, abs=1e-3)


# --- The conservative layer against FCL ------------------------------------------------
#
# The verifier clears most samples with its own lower bounds on the distance and lets FCL
# judge the rest. The tests below hold it to a dense check written here: every grid
# sample placed with pinocchio and judged with FCL, pair by pair.


def _bodies(verifier: FclVerifier, pair: CheckedPair) -> tuple[Body, Body]:
    """The verifier's two bodies of ``pair``."""
    movers, env = verifier.movers, verifier.environment
    return movers[pair.first], (env if pair.environment else movers)[pair.second]


def _judge(verifier: FclVerifier, pair: CheckedPair, margin_of: dict[str, float]
           ) -> tuple[bool, float]:
    """FCL's judgement of ``pair`` as placed now: (fails, distance [m])."""
    a, b = _bodies(verifier, pair)
    o1, o2, env, depth = a.fcl, b.fcl, pair.environment, pair.allowed_depth
    if depth > 0.0:  # allowed to touch, up to a depth
        res = fcl.CollisionResult()
        if fcl.collide(o1, o2, fcl.CollisionRequest(enable_contact=True, num_max_contacts=4),
                       res):
            return max(c.penetration_depth for c in res.contacts) > depth, 0.0
        return False, np.inf
    d = fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult())
    keep = margin_of[b.name] if env else 0.0
    hit = d <= 0.0 and fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult())
    return hit or d < keep, d


def _dense(verifier: FclVerifier, q: np.ndarray, margin_of: dict[str, float]
           ) -> tuple[int | None, set[tuple[str, str]], float]:
    """(first failing sample or None, the pairs failing there, smallest clearance [m])."""
    grid = verifier.grid(q)
    model = verifier.robot.model
    data = model.createData()
    clearance = np.inf
    for s in range(grid.samples):
        pin.forwardKinematics(model, data, grid.state(q, s))
        for body in verifier.movers:
            T = data.oMi[body.joint].homogeneous @ body.T
            body.fcl.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
        bad = set()
        for pair in verifier.pairs:
            fails, d = _judge(verifier, pair, margin_of)
            if fails:
                bad.add(pair.names)
            elif pair.environment and pair.allowed_depth == 0.0:
                clearance = min(clearance, d)
        if bad:
            return s, bad, clearance
    return None, set(), clearance


def _margins(cell: Cell, margin: float | None, enforce: bool) -> dict[str, float]:
    return {name: (0.0 if not enforce else margin if margin is not None
                   else cell.scene.margin_for(name)) for name in cell.scene.objects}


def _step(bundled: Plans, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    traj = bundled.trajectories["phase1"]
    sel = traj.step_index == traj.steps.index(label)
    return traj.t[sel], traj.q[sel], traj.qd[sel]


def _assert_same_as_dense(verifier: FclVerifier, t: np.ndarray, q: np.ndarray,
                          margin_of: dict[str, float]) -> VerifyResult | VerificationError:
    first, bad, clearance = _dense(verifier, q, margin_of)
    grid = verifier.grid(q)
    try:
        result = verifier.verify(t, q, np.zeros_like(q), steps=["step"] * len(t))
    except VerificationError as err:
        assert first is not None, f"the verifier rejects what the dense check accepts: {err}"
        assert err.time == float(t[grid.knot_of[first]])
        np.testing.assert_array_equal(err.q, grid.state(q, first))
        assert set(err.pairs) == bad
        return err
    assert first is None, f"the verifier accepts sample {first} ({bad})"
    # Its clearance is FCL's at one sample (placed by its own kinematics: to rounding),
    # and no sample is closer by more than half a resolution.
    assert clearance - 1e-9 <= result.min_clearance <= clearance + verifier.resolution / 2
    assert result.checked <= result.samples
    return result


def test_the_post_is_found_where_a_dense_check_finds_it(detour_cell: Cell) -> None:
    piece = _straight(detour_cell, "high1", "high2")
    verifier = _verifier(detour_cell, resolution=0.004)
    err = _assert_same_as_dense(verifier, piece.t, piece.q, _margins(detour_cell, None, True))
    assert isinstance(err, VerificationError)


@pytest.mark.parametrize("excess", [0.0003, -0.0003], ids=["just-inside", "just-outside"])
def test_a_margin_is_judged_as_a_dense_check_judges_it(bundled: Plans, excess: float) -> None:
    """A margin a fraction of a millimetre above (then below) the move's clearance."""
    cell = bundled.cell
    t, q, _ = _step(bundled, STEP)
    clearance = _dense(_verifier(cell), q, _margins(cell, None, False))[2]
    margin = clearance + excess
    out = _assert_same_as_dense(_verifier(cell, margin=margin), t, q,
                                _margins(cell, margin, True))
    assert isinstance(out, VerificationError) == (excess > 0)


def _raised(cell: Cell, name: str, dz: float) -> Scene:
    """The cell's scene with object ``name`` raised by dz [m]."""
    obj = cell.scene.objects[name]
    T = obj.T_world_object.copy()
    T[2, 3] += dz
    return dataclasses.replace(cell.scene, objects={**cell.scene.objects,
                                                    name: obj.placed(T)})


@pytest.mark.parametrize(("dz", "max_depth", "fails"), [
    (0.0, 0.001, False),      # the planned put-down: touches within the allowed depth
    (0.003, 0.001, True),     # the plate 3 mm higher: the vial presses into it
    (0.003, 0.005, False),    # ... which a deeper allowed contact accepts
], ids=["planned", "pressed-in", "pressed-in-allowed"])
def test_an_allowed_contact_is_judged_as_a_dense_check_judges_it(
        bundled: Plans, dz: float, max_depth: float, fails: bool) -> None:
    """The held vial put down on the test plate: in contact, FCL's depth decides."""
    cell = bundled.cell
    t, q, _ = _step(bundled, "4 line low1")
    scene = _raised(cell, "test_plate", dz)
    allowed = (AllowedContact(("vial", "test_plate"), ("low1",), max_depth),
               *cell.scene.contacts_at("high2"))
    verifier = FclVerifier(cell.robot, scene, held="vial",
                           resting=dict(initial_world(cell).resting), allowed=allowed)
    out = _assert_same_as_dense(verifier, t, q, _margins(cell, None, True))
    assert isinstance(out, VerificationError) == fails
    if fails:
        assert isinstance(out, VerificationError) and out.pairs == [("vial", "test_plate")]
        assert 0 < int(np.searchsorted(t, out.time))  # not at the start of the line


@pytest.mark.parametrize("excess", [None, 0.0003], ids=["scene-margins", "just-inside"])
def test_the_open_jaws_leaving_the_vial_are_judged_as_a_dense_check_judges_them(
        bundled: Plans, excess: float | None) -> None:
    """Nothing held, the vial resting on the plate between the open jaws (allowed to
    touch them): the line back up to high2, with the scene's margins, then with a margin
    a fraction of a millimetre above its clearance."""
    cell = bundled.cell
    t, q, _ = _step(bundled, "6 line high2")
    resting = {"vial": object_released_at(cell, bundled.trajectories["phase1"])}

    def verifier(margin: float | None) -> FclVerifier:
        return FclVerifier(cell.robot, cell.scene, held=None, resting=resting,
                           allowed=cell.scene.contacts_at("low1"), margin=margin)

    margin = None
    if excess is not None:
        margin = _dense(verifier(None), q, _margins(cell, None, False))[2] + excess
    out = _assert_same_as_dense(verifier(margin), t, q, _margins(cell, margin, True))
    assert isinstance(out, VerificationError) == (excess is not None)


def test_the_layer_bounds_are_below_fcl_distances(bundled_cell: Cell) -> None:
    """At sampled states, the layer's kinematics are pinocchio's and its bound on every
    pair (held vial; resting vial with the jaws allowed around it) is at most FCL's
    distance (at most zero in collision), and tight where the shapes are apart."""
    cell = bundled_cell
    rng = np.random.default_rng(7)
    model = cell.robot.model
    data = model.createData()
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    states = [rng.uniform(lo, hi) for _ in range(40)]
    states += [cell.pose(name) + rng.normal(0.0, 0.05, model.nq)
               for name in cell.poses for _ in range(3)]
    verifiers = [_verifier(cell),
                 FclVerifier(cell.robot, cell.scene,
                             resting=dict(initial_world(cell).resting),
                             allowed=cell.scene.contacts_at("grip"))]
    slack = []
    for verifier in verifiers:
        for q in states:
            at = verifier.bounds_at(q)
            bounds, poses = at.bounds, at.T_world_geom
            pin.forwardKinematics(model, data, q)
            for m, body in enumerate(verifier.movers):
                T = data.oMi[body.joint].homogeneous @ body.T
                np.testing.assert_allclose(poses[m], T[:3], atol=1e-12)
                body.fcl.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
            for p, pair in enumerate(verifier.pairs):
                o1, o2 = (body.fcl for body in _bodies(verifier, pair))
                d = fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult())
                if fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult()):
                    assert bounds[p] <= 0.0, (pair.names, q, bounds[p])
                else:
                    assert bounds[p] <= d + 1e-9, (pair.names, q, bounds[p], d)
                    slack.append(d - bounds[p])
    assert np.quantile(slack, 0.95) < 1e-4  # not a vacuous bound


def _shape(kind: str, rng: np.random.Generator) -> object:
    size = rng.uniform(0.01, 0.1, 3)
    if kind == "box":
        return coal.Box(*size)
    if kind == "sphere":
        return coal.Sphere(size[0])
    if kind == "cylinder":
        return coal.Cylinder(size[0], size[1])
    if kind == "capsule":
        return coal.Capsule(size[0], size[1])
    points = coal.StdVec_Vec3s()
    for point in rng.normal(0.0, 0.04, (20, 3)) + rng.normal(0.0, 0.02, 3):
        points.append(point)
    return coal.Convex.convexHull(points, False, "")


KINDS = ["box", "sphere", "cylinder", "capsule", "convex"]


def _pose_pair(rng: np.random.Generator, low: float, high: float) -> list[np.ndarray]:
    """Two random world poses (4 x 4), the second shifted along x by U(low, high) [m]."""
    poses = []
    for shift in (0.0, rng.uniform(low, high)):
        T = np.eye(4)
        T[:3, :3] = pin.exp3(rng.normal(0.0, 2.0, 3))
        T[:3, 3] = rng.normal(0.0, 0.02, 3) + [shift, 0.0, 0.0]
        poses.append(T)
    return poses


@pytest.mark.parametrize("kinds", list(itertools.combinations_with_replacement(KINDS, 2)),
                         ids="-".join)
def test_the_shape_bound_is_below_fcl_distance(kinds: tuple[str, str]) -> None:
    """Every pair of shape kinds, at random poses: the bound never exceeds FCL's distance
    (nor zero in collision)."""
    rng = np.random.default_rng(sum(map(ord, "".join(kinds))))
    for _ in range(40):
        shapes = [_shape(kind, rng) for kind in kinds]
        poses = _pose_pair(rng, 0.0, 0.25)
        objects = [fcl.CollisionObject(fcl_shape(g), fcl.Transform(T[:3, :3], T[:3, 3]))
                   for g, T in zip(shapes, poses, strict=True)]
        bound = bound_between(shape_spec(shapes[0]), poses[0], shape_spec(shapes[1]), poses[1])
        if fcl.collide(*objects, fcl.CollisionRequest(), fcl.CollisionResult()):
            assert bound <= 0.0
        else:
            assert bound <= fcl.distance(*objects, fcl.DistanceRequest(),
                                         fcl.DistanceResult()) + 1e-9


def test_the_same_input_gives_the_same_result(bundled: Plans) -> None:
    t, q, qd = _step(bundled, STEP)
    cell = bundled.cell
    first = _verifier(cell).verify(t, q, qd)
    assert _verifier(cell).verify(t, q, qd) == first


def test_a_known_clearance_is_measured_only_below_it_as_a_dense_check_finds_it(
        bundled: Plans) -> None:
    """Given the clearance an earlier piece of the route found, a verification measures
    its own only where it comes closer: below ``known`` the value is FCL's at a sample
    with no sample closer by more than half the resolution (as without it); not below,
    the result says inf, and then no sample is closer than ``known`` minus half the
    resolution. The verdict is the same either way (the work may differ a little: the
    bounds are refined in another order); well below, there is less of it."""
    t, q, qd = _step(bundled, STEP)
    cell = bundled.cell
    verifier = _verifier(cell)
    _, _, dense = _dense(verifier, q, _margins(cell, None, True))
    alone = verifier.verify(t, q, qd)
    tol = verifier.resolution / 2
    assert dense - 1e-9 <= alone.min_clearance <= dense + tol
    for known in (dense + 0.02, dense + tol / 2, dense - tol / 2, dense - 0.02):
        result = verifier.verify(t, q, qd, known=known)
        # The same verdict on the same samples: released (a collision would raise), its
        # certified bound between samples not negative.
        assert result.samples == alone.samples and result.clearance_bound >= 0.0
        if result.min_clearance < np.inf:  # measured: FCL's at a sample, below known
            assert dense - 1e-9 <= result.min_clearance <= min(dense + tol, known)
            assert result.closest_pair is not None
        else:  # nothing below known: then the samples keep known - tol
            assert result.closest_pair is None
            assert dense >= known - tol - 1e-9
    # Well above: measured as alone; well below: inf, for fewer bound evaluations.
    assert verifier.verify(t, q, qd, known=dense + 0.02).min_clearance < np.inf
    below = verifier.verify(t, q, qd, known=dense - 0.02)
    assert below.min_clearance == np.inf
    assert below.bound_checks < alone.bound_checks


def _layer_of(verifier: FclVerifier) -> Layer:
    """A conservative layer of the verifier's bodies, environment and pairs, made as the
    verifier makes its own."""
    model = verifier.robot.model
    movers, env, pairs = verifier.movers, verifier.environment, verifier.pairs
    return Layer([b.joint for b in movers], [b.T for b in movers],
                 [b.spec for b in movers], [b.T for b in env], [b.spec for b in env],
                 [(p.first, p.second, p.environment) for p in pairs],
                 verifier.pair_weights.copy(),  # the kernels take writeable arrays
                 np.array([p.clearance for p in pairs]), joint_tables(model))


def test_a_walk_that_fills_its_outputs_resumes_where_it_stopped(
        bundled: Plans, monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernel writes the couples it leaves to buffers of fixed room and returns when
    they are full; resumed, the walk must go on as if it had not stopped: the same
    couples, bounds and result as in one go, whatever the room."""
    from safepath.verify import _bounds as _verify_bounds

    t, q, qd = _step(bundled, STEP)
    verifier = _verifier(bundled.cell)
    layer, grid = _layer_of(verifier), verifier.grid(q)
    pairs = len(verifier.pairs)
    bound_theta = np.array([p.certified_above for p in verifier.pairs])
    # The layer made here is the verifier's: the same bounds.
    np.testing.assert_array_equal(layer.bounds_at(q[0])[0], verifier.bounds_at(q[0]).bounds)

    def walk(theta: np.ndarray) -> tuple[np.ndarray, ...]:
        memory = _verify_bounds.WalkMemory.empty(pairs)
        return layer.walk(np.arange(pairs), theta, q, grid, layer.cache(grid.samples), memory)

    # Nothing clears an infinite threshold: every couple is left, pair by pair.
    left = walk(np.full(pairs, np.inf))
    assert left[0].size == pairs * grid.samples
    np.testing.assert_array_equal(left[0], np.repeat(np.arange(pairs), grid.samples))
    np.testing.assert_array_equal(left[1], np.tile(np.arange(grid.samples), pairs))
    real = walk(bound_theta)
    one_go = verifier.verify(t, q, qd)
    for room in (1, 7):
        monkeypatch.setattr(_verify_bounds, "_ROOM", room)
        for mine, theirs in zip(walk(np.full(pairs, np.inf)), left, strict=True):
            np.testing.assert_array_equal(mine, theirs)
        for mine, theirs in zip(walk(bound_theta), real, strict=True):
            np.testing.assert_array_equal(mine, theirs)
        assert verifier.verify(t, q, qd) == one_go


def _toy_arm(rng: np.random.Generator, joints: list[object] | None = None) -> Robot:
    """A random three-joint arm (turn, tilt, spin, or ``joints``), with a box off the
    spin axis and a capsule along the tilted link."""
    model = pin.Model()
    geometry = pin.GeometryModel()
    parent, placement = 0, pin.SE3.Identity()
    spin = rng.normal(size=3)
    for k, joint in enumerate(joints or [
            pin.JointModelRZ(), pin.JointModelRX(),
            pin.JointModelRevoluteUnaligned(spin / np.linalg.norm(spin))]):
        parent = model.addJoint(parent, joint, placement, f"j{k}")
        model.lowerPositionLimit[k], model.upperPositionLimit[k] = -np.pi, np.pi
        frame = model.addFrame(pin.Frame(f"link{k}", parent, pin.SE3.Identity(),
                                         pin.FrameType.BODY))
        shape = coal.Capsule(0.02, 0.2) if k < 2 else coal.Box(0.08, 0.03, 0.05)
        where = pin.SE3(pin.exp3(rng.normal(0.0, 1.0, 3)), rng.uniform(-0.1, 0.1, 3))
        geometry.addGeometryObject(pin.GeometryObject(f"link{k}_0", parent, frame, where,
                                                      shape))
        placement = pin.SE3(pin.exp3(rng.normal(0.0, 0.5, 3)), np.array([0.0, 0.0, 0.25]))
    return Robot(name="toy", model=model, collision_model=geometry, visual_model=None,
                 velocity_limits=np.ones(3), acceleration_limits=np.ones(3),
                 tcp_frame="link2")


def _toy_scene(rng: np.random.Generator) -> Scene:
    objects = {}
    for name, shape in (("wall", Shape("box", (0.05, 0.6, 0.6))),
                        ("post", Shape("cylinder", (0.03, 0.8)))):
        T = np.eye(4)
        T[:3, :3] = pin.exp3(rng.normal(0.0, 0.3, 3))
        T[:3, 3] = rng.uniform(-0.4, 0.4, 3) + [0.0, 0.0, 0.3]
        objects[name] = SceneObject(name, shape, T)
    return Scene("toy", "toy", objects, margin=0.0)


@pytest.mark.parametrize(("seed", "axes"), [(k, "z-x-any") for k in range(16)]
                         + [(k, "y-x-z") for k in range(8)])
def test_random_arms_are_judged_as_a_dense_check_judges_them(seed: int, axes: str) -> None:
    """Random arms (a turn, a tilt and a spin about an unaligned axis; or about y, x and
    z), obstacles and joint paths: collisions found alike, and, for a path free of them,
    margins a tenth of a millimetre on either side of its dense clearance judged alike.
    The bounds, the kinematics and the steps they allow must never skip a failing
    sample."""
    rng = np.random.default_rng(seed)
    joints = ([pin.JointModelRY(), pin.JointModelRX(), pin.JointModelRZ()]
              if axes == "y-x-z" else None)
    robot, scene = _toy_arm(rng, joints), _toy_scene(rng)
    q = np.cumsum(rng.normal(0.0, 0.6, (6, 3)), axis=0)
    # Knots 1 ms apart: the controller's join of them strays from the straight joint
    # segments by amax h^2 / 8, which the release criterion allows for: negligible here.
    t = np.arange(len(q), dtype=float) * 1e-3
    zero = dict.fromkeys(scene.objects, 0.0)
    first, _, clearance = _dense(FclVerifier(robot, scene, margin=0.0), q, zero)
    _assert_same_as_dense(FclVerifier(robot, scene, margin=0.0), t, q, zero)
    if first is None:
        for excess in (1e-4, -1e-4):
            margin = clearance + excess
            out = _assert_same_as_dense(FclVerifier(robot, scene, margin=margin), t, q,
                                        dict.fromkeys(scene.objects, margin))
            assert isinstance(out, VerificationError) == (excess > 0)


def _reaching_arm(tip: float) -> Robot:
    """A turn about z, then a slide along the turned x (0 to 0.6 m) carrying a ball of
    radius ``tip`` at its end: the ball's distance to the turn's axis grows with the
    slide."""
    model = pin.Model()
    geometry = pin.GeometryModel()
    turn = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "turn")
    slide = model.addJoint(turn, pin.JointModelPX(), pin.SE3.Identity(), "slide")
    model.lowerPositionLimit[:] = [-np.pi, 0.0]
    model.upperPositionLimit[:] = [np.pi, 0.6]
    frame = model.addFrame(pin.Frame("hand", slide, pin.SE3.Identity(), pin.FrameType.BODY))
    geometry.addGeometryObject(pin.GeometryObject(
        "hand_0", slide, frame, pin.SE3(np.eye(3), np.array([0.05, 0.0, 0.0])),
        coal.Sphere(tip)))
    return Robot(name="reach", model=model, collision_model=geometry, visual_model=None,
                 velocity_limits=np.ones(2), acceleration_limits=np.ones(2),
                 tcp_frame="hand")


@pytest.mark.parametrize("turn", [0.3, 0.8, 1.4])
def test_a_body_sliding_away_from_an_axis_is_judged_as_a_dense_check_judges_it(
        turn: float) -> None:
    """The motion bound counts a body's distance to a joint's axis at the sample its
    bound was taken (plus how far the joints between them move it since), not the
    joint's weight: a ball sliding out while the arm turns sweeps ever faster towards a
    wall it comes closest to at the end. Margins a tenth of a millimetre on either side
    of the dense clearance are judged alike (a third of that distance steps past the
    closest sample: checked)."""
    robot = _reaching_arm(0.02)
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.65 * np.sin(turn) + 0.02 + 0.025 + 0.01, 0.0]  # a wall across y,
    # 1 cm from the ball at the end of the turn
    scene = Scene("wall", "reach", {"wall": SceneObject("wall", Shape("box", (2.0, 0.05, 0.2)),
                                                        T)}, margin=0.0)
    s = np.linspace(0.0, 1.0, 40)[:, None]
    q = np.hstack([turn * s, 0.6 * s ** 3])  # the slide mostly at the end
    # Knots 1 ms apart: the controller's join of them strays from the straight joint
    # segments by amax h^2 / 8, which the release criterion allows for: negligible here.
    t = np.arange(len(q), dtype=float) * 1e-3
    zero = {"wall": 0.0}
    first, _, clearance = _dense(FclVerifier(robot, scene, margin=0.0), q, zero)
    assert first is None and clearance < 0.011
    for excess in (1e-4, -1e-4):
        margin = clearance + excess
        out = _assert_same_as_dense(FclVerifier(robot, scene, margin=margin), t, q,
                                    {"wall": margin})
        assert isinstance(out, VerificationError) == (excess > 0)


def test_a_hull_is_bounded_by_its_own_vertices() -> None:
    """A Panda link's hull against a box, apart: the bound is within a millimetre of
    coal's distance (a hull is measured as itself, not as its bounding box), and never
    above it."""
    from safepath import load_robot

    hulls = [g.geometry for g in load_robot("panda").collision_model.geometryObjects
             if isinstance(g.geometry, coal.ConvexBase)]
    rng = np.random.default_rng(5)
    apart = 0
    for trial in range(120):
        hull, box = hulls[trial % len(hulls)], coal.Box(*rng.uniform(0.05, 0.4, 3))
        poses = _pose_pair(rng, 0.1, 0.4)
        true = coal.distance(hull, coal.Transform3s(poses[0][:3, :3], poses[0][:3, 3]), box,
                             coal.Transform3s(poses[1][:3, :3], poses[1][:3, 3]),
                             coal.DistanceRequest(), coal.DistanceResult())
        bound = bound_between(shape_spec(hull), poses[0], shape_spec(box), poses[1])
        assert bound <= true + 1e-9
        if true > 0.002:
            apart += 1
            assert bound >= true - 1e-3, (trial, bound, true)
    assert apart > 30


def test_a_hulls_support_climbs_to_the_largest_vertex_from_any_start() -> None:
    """The layer's support of a hull climbs the hull's edges instead of scanning every
    vertex: on the Panda's link hulls, for random directions, from random starts, it
    must reach the same value as the scan over all vertices."""
    from safepath import load_robot
    from safepath.verify import _distance as kernel
    from safepath.verify._bounds import climbing, shape_table

    specs = [shape_spec(g.geometry) for g in load_robot("panda").collision_model.geometryObjects
             if isinstance(g.geometry, coal.ConvexBase)]
    assert sum(len(s.vertices) > 50 for s in specs) >= 5
    table, hulls = shape_table(specs)
    hulls = kernel.Hulls(*climbing(hulls))
    V, ptr, nbr = hulls.vertices, hulls.starts, hulls.neighbours
    assert ptr.size == len(V) + 1 and nbr.size == ptr[-1]
    rng = np.random.default_rng(11)
    for k, spec in enumerate(specs):
        first, count = int(table[k, 1]), int(table[k, 2])
        S = kernel.Placed(kind=float(kernel.HULL), par0=float(first),
                          par1=float(count), par2=0.0,
                          radius=spec.radius, cx=0.0, cy=0.0, cz=0.0, r00=1.0, r01=0.0,
                          r02=0.0, r10=0.0, r11=1.0, r12=0.0, r20=0.0, r21=0.0, r22=1.0)
        for _ in range(300):
            hulls.climb[first] = first + int(rng.integers(count))
            n = rng.normal(size=3)
            n /= np.linalg.norm(n)
            want = max(V[i, 0] * n[0] + V[i, 1] * n[1] + V[i, 2] * n[2]
                       for i in range(first, first + count))
            assert kernel.support(S, hulls, n[0], n[1], n[2]) == want


# -- geometry the verifier handles, and refuses before planning --------------------------------
def _with_geometry(robot: Robot, change: dict[str, object]) -> Robot:
    """A copy of ``robot`` whose collision geometries named in ``change`` are replaced."""
    out = copy.copy(robot)
    out.collision_model = robot.collision_model.copy()
    for g in out.collision_model.geometryObjects:
        if g.name in change:
            g.geometry = change[g.name]
    return out


def _box_mesh(box: coal.Box) -> coal.BVHModelOBBRSS:
    """The triangle mesh of a box's surface (12 triangles)."""
    half = np.asarray(box.halfSide)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=3))) * half
    hull = ConvexHull(corners)
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(len(hull.simplices), len(corners))
    mesh.addVertices(corners)
    mesh.addTriangles(hull.simplices.astype(np.int32))
    mesh.endModel()
    return mesh


def test_a_triangle_mesh_is_verified_like_the_shape_it_meshes(detour_cell: Cell) -> None:
    # Every box of the arm as a triangle mesh (as a user's own URDF meshes load): FCL
    # checks the mesh, the conservative layer bounds it by its hull.
    robot = detour_cell.robot
    meshed = _with_geometry(robot, {g.name: _box_mesh(g.geometry)
                                    for g in robot.collision_model.geometryObjects
                                    if isinstance(g.geometry, coal.Box)})
    check_verifiable(meshed, detour_cell.scene)
    piece = _straight(detour_cell, "high1", "high2")
    world = initial_world(detour_cell)
    errors = []
    for arm in (robot, meshed):
        verifier = FclVerifier(arm, detour_cell.scene, held="vial",
                               resting=dict(world.resting))
        with pytest.raises(VerificationError) as info:
            verifier.verify(piece.t, piece.q, piece.qd, steps=[STEP] * len(piece.t))
        errors.append(info.value)
    assert errors[1].time == errors[0].time and errors[1].pairs == errors[0].pairs
    free = _straight(detour_cell, "high1", "safe")
    results = [FclVerifier(arm, None).verify(free.t, free.q, free.qd)
               for arm in (robot, meshed)]
    assert results[1].samples == results[0].samples


def test_unsupported_geometry_is_refused_before_planning_naming_it(
        detour_cell: Cell) -> None:
    odd = _with_geometry(detour_cell.robot, {"forearm_link_0": coal.Ellipsoid(0.05, 0.04, 0.1)})
    for _ in range(2):  # the second from what the robot keeps of the first
        with pytest.raises(ConfigError, match="forearm_link_0.*Ellipsoid") as info:
            check_verifiable(odd, detour_cell.scene)
        assert info.value.key == "forearm_link_0"
    check_verifiable(detour_cell.robot, detour_cell.scene)  # the robot it was made from
    with pytest.raises(ConfigError) as info:
        FclVerifier(odd, detour_cell.scene)
    assert info.value.key == "forearm_link_0"
    cell = dataclasses.replace(detour_cell, robot=odd)
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match="forearm_link_0"):
        plan_cell(cell)
    assert time.perf_counter() - t0 < 1.0  # refused up front, nothing planned


def test_pair_weights_leave_out_exactly_the_joints_that_carry_both_bodies(
        bundled_cell: Cell) -> None:
    """Per pair and joint: a body against the environment moves by its own weight; two
    bodies by the sum of theirs, except for a joint upstream of both (pinocchio's
    ``supports``), which moves them as one piece."""
    robot = bundled_cell.robot
    verifier = _verifier(bundled_cell)
    model, movers = robot.model, verifier.movers
    weights = verifier.motion_weights
    pairs = [(p.first, p.second, p.environment) for p in verifier.pairs]
    got = pair_weights(model, [b.joint for b in movers], weights, pairs)
    assert got.shape == (len(pairs), model.nv)
    np.testing.assert_array_equal(verifier.pair_weights, got)  # what the layer walks
    carriers = [{model.joints[j].idx_v for j in model.supports[b.joint] if j > 0}
                for b in movers]
    assert any(not env and carriers[i] & carriers[j] for i, j, env in pairs)
    for p, (i, j, env) in enumerate(pairs):
        for v in range(model.nv):
            want = (weights[i, v] if env else
                    0.0 if v in carriers[i] & carriers[j] else weights[i, v] + weights[j, v])
            assert got[p, v] == want, (p, v)


@pytest.mark.parametrize("seed", range(3))
def test_a_grid_cut_with_the_undominated_weights_is_the_grid_cut_with_all(
        bundled_cell: Cell, seed: int) -> None:
    """The verifier cuts its grids with the bodies' weights that no other body's bound in
    every joint: the same samples, bit for bit, on random knots (the cell's verifier,
    and random weights with bounded and equal rows)."""
    rng = np.random.default_rng(seed)
    verifier = _verifier(bundled_cell)
    robot = bundled_cell.robot
    q = robot.lower + rng.random((40, robot.model.nq)) * (robot.upper - robot.lower)
    random = rng.random((12, robot.model.nq)) * rng.integers(0, 2, (12, robot.model.nq))
    random = np.vstack([random, random[:3], random[:4] * 0.5])  # equal and bounded rows
    for weights in (verifier.motion_weights, random):
        kept = undominated(weights)
        assert 0 < len(kept) < len(weights)
        for row in weights:  # each row is bounded by a kept one
            assert any((row <= k).all() for k in kept)
        for resolution in (0.002, 0.05):
            want, got = (Grid.cut(q, w, resolution) for w in (weights, kept))
            for name in ("knot_of", "frac", "step", "cum"):
                assert np.array_equal(getattr(want, name), getattr(got, name)), name
    assert len(undominated(verifier.motion_weights)) < len(verifier.motion_weights) / 2


def test_verifiers_of_a_robot_share_its_bodies_and_see_them_change(detour_cell: Cell) -> None:
    """A robot's FCL shapes and motion weights are made once and shared; every verifier
    places collision objects of its own; moving a geometry makes them again."""
    robot = copy.copy(detour_cell.robot)
    robot.collision_model = detour_cell.robot.collision_model.copy()
    robot.derived.forget()
    (a, wa, _), (b, wb, _) = robot_bodies(robot), robot_bodies(robot)
    assert wa is wb and not wa.flags.writeable
    assert all(x.fcl is not y.fcl for x, y in zip(a, b, strict=True))
    geom = robot.collision_model.geometryObjects[2]
    geom.placement = pin.SE3(geom.placement.rotation, geom.placement.translation + 0.05)
    c, wc, _ = robot_bodies(robot)
    assert not np.array_equal(wc, wa)
    assert not np.array_equal(c[2].T, a[2].T)
    robot.derived.forget()
    d, wd, _ = robot_bodies(robot)
    np.testing.assert_array_equal(wd, wc)
    np.testing.assert_array_equal(d[2].T, c[2].T)


def _two_steps(bundled: Plans, a: str, b: str) -> tuple[np.ndarray, np.ndarray, int]:
    """Knot times and positions of phase1's consecutive steps a and b, and the knot where
    b's stage starts (a's last knot)."""
    traj = bundled.trajectories["phase1"]
    ia, ib = traj.steps.index(a), traj.steps.index(b)
    sel = np.flatnonzero((traj.step_index == ia) | (traj.step_index == ib))
    assert np.all(np.diff(sel) == 1)
    start = int(np.argmax(traj.step_index[sel] == ib)) - 1
    return traj.t[sel], traj.q[sel], start


@pytest.mark.parametrize(("dz", "fails"), [(0.0, False), (0.003, True)],
                         ids=["planned", "pressed-in"])
def test_stages_are_judged_as_each_stage_alone_judges_its_stretch(
        bundled: Plans, dz: float, fails: bool) -> None:
    """The move to high2 (no contact allowed), then the line down to the plate (the vial
    may touch it 1 mm deep), checked as one: as a dense check of each stretch under its
    own stage's rules finds, the first failure in time, the clearance to within half a
    resolution; under the first stage's rules alone the put-down fails."""
    from safepath.verify import StagedVerifier

    cell = bundled.cell
    t, q, start = _two_steps(bundled, STEP, "4 line low1")
    scene = _raised(cell, "test_plate", dz)
    resting = dict(initial_world(cell).resting)
    first = FclVerifier(cell.robot, scene, held="vial", resting=resting)
    second = first.with_allowed(cell.scene.contacts_at("low1"))
    margins = _margins(cell, None, True)
    stretches = [(first, slice(0, start + 1)), (second, slice(start, len(t)))]
    dense = [(_dense(v, q[k], margins), t[k], v.grid(q[k])) for v, k in stretches]
    failing = [(float(tk[g.knot_of[f]]), bad) for (f, bad, _), tk, g in dense if f is not None]
    staged = StagedVerifier([first, second])
    try:
        result = staged.verify(t, q, [0, start], steps=["s"] * len(t))
    except VerificationError as err:
        assert failing, f"staged rejects what the stages' dense checks accept: {err}"
        when = min(w for w, _ in failing)
        assert err.time == when
        assert set(err.pairs) == set().union(*(bad for w, bad in failing if w == when))
        assert fails and ("vial", "test_plate") in err.pairs
    else:
        assert not failing and not fails
        clearance = min(c for (_, _, c), _, _ in dense)
        assert clearance - 1e-9 <= result.min_clearance <= clearance + first.resolution / 2
        assert result.samples == sum(g.samples for _, _, g in dense) - 1  # the shared knot
    # The first stage's rules on the whole: the vial must not touch the plate.
    with pytest.raises(VerificationError):
        first.verify(t, q, np.zeros_like(q))


def test_a_pair_in_consecutive_stages_is_walked_across_their_boundary(bundled: Plans) -> None:
    """Where two stages share a pair's rules, the pair is walked once across both: fewer
    bounds than the stages checked one by one, the same judgement and clearance to
    within half a resolution; stages from other world states, or starts not one per
    stage from knot 0, are refused."""
    from safepath.verify import StagedVerifier

    cell = bundled.cell
    t, q, start = _two_steps(bundled, STEP, "4 line low1")
    first = _verifier(cell)
    second = first.with_allowed(cell.scene.contacts_at("low1"))
    staged = StagedVerifier([first, second]).verify(t, q, [0, start])
    alone = [first.verify(t[:start + 1], q[:start + 1], q[:start + 1]),
             second.verify(t[start:], q[start:], q[start:])]
    assert staged.bound_checks < sum(r.bound_checks for r in alone)
    best = min(r.min_clearance for r in alone)
    assert abs(staged.min_clearance - best) <= first.resolution / 2
    # One stage is the verifier itself.
    one = StagedVerifier([second]).verify(t[start:], q[start:], [0])
    assert one == alone[1]
    with pytest.raises(ValueError, match="one world state"):
        StagedVerifier([first, _verifier(cell)])
    with pytest.raises(ValueError, match="one per stage"):
        StagedVerifier([first, second]).verify(t, q, [start, 0])
    with pytest.raises(ValueError, match="one per stage"):
        StagedVerifier([first, second]).verify(t, q, [0])


@pytest.mark.parametrize("seed", range(4))
def test_the_layers_own_kinematics_place_the_bodies_as_pinocchio_does(
        bundled_cell: Cell, seed: int) -> None:
    """The layer's forward kinematics (a turn about a joint's own x, y or z written out,
    any other axis by Rodrigues) place every body where pinocchio does, on the grid and at
    states off it (the check between samples): random toy arms (z, x and an unaligned
    axis; y, x and z) and the Ned3 Pro (z axes)."""
    rng = np.random.default_rng(seed)
    robot, scene = _toy_arm(rng), _toy_scene(rng)
    other = _toy_arm(rng, [pin.JointModelRY(), pin.JointModelRX(), pin.JointModelRZ()])
    for verifier in (FclVerifier(robot, scene), FclVerifier(other, scene),
                     _verifier(bundled_cell)):
        model = verifier.robot.model
        data = model.createData()
        for _ in range(5):
            q = pin.randomConfiguration(model)
            poses = verifier.bounds_at(q).T_world_geom
            pin.forwardKinematics(model, data, q)
            for m, body in enumerate(verifier.movers[:len(poses)]):
                want = (data.oMi[body.joint].homogeneous @ body.T)[:3]
                np.testing.assert_allclose(poses[m], want, atol=1e-12)
        # States off the grid (the check between samples), many at once.
        states = np.array([pin.randomConfiguration(model) for _ in range(6)])
        for m, body in enumerate(verifier.movers):
            placed = verifier.poses_at(states, m)
            for q, got in zip(states, placed, strict=True):
                pin.forwardKinematics(model, data, q)
                want = (data.oMi[body.joint].homogeneous @ body.T)[:3]
                np.testing.assert_allclose(got, want, atol=1e-12)
