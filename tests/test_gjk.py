"""GJK's distance bounds (the sphere layer's measures for convex hulls) against coal.

For random placements of a Panda link hull against boxes, cylinders, spheres, capsules
and another hull: the bound never exceeds coal's distance (it is a lower bound, the
soundness the layer rests on), and where the shapes are apart it is tight (GJK
converged to within its tolerance), so hull links near obstacles are decided without
coal. Its upper bound on the signed distance (the layer's proof of a collision) never
falls below coal's signed distance, and proves most overlaps deeper than a millimetre.
"""

from __future__ import annotations

import coal
import numpy as np
import pytest

from safepath import load_robot
from safepath.collision._gjk import (
    HULL,
    TOL,
    distance_lower_bound,
    distance_upper_bound,
)
from safepath.collision._probe import Placed, hull_block, pair_buffers
from safepath.model.shapes import SHAPES, from_code


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


def _primitive(code: int, rng: np.random.Generator) -> tuple[object, np.ndarray]:
    """A random primitive of the shape table's kind ``code``: coal's, and its kernel
    parameters [m]."""
    kind = from_code(code)
    size = kind.size(kind.half(tuple(rng.uniform(0.04, 0.4, len(kind.size_names)))))
    return kind.to_coal(size), kind.half(size)


def _search(bound: object, ka: int, Ra: np.ndarray, pa: np.ndarray, da: np.ndarray,
            kb: int, Rb: np.ndarray, pb: np.ndarray, db: np.ndarray, hulls: list,
            *limits: float) -> float:
    """``bound`` (a GJK search of ``safepath.collision._gjk``) on shapes A and B, the hulls among
    them in ``hulls`` (in order), with fresh hints and scratch, searched to ``limits``."""
    found = iter(hulls)
    a, b = (Placed(k, R, p, d, np.asarray(next(found).points()) if k == HULL else None)
            for k, R, p, d in ((ka, Ra, pa, da), (kb, Rb, pb, db)))
    return bound(*pair_buffers(a, b), 0, *limits)  # type: ignore[operator, no-any-return]


def _bound(ka: int, Ra: np.ndarray, pa: np.ndarray, da: np.ndarray, kb: int,
           Rb: np.ndarray, pb: np.ndarray, db: np.ndarray, hulls: list,
           low: float = -1e300, high: float = 1e300) -> float:
    return _search(distance_lower_bound, ka, Ra, pa, da, kb, Rb, pb, db, hulls, low, high)


def _upper(ka: int, Ra: np.ndarray, pa: np.ndarray, da: np.ndarray, kb: int,
           Rb: np.ndarray, pb: np.ndarray, db: np.ndarray, hulls: list, goal: float) -> float:
    return _search(distance_upper_bound, ka, Ra, pa, da, kb, Rb, pb, db, hulls, goal)


def _random_pair(hulls: list, other: int, rng: np.random.Generator, trial: int,
                 partner: int, spread: float) -> tuple:
    """Hull ``trial`` (cycling) of ``hulls`` against hull ``partner`` or a random primitive
    of kind ``other``, both turned at random and placed within ``spread`` [m] of the
    origin: (hull a, shape b, b's dimensions, the hulls the search reads, Ra, pa, Rb,
    pb)."""
    ha = hulls[trial % len(hulls)]
    if other == HULL:
        hb = hulls[partner]
        shape_b, db, both = hb, np.zeros(3), [ha, hb]
    else:
        shape_b, db = _primitive(other, rng)
        both = [ha]
    Ra, Rb = _random_rotation(rng), _random_rotation(rng)
    pa, pb = rng.uniform(-spread, spread, 3), rng.uniform(-spread, spread, 3)
    return ha, shape_b, db, both, Ra, pa, Rb, pb


def _signed_distance(a: object, Ta: coal.Transform3s, b: object, Tb: coal.Transform3s
                     ) -> float:
    """coal's distance, negative by the penetration depth where the shapes overlap."""
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    req.enable_signed_distance = True
    return float(coal.distance(a, Ta, b, Tb, req, res))


@pytest.mark.parametrize("other", [*(kind.code for kind in SHAPES.values()), HULL])
def test_upper_bound_is_above_coal_and_proves_overlaps(hulls: list, other: int) -> None:
    rng = np.random.default_rng(23 + other)
    overlaps = proven = near = 0
    for trial in range(600):
        spread = 0.08 if other == HULL else 0.15  # two links: mostly apart otherwise
        ha, shape_b, db, both, Ra, pa, Rb, pb = _random_pair(
            hulls, other, rng, trial, (trial * 5 + 1) % len(hulls), spread)
        true = _signed_distance(ha, coal.Transform3s(Ra, pa), shape_b,
                                coal.Transform3s(Rb, pb))
        goal = 0.0 if trial % 2 else 0.01  # a contact, and a 10 mm margin
        ub = _upper(HULL, Ra, pa, np.zeros(3), other, Rb, pb, db, both, goal)
        # A bound that proves (below the goal) is never below coal's signed distance
        # (within coal's own tolerance); a bound that does not is at least the goal.
        assert ub >= true - 1e-6 or ub >= goal, (trial, ub, true)
        if ub >= goal:
            near += abs(true - goal) < 1e-3
        if true < goal - 1e-3:
            overlaps += 1
            proven += ub < goal
    assert overlaps > 100
    assert proven >= 0.95 * overlaps, f"{overlaps - proven} of {overlaps} not proven"


@pytest.mark.parametrize("other", [*(kind.code for kind in SHAPES.values()), HULL])
def test_bound_is_below_coal_and_tight_when_apart(hulls: list, other: int) -> None:
    rng = np.random.default_rng(11 + other)
    apart = tight = 0
    for trial in range(400):
        ha, shape_b, db, both, Ra, pa, Rb, pb = _random_pair(
            hulls, other, rng, trial, (trial * 7 + 3) % len(hulls), 0.25)
        true = _coal_distance(ha, coal.Transform3s(Ra, pa), shape_b, coal.Transform3s(Rb, pb))
        lb = _bound(HULL, Ra, pa, np.zeros(3), other, Rb, pb, db, both)
        assert lb <= true + 1e-9, (trial, lb, true)
        if true > 1e-3:
            apart += 1
            tight += lb >= true - TOL - 1e-9
    assert apart > 50
    assert tight == apart, f"{apart - tight} of {apart} separated cases not tight"


def test_search_stops_at_the_callers_thresholds(hulls: list) -> None:
    """``high``: stop once the bound suffices (still a lower bound); ``low``: stop once
    the distance is known to be below it."""
    box, db = coal.Box(0.2, 0.2, 0.2), np.array([0.1, 0.1, 0.1])
    R = np.eye(3)
    pa, pb = np.zeros(3), np.array([0.6, 0.0, 0.0])
    true = _coal_distance(hulls[2], coal.Transform3s(R, pa), box, coal.Transform3s(R, pb))
    args = (HULL, R, pa, np.zeros(3), SHAPES["box"].code, R, pb, db, [hulls[2]])
    full = _bound(*args)
    assert true - TOL <= full <= true + 1e-9
    enough = _bound(*args, high=0.05)
    assert 0.05 <= enough <= true + 1e-9
    hopeless = _bound(*args, low=true + 0.1)
    assert hopeless <= true + 1e-9


def test_edge_climbing_finds_the_farthest_vertex(hulls: list) -> None:
    """The support search climbs the hull's edges from any start: it must find the same
    farthest vertex as scanning them all."""
    from safepath.collision._gjk import climb

    rng = np.random.default_rng(3)
    for shape in hulls:
        fb, ib, _ = hull_block([np.asarray(shape.points())])
        v = fb.reshape(-1, 3)
        for _ in range(200):
            n = rng.normal(size=3)
            start = int(rng.integers(len(v)))
            found = climb(fb, ib, 0, len(v), start, *n)
            assert v[found] @ n == pytest.approx(np.max(v @ n), abs=1e-12)
