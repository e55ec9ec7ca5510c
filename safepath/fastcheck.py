"""The fast layer of the collision checker: spheres that decide most states, exactly.

A :class:`SphereLayer` is built from a :class:`~safepath.collision.CollisionChecker`
(same robot, scene, world state, pairs and margins) and answers, for a state:

* ``FREE``: every checked pair is farther apart than its margin. Certain: the robot's
  and held object's shapes are enclosed by their outer spheres (:mod:`safepath.spheres`)
  and the scene's primitives are measured exactly, so sphere distances are lower bounds
  of the true ones; pairs of primitives are refined by separating axes, pairs with a
  convex hull (mesh links) by GJK on the hull's own vertices (:mod:`safepath._gjk`),
  both lower bounds too;
* ``COLLIDES``: outside the joint limits, or an inner sphere (inside a shape) is closer
  to another shape than the margin. Certain too;
* ``UNSURE``: anything else; the exact coal check decides.

So the checker's answers do not change; only the time to reach them does. For a
straight joint segment the layer also certifies *intervals*: a state whose clearance
lower bound exceeds the margin by ``d`` proves every state closer than
``d / (rate of approach)`` free, the rate being bounded per pair from the per-joint
reach of each body (Σ_j w_j |Δq_j|, joints that carry both bodies of a pair left out),
or from the bodies' distances to the joint axes at that state, whichever proves more.
Segments are walked middle first, so open space costs a few evaluations and narrow
places are cut down to the checker's grid (hpp-core's progressive / dichotomy continuous
validation works this way); along a polyline, a certificate that reaches a segment's end
carries on into the next segments while every pair's budget lasts.

The kernels are compiled with numba on first use (cached on disk afterwards).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from .robot import is_prismatic
from .spheres import SphereFit, fit_spheres

if TYPE_CHECKING:
    from .collision import CollisionChecker

__all__ = ["SphereLayer", "FREE", "COLLIDES", "UNSURE", "LayerOptions"]

FREE, COLLIDES, UNSURE = 0, 1, 2
#: A segment with an end outside the joint limits (see SphereLayer.certify_segment).
OUTSIDE = 3


@dataclass(frozen=True)
class LayerOptions:
    """Options of the sphere layer.

    Attributes:
        cell: Edge of the grid cells the outer spheres circumscribe [m].
        refine: A pair whose bounding spheres are farther apart than its margin plus
            this is not refined with its fine spheres when certifying segments [m].
        free_eps: A pair counts as certainly free only beyond its margin plus this [m].
        proof_eps: An inner sphere proves a collision only this far inside [m].
    """

    cell: float = 0.04
    refine: float = 0.01
    free_eps: float = 1e-6
    proof_eps: float = 1e-5


def _kernels() -> Any:
    from . import _fastkernels

    return _fastkernels


class SphereLayer:
    """Sphere-based certificates for one collision checker (see the module doc).

    Args:
        checker: The exact checker whose pairs, margins and limits are mirrored.
        options: Sphere fitting and tolerances.

    Raises:
        ValueError: A robot or held shape has no sphere fit (the caller stays exact).
    """

    def __init__(self, checker: CollisionChecker, options: LayerOptions | None = None) -> None:
        self.options = options or LayerOptions()
        self.F, self.I, self._fits = pack(checker, self.options)

    # -- queries ------------------------------------------------------------------------
    @staticmethod
    def kernel(name: str) -> Any:
        """A compiled kernel of :mod:`safepath._fastkernels` by name."""
        return getattr(_kernels(), name)

    def classify(self, q: np.ndarray) -> int:
        """FREE, COLLIDES (or outside the limits) or UNSURE for one joint vector."""
        return int(_kernels().classify(q, self.F, self.I))

    def classify_many(self, Q: np.ndarray) -> np.ndarray:  # noqa: N803
        """The status of every row of ``Q``."""
        out = np.empty(len(Q), dtype=np.int64)
        _kernels().classify_many(np.ascontiguousarray(Q, dtype=float), self.F, self.I, out)
        return out

    def certify(self, P: np.ndarray, n: np.ndarray, lo: np.ndarray, hi: np.ndarray,  # noqa: N803
                max_unsure: int | None = None
                ) -> tuple[int, int, int, int, np.ndarray, np.ndarray]:
        """Certify grid states of a polyline (see ``certify_polyline`` in the kernels);
        with ``max_unsure``, stop once that many states are left undecided.

        Returns:
            (status, segment, index, evaluated, unsure segments, unsure indices).
        """
        total = int(np.sum(np.maximum(hi - lo + 1, 0)))
        seg = np.empty(max(total, 1), dtype=np.int64)
        idx = np.empty(max(total, 1), dtype=np.int64)
        status, k, i, evaluated, m = _kernels().certify_polyline(
            np.ascontiguousarray(P, dtype=float), n.astype(np.int64), lo.astype(np.int64),
            hi.astype(np.int64), self.F, self.I, seg, idx,
            total + 1 if max_unsure is None else max_unsure)
        return int(status), int(k), int(i), int(evaluated), seg[:m], idx[:m]

    def certify_segment(self, q0: np.ndarray, q1: np.ndarray, skip_start: bool,
                        skip_end: bool, max_unsure: int) -> tuple[int, int, int, int, int]:
        """Limits, grid count and certification of one segment in one kernel call (see
        ``certify_segment`` in the kernels).

        Returns:
            (status, index, evaluated, unsure, states): status OUTSIDE (index 0: the
            start, 1: the end), COLLIDES (at grid index), UNSURE or FREE (``unsure``
            states left undecided); the segment is cut into ``states`` steps.
        """
        return _kernels().certify_segment(q0, q1, self.F, self.I, skip_start, skip_end,
                                          max_unsure)  # type: ignore[no-any-return]

    @property
    def fits(self) -> list[SphereFit]:
        """The sphere fit of every moving body (the robot's geometries in model order, then
        the held object), in the frame of the joint that carries it."""
        return list(self._fits)


def pack(checker: CollisionChecker, options: LayerOptions
         ) -> tuple[np.ndarray, np.ndarray, list[SphereFit]]:
    """The flat buffers the kernels read (layout in :mod:`safepath._fastkernels`)."""

    import coal

    from . import _fastkernels as K  # noqa: N812  (constants only; compiles nothing)
    from ._gjk import hull_tables

    robot = checker.robot
    model, gmodel = robot.model, checker.geometry_model
    dof, nj = model.nq, model.njoints
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    # Joints: placement (9 + 3), axis (3); parent, kind, q index.
    J = np.zeros((nj, 15))
    Ji = np.zeros((nj, 3), dtype=np.int64)
    for j in range(1, nj):
        M = model.jointPlacements[j]
        J[j, :9] = np.asarray(M.rotation).ravel()
        J[j, 9:12] = M.translation
        S = np.asarray(data.joints[j].S).ravel()
        angular = np.linalg.norm(S[3:]) > 0.5
        J[j, 12:15] = S[3:] if angular else S[:3]
        Ji[j] = (model.parents[j], K.JOINT_REVOLUTE if angular else K.JOINT_PRISMATIC,
                 model.joints[j].idx_q)
    env_set = set(checker._env)
    movers = [i for i in range(gmodel.ngeoms) if i not in env_set]
    mover_of = {g: m for m, g in enumerate(movers)}
    env_of = {g: e for e, g in enumerate(checker._env)}
    # Movers: bounding sphere (joint frame) and fine / inner sphere ranges.
    fits: list[SphereFit] = []
    G = np.zeros((len(movers), K.GW))
    Gi = np.zeros((len(movers), K.GIW), dtype=np.int64)
    spheres: list[np.ndarray] = []
    vertices: list[np.ndarray] = []
    edge_ptr: list[np.ndarray] = [np.zeros(1, dtype=np.int64)]
    edges: list[np.ndarray] = []
    count = n_vertices = n_edges = 0
    for m, g in enumerate(movers):
        geom = gmodel.geometryObjects[g]
        fit = fit_spheres(geom.geometry, cell=options.cell).transformed(
            geom.placement.homogeneous)
        fits.append(fit)
        c, r = fit.bounding
        kind, dims = _primitive(geom.geometry)
        hull = np.zeros((0, 3))
        if kind == K.SPHERES_ONLY and isinstance(geom.geometry, coal.ConvexBase):
            hull, ptr, idx = hull_tables(np.asarray(geom.geometry.points()))
            kind = K.HULL
            edge_ptr.append(ptr[1:] + n_edges)
            edges.append(idx + n_vertices)
            n_edges += len(idx)
        T = geom.placement.homogeneous
        G[m] = (*c, r, *T[:3, :3].ravel(), *T[:3, 3], *dims)
        outer = np.column_stack([fit.outer_centers, fit.outer_radii])
        inner = np.column_stack([fit.inner_centers, fit.inner_radii])
        Gi[m] = (geom.parentJoint, count, count + len(outer), count + len(outer),
                 count + len(outer) + len(inner), kind, n_vertices, n_vertices + len(hull))
        spheres += [outer, inner]
        vertices.append(hull)
        count += len(outer) + len(inner)
        n_vertices += len(hull)
    S_ = np.vstack(spheres) if spheres else np.zeros((0, 4))
    # Environment: world placement, dimensions, kind.
    E = np.zeros((len(checker._env), 15))
    Ei = np.zeros(len(checker._env), dtype=np.int64)
    ER = np.zeros(len(checker._env))
    for e, g in enumerate(checker._env):
        geom = gmodel.geometryObjects[g]
        shape = geom.geometry
        T = geom.placement.homogeneous.copy()
        kind, dims = _primitive(shape)
        if kind == K.SPHERES_ONLY:  # any other shape: its local bounding box (no proofs)
            shape.computeLocalAABB()
            lo, hi = np.asarray(shape.aabb_local.min_), np.asarray(shape.aabb_local.max_)
            kind, dims = K.ENV_BOX_ONLY_OUTER, (hi - lo) / 2
            T[:3, 3] = T[:3, :3] @ ((hi + lo) / 2) + T[:3, 3]
        E[e, :9] = T[:3, :3].ravel()
        E[e, 9:12] = T[:3, 3]
        E[e, 12:15] = dims
        Ei[e] = kind
        ER[e] = _holding_radius(kind, dims)
    # Pairs: as the exact checker's, with its security margins.
    requests = checker._gdata.collisionRequests
    P = np.zeros(len(checker._pairs))
    Pi = np.zeros((len(checker._pairs), 4), dtype=np.int64)
    for k, (a, b) in enumerate(checker._pairs):
        sm = float(requests[k].security_margin)
        if b in env_of:
            Pi[k] = (mover_of[a], env_of[b], 1, 1 if sm >= 0 else 0)
        elif a in env_of:
            Pi[k] = (mover_of[b], env_of[a], 1, 1 if sm >= 0 else 0)
        else:
            Pi[k] = (mover_of[a], mover_of[b], 0, 1 if sm >= 0 else 0)
        P[k] = sm
    W = _mover_weights(model, G, Gi, robot.lower, robot.upper)
    PM = _pair_masks(model, Gi, Pi)
    L = np.concatenate([robot.lower, robot.upper])
    C = np.array([options.refine, options.free_eps, options.proof_eps,
                  checker.options.resolution])
    V = np.vstack(vertices) if vertices else np.zeros((0, 3))
    blocks_f = [J.ravel(), G.ravel(), S_.ravel(), E.ravel(), P, W.ravel(), L, C, V.ravel(), ER,
                checker.displacement_weights]
    AP = np.concatenate(edge_ptr)
    AI = np.concatenate(edges) if edges else np.zeros(0, dtype=np.int64)
    blocks_i = [Ji.ravel(), Gi.ravel(), Ei, Pi.ravel(), PM.ravel(), AP, AI]
    f_off = np.cumsum([0] + [len(b) for b in blocks_f])
    i_off = K.HEADER + np.cumsum([0] + [len(b) for b in blocks_i])
    header = np.zeros(K.HEADER, dtype=np.int64)
    header[[K.H_NJ, K.H_NG, K.H_NS, K.H_NE, K.H_NP, K.H_DOF]] = (
        nj, len(movers), len(S_), len(checker._env), len(checker._pairs), dof)
    header[[K.H_J, K.H_G, K.H_S, K.H_E, K.H_P, K.H_W, K.H_L, K.H_C, K.H_V, K.H_ER,
            K.H_DW]] = f_off[:11]
    header[[K.H_JI, K.H_GI, K.H_EI, K.H_PI, K.H_PM, K.H_AP, K.H_AI]] = i_off[:7]
    F = np.concatenate(blocks_f).astype(np.float64)
    I_ = np.concatenate([header, *blocks_i]).astype(np.int64)
    return F, I_, fits


def _holding_radius(kind: int, dims: np.ndarray) -> float:
    """Radius [m] of a sphere about a primitive's centre that holds it."""
    from . import _fastkernels as K  # noqa: N812

    if kind in (K.ENV_BOX, K.ENV_BOX_ONLY_OUTER):
        return float(np.linalg.norm(dims))
    if kind == K.ENV_CYLINDER:
        return float(np.hypot(dims[0], dims[1]))
    if kind == K.ENV_CAPSULE:
        return float(dims[0] + dims[1])
    return float(dims[0])  # sphere


def _primitive(shape: Any) -> tuple[int, np.ndarray]:
    """Kind code and dimensions [m] of a primitive the kernels measure exactly."""
    import coal

    from . import _fastkernels as K  # noqa: N812

    if isinstance(shape, coal.Box):
        return K.ENV_BOX, np.asarray(shape.halfSide, dtype=float)
    if isinstance(shape, coal.Cylinder):
        return K.ENV_CYLINDER, np.array([shape.radius, shape.halfLength, 0.0])
    if isinstance(shape, coal.Sphere):
        return K.ENV_SPHERE, np.array([shape.radius, 0.0, 0.0])
    if isinstance(shape, coal.Capsule):
        return K.ENV_CAPSULE, np.array([shape.radius, shape.halfLength, 0.0])
    return K.SPHERES_ONLY, np.zeros(3)


def _pair_masks(model: Any, Gi: np.ndarray, Pi: np.ndarray) -> np.ndarray:
    """Per pair and velocity index: bit 1 if the joint moves body a relative to body b
    (or the world), bit 2 if it moves b relative to a; 0 for joints that carry both
    (they move the pair as one rigid piece) and joints that carry neither."""
    chains: dict[int, set[int]] = {}

    def chain(joint: int) -> set[int]:  # once per joint: pinocchio's accessors are slow
        if joint not in chains:
            out, j = set(), joint
            while j > 0:
                out.add(int(model.joints[j].idx_v))
                j = model.parents[j]
            chains[joint] = out
        return chains[joint]

    PM = np.zeros((len(Pi), model.nv), dtype=np.int64)
    for k, (a, b, is_env, _) in enumerate(Pi):
        ca = chain(int(Gi[a, 0]))
        cb = set() if is_env else chain(int(Gi[b, 0]))
        for v in ca - cb:
            PM[k, v] |= 1
        for v in cb - ca:
            PM[k, v] |= 2
    return PM


def _mover_weights(model: Any, G: np.ndarray, Gi: np.ndarray, lower: np.ndarray,
                   upper: np.ndarray) -> np.ndarray:
    """Per mover and joint, how far [m] the mover's points can lie from the joint's axis
    (1 for a prismatic joint; 0 for joints that do not move it): a point moves at most
    Σ_j w_j |Δq_j| along a straight joint segment."""
    W = np.zeros((len(G), model.nv))
    for m in range(len(G)):
        reach = float(np.linalg.norm(G[m, :3])) + float(G[m, 3])
        j = int(Gi[m, 0])
        while j > 0:
            prismatic = is_prismatic(model, j)
            iv = model.joints[j].idx_v
            W[m, iv] = 1.0 if prismatic else reach
            reach += float(np.linalg.norm(model.jointPlacements[j].translation))
            if prismatic:  # the slide moves the points away from the joints above it
                reach += max(abs(float(lower[iv])), abs(float(upper[iv])))
            j = model.parents[j]
    return W
