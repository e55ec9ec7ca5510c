"""What every collision checker of a robot takes from the robot alone, made once per robot.

The link of each geometry and, per joint, how far its own geometry reaches from its origin
(:func:`robot_part`, for the checker's displacement bound), and the sphere layer's part
of the robot (sphere fits, hull tables: :func:`safepath.collision._pack._robot_part`),
both kept by the robot (:mod:`safepath.files.derived`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..files.derived import DerivedKind
from ..model.robot import Robot, is_prismatic
from ..model.shapes import from_coal
from ._pack import _robot_part
from .options import LayerOptions

__all__ = ["robot_part", "prepare_checkers", "reach_into", "displacement_weights"]

#: The link of each geometry, and per joint how far its own geometry reaches [m].
_LINKS_AND_REACH: DerivedKind[tuple[tuple[str, ...], np.ndarray]] = DerivedKind(
    "collision checker's links and reach")


def robot_part(robot: Robot) -> tuple[tuple[str, ...], np.ndarray]:
    """What every checker of ``robot`` takes from it, made once per robot: the link of
    each geometry, and per joint how far its own geometry reaches from its origin [m]."""
    def make() -> tuple[tuple[str, ...], np.ndarray]:
        geoms = robot.collision_model.geometryObjects
        reach = reach_into(np.zeros(robot.model.njoints), geoms)
        return tuple(map(robot.geometry_link, range(len(geoms)))), reach

    return robot.derived.get(_LINKS_AND_REACH, make)


def prepare_checkers(robot: Robot) -> None:
    """Make what every collision checker of ``robot`` takes from the robot alone: its
    links and reach, and, where the kernels are compiled ahead of time, its sphere
    layer's part (sphere fits, hull tables: read from the disk cache,
    :mod:`safepath.files.derived`, where a process made them before). Without
    them the part waits for the first check, which imports numba anyway. A shape the
    layer cannot fit is left to the checkers (they stay exact)."""
    from .. import _aot

    robot_part(robot)
    if _aot.compiled() is None:
        return
    try:
        _robot_part(robot, LayerOptions())
    except ValueError:
        pass


def reach_into(reach: np.ndarray, geoms: Any) -> np.ndarray:
    """``reach`` (per joint [m]) raised to how far each geometry of ``geoms`` on a joint
    reaches from that joint's origin."""
    for g in geoms:
        if g.parentJoint == 0:
            continue
        r = np.linalg.norm(g.placement.translation) + _bounding_radius(g.geometry)
        reach[g.parentJoint] = max(reach[g.parentJoint], r)
    return reach


def _bounding_radius(geometry: Any) -> float:
    import coal

    primitive = from_coal(geometry)
    if primitive is not None:
        return primitive[0].holding_radius(primitive[1])
    if isinstance(geometry, coal.ConvexBase):
        pts = np.asarray(geometry.points())
        return float(np.max(np.linalg.norm(pts, axis=1)))
    geometry.computeLocalAABB()
    aabb = geometry.aabb_local
    corner = np.maximum(np.abs(aabb.min_), np.abs(aabb.max_))
    return float(np.linalg.norm(corner))


def displacement_weights(model: Any, own_reach: np.ndarray, extra: list[Any]) -> np.ndarray:
    """Per joint, the largest distance [m] of any downstream point from the joint (1 for
    a prismatic joint): the reach of each joint's own geometry about its origin
    (``own_reach``: the robot's, from :func:`robot_part`; then ``extra``, the geometry
    objects added to the robot's, e.g. a held object), propagated from the leaves."""
    nj = model.njoints
    reach = reach_into(own_reach.copy(), extra)
    # Propagate from the leaves: reach(i) >= |origin of child| + reach(child).
    for j in range(nj - 1, 0, -1):
        parent = model.parents[j]
        if parent > 0:
            offset = float(np.linalg.norm(model.jointPlacements[j].translation))
            reach[parent] = max(reach[parent], offset + reach[j])
    w = np.zeros(model.nv)
    for j in range(1, nj):
        w[model.joints[j].idx_v] = 1.0 if is_prismatic(model, j) else reach[j]
    return w
