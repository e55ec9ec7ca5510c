"""The flat buffers the sphere layer's kernels read (layout in
:mod:`safepath.collision._layout`), built from what a collision checker mirrors to its
layer (a :class:`LayerSource`: geometry, pairs, margins; explicit inputs, no checker).

What depends on the robot alone (its joints, and each of its shapes: sphere fit, hull
tables, reach per joint, the joints that carry it) is made once per robot and options and
shared, read-only, by every checker of that robot: a planner builds a checker per world
state and allowed-contact set (a dozen for a cell, one per problem for a benchmark), and
they differ only in the held object, the scene and the pairs.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..files.derived import StoredKind
from ..model._joint_table import HELICAL, JI_KIND, WORLD, joint_table
from ..model.robot import Robot, is_prismatic
from ..model.shapes import from_coal, from_code
from . import _layout as K  # noqa: N812  (constants only: imports no kernel)
from .options import LayerOptions
from .spheres import SphereFit, fit_spheres

__all__ = ["LayerSource", "pack"]


@dataclass(frozen=True, kw_only=True)
class LayerSource:
    """What the sphere layer mirrors of one collision checker
    (:meth:`safepath.collision.CollisionChecker.layer_source`).

    Attributes:
        robot: The robot.
        geometry: The checker's geometry model: the robot's shapes, then the scene's and
            the held object's.
        environment: The geometry indices of the environment objects (the rest move).
        pairs: The pairs checked, as rows of geometry indices (a, b) (pairs, 2).
        security: Each pair's security margin [m] (negative: the depth it may touch by).
        resolution: The checker's resolution [m].
        displacement_weights: Per joint, how far [m] a unit step moves any point of the
            robot or held object.
    """

    robot: Robot
    geometry: pin.GeometryModel
    environment: list[int]
    pairs: np.ndarray
    security: np.ndarray
    resolution: float
    displacement_weights: np.ndarray


@dataclass(frozen=True)
class _Mover:
    """What the layer needs of one moving shape (a robot geometry or the held object)."""

    fit: SphereFit  # in the frame of its joint
    row: np.ndarray  # its row of G: bounding sphere, placement, primitive dimensions
    joint: int
    kind: int
    spheres: np.ndarray  # outer rows, then inner rows: (x, y, z, r) in the joint frame
    n_outer: int
    hull: np.ndarray  # vertices (shape frame), or (0, 3)
    degree: np.ndarray  # neighbours per hull vertex
    neighbours: np.ndarray  # hull vertex rows, relative to this hull
    weights: np.ndarray  # (nv,): how far its points lie from each joint's axis [m]
    chain: np.ndarray  # (nv,) bool: the velocity indices of the joints that carry it


@dataclass(frozen=True)
class _RobotPart:
    J: np.ndarray  # noqa: N815
    Ji: np.ndarray  # noqa: N815
    movers: list[_Mover]


def _robot_part(robot: Robot, options: LayerOptions) -> _RobotPart:
    """The robot's joints and shapes, made by the first checker of the robot (or read
    from the disk cache, :mod:`safepath.files.derived`, where a process made them before)."""
    from .spheres import _fit_key

    model, geoms = robot.model, robot.collision_model.geometryObjects
    joints = functools.cache(lambda: _joints(model))  # names the disk entry, then made into it

    def inputs() -> list[object]:
        return [*joints(),
                np.array([model.joints[j].idx_v for j in range(1, model.njoints)]),
                robot.lower, robot.upper,
                *((int(g.parentJoint), g.placement.homogeneous.tobytes(),
                   _fit_key(g.geometry, options.cell)) for g in geoms)]

    def make() -> _RobotPart:
        J, Ji = joints()
        return _RobotPart(J, Ji, [_mover(model, g, options, robot.lower, robot.upper)
                                  for g in geoms])

    return robot.derived.get(ROBOT_PART, make, options=options, inputs=inputs)


#: The arrays of a mover in the disk cache's entries, by suffix.
_MOVER_ARRAYS = ("oc", "or", "ic", "ir", "row", "spheres", "hull", "degree", "neighbours",
                 "weights", "chain", "ints")


def _flat(J: np.ndarray, Ji: np.ndarray, movers: list[_Mover]  # noqa: N803
          ) -> dict[str, np.ndarray]:
    """A robot part as named arrays (see :func:`_unflat`)."""
    out = {"J": J, "Ji": Ji, "count": np.array([len(movers)], dtype=np.int64)}
    for i, m in enumerate(movers):
        f = m.fit
        values = (f.outer_centers, f.outer_radii, f.inner_centers, f.inner_radii, m.row,
                  m.spheres, m.hull, m.degree, m.neighbours, m.weights, m.chain,
                  np.array([m.joint, m.kind, m.n_outer], dtype=np.int64))
        out.update({f"{i}.{name}": v for name, v in zip(_MOVER_ARRAYS, values, strict=True)})
    return out


def _unflat(a: Mapping[str, np.ndarray]) -> _RobotPart:
    """The robot part of :func:`_flat`'s arrays, its fits read-only (every checker of
    the robot shares them)."""
    movers = []
    for i in range(int(a["count"][0])):
        oc, orad, ic, irad, row, spheres, hull, degree, neighbours, weights, chain, ints = (
            a[f"{i}.{name}"] for name in _MOVER_ARRAYS)
        fit = SphereFit(oc, orad, ic, irad)
        for array in (oc, orad, ic, irad):
            array.flags.writeable = False
        movers.append(_Mover(fit, row, int(ints[0]), int(ints[1]), spheres, int(ints[2]),
                             hull, degree, neighbours, weights, chain))
    return _RobotPart(a["J"], a["Ji"], movers)


#: The sphere layer's part of a robot (its joints, and each shape's sphere fit, hull
#: tables, reach per joint and chain), kept per robot and layer options, and on disk.
ROBOT_PART: StoredKind[_RobotPart] = StoredKind(
    "sphere layer robot part",
    makers=(*(Path(__file__).with_name(name)
              for name in ("_pack.py", "_layout.py", "spheres.py", "_gjk.py")),
            Path(__file__).parent.parent / "model" / "shapes.py"),
    to_arrays=lambda part: _flat(part.J, part.Ji, part.movers),
    from_arrays=_unflat)


def _joints(model: pin.Model) -> tuple[np.ndarray, np.ndarray]:
    """The joint table (:mod:`safepath.model._joint_table`) of every joint of ``model``, row j
    for joint j (row 0: the universe, fixed at the origin).

    Raises:
        ValueError: A helical joint: the layer's motion bounds (``_weights``) know the
            turn and the slide of a joint, not both at once, so its checker stays exact.
    """
    jf, ji = joint_table(model, range(model.njoints),
                         [WORLD, *(int(model.parents[j]) for j in range(1, model.njoints))])
    helical = [str(model.names[j]) for j in range(model.njoints) if ji[j, JI_KIND] == HELICAL]
    if helical:
        raise ValueError(f"helical joints {helical}")
    return jf, ji


def _mover(model: pin.Model, geom: Any, options: LayerOptions, lower: np.ndarray,
           upper: np.ndarray) -> _Mover:
    """One moving shape's part of the buffers."""
    import coal

    from ._gjk import HULL, hull_tables

    T = geom.placement.homogeneous
    fit = fit_spheres(geom.geometry, cell=options.cell).transformed(T)
    for array in (fit.outer_centers, fit.outer_radii, fit.inner_centers, fit.inner_radii):
        array.flags.writeable = False  # shared by every checker of the robot
    c, r = fit.bounding
    kind, dims = _primitive(geom.geometry)
    hull = np.zeros((0, 3))
    degree = neighbours = np.zeros(0, dtype=np.int64)
    if kind == K.SPHERES_ONLY and isinstance(geom.geometry, coal.ConvexBase):
        hull, ptr, neighbours = hull_tables(np.asarray(geom.geometry.points()))
        degree = np.diff(ptr)
        kind = HULL
    row = np.zeros(K.GW)
    row[K.G_CENTRE:K.G_CENTRE + 3], row[K.G_RADIUS] = c, r
    row[K.G_ROT:K.G_ROT + 9], row[K.G_POS:K.G_POS + 3] = T[:3, :3].ravel(), T[:3, 3]
    row[K.G_DIMS:K.G_DIMS + 3] = dims
    outer = np.column_stack([fit.outer_centers, fit.outer_radii])
    inner = np.column_stack([fit.inner_centers, fit.inner_radii])
    joint = int(geom.parentJoint)
    chain = np.zeros(model.nv, dtype=bool)
    j = joint
    while j > 0:
        chain[model.joints[j].idx_v] = True
        j = model.parents[j]
    return _Mover(fit, row, joint, kind, np.vstack([outer, inner]), len(outer), hull, degree,
                  neighbours, _weights(model, c, r, joint, lower, upper), chain)


def pack(source: LayerSource, options: LayerOptions
         ) -> tuple[np.ndarray, np.ndarray, list[SphereFit]]:
    """The flat buffers the kernels read, and the movers' sphere fits."""
    robot = source.robot
    model, gmodel = robot.model, source.geometry
    n_robot = robot.collision_model.ngeoms
    part = _robot_part(robot, options)
    env_set = set(source.environment)
    movers_idx = [i for i in range(gmodel.ngeoms) if i not in env_set]
    movers = [part.movers[g] if g < n_robot else
              _mover(model, gmodel.geometryObjects[g], options, robot.lower, robot.upper)
              for g in movers_idx]
    G, Gi, S_, V, AP, AI = _mover_blocks(movers)
    E, Ei, ER = _environment(source)
    P, Pi = _pairs(source, movers_idx)
    W = np.array([m.weights for m in movers]).reshape(len(movers), model.nv)
    chains = np.array([m.chain for m in movers]).reshape(len(movers), model.nv)
    PM = _pair_masks(chains, Pi)
    PW = _pair_weights(W, Pi, PM)
    L = np.concatenate([robot.lower, robot.upper])
    C = np.array([options.refine, options.free_eps, options.proof_eps,
                  source.resolution])
    blocks_f = [part.J.ravel(), G.ravel(), S_.ravel(), E.ravel(), P, W.ravel(), L, C,
                V.ravel(), ER, source.displacement_weights, PW.ravel()]
    blocks_i = [part.Ji.ravel(), Gi.ravel(), Ei, Pi.ravel(), PM.ravel(), AP, AI]
    f_off = np.cumsum([0] + [len(b) for b in blocks_f])
    i_off = K.HEADER + np.cumsum([0] + [len(b) for b in blocks_i])
    header = np.zeros(K.HEADER, dtype=np.int64)
    header[[K.H_NJ, K.H_NG, K.H_NS, K.H_NE, K.H_NP, K.H_DOF]] = (
        model.njoints, len(movers), len(S_), len(source.environment), len(source.pairs), model.nq)
    header[[K.H_J, K.H_G, K.H_S, K.H_E, K.H_P, K.H_W, K.H_L, K.H_C, K.H_V, K.H_ER,
            K.H_DW, K.H_PW]] = f_off[:12]
    header[[K.H_JI, K.H_GI, K.H_EI, K.H_PI, K.H_PM, K.H_AP, K.H_AI]] = i_off[:7]
    header[K.H_LAST] = -1
    F = np.concatenate(blocks_f).astype(np.float64)
    I_ = np.concatenate([header, *blocks_i]).astype(np.int64)
    return F, I_, [m.fit for m in movers]


def _mover_blocks(movers: list[_Mover]) -> tuple[np.ndarray, ...]:
    """G, Gi, the spheres, the hull vertices and the hulls' neighbour tables."""
    G = np.zeros((len(movers), K.GW))
    Gi = np.zeros((len(movers), K.GIW), dtype=np.int64)
    count = n_vertices = 0
    for m, mover in enumerate(movers):
        G[m] = mover.row
        n_spheres, n_hull = len(mover.spheres), len(mover.hull)
        row = Gi[m]
        row[K.GI_JOINT], row[K.GI_KIND] = mover.joint, mover.kind
        row[K.GI_OUTER], row[K.GI_OUTER_END] = count, count + mover.n_outer
        row[K.GI_INNER], row[K.GI_INNER_END] = count + mover.n_outer, count + n_spheres
        row[K.GI_HULL], row[K.GI_HULL_END] = n_vertices, n_vertices + n_hull
        count += n_spheres
        n_vertices += n_hull
    S_ = (np.vstack([m.spheres for m in movers]) if movers else np.zeros((0, K.SW)))
    V = np.vstack([m.hull for m in movers]) if movers else np.zeros((0, 3))
    # Hull edges: one neighbour list per vertex row of V, in V's rows.
    degree = np.concatenate([np.zeros(1, dtype=np.int64)]
                            + [m.degree for m in movers]).astype(np.int64)
    AP = np.cumsum(degree)
    starts = np.cumsum([0] + [len(m.hull) for m in movers])
    AI = np.concatenate([np.zeros(0, dtype=np.int64)]
                        + [m.neighbours + s for m, s in zip(movers, starts, strict=False)]
                        ).astype(np.int64)
    return G, Gi, S_, V, AP, AI


def _environment(source: LayerSource) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World placement, dimensions and kind of each environment object, and the radius
    of a sphere about its centre that holds it."""
    gmodel, env = source.geometry, source.environment
    E = np.zeros((len(env), K.EW))
    Ei = np.zeros(len(env), dtype=np.int64)
    ER = np.zeros(len(env))
    for e, g in enumerate(env):
        geom = gmodel.geometryObjects[g]
        shape = geom.geometry
        T = geom.placement.homogeneous.copy()
        kind, dims = _primitive(shape)
        if kind == K.SPHERES_ONLY:  # any other shape: its local bounding box (no proofs)
            shape.computeLocalAABB()
            lo, hi = np.asarray(shape.aabb_local.min_), np.asarray(shape.aabb_local.max_)
            kind, dims = K.ENV_BOX_ONLY_OUTER, (hi - lo) / 2
            T[:3, 3] = T[:3, :3] @ ((hi + lo) / 2) + T[:3, 3]
        E[e, K.E_ROT:K.E_ROT + 9] = T[:3, :3].ravel()
        E[e, K.E_POS:K.E_POS + 3] = T[:3, 3]
        E[e, K.E_DIMS:K.E_DIMS + 3] = dims
        Ei[e] = kind
        ER[e] = _holding_radius(kind, dims)
    return E, Ei, ER


def _pairs(source: LayerSource, movers_idx: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Per pair: its security margin, and (mover, mover or environment object, is
    environment, margin >= 0), as the exact checker's pairs."""
    n = source.geometry.ngeoms
    env_pos = np.full(n, -1, dtype=np.int64)
    env_pos[source.environment] = np.arange(len(source.environment))
    mover_pos = np.full(n, -1, dtype=np.int64)
    mover_pos[movers_idx] = np.arange(len(movers_idx))
    ab = np.array(source.pairs, dtype=np.int64).reshape(-1, 2)
    a, b = ab[:, 0], ab[:, 1]
    b_env, a_env = env_pos[b] >= 0, env_pos[a] >= 0
    P = source.security.astype(float)
    Pi = np.zeros((len(ab), K.PIW), dtype=np.int64)
    Pi[:, K.PI_A] = np.where(a_env, mover_pos[b], mover_pos[a])
    Pi[:, K.PI_B] = np.where(b_env, env_pos[b], np.where(a_env, env_pos[a], mover_pos[b]))
    Pi[:, K.PI_ENV] = a_env | b_env
    Pi[:, K.PI_PROOF] = P >= 0
    return P, Pi


def _holding_radius(kind: int, dims: np.ndarray) -> float:
    """Radius [m] of a sphere about a primitive's centre that holds it."""
    return from_code(K.ENV_BOX if kind == K.ENV_BOX_ONLY_OUTER else kind).holding_radius(dims)


def _primitive(shape: Any) -> tuple[int, np.ndarray]:
    """Kind code and dimensions [m] of a primitive the kernels measure exactly."""
    found = from_coal(shape)
    if found is None:
        return K.SPHERES_ONLY, np.zeros(3)
    return found[0].code, found[1]


def _pair_masks(chains: np.ndarray, Pi: np.ndarray) -> np.ndarray:  # noqa: N803
    """Per pair and velocity index: bit 1 if the joint moves body a relative to body b
    (or the world), bit 2 if it moves b relative to a; 0 for joints that carry both
    (they move the pair as one rigid piece) and joints that carry neither."""
    ca = chains[Pi[:, K.PI_A]]
    is_env = Pi[:, K.PI_ENV].astype(bool)
    cb = chains[np.where(is_env, 0, Pi[:, K.PI_B])] & ~is_env[:, None]
    return ((ca & ~cb).astype(np.int64) | ((cb & ~ca).astype(np.int64) << 1)).reshape(
        len(Pi), chains.shape[1])


def _pair_weights(W: np.ndarray, Pi: np.ndarray, PM: np.ndarray) -> np.ndarray:  # noqa: N803
    """Per pair and velocity index, how fast the joint can close the pair [m per unit]:
    body a's weight where the mask has bit 1, plus body b's where it has bit 2 (in that
    order, from 0: the sums the kernels made from the masks, bit for bit). An
    environment object is never b's side of a mask."""
    a = W[Pi[:, K.PI_A]]
    b = W[np.where(Pi[:, K.PI_ENV] == 1, 0, Pi[:, K.PI_B])]
    return (0.0 + np.where(PM & 1, a, 0.0)) + np.where(PM & 2, b, 0.0)


def _weights(model: pin.Model, centre: np.ndarray, radius: float, joint: int,
             lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Per joint, how far [m] a mover's points can lie from the joint's axis (1 for a
    prismatic joint; 0 for joints that do not move it): a point moves at most
    Σ_j w_j |Δq_j| along a straight joint segment."""
    w = np.zeros(model.nv)
    reach = float(np.linalg.norm(centre)) + float(radius)
    j = joint
    while j > 0:
        prismatic = is_prismatic(model, j)
        iv = model.joints[j].idx_v
        w[iv] = 1.0 if prismatic else reach
        reach += float(np.linalg.norm(model.jointPlacements[j].translation))
        if prismatic:  # the slide moves the points away from the joints above it
            reach += max(abs(float(lower[iv])), abs(float(upper[iv])))
        j = model.parents[j]
    return w
