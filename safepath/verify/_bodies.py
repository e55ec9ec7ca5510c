"""The verifier's bodies: FCL objects and layer shapes built from the robot's collision
geometry, the held object and the scene, and the check that refuses what the verifier
cannot handle before anything is planned."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..files.derived import DerivedKind
from ..model.robot import Robot, is_prismatic
from ..model.scene import Scene, Shape
from ..model.shapes import from_coal
from ._bounds import (
    ShapeSpec,
    joint_kind,
    joint_tables,
    motion_weights,
    shape_spec,
    unsupported_geometry,
)

__all__ = ["Body", "check_verifiable", "unverifiable", "fcl_shape", "robot_bodies",
           "held_bodies", "environment_bodies", "prepare_verifiers"]


def _supported(geometry: object) -> bool:
    import coal

    return isinstance(geometry, (coal.Box, coal.Sphere, coal.Cylinder, coal.Capsule,
                                 coal.ConvexBase, coal.BVHModelBase))


def check_verifiable(robot: Robot, scene: Scene | None = None) -> None:
    """Refuse, before anything is planned, what the independent verifier cannot check
    (a trajectory it cannot check is never released, so planning would be in vain).

    Raises:
        ConfigError: A collision geometry of the robot or the scene, or a joint, the
            verifier does not handle; names it (``key``). The first of
            :func:`unverifiable`.
    """
    refused = unverifiable(robot, scene)
    if refused:
        raise refused[0]


def unverifiable(robot: Robot, scene: Scene | None = None) -> list[ConfigError]:
    """What the independent verifier cannot check of ``robot`` (and ``scene``), each as
    the error that refuses it (names it, ``key``): a collision geometry of a kind it does
    not handle, a joint other than a 1-dof revolute or prismatic one, a prismatic joint
    without position limits that moves a geometry. Empty: it checks all of it."""
    geometries, joints = robot.derived.get(ROBOT_REFUSALS, lambda: _robot_refusals(robot))
    refused = list(geometries)
    for obj in (scene.objects.values() if scene is not None else ()):
        shape = obj.shape.to_coal()
        if not _supported(shape):
            refused.append(unsupported_geometry(shape, obj.name))
    return refused + list(joints)


#: What the verifier cannot check of a robot (:func:`unverifiable`): its geometries', then
#: its joints' refusals, kept by the robot (read before every plan, they walk every
#: geometry and joint: ~0.2 ms on the Panda).
ROBOT_REFUSALS: DerivedKind[tuple[tuple[ConfigError, ...], tuple[ConfigError, ...]]] = \
    DerivedKind("what the release check cannot check of the robot")


def _robot_refusals(robot: Robot) -> tuple[tuple[ConfigError, ...], tuple[ConfigError, ...]]:
    """The robot's part of :func:`unverifiable`: the refusals of its geometries, and those
    of its joints."""
    model = robot.model
    geometries = tuple(unsupported_geometry(g.geometry, g.name)
                       for g in robot.collision_model.geometryObjects
                       if not _supported(g.geometry))
    refused: list[ConfigError] = []
    moving: set[int] = set()  # the joints that move a geometry
    for g in robot.collision_model.geometryObjects:
        j = int(g.parentJoint)
        while j > 0:
            moving.add(j)
            j = int(model.parents[j])
    for j in range(1, model.njoints):
        try:
            joint_kind(model, j)
        except ConfigError as exc:  # collected: each refusal names its joint
            refused.append(exc)
            continue
        if j in moving and is_prismatic(model, j):
            v = model.joints[j].idx_v
            stroke = max(abs(model.lowerPositionLimit[v]), abs(model.upperPositionLimit[v]))
            if not np.isfinite(stroke):  # the motion weights need a bound on its offset
                refused.append(ConfigError(f"prismatic joint '{model.names[j]}' has no "
                                           "position limits", key=model.names[j]))
    return geometries, tuple(refused)


def fcl_shape(geometry: object, name: str = "") -> object:
    """The python-fcl shape of a coal collision geometry (a mesh: FCL's own BVH of its
    triangles; ``name`` names it in the error).

    Raises:
        ConfigError: A geometry the verifier does not handle.
    """
    import coal
    import fcl

    primitive = from_coal(geometry)
    if primitive is not None:
        kind, half = primitive
        return kind.to_fcl(kind.size(half))
    if isinstance(geometry, coal.ConvexBase):
        pts = np.asarray(geometry.points(), dtype=float)
        from scipy.spatial import ConvexHull

        hull = ConvexHull(pts)
        faces = np.hstack([np.full((len(hull.simplices), 1), 3), hull.simplices]).ravel()
        return fcl.Convex(pts, len(hull.simplices), faces)
    if isinstance(geometry, coal.BVHModelBase):
        mesh = fcl.BVHModel()
        triangles = np.array([[t[0], t[1], t[2]] for t in
                              (geometry.tri_indices(k) for k in range(geometry.num_tris))],
                             dtype=np.int64).reshape(-1, 3)
        mesh.beginModel(geometry.num_vertices, geometry.num_tris)
        mesh.addSubModel(np.asarray(geometry.vertices(), dtype=float), triangles)
        mesh.endModel()
        return mesh
    raise unsupported_geometry(geometry, name)


@dataclass(frozen=True)
class Body:
    """A moving body (robot geometry or held object) or an environment object."""

    name: str
    joint: int  # 0 for the environment and bodies fixed to the base
    T: np.ndarray  # in its joint frame (movers) or in the world (environment), 4 x 4
    fcl: object
    spec: ShapeSpec

    def distances(self, other: Body, poses: Iterable[np.ndarray]) -> np.ndarray:
        """FCL's distances [m] between this body, placed at each world pose of
        ``poses`` (3 x 4; it is left at the last), and ``other`` where it is."""
        import fcl

        body, request = self.fcl, fcl.DistanceRequest()
        # A result python-fcl never fills (it keeps the smaller distance, and this one's
        # is -inf): filling one (nearest points, geometries) costs a third of a call.
        unread = fcl.DistanceResult(-np.inf)
        out = []
        for T in poses:
            body.setTransform(fcl.Transform(T[:, :3], T[:, 3]))  # type: ignore[attr-defined]
            out.append(fcl.distance(body, other.fcl, request, unread))
        return np.array(out, dtype=float)


def _body(name: str, joint: int, T: np.ndarray, geometry: object, label: str = "",
          shape: object = None, spec: ShapeSpec | None = None) -> Body:
    """A body named ``name`` (its link or object: the pairs' names); ``label`` names its
    geometry in errors (default: ``name``); ``shape``, ``spec``: its FCL shape and layer
    shape, if made before."""
    import fcl

    T = np.asarray(T, dtype=float)
    if shape is None:
        shape = fcl_shape(geometry, label or name)
    obj = fcl.CollisionObject(shape, fcl.Transform(T[:3, :3], T[:3, 3]))
    return Body(name, joint, T, obj, spec or shape_spec(geometry, label or name))


#: The robot's bodies, their FCL shapes, motion weights and joint tables (see
#: :func:`robot_bodies`).
_BODIES: DerivedKind[tuple[list[Body], list[object], np.ndarray, tuple[np.ndarray, ...]]] = \
    DerivedKind("release verifier's bodies")


def robot_bodies(robot: Robot) -> tuple[list[Body], np.ndarray, tuple[np.ndarray, ...]]:
    """The robot's collision geometries, each on its joint, their motion weights
    (:func:`motion_weights`: (bodies, dof), read-only) and the robot's
    :func:`joint_tables`.

    The FCL shapes and layer shapes are made once per robot and shared (an FCL collision
    object keeps a reference to its shape and never frees it); every verifier gets
    collision objects of its own, as it places them.
    """
    import fcl

    def make() -> tuple[list[Body], list[object], np.ndarray, tuple[np.ndarray, ...]]:
        geoms = list(robot.collision_model.geometryObjects)
        shapes = [fcl_shape(g.geometry, g.name) for g in geoms]
        bodies = [_body(robot.model.frames[g.parentFrame].name, int(g.parentJoint),
                        g.placement.homogeneous, g.geometry, g.name, shape)
                  for g, shape in zip(geoms, shapes, strict=True)]
        weights = motion_weights(robot.model, [b.joint for b in bodies],
                                 [b.T for b in bodies], [b.spec for b in bodies])
        weights.flags.writeable = False
        return bodies, shapes, weights, joint_tables(robot.model)

    bodies, shapes, weights, tables = robot.derived.get(_BODIES, make)
    return [Body(b.name, b.joint, b.T, fcl.CollisionObject(
        shape, fcl.Transform(b.T[:3, :3], b.T[:3, 3])), b.spec)
        for b, shape in zip(bodies, shapes, strict=True)], weights, tables


def prepare_verifiers(robot: Robot) -> None:
    """Make what every verifier of ``robot`` takes from the robot alone (its FCL shapes,
    layer shapes, motion weights and joint tables; kept by the robot), as loading a cell
    does so that its first plan pays for planning only.

    Raises:
        ConfigError: A geometry or joint the verifier does not handle (see
            :func:`unverifiable`, which lists them without raising).
    """
    robot_bodies(robot)


def held_bodies(robot: Robot, scene: Scene | None, held: str | None) -> list[Body]:
    """The held object, on the TCP's joint where the scene's grasp holds it (or none)."""
    if held is None or scene is None or scene.grasp is None:
        return []
    tcp = robot.model.frames[robot.tcp_frame_id]
    T_joint_obj = tcp.placement.homogeneous @ scene.grasp.T_tcp_object
    return [_body(held, int(tcp.parentJoint), T_joint_obj, scene.objects[held].shape.to_coal())]


def environment_bodies(scene: Scene | None, held: str | None,
                        resting: dict[str, np.ndarray | None] | None) -> list[Body]:
    """The scene's objects in the world: movable ones where they rest (absent if None),
    the held one left out."""
    out: list[Body] = []
    for obj in (scene.objects.values() if scene is not None else ()):
        placed: np.ndarray | None = obj.T_world_object
        if obj.movable:
            if obj.name == held:
                continue
            placed = (resting or {}).get(obj.name, obj.T_world_object)
        if placed is not None:
            made = _ENV_SHAPES.get(obj.shape)
            if made is None:
                coal_shape = obj.shape.to_coal()
                made = _ENV_SHAPES[obj.shape] = (fcl_shape(coal_shape, obj.name),
                                                 shape_spec(coal_shape, obj.name))
                while len(_ENV_SHAPES) > _ENV_KEPT:
                    del _ENV_SHAPES[next(iter(_ENV_SHAPES))]
            out.append(_body(obj.name, 0, placed, None, shape=made[0], spec=made[1]))
    return out


#: The FCL shape and layer shape of each scene shape (a primitive: its kind and sizes)
#: made in this process, shared read-only by every verifier; the oldest go first.
_ENV_SHAPES: dict[Shape, tuple[object, ShapeSpec]] = {}
_ENV_KEPT = 256
