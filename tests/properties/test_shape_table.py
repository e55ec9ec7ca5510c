"""Property: every layer handles every kind of the shape table (safepath.model.shapes).

For random sizes of each kind: the scene's shape and coal's agree on the kind and size (and
back: coal's primitive reads as the same kind and size), python-fcl's is the same solid
(equal distances to a probe sphere), the twin's MuJoCo geom has the table's type and
half-sizes, and the monitor's distance kernel measures points as coal does. The sphere
fit, a locked joint's travel shape and the page's drawing are measured against coal's
solid: the outer spheres hold its surface, the inner ones lie in it, the travel shape holds
it wherever the joint puts it, and the drawn mesh is closed, turned outwards, on its
surface and as large. (The sphere layer's GJK bounds against each table kind:
``tests/test_gjk.py``.) A kind added to the table without its code in one of these layers,
or with geometry that misses its solid, fails here; a kind added to the table alone (a cone,
defined here) reaches the sphere fit, the travel shapes and the page.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator

import coal
import fcl
import mujoco
import numpy as np
import pinocchio as pin
import pytest
import viser
from hypothesis import given
from hypothesis import strategies as st

from safepath.collision.spheres import fit_spheres, surface_points
from safepath.model._locked import lock_joints
from safepath.model._solids import SLACK, revolve
from safepath.model.scene import SceneObject, Shape
from safepath.model.shapes import SHAPES, ShapeKind, from_coal
from safepath.monitor import _kernels
from safepath.monitor.elements import scene_arrays
from safepath.sim.model import build_robot_model
from safepath.view.scene_nodes import add_shape, coal_shape

from .strategies import bounded, bundled_cell

KINDS = list(SHAPES.values())
#: Radius of the probe sphere the solids are measured from [m].
PROBE = 0.01


def _sizes(kind: ShapeKind) -> st.SearchStrategy[tuple[float, ...]]:
    return st.tuples(*(st.floats(0.01, 0.5) for _ in kind.size_names))


def _placed(seed: int) -> np.ndarray:
    """A random rigid placement (4x4) within 0.5 m of the origin."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    T = np.eye(4)  # noqa: N806
    T[:3, :3] = coal.Quaternion(*(q / np.linalg.norm(q))).toRotationMatrix()
    T[:3, 3] = rng.uniform(-0.5, 0.5, 3)
    return T


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_coal_and_fcl_build_the_same_solid(kind: ShapeKind) -> None:
    @bounded(40)
    @given(size=_sizes(kind), probe=st.tuples(*(st.floats(-1.0, 1.0),) * 3))
    def same(size: tuple[float, ...], probe: tuple[float, float, float]) -> None:
        shape = Shape(kind.name, size)  # type: ignore[arg-type]
        solid = shape.to_coal()
        found = from_coal(solid)
        assert found is not None and found[0] is kind
        assert coal_shape(solid) == (kind.name, pytest.approx(shape.size, abs=1e-12))
        ball = coal.Sphere(PROBE)
        at = coal.Transform3s(np.eye(3), np.array(probe))
        want = coal.distance(solid, coal.Transform3s(), ball, at, coal.DistanceRequest(),
                             coal.DistanceResult())
        got = fcl.distance(fcl.CollisionObject(kind.to_fcl(size)),
                           fcl.CollisionObject(fcl.Sphere(PROBE), fcl.Transform(np.array(probe))),
                           fcl.DistanceRequest(), fcl.DistanceResult())
        if want > 1e-3:  # fcl reports -1 for overlaps
            assert got == pytest.approx(want, abs=1e-4)

    same()


def _cell_with_every_kind(sizes: dict[str, tuple[float, ...]], seed: int):  # type: ignore[no-untyped-def]
    cell = bundled_cell("panda")
    objects = {f"probe_{name}": SceneObject(f"probe_{name}", Shape(name, size),  # type: ignore[arg-type]
                                            _placed(seed + i))
               for i, (name, size) in enumerate(sizes.items())}
    return dataclasses.replace(cell, scene=dataclasses.replace(cell.scene, objects=objects))


def test_the_twin_and_the_monitor_take_every_kind() -> None:
    @bounded(25)
    @given(sizes=st.fixed_dictionaries({k.name: _sizes(k) for k in KINDS}),
           seed=st.integers(0, 2**16), points=st.lists(st.tuples(*(st.floats(-1.5, 1.5),) * 3),
                                                       min_size=1, max_size=20))
    def handled(sizes: dict[str, tuple[float, ...]], seed: int,
                points: list[tuple[float, float, float]]) -> None:
        cell = _cell_with_every_kind(sizes, seed)
        twin = build_robot_model(cell.robot, cell.scene).model
        kinds, Ts, dims = scene_arrays(cell)  # noqa: N806
        objects = list(cell.scene.objects.values())
        assert len(objects) == len(kinds) == len(KINDS)
        for obj, code, half in zip(objects, kinds, dims, strict=True):
            kind = SHAPES[obj.shape.kind]
            assert code == kind.code
            g = mujoco.mj_name2id(twin, mujoco.mjtObj.mjOBJ_GEOM, f"cell/{obj.name}")
            assert g >= 0
            assert mujoco.mjtGeom(twin.geom_type[g]).name == f"mjGEOM_{kind.mujoco.upper()}"
            assert twin.geom_size[g][:kind.mujoco_params] == pytest.approx(
                half[:kind.mujoco_params], rel=1e-9)
        P = np.array(points, dtype=float)  # noqa: N806
        reach = np.array([o.shape.bounding_radius() for o in objects])
        out = np.empty(len(P))
        _kernels.scene_distance(P, kinds, Ts, dims, reach, np.inf, out)
        ball = coal.Sphere(PROBE)
        for p, d in zip(P, out, strict=True):
            want = min(coal.distance(o.shape.to_coal(), coal.Transform3s(o.T_world_object[:3, :3],
                                                                          o.T_world_object[:3, 3]),
                                     ball, coal.Transform3s(np.eye(3), p),
                                     coal.DistanceRequest(), coal.DistanceResult()) + PROBE
                       for o in objects)
            if want > 2 * PROBE:
                assert d == pytest.approx(want, abs=1e-6)

    handled()


def _signed_distance(geometry: object, points: np.ndarray) -> np.ndarray:
    """coal's signed distance [m] from each point (< 0 inside) to a solid at the origin."""
    dot, at = coal.Sphere(0.0), coal.Transform3s()
    return np.array([coal.distance(geometry, at, dot, coal.Transform3s(np.eye(3), p),
                                   coal.DistanceRequest(), coal.DistanceResult())
                     for p in points])


def _fit_holds(geometry: object, cell: float, rng: np.random.Generator) -> None:
    """The sphere fit's outer spheres hold coal's surface points and points inside, its
    inner spheres lie inside the solid."""
    fit = fit_spheres(geometry, cell=cell)
    surface = surface_points(geometry, 300, rng)
    middle = surface.mean(axis=0)
    inside = middle + (surface - middle) * rng.random((len(surface), 1))
    for points in (surface, inside):
        d = np.linalg.norm(points[:, None, :] - fit.outer_centers[None], axis=2)
        held = np.any(d <= fit.outer_radii[None, :], axis=1)
        assert held.all(), f"{np.sum(~held)} points of the solid outside the outer spheres"
    if len(fit.inner_radii):
        v = rng.normal(size=(200, 3))
        which = rng.integers(len(fit.inner_radii), size=len(v))
        rim = fit.inner_centers[which] + fit.inner_radii[which, None] * (
            v / np.linalg.norm(v, axis=1, keepdims=True))
        assert _signed_distance(geometry, rim).max() <= 1e-9, "an inner sphere leaves the solid"


def _travel_holds(geometry: object, rng: np.random.Generator) -> None:
    """A joint whose link carries ``geometry``, locked over its whole travel: the travel
    shape holds coal's solid wherever the joint puts it."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0.1, 0.0, 0.0])),
                           "finger", np.ones(1), np.ones(1), np.zeros(1), np.full(1, 0.4))
    placement = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)),
                        rng.uniform(-0.05, 0.05, 3))
    geom = pin.GeometryModel()
    geom.addGeometryObject(pin.GeometryObject("link", joint, model.addJointFrame(joint),
                                              placement, geometry))
    reduced, (travel_geom,), _ = lock_joints(model, [geom], [], None, mimics={})
    travel = travel_geom.geometryObjects[0]
    assert reduced.njoints == 1 and travel.parentJoint == 0
    data = model.createData()
    local = surface_points(geometry, 60, rng)
    for q in np.linspace(0.0, 0.4, 5):
        pin.forwardKinematics(model, data, np.array([q]))
        T = (travel.placement.actInv(data.oMi[joint] * placement)).homogeneous  # noqa: N806
        worst = _signed_distance(travel.geometry, local @ T[:3, :3].T + T[:3, 3]).max()
        assert worst <= 1e-6, f"a point {worst * 1e3:.3f} mm outside the travel shape"


def _drawn_as(node: object, geometry: object) -> None:
    """The drawn mesh is closed and turned outwards, its vertices lie on coal's solid (about
    its origin), and it is as large: the same box around it, at least 97 % of its volume
    (no more)."""
    vertices = np.asarray(node.root.vertices, dtype=float)  # type: ignore[attr-defined]
    faces = np.asarray(node.root.faces)  # type: ignore[attr-defined]
    _, weld = np.unique(np.round(vertices, 6), axis=0, return_inverse=True)
    tris = weld.reshape(-1)[faces]
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2])
                & (tris[:, 0] != tris[:, 2])]
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    directed = {tuple(e) for e in edges}
    assert len(directed) == len(edges), "an edge is walked twice the same way"
    assert all((b, a) in directed for a, b in directed), "the mesh is not closed"
    # On the surface: not outside, and outside 10 um farther from the centre (coal's
    # distance inside a cylinder ignores its caps: only its sign is used there).
    away = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    assert _signed_distance(geometry, vertices).max() <= 1e-6
    assert _signed_distance(geometry, vertices + 1e-5 * away).min() > 0
    geometry.computeLocalAABB()  # type: ignore[attr-defined]
    box = geometry.aabb_local  # type: ignore[attr-defined]
    np.testing.assert_allclose(vertices.min(axis=0), box.min_, atol=1e-6)
    np.testing.assert_allclose(vertices.max(axis=0), box.max_, atol=1e-6)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)
    assert 0.97 <= volume / geometry.computeVolume() <= 1 + 1e-5  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def server() -> Iterator[viser.ViserServer]:
    page = viser.ViserServer(host="127.0.0.1", port=0)
    yield page
    page.stop()


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_the_sphere_fit_and_the_travel_shapes_hold_every_kind(kind: ShapeKind) -> None:
    @bounded(20)
    @given(size=_sizes(kind), cell=st.sampled_from([0.015, 0.03]), seed=st.integers(0, 2**16))
    def held(size: tuple[float, ...], cell: float, seed: int) -> None:
        rng = np.random.default_rng(seed)
        solid = Shape(kind.name, size).to_coal()  # type: ignore[arg-type]
        _fit_holds(solid, cell, rng)
        _travel_holds(solid, rng)

    held()


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_the_page_draws_every_kind(kind: ShapeKind, server: viser.ViserServer) -> None:
    @bounded(20)
    @given(size=_sizes(kind))
    def drawn(size: tuple[float, ...]) -> None:
        node = add_shape(server, f"/probe/{kind.name}", kind.name, kind.name, size,
                         (0.5, 0.5, 0.5))
        assert node is not None, kind.name
        _drawn_as(node, Shape(kind.name, size).to_coal())  # type: ignore[arg-type]

    drawn()


def _cone_points(h: np.ndarray) -> np.ndarray:
    """The apex and a 24-gon circumscribing the base."""
    a = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    r = h[0] / math.cos(math.pi / 24)
    base = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(24, -h[1])])
    return np.vstack([base, [[0.0, 0.0, h[1]]]])


#: A kind the library does not have: a cone along z (coal's: the base at -length / 2),
#: fitted by one sphere about its origin.
CONE = ShapeKind(
    "cone", 4, ("radius", "length"), ("radius", "length"), "Cone", "Cone", "mesh",
    half=lambda s: np.array([s[0], s[1] / 2, 0.0]), size=lambda h: (h[0], 2 * h[1]),
    mujoco_params=2, bounding_radius=lambda s: float(np.hypot(s[0], s[1] / 2)),
    holding_radius=lambda h: float(np.hypot(h[0], h[1])),
    coal_half=lambda g: np.array([g.radius, g.halfLength, 0.0]),
    sphere_fit=lambda h, cell: (np.zeros((1, 3)), np.array([np.hypot(h[0], h[1]) + SLACK]),
                                np.zeros((0, 3)), np.zeros(0)),
    enclosing_points=_cone_points,
    mesh=lambda h: revolve([np.array([[0.0, -h[1]], [h[0], -h[1]]]),
                            np.array([[h[0], -h[1]], [0.0, h[1]]])]))


def test_a_kind_added_to_the_table_alone_is_fitted_locked_and_drawn(
        monkeypatch: pytest.MonkeyPatch, server: viser.ViserServer) -> None:
    """The issue's promise for these three layers: a new kind is its row, nothing else."""
    monkeypatch.setitem(SHAPES, CONE.name, CONE)
    rng = np.random.default_rng(4)
    for size in ((0.05, 0.2), (0.3, 0.04)):
        solid = coal.Cone(*size)
        assert from_coal(solid) is not None
        _fit_holds(solid, 0.015, rng)
        _travel_holds(solid, rng)
        node = add_shape(server, "/probe/cone", "cone", "cone", size, (0.5, 0.5, 0.5))
        assert node is not None
        _drawn_as(node, solid)
