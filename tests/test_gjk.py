"""GJK's distance lower bound (the sphere layer's measure for convex hulls) against coal.

For random placements of a Panda link hull against boxes, cylinders, spheres, capsules
and another hull: the bound never exceeds coal's distance (it is a lower bound, the
soundness the layer rests on), and where the shapes are apart it is tight (GJK
converged to within its tolerance), so hull links near obstacles are decided without
coal.
"""

from __future__ import annotations

import coal
import numpy as np
import pytest

from safepath import load_robot
from safepath._gjk import (
    BOX,
    CAPSULE,
    CYLINDER,
    HULL,
    SPHERE,
    TOL,
    distance_lower_bound,
    vertices_of,
)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return coal.Quaternion(*q).toRotationMatrix()


def _coal_distance(a: object, Ta: coal.Transform3s, b: object, Tb: coal.Transform3s) -> float:
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    return float(coal.distance(a, Ta, b, Tb, req, res))


@pytest.fixture(scope="module")
def hulls() -> list[coal.ConvexBase]:
    robot = load_robot("panda")
    shapes = [g.geometry for g in robot.collision_model.geometryObjects
              if isinstance(g.geometry, coal.ConvexBase)]
    assert len(shapes) >= 5
    return shapes


def _primitive(kind: int, rng: np.random.Generator) -> tuple[object, np.ndarray]:
    a, b, c = rng.uniform(0.02, 0.2, 3)
    if kind == BOX:
        return coal.Box(2 * a, 2 * b, 2 * c), np.array([a, b, c])
    if kind == CYLINDER:
        return coal.Cylinder(a, 2 * b), np.array([a, b, 0.0])
    if kind == CAPSULE:
        return coal.Capsule(a, 2 * b), np.array([a, b, 0.0])
    return coal.Sphere(a), np.array([a, 0.0, 0.0])


@pytest.mark.parametrize("other", [BOX, CYLINDER, SPHERE, CAPSULE, HULL])
def test_bound_is_below_coal_and_tight_when_apart(hulls: list, other: int) -> None:
    rng = np.random.default_rng(11 + other)
    scratch = [np.empty((4, 3)), np.empty(3), np.empty(3), np.empty(3), np.empty(3)]
    apart = tight = 0
    for trial in range(400):
        ha = hulls[trial % len(hulls)]
        va = vertices_of(np.asarray(ha.points()))
        if other == HULL:
            hb = hulls[(trial * 7 + 3) % len(hulls)]
            vb = vertices_of(np.asarray(hb.points()))
            shape_b, db = hb, np.zeros(3)
        else:
            shape_b, db = _primitive(other, rng)
            vb = np.zeros((0, 3))
        fb = np.concatenate([va.ravel(), vb.ravel()])
        Ra, Rb = _random_rotation(rng), _random_rotation(rng)
        pa, pb = rng.uniform(-0.25, 0.25, 3), rng.uniform(-0.25, 0.25, 3)
        true = _coal_distance(ha, coal.Transform3s(Ra, pa), shape_b, coal.Transform3s(Rb, pb))
        lb = distance_lower_bound(HULL, Ra, pa, np.zeros(3), 0, len(va), other, Rb, pb, db,
                                  len(va), len(va) + len(vb), fb, 0, np.zeros(3), *scratch,
                                  -1e300, 1e300)
        assert lb <= true + 1e-9, (trial, lb, true)
        if true > 1e-3:
            apart += 1
            tight += lb >= true - TOL - 1e-9
    assert apart > 50
    assert tight == apart, f"{apart - tight} of {apart} separated cases not tight"


def test_search_stops_at_the_callers_thresholds(hulls: list) -> None:
    """``high``: stop once the bound suffices (still a lower bound); ``low``: stop once
    the distance is known to be below it."""
    va = vertices_of(np.asarray(hulls[2].points()))
    box, db = coal.Box(0.2, 0.2, 0.2), np.array([0.1, 0.1, 0.1])
    R = np.eye(3)
    pa, pb = np.zeros(3), np.array([0.6, 0.0, 0.0])
    true = _coal_distance(hulls[2], coal.Transform3s(R, pa), box, coal.Transform3s(R, pb))
    scratch = [np.empty((4, 3)), np.empty(3), np.empty(3), np.empty(3), np.empty(3)]
    args = (HULL, R, pa, np.zeros(3), 0, len(va), BOX, R, pb, db, 0, 0, va.ravel(), 0)
    full = distance_lower_bound(*args, np.zeros(3), *scratch, -1e300, 1e300)
    assert true - TOL <= full <= true + 1e-9
    enough = distance_lower_bound(*args, np.zeros(3), *scratch, -1e300, 0.05)
    assert 0.05 <= enough <= true + 1e-9
    hopeless = distance_lower_bound(*args, np.zeros(3), *scratch, true + 0.1, 1e300)
    assert hopeless <= true + 1e-9
