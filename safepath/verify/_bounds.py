"""The verifier's conservative layer: its own kinematics, shape bounds and motion bounds.

Everything here is the verifier's own code, written from the robot's and the scene's
data (joint placements and axes, collision geometry), never the planner's checker:

* :func:`motion_weights` and :func:`pair_weights` bound how far a unit of each joint's
  motion moves a body's points, and so how much it can change a pair's distance (the
  walk tightens them with the body's distance to the joint's axis where it takes a
  bound, plus what the joints between them move it since);
* :class:`Grid` cuts the knots so that no robot point moves more than the resolution
  between two samples, and accumulates the joints' motion along it;
* :class:`Layer` walks every pair along that grid with lower bounds on the distance
  (the numba kernels in ``_kernel`` and ``_distance``), certifying what the bounds prove and
  handing the rest to FCL.
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ConfigError
from ..model.robot import joint_motion
from ..model.shapes import from_coal

if TYPE_CHECKING:
    import pinocchio as pin

__all__ = ["Grid", "Layer", "PoseCache", "ShapeSpec", "WalkMemory", "bound_between",
           "climbing", "joint_kind", "joint_tables", "motion_weights", "pair_weights",
           "shape_spec", "shape_table", "unsupported_geometry", "SUPPORTED"]

_REVOLUTE, _PRISMATIC = 1, 2
#: Above this excess over its threshold [m], a pair's bounding-sphere bound is used
#: alone: the step it allows is long enough that the finer bounds would not pay.
_COARSE = 0.05
#: Below this excess [m], the axis bound is refined with GJK's directions.
_FINE = 0.02
#: A pair's last separating axis is trusted while its gap keeps this share of the last
#: full bound's excess over the threshold.
_KEEP = 0.5
#: Room for uncertified couples per kernel call (the walk resumes when it is full).
_ROOM = 1024


@dataclass(frozen=True)
class ShapeSpec:
    """A convex shape as the conservative layer sees it.

    Attributes:
        kind: The shape table's code of a primitive (:mod:`safepath.model.shapes`;
            cylinders and capsules along z), or ``HULL`` (a convex hull).
        par: Box half extents; (radius,) for spheres; (radius, half length) for
            cylinders and capsules [m]; unused for hulls.
        centre: Its centre in the geometry frame [m] (a hull's: its bounding box's).
        radius: Radius of a sphere about the centre that holds it [m].
        vertices: A hull's vertices about its centre, in the geometry frame (rows) [m].
        neighbours: A hull's edges: per vertex, where its neighbours start in
            ``adjacent`` (vertices + 1 entries).
        adjacent: The neighbours' rows in ``vertices``.
    """

    kind: int
    par: tuple[float, float, float]
    centre: tuple[float, float, float]
    radius: float
    vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), compare=False)
    neighbours: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int64),
                                   compare=False)
    adjacent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                                 compare=False)


def shape_spec(geometry: object, name: str = "") -> ShapeSpec:
    """The conservative layer's view of a coal geometry (a convex mesh: its hull's
    vertices, the points FCL's convex is made of; a triangle mesh: the hull of its
    vertices, which encloses it, so that its distance bounds the mesh's from below).

    Raises:
        ConfigError: A geometry the verifier does not handle (names it as ``name``).
    """
    import coal

    origin = (0.0, 0.0, 0.0)
    primitive = from_coal(geometry)
    if primitive is not None:
        kind, half = primitive
        return ShapeSpec(kind.code, (float(half[0]), float(half[1]), float(half[2])), origin,
                         kind.holding_radius(half))
    if isinstance(geometry, (coal.ConvexBase, coal.BVHModelBase)):
        from scipy.spatial import ConvexHull

        from ._distance import HULL  # the kernel module, imported by the first hull

        pts = np.asarray(geometry.points() if isinstance(geometry, coal.ConvexBase)
                         else geometry.vertices(), dtype=float)
        hull = ConvexHull(pts)
        pts = pts[hull.vertices]
        c = (pts.min(axis=0) + pts.max(axis=0)) / 2
        rel = np.ascontiguousarray(pts - c)
        return ShapeSpec(HULL, (0.0, 0.0, 0.0), (float(c[0]), float(c[1]), float(c[2])),
                         float(np.linalg.norm(rel, axis=1).max()), rel,
                         *_edges(hull.vertices, hull.simplices))
    raise unsupported_geometry(geometry, name)


#: What the verifier handles, for messages.
SUPPORTED = "boxes, spheres, cylinders, capsules, convex meshes and triangle meshes"


def unsupported_geometry(geometry: object, name: str) -> ConfigError:
    """The error for a collision geometry the verifier cannot check."""
    what = f"collision geometry '{name}'" if name else "a collision geometry"
    return ConfigError(f"{what} is a {type(geometry).__name__}: the independent verifier "
                       f"handles {SUPPORTED}", key=name or None)


def bound_between(a: ShapeSpec, T_world_a: np.ndarray, b: ShapeSpec,
                  T_world_b: np.ndarray) -> float:
    """The layer's finest lower bound on the signed distance between two shapes whose
    geometry frames are at ``T_world_a`` and ``T_world_b`` (4 x 4) [m] (the axis gaps,
    raised by GJK's directions): for tests and diagnostics."""
    from . import _distance as shapes

    table, hulls = shape_table([a, b])

    def placed(k: int, T: np.ndarray) -> tuple[float, ...]:
        T = np.asarray(T, dtype=float)
        centre = T[:3, :3] @ table[k, 4:7] + T[:3, 3]
        return (*table[k, :4], table[k, 7], *centre, *T[:3, :3].ravel())

    Sa, Sb = placed(0, T_world_a), placed(1, T_world_b)
    hulls = climbing(hulls)
    bound, n0, n1, n2 = shapes.axis_bound_entry(Sa, Sb, hulls)
    return float(shapes.gjk_bound_entry(Sa, Sb, hulls, bound, n0, n1, n2, False,
                                        np.empty((4, 3)), np.empty((3, 3)),
                                        np.empty(4, dtype=np.int64))[0])


def _edges(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A hull's edges as (neighbour starts, neighbour rows), its vertices numbered in
    the order of ``vertices`` (qhull's vertex indices), from its facets' ``triangles``
    (qhull's simplices: every edge of the hull is a side of one)."""
    row = np.full(int(vertices.max()) + 1, -1, dtype=np.int64)
    row[vertices] = np.arange(len(vertices))
    tri = row[triangles]
    pairs = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    pairs = np.unique(np.sort(np.concatenate([pairs, pairs[:, ::-1]]), axis=1), axis=0)
    both = np.concatenate([pairs, pairs[:, ::-1]])
    both = both[np.lexsort((both[:, 1], both[:, 0]))]
    starts = np.searchsorted(both[:, 0], np.arange(len(vertices) + 1))
    return starts.astype(np.int64), np.ascontiguousarray(both[:, 1], dtype=np.int64)


def shape_table(specs: list[ShapeSpec]) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """The kernels' shape table (kind, parameters, centre, radius; a hull's parameters:
    its first row in the vertex table and its count) and the hull tables (vertices,
    per vertex row where its neighbours start, the neighbours' rows: all rows of the
    vertex table)."""
    from ._distance import HULL  # the kernel module, imported when a check is built

    rows, verts, count = [], [], 0
    starts: list[np.ndarray] = []
    adjacent: list[np.ndarray] = []
    for spec in specs:
        par = spec.par
        if spec.kind == HULL:
            if len(spec.neighbours) != len(spec.vertices) + 1:
                raise ValueError("a hull's shape spec needs its edges (shape_spec makes them)")
            par = (float(count), float(len(spec.vertices)), 0.0)
            verts.append(spec.vertices)
            edges = sum(a.size for a in adjacent)
            starts.append(spec.neighbours[:-1] + edges)
            adjacent.append(spec.adjacent + count)
            count += len(spec.vertices)
        rows.append((spec.kind, *par, *spec.centre, spec.radius))
    table = np.array(rows, dtype=float).reshape(-1, 8)
    if not verts:
        return table, (np.zeros((0, 3)), np.zeros(1, dtype=np.int64),
                       np.zeros(0, dtype=np.int64))
    nbr = np.concatenate(adjacent).astype(np.int64)
    ptr = np.concatenate([*starts, [nbr.size]]).astype(np.int64)
    return table, (np.ascontiguousarray(np.vstack(verts)), ptr, nbr)


def climbing(hulls: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """The hull tables as the kernels take them: with a fresh start table (every climb
    of a hull starts at its first vertex until one has ended elsewhere). One per walk:
    the kernel updates it."""
    return (*hulls, np.arange(len(hulls[0]), dtype=np.int64))


def joint_kind(model: pin.Model, j: int) -> tuple[int, tuple[float, float, float]]:
    """(revolute or prismatic, unit axis in the joint frame) of joint ``j``.

    Raises:
        ConfigError: Any other joint (names it).
    """
    motion = joint_motion(model, j)
    if motion is None:
        raise ConfigError(f"joint '{model.names[j]}' is a {model.joints[j].shortname()}: the "
                          "independent verifier handles 1-dof revolute and prismatic joints",
                          key=model.names[j])
    kind, axis = motion
    if abs(float(np.linalg.norm(axis)) - 1.0) > 1e-9:
        raise ConfigError(f"joint '{model.names[j]}': axis {list(axis)} is not a unit vector",
                          key=model.names[j])
    return (_REVOLUTE if kind == "revolute" else _PRISMATIC), axis


def undominated(weights: np.ndarray) -> np.ndarray:
    """The rows of ``weights`` (bodies x dof, not negative) that no other row bounds in
    every column (of equal rows, the first). A grid cut with them is the grid cut with
    all: for a step of joint motions (not negative), a row bounded by another in every
    column moves no more than it (the products and their sums round monotonically, so
    also in floating point)."""
    w = np.asarray(weights, dtype=float)
    below = (w[:, None, :] <= w[None, :, :]).all(axis=2)  # [b, c]: row b <= row c
    beaten = below & ~below.T  # strictly, in some column
    same = below & below.T
    first = np.arange(len(w))[:, None] > np.arange(len(w))[None, :]  # c before b
    dropped = (beaten | (same & first)).any(axis=1)
    return np.ascontiguousarray(w[~dropped])


def motion_weights(model: pin.Model, joints: list[int], T_joint_geom: list[np.ndarray],
                   shapes: list[ShapeSpec]) -> np.ndarray:
    """Per body and joint, a bound on how far a unit of that joint's motion moves the
    body's points [m/rad] or [m/m] (zero for joints that do not move it): (bodies, dof).

    A revolute joint moves a point by at most its distance to the joint's axis times the
    angle. For the body's own joint, that distance is at most the shape centre's distance
    to the axis plus the shape's radius; for a joint upstream, its distance to the
    joint's origin: the centre's distance to its own joint's origin plus the radius,
    plus the offsets of the frames in between (a prismatic joint's offset up to its
    position limits). A prismatic joint moves every point by its own motion.
    """
    out = np.zeros((len(joints), model.nv))
    for m, (joint, T, shape) in enumerate(zip(joints, T_joint_geom, shapes, strict=True)):
        centre = np.asarray(T)[:3, :3] @ np.asarray(shape.centre) + np.asarray(T)[:3, 3]
        dist = float(np.linalg.norm(centre)) + shape.radius
        j = joint
        while j > 0:
            kind, axis = joint_kind(model, j)
            v = model.joints[j].idx_v
            if kind == _PRISMATIC:
                out[m, v] = 1.0
                stroke = max(abs(model.lowerPositionLimit[v]), abs(model.upperPositionLimit[v]))
                if not np.isfinite(stroke):
                    raise ConfigError(f"prismatic joint '{model.names[j]}' has no position "
                                      "limits", key=model.names[j])
                dist += stroke
            elif j == joint:
                across = centre - np.dot(centre, axis) * np.asarray(axis)
                out[m, v] = float(np.linalg.norm(across)) + shape.radius
            else:
                out[m, v] = dist
            dist += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = model.parents[j]
    return out


def joint_tables(model: pin.Model) -> tuple[np.ndarray, ...]:
    """The kinematic tables the walk reads: per joint its parent, placement in its
    parent (3 x 4), kind, axis and q index; per velocity index its joint, and which
    revolute joints lie upstream of it."""
    nj = model.njoints
    place = np.zeros((nj, 3, 4))
    kind = np.zeros(nj, dtype=np.int64)
    axis = np.zeros((nj, 3))
    iq = np.zeros(nj, dtype=np.int64)
    for j in range(1, nj):
        place[j] = model.jointPlacements[j].homogeneous[:3]
        kind[j], axis[j] = joint_kind(model, j)
        iq[j] = model.joints[j].idx_q
    joint_of = np.zeros(model.nv, dtype=np.int64)
    upstream = np.zeros((model.nv, model.nv))
    for j in range(1, nj):
        v = model.joints[j].idx_v
        joint_of[v] = j
        k = model.parents[j]
        while k > 0:
            if kind[k] == _REVOLUTE:
                upstream[v, model.joints[k].idx_v] = 1.0
            k = model.parents[k]
    return (np.array(model.parents, dtype=np.int64), place, kind, axis, iq, joint_of,
            upstream)


def _chains(parents: np.ndarray, joint_of: np.ndarray) -> np.ndarray:
    """Per joint, the velocity indices of the joints that carry it (itself and its
    ancestors): (joints, dof) bool, from each joint's parent (a parent before its
    children) and each velocity index's joint."""
    v_of = np.full(len(parents), -1)
    v_of[joint_of] = np.arange(len(joint_of))
    carried = np.zeros((len(parents), len(joint_of)), dtype=np.bool_)
    for j in range(1, len(parents)):
        carried[j] = carried[parents[j]]
        if v_of[j] >= 0:
            carried[j, v_of[j]] = True
    return carried


def pair_weights(model: pin.Model, joints: list[int], weights: np.ndarray,
                 pairs: list[tuple[int, int, bool]] | np.ndarray) -> np.ndarray:
    """Per pair and joint, a bound on how much a unit of that joint's motion changes the
    pair's distance [m/rad] or [m/m]: (pairs, dof).

    Against the environment, that is the body's own weight. Between two bodies, a joint
    that moves both (a common ancestor) moves them as one rigid piece and leaves their
    distance alone; every other joint moves one of them relative to the other.
    """
    joint_of = np.zeros(model.nv, dtype=np.int64)
    for j in range(1, model.njoints):
        joint_of[model.joints[j].idx_v] = j
    carried = _chains(np.asarray(model.parents), joint_of)
    a, b, env = _pair_columns(pairs)
    body_joint = np.asarray(joints, dtype=np.int64).reshape(-1)
    w = np.asarray(weights, dtype=float).reshape(len(body_joint), model.nv)
    if not len(a):
        return np.zeros((0, model.nv))
    mover_b = np.where(env, 0, b)  # an environment index is no body's
    other = np.where(env[:, None], 0.0, w[mover_b])
    common = carried[body_joint[a]] & carried[body_joint[mover_b]] & ~env[:, None]
    return np.where(common, 0.0, w[a] + other)


@dataclass(frozen=True)
class Grid:
    """The resolution grid of a timed trajectory.

    Sample ``s`` lies on knot interval ``knot_of[s]`` (0: the first knot itself), at
    fraction ``frac[s]`` of it (linear in joint space, as the knots are dense).

    Attributes:
        knot_of: Knot each sample ends its interval at.
        frac: Fraction of that interval.
        step: |dq| of every joint into every knot (0 at the first) [rad] or [m]:
            (knots, dof). Weighted by a pair's weights, the joints' motion since an
            earlier sample bounds how much the pair's distance can have changed.
        cum: Its accumulated sum at every knot.
    """

    knot_of: np.ndarray
    frac: np.ndarray
    step: np.ndarray
    cum: np.ndarray

    @staticmethod
    def cut(q: np.ndarray, weights: np.ndarray, resolution: float) -> Grid:
        """Cut the knots so that no body moves more than ``resolution`` [m] per sample
        (the kernel's ``grid``).

        Args:
            q: Knot positions [rad]: (knots, dof).
            weights: Motion weights of the bodies (:func:`motion_weights`).
            resolution: Largest motion between samples [m].
        """
        from . import _kernel as kernel

        w = np.ascontiguousarray(weights, dtype=float)
        if not w.flags.writeable:  # a shared table (motion_weights): the kernel only reads
            w = w.copy()           # it, but its compiled signature takes writeable arrays
        return Grid(*kernel.grid(np.ascontiguousarray(q, dtype=float), w, float(resolution)))

    @property
    def samples(self) -> int:
        """Number of samples."""
        return len(self.knot_of)

    def state(self, q: np.ndarray, s: int) -> np.ndarray:
        """Joint positions of sample ``s`` [rad]."""
        k = int(self.knot_of[s])
        return q[0].copy() if k == 0 else q[k - 1] + self.frac[s] * (q[k] - q[k - 1])

    def states(self, q: np.ndarray, samples: np.ndarray) -> np.ndarray:
        """Joint positions of the samples ``samples`` [rad] (samples x dof): each as
        :meth:`state` computes it, with the same operations."""
        k = self.knot_of[samples]
        before = np.maximum(k - 1, 0)
        out = q[before] + self.frac[samples][:, None] * (q[k] - q[before])
        out[k == 0] = q[0]
        return out


@dataclass
class PoseCache:
    """Joint poses computed so far on one grid, by sample (filled by the kernel):
    whether each is done, and each (samples x joints x 3 x 4)."""

    jdone: np.ndarray
    jpose: np.ndarray

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The arrays, as the kernel takes them."""
        return self.jdone, self.jpose


@dataclass
class WalkMemory:
    """What the walks along one grid learn.

    Attributes:
        axes: Per pair, the axis that separated it best at its last full evaluation,
            and 1 if there is one: (pairs, 4).
        last: Per pair, its last full bound [m].
        stats: Bounds evaluated: all, with the axes, with GJK.
        ceiling: Smallest GJK upper bound of a clearance pair [m] (the distance between
            two points of the shapes), its pair and its sample.
    """

    axes: np.ndarray
    last: np.ndarray
    stats: np.ndarray
    ceiling: np.ndarray

    @staticmethod
    def empty(pairs: int) -> WalkMemory:
        """Nothing learnt yet, for ``pairs`` pairs."""
        return WalkMemory(np.zeros((pairs, 4)), np.full(pairs, np.inf),
                          np.zeros(3, dtype=np.int64), np.array([np.inf, -1.0, -1.0]))

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays, as the kernel takes them."""
        return self.axes, self.last, self.stats, self.ceiling


def _pair_columns(pairs: list[tuple[int, int, bool]] | np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body a, body or environment object b and whether b is the environment, of each
    pair of ``pairs``: (a, b, is environment) triples, or their rows in an array."""
    table = np.asarray(pairs, dtype=float).reshape(-1, 3)
    return table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2] != 0.0


def _pair_arrays(pairs: list[tuple[int, int, bool]] | np.ndarray, weights: np.ndarray,
                 clearance: np.ndarray, kin: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """The pairs as the kernel takes them (see :class:`Layer`), with, per pair and
    velocity index, whether the joint moves body b and not body a (``kin``: the layer's
    kinematic tables)."""
    a, b, env = _pair_columns(pairs)
    m_joint, joint_of = kin[5], kin[7]
    carried = _chains(kin[0], joint_of)
    moves_b = np.zeros((a.size, joint_of.size), dtype=np.bool_)
    if a.size:
        mover_b = np.where(env, 0, b)  # an environment index is no body's
        moves_b = (~env[:, None] & carried[m_joint[mover_b]] & ~carried[m_joint[a]])
    return (a, b, env, np.ascontiguousarray(weights, dtype=float),
            np.asarray(clearance, dtype=np.bool_), np.ascontiguousarray(moves_b))


class Layer:
    """Lower bounds on the distance of every checked pair, on a whole grid at once.

    Args:
        joints: Joint of each moving body.
        T_joint_geom: Geometry frame of each moving body in its joint frame (4 x 4).
        movers: Shape of each moving body.
        T_world_env: World placement of each environment object (4 x 4).
        env: Shape of each environment object.
        pairs: (mover, mover or environment object, is environment) of each pair (triples
            or the rows of an array).
        weights: Motion weights of each pair (:func:`pair_weights`).
        clearance: Whether each pair counts for the clearance.
        tables: :func:`joint_tables` of the robot's model (read only; shared by its
            verifiers).
    """

    def __init__(self, joints: list[int], T_joint_geom: list[np.ndarray],
                 movers: list[ShapeSpec], T_world_env: list[np.ndarray],
                 env: list[ShapeSpec], pairs: list[tuple[int, int, bool]] | np.ndarray,
                 weights: np.ndarray, clearance: np.ndarray,
                 tables: tuple[np.ndarray, ...]) -> None:
        parents, place, kind, axis, iq, joint_of, upstream = tables
        self._kin = (parents, place, kind, axis, iq, np.array(joints, dtype=np.int64),
                     np.array([np.asarray(T)[:3] for T in T_joint_geom]).reshape(-1, 3, 4),
                     joint_of)
        self._upstream = upstream
        self._env_pose = np.array([np.asarray(T)[:3] for T in T_world_env]).reshape(-1, 3, 4)
        # The kernels' shape and vertex tables; bodies first.
        self._shapes, self._hulls = shape_table(movers + env)
        self._pairs = _pair_arrays(pairs, weights, clearance, self._kin)

    def with_clearance(self, clearance: np.ndarray) -> Layer:
        """This layer with other pairs counting for the clearance (the same pairs)."""
        out = copy.copy(self)
        out._pairs = (*self._pairs[:4], np.asarray(clearance, dtype=np.bool_),
                      self._pairs[5])
        return out

    def with_pairs(self, pairs: list[tuple[int, int, bool]] | np.ndarray, weights: np.ndarray,
                   clearance: np.ndarray) -> Layer:
        """This layer (the same bodies, environment objects and their tables) for other
        pairs (arguments as the constructor's)."""
        out = copy.copy(self)
        out._pairs = _pair_arrays(pairs, weights, clearance, self._kin)
        return out

    @property
    def pair_weights(self) -> np.ndarray:
        """Motion weights of each pair, as walked (:func:`pair_weights`): (pairs x dof)
        [m/rad] or [m/m], read-only."""
        weights = self._pairs[3].view()
        weights.flags.writeable = False
        return weights

    def cache(self, samples: int) -> PoseCache:
        """An empty pose cache for a grid of ``samples`` samples."""
        nj = self._kin[0].size
        return PoseCache(np.zeros((samples, nj), dtype=np.bool_),
                         np.empty((samples, nj, 3, 4)))

    def walk(self, todo: np.ndarray, theta: np.ndarray, q: np.ndarray, grid: Grid,
             cache: PoseCache, memory: WalkMemory, drop: float = -1.0,
             stretches: tuple[np.ndarray, np.ndarray] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Certify what the bounds prove along the grid, for the pairs ``todo``.

        A sample of pair ``p`` is certified when the bound at an earlier (or the same)
        sample of the stretch walked, minus the pair's motion bound since, exceeds
        ``theta[p]``.

        Args:
            todo: Pair indices, walked in this order (a pair may come more than once,
                with stretches apart).
            theta: Threshold of every pair: the signed distance must exceed it [m].
            q: Knot positions [rad].
            grid: The grid.
            cache: Its pose cache (filled here, read by the FCL checks).
            memory: What the walks of this grid learnt so far (updated).
            drop: If not negative, a clearance pair's threshold is the memory's ceiling
                (falling as GJK finds closer points) minus ``drop`` [m], where that is
                higher than ``theta``.
            stretches: Per entry of ``todo``, the first sample it walks and the one
                after its last (None: the whole grid).

        Returns:
            (pairs, samples, bounds [m]) not certified, entry by entry, samples
            ascending.
        """
        return self._certify(todo, theta, q, grid, cache, memory,
                             (_COARSE, _FINE, _KEEP, float(drop)), stretches)

    def pilot(self, entries: tuple[np.ndarray, ...], theta: np.ndarray, q: np.ndarray,
              grid: Grid, cache: PoseCache, memory: WalkMemory, drop: float,
              count: int = 4) -> None:
        """Bound the clearance pairs of ``entries`` (pairs, first sample, the one after
        the last) at ``count`` samples spread over each stretch, as :meth:`walk` would
        (``theta``, ``drop``), before their walk: GJK's upper bounds there (distances
        between two points of the shapes, at samples of the grid) lower the memory's
        ceiling, so that the walk holds the pairs to a lower threshold from its start
        and certifies with longer steps. What is left here is the walk's to find."""
        todo, first, stop = (a[entries[2] > entries[1]] for a in entries)
        k = 2 * np.arange(count) + 1
        at = (first[:, None] + (stop - first - 1)[:, None] * k // (2 * count)).ravel()
        self._certify(np.repeat(todo, count), theta, q, grid, cache, memory,
                      (_COARSE, _FINE, _KEEP, float(drop)), (at, at + 1))

    def _certify(self, todo: np.ndarray, theta: np.ndarray, q: np.ndarray, grid: Grid,
                 cache: PoseCache, memory: WalkMemory, params: tuple[float, ...],
                 stretches: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from . import _kernel as kernel

        todo = np.ascontiguousarray(todo, dtype=np.int64)
        if stretches is None:
            stretches = (np.zeros(todo.size, dtype=np.int64),
                         np.full(todo.size, grid.samples, dtype=np.int64))
        first, stop = (np.ascontiguousarray(a, dtype=np.int64) for a in stretches)
        scratch = self._scratch  # written by the kernel; what it returns is copied out
        args = (todo, first, stop, theta,
                (grid.cum, grid.step, grid.cum @ self._upstream.T, grid.step @ self._upstream.T,
                 np.ascontiguousarray(q, dtype=float), grid.knot_of, grid.frac),
                self._kin, cache.arrays(), self._pairs, (self._shapes, self._env_pose,
                                                         climbing(self._hulls)),
                memory.arrays(), params, scratch)
        parts = []
        t, s = 0, (int(first[0]) if todo.size else 0)
        while True:  # one call, unless the outputs fill up: then resume where it stopped
            count, t, s = kernel.certify(*args, t, s)
            pairs, samples, bounds = (out[:count].copy() for out in scratch[-3:])
            parts.append((pairs, samples, bounds))
            if t >= todo.size:
                break
        if len(parts) > 1:
            pairs, samples, bounds = (np.concatenate(c) for c in zip(*parts, strict=True))
        return pairs, samples, bounds

    @functools.cached_property
    def _scratch(self) -> tuple[np.ndarray, ...]:
        """The walk's scratch and output buffers (see ``certify`` in the kernels), made
        once per layer: a layer walks one grid at a time (a verifier is used by one
        thread)."""
        nv, room = self._upstream.shape[0], _ROOM
        return (np.empty(self._kin[0].size, dtype=np.int64), np.empty(nv), np.empty(nv),
                np.empty((4, 3)), np.empty((3, 3)), np.empty(4, dtype=np.int64),
                np.empty(room, dtype=np.int64), np.empty(room, dtype=np.int64),
                np.empty(room))

    def pose(self, q: np.ndarray, grid: Grid, cache: PoseCache, s: int, m: int
             ) -> np.ndarray:
        """World pose (3 x 4) of moving body ``m``'s geometry frame at sample ``s``: from
        the layer's joint poses, or :meth:`pose_at` where the walk never looked."""
        joint = int(self._kin[5][m])
        T_joint_geom = self._homogeneous[m]
        if joint == 0:
            return T_joint_geom[:3]
        if cache.jdone[s, joint]:
            return np.asarray(cache.jpose[s, joint] @ T_joint_geom)
        return self.pose_at(grid.state(q, s), m)

    def poses(self, q: np.ndarray, grid: Grid, cache: PoseCache, samples: np.ndarray,
              m: int) -> np.ndarray:
        """:meth:`pose` of moving body ``m`` at each of the samples ``samples``
        (samples x 3 x 4), with the same operations."""
        joint = int(self._kin[5][m])
        T_joint_geom = self._homogeneous[m]
        out = np.empty((len(samples), 3, 4))
        if joint == 0:
            out[:] = T_joint_geom[:3]
            return out
        done = cache.jdone[samples, joint]
        out[done] = cache.jpose[samples[done], joint] @ T_joint_geom
        if not done.all():
            out[~done] = self.poses_at(grid.states(q, samples[~done]), m)
        return out

    def pose_at(self, q: np.ndarray, m: int) -> np.ndarray:
        """World pose (3 x 4) of moving body ``m``'s geometry frame at the joint positions
        ``q`` [rad] (:meth:`poses_at` of one state)."""
        return self.poses_at(np.asarray(q, dtype=float).reshape(1, -1), m)[0]

    def poses_at(self, states: np.ndarray, m: int) -> np.ndarray:
        """World poses (states x 3 x 4) of moving body ``m``'s geometry frame at the joint
        positions ``states`` [rad] (states x dof): for states off the grid, with the
        walk's own kinematics and operations (the kernel's ``body_poses``)."""
        from . import _kernel as kernel

        states = np.ascontiguousarray(states, dtype=float)
        out = np.empty((states.shape[0], 3, 4))
        kernel.body_poses(states, self._kin, int(m), out)
        return out

    @functools.cached_property
    def _homogeneous(self) -> np.ndarray:
        """Each moving body's geometry frame in its joint frame, 4 x 4."""
        out = np.zeros((self._kin[6].shape[0], 4, 4))
        out[:, :3], out[:, 3, 3] = self._kin[6], 1.0
        return out

    def bounds_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every pair's lower bound at the state ``q`` [rad] (the finest the layer
        computes) [m], and the moving bodies' geometry frames in the world (bodies x 3 x
        4) [m], from the layer's own kinematics: the diagnostic
        :meth:`FclVerifier.bounds_at <safepath.verify.FclVerifier.bounds_at>` reads."""
        q = np.asarray(q, dtype=float).reshape(1, -1)
        zero = np.zeros((1, q.shape[1]))
        grid = Grid(np.zeros(1, dtype=np.int64), np.ones(1), zero, zero)
        cache = self.cache(1)
        memory = WalkMemory.empty(len(self._pairs[0]))
        theta = np.full(len(self._pairs[0]), np.inf)
        pairs, _, bounds = self._certify(np.arange(theta.size), theta, q, grid, cache,
                                         memory, (np.inf, np.inf, 0.0, -1.0))
        out = np.full(theta.size, np.nan)
        out[pairs] = bounds
        poses = np.array([self.pose(q, grid, cache, 0, m)
                          for m in range(self._kin[5].size)]).reshape(-1, 3, 4)
        return out, poses
