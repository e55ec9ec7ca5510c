"""Property: every layer handles every kind of the shape table (safepath.model.shapes).

For random sizes of each kind: the scene's shape and coal's agree on the kind and size (and
back: coal's primitive reads as the same kind and size), python-fcl's is the same solid
(equal distances to a probe sphere), the twin's MuJoCo geom has the table's type and
half-sizes, the page draws it, and the monitor's distance kernel measures points as coal
does. (The sphere layer's GJK bounds against each table kind: ``tests/test_gjk.py``.) A
kind added to the table without its code in one of these layers fails here.
"""

from __future__ import annotations

import dataclasses

import coal
import fcl
import mujoco
import numpy as np
import pytest
import viser
from hypothesis import given
from hypothesis import strategies as st

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


def test_the_page_draws_every_kind() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0)
    try:
        for kind in KINDS:
            size = tuple(0.1 for _ in kind.size_names)
            node = add_shape(server, f"/probe/{kind.name}", kind.name, kind.name, size,
                             (0.5, 0.5, 0.5))
            assert node is not None, kind.name
    finally:
        server.stop()
