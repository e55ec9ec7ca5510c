"""Collision checking with Pinocchio and coal: states, clearance, margins, segments.

A :class:`CollisionChecker` is built for one robot, one scene and one *world state*
(which movable object is held, where the others rest, which contacts are allowed).
It answers, for a joint vector: inside the limits? collision-free? if not, which
pair? how far from the environment (clearance), and is every object's safety margin
kept? For a straight joint-space segment it checks states so densely that no point
of the robot (or of what it holds) moves more than ``resolution`` between two checked
states (the bound is computed from the kinematic chain, see :meth:`displacement_bound`).

Conventions: a *pair* is reported as two names, a robot link (``forearm_link``) or a
scene object (``qc_conveyor``). *Clearance* is the smallest distance between the
robot or the object it holds and the environment [m]; self-distances are not part
of it. Allowed contacts are excluded from clearance and margins.
"""

from __future__ import annotations

import copy
import functools
import logging
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError, InputError
from ..model.robot import Robot
from ..model.scene import AllowedContact, Scene, SceneObject
from ._margins import PairMargins
from ._nearest import NearestPairs, bounds_kernel
from ._pack import LayerSource
from ._pairs import allowed_depths, allowed_rows, candidate_pairs
from .layer import COLLIDES, FREE, OUTSIDE, UNSURE, SphereLayer
from .options import CheckOptions
from .prepare import displacement_weights, robot_part
from .reports import Pair, SegmentReport, StateReport

__all__ = ["CollisionChecker"]

#: Undecided states checked exactly before a segment's certification goes on.
_EARLY_UNSURE = 4

log = logging.getLogger(__name__)



class CollisionChecker:
    """Checks joint vectors and segments of one robot in one scene and world state.

    Args:
        robot: The robot.
        scene: Its surroundings; None for self-collision only.
        held: Name of the movable object held by the gripper (placed by the scene's
            grasp), or None.
        resting: World placements (4x4) of movable objects that are not held; a
            movable object missing here rests at its scene placement; None removes it.
        allowed: Contacts allowed in this state (see :class:`AllowedContact`).
        options: Resolution and margin.

    Not thread-safe: one checker per thread (:meth:`clone` makes another).
    """

    def __init__(self, robot: Robot, scene: Scene | None = None, *, held: str | None = None,
                 resting: Mapping[str, np.ndarray | None] | None = None,
                 allowed: Iterable[AllowedContact] = (),
                 options: CheckOptions | None = None) -> None:
        self.robot = robot
        self.scene = scene
        self.held = held
        self.resting = dict(resting or {})
        self.allowed = tuple(allowed)
        self.options = options or CheckOptions()
        self._build()

    # -- construction ----------------------------------------------------------------------
    def clone(self, **changes: Any) -> CollisionChecker:
        """A new checker with the same inputs except ``changes`` (held, resting, ...)."""
        kwargs: dict[str, Any] = dict(held=self.held, resting=self.resting,
                                      allowed=self.allowed, options=self.options)
        kwargs.update(changes)
        return CollisionChecker(self.robot, self.scene, **kwargs)

    def with_allowed(self, allowed: Iterable[AllowedContact]) -> CollisionChecker:
        """This checker with other allowed contacts (the same robot, scene, world state
        and options): its geometry, names, reach and, for the same pairs, the sphere
        layer's tables are taken from this one; the pairs, their depths and margins are
        made anew. Answers as ``clone(allowed=...)`` does (tested): a planner needs one
        per step's allowed contacts in each world state."""
        new = copy.copy(self)
        for name in ("_gdata", "_broad", "_F", "_I", "_pair_names",
                     "_distance_pairs", "_nearest"):
            new.__dict__.pop(name, None)  # coal's side and the layer: this checker's own
        new.allowed = tuple(allowed)
        new._gmodel = self._gmodel.copy()
        new._gmodel.removeAllCollisionPairs()
        new._names = list(self._names)
        new._set_pairs()
        if (self._layer_built and self._layer is not None
                and np.array_equal(new._pairs, self._pairs)):
            new._layer = self._layer.with_security(new._security)
            new._layer_built = True
            new._bind_kernels()
        return new

    def _build(self) -> None:
        """The geometry model (robot, scene, held object), the pairs to check and the
        coal requests, step by step."""
        gmodel = self.robot.collision_model.copy()
        gmodel.removeAllCollisionPairs()  # loaders may have added their own
        links, self._own_reach = robot_part(self.robot)
        self._names: list[str] = list(links)
        self._env = self._add_environment(gmodel)
        self._add_held(gmodel)
        self._gmodel = gmodel
        self._set_pairs()
        self._weights = self._displacement_weights()

    def _set_pairs(self) -> None:
        """The pairs of the allowed contacts, their margins and coal's security margins;
        coal's side of the checker and the sphere layer are left to be made when first
        needed (coal's pairs are added to the model on the first exact query)."""
        rows, depth = self._pair_list()
        candidates, _, margins = self._candidates
        self._pairs = candidates[rows]  # (geometry a, geometry b) per pair
        self._pairs_added = False
        self._data = self.robot.model.createData()
        self._pair_margin = margins[rows]
        self._set_requests(depth)
        self._pool: Any = None  # coal's batch broad phase
        self._layer: SphereLayer | None = None
        self._layer_built = False
        self._classify: Any = None
        self._segment: Any = None

    def _add_environment(self, gmodel: pin.GeometryModel) -> list[int]:
        """Add the scene's objects (movable ones where they rest, the held one left out);
        their geometry indices."""
        env: list[int] = []
        for obj in (self.scene.objects.values() if self.scene is not None else ()):
            if obj.movable:
                if obj.name == self.held:
                    continue
                T = self.resting.get(obj.name, obj.T_world_object)
                if T is None:
                    continue
                obj = obj.placed(T)
            env.append(self._add(gmodel, obj.name, 0, 0, obj.T_world_object, obj))
        return env

    def _add_held(self, gmodel: pin.GeometryModel) -> int | None:
        """Add the held object on the TCP's joint, where the scene's grasp holds it; its
        geometry index (None: nothing held)."""
        if self.held is None:
            return None
        scene = self.scene
        if scene is None or scene.grasp is None or scene.grasp.object != self.held:
            raise ConfigError(f"cannot hold '{self.held}': the scene has no grasp for it",
                              key="grasp.object")
        tcp = self.robot.model.frames[self.robot.tcp_frame_id]
        T_joint_obj = tcp.placement.homogeneous @ scene.grasp.T_tcp_object
        return self._add(gmodel, self.held, tcp.parentJoint, self.robot.tcp_frame_id,
                         T_joint_obj, scene.objects[self.held])

    def _pair_list(self) -> tuple[np.ndarray, np.ndarray]:
        """The pairs to check, as rows of :attr:`_candidates`, and the depth [m] each
        is allowed to touch by (see :func:`._pairs.allowed_rows`)."""
        contact_links = set(self.robot.tool.contact_links) if self.robot.tool else set()
        candidates, rows_of, _ = self._candidates
        return allowed_rows(len(candidates), rows_of,
                            allowed_depths(self.allowed, contact_links))

    @functools.cached_property
    def _candidates(self) -> tuple[np.ndarray, dict[Pair, list[int]], np.ndarray]:
        """The pairs to check where no contact is allowed (see
        :func:`._pairs.candidate_pairs`). Made once for a world state (its checkers for
        other allowed contacts share it)."""
        gmodel, n_robot = self._gmodel, self.robot.collision_model.ngeoms
        held_idx = gmodel.ngeoms - 1 if self.held is not None else None  # added last
        contact_links = set(self.robot.tool.contact_links) if self.robot.tool else set()
        movers = list(range(n_robot)) + ([held_idx] if held_idx is not None else [])
        return candidate_pairs(
            names=self._names, joints=[int(g.parentJoint) for g in gmodel.geometryObjects],
            movers=movers, held=held_idx, environment=self._env,
            contact_links=contact_links, self_pairs=self.robot.allowed_self_pairs,
            margin_of=self._margins())

    def _margins(self) -> Callable[[str], float]:
        """The safety margin [m] of an object or link by name: the options' override,
        or the scene's."""
        scene, override = self.scene, self.options.margin
        if override is not None or scene is None:
            value = override if override is not None else 0.0
            return lambda name: value
        return functools.cache(scene.margin_for)

    @functools.cached_property
    def _pair_names(self) -> list[Pair]:
        """The names of each pair checked (for reports)."""
        names = self._names
        return [(names[a], names[b]) for a, b in self._pairs.tolist()]

    def _set_requests(self, depth: np.ndarray) -> None:
        """Each pair's security margin for coal (minus the allowed ``depth``, or the
        margin where enforced; coal's requests get it when first needed) and the distance
        pairs."""
        is_env = np.zeros(self._gmodel.ngeoms, dtype=bool)
        is_env[self._env] = True
        ab = self._pairs
        across = is_env[ab[:, 0]] != is_env[ab[:, 1]]  # a mover and the environment
        margin = self._pair_margin
        self._security = np.where(depth != 0.0, -depth, np.where(
            across & self.options.enforce_margin, margin, 0.0))
        # Distances: robot (and held object) against the environment, not allowed ones.
        self._dist_pairs = np.flatnonzero(across & (depth == 0.0)).tolist()

    @property
    def geometry_model(self) -> pin.GeometryModel:
        """The robot's, the scene's and the held object's geometry, with the pairs checked
        (coal's side of the checker; see :attr:`pairs` for their names)."""
        if not self._pairs_added:
            for a, b in self._pairs.tolist():
                self._gmodel.addCollisionPair(pin.CollisionPair(a, b))
            self._pairs_added = True
        return self._gmodel

    # coal's side of the checker is made on the first exact query: the sphere layer
    # decides most states without it, and a planner builds a checker per world state
    # and allowed-contact set (a dozen for a cell), most of which check a few segments.
    def _requests_into(self, gdata: pin.GeometryData) -> pin.GeometryData:
        """``gdata`` with contacts on and each pair's security margin."""
        requests = gdata.collisionRequests
        for k, margin in enumerate(self._security.tolist()):
            # Without contacts coal 3.0's boolean GJK path misses some deep box-box
            # penetrations (seen: two boxes 18 mm into each other reported free).
            requests[k].enable_contact = True
            if margin:
                requests[k].security_margin = margin
        return gdata

    @functools.cached_property
    def _gdata(self) -> pin.GeometryData:
        """coal's data of every pair, with its request."""
        return self._requests_into(pin.GeometryData(self.geometry_model))

    @functools.cached_property
    def _broad(self) -> Any:
        """Broad phase (AABB tree) for the fast path; it honours the same pairs and the
        same per-pair margins, and answers like the pair-by-pair loop (tested)."""
        return pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
            self.robot.model, self.geometry_model, self._gdata)

    def _batch_pool(self) -> Any:
        """The broad phase for batches of states (one C++ call), with the same pairs and
        per-pair margins."""
        if self._pool is None:
            pool = pin.BroadPhaseManagerPool_DynamicAABBTreeCollisionManager(
                self.robot.model, self.geometry_model, 1)
            self._requests_into(pool.getGeometryData(0))
            self._pool = pool
        return self._pool

    def _add(self, gmodel: pin.GeometryModel, name: str, joint: int, frame: int,
             T: np.ndarray, obj: SceneObject) -> int:
        geom = pin.GeometryObject(name, joint, frame, pin.SE3(np.asarray(T)),
                                  obj.shape.to_coal())
        idx = gmodel.addGeometryObject(geom)
        self._names.append(name)
        return int(idx)

    # -- facts -----------------------------------------------------------------------------
    @property
    def pairs(self) -> list[Pair]:
        """The pairs checked, as names."""
        return list(self._pair_names)

    def displacement_bound(self, q0: np.ndarray, q1: np.ndarray) -> float:
        """Upper bound on how far any point of the robot (or held object) moves along the
        straight joint segment ``q0 -> q1`` [m]."""
        return float(self._weights @ np.abs(np.asarray(q1) - np.asarray(q0)))

    @property
    def displacement_weights(self) -> np.ndarray:
        """Per joint, the largest distance [m] of any downstream point from the joint
        (a point moves at most ``weight * |dq|`` when the joint turns by ``dq`` [rad])."""
        return self._weights.copy()

    def _displacement_weights(self) -> np.ndarray:
        """Per joint, the reach of everything downstream (:func:`displacement_weights`)."""
        gmodel = self._gmodel
        return displacement_weights(self.robot.model, self._own_reach, [
            gmodel.geometryObjects[i]
            for i in range(self.robot.collision_model.ngeoms, gmodel.ngeoms)])

    # -- the fast layer ----------------------------------------------------------------------
    @property
    def layer(self) -> SphereLayer | None:
        """The sphere layer that decides most states before coal (None when disabled by
        ``CheckOptions(fast=False)`` or when a shape has no sphere fit)."""
        if not self._layer_built:
            self._bind_layer()
        return self._layer

    def layer_source(self) -> LayerSource:
        """What the sphere layer mirrors of this checker: its geometry, the environment's
        shapes, the pairs and their security margins, the resolution and the
        displacement weights."""
        return LayerSource(robot=self.robot, geometry=self._gmodel, environment=self._env,
                           pairs=self._pairs, security=self._security,
                           resolution=self.options.resolution,
                           displacement_weights=self.displacement_weights)

    def _bind_layer(self) -> None:
        self._layer_built = True
        if self.options.fast:
            try:
                self._layer = SphereLayer(self.layer_source())
            except ValueError as exc:
                log.info("no sphere layer (%s): every check is exact", exc)
        if self._layer is not None:
            self._bind_kernels()

    def _bind_kernels(self) -> None:
        """The layer's single-state and segment kernels and tables, bound once: they are
        the planners' innermost calls."""
        assert self._layer is not None
        self._classify = self._layer.kernel("classify")
        self._segment = self._layer.kernel("certify_segment")
        self._F, self._I = self._layer.F, self._layer.I

    # -- single states ---------------------------------------------------------------------
    def is_valid(self, q: np.ndarray) -> bool:
        """Inside the limits and collision-free (fast path, no details)."""
        if not self._layer_built:
            self._bind_layer()
        if self._classify is not None:
            # The layer has checked the limits: UNSURE states are inside them.
            status = self._classify(q, self._F, self._I)
            if status == UNSURE:
                return not self.exact_collides(q)
            return status == FREE
        r = self.robot
        if (q < r.lower).any() or (q > r.upper).any():
            return False
        return not self.exact_collides(q)

    def exact_collides(self, q: np.ndarray) -> bool:
        """Whether coal finds a collision at ``q`` (limits ignored; no sphere layer)."""
        return bool(pin.computeCollisions(self.robot.model, self._data, self._broad, q, True))

    def collisions(self, q: np.ndarray) -> list[Pair]:
        """Every colliding pair at ``q`` (limits ignored)."""
        if not pin.computeCollisions(self.robot.model, self._data, self.geometry_model,
                                     self._gdata, q, False):
            return []  # no pair collides: no result to read back
        hits = [self._pair_names[k] for k, res in enumerate(self._gdata.collisionResults)
                if res.isCollision()]
        return list(dict.fromkeys(hits))  # a link may have several shapes

    def distances(self, q: np.ndarray) -> list[tuple[Pair, float]]:
        """Distance [m] of every robot-environment pair of names at ``q`` (the smallest
        over the shapes of a link; allowed contacts excluded)."""
        return self._nearest.every_distance(q)

    def margins(self) -> dict[Pair, float]:
        """The margin [m] each robot-environment pair of names keeps (allowed contacts
        excluded; the largest over the shapes of a link)."""
        return dict(self._distance_pairs.margin_of)

    @functools.cached_property
    def _distance_pairs(self) -> PairMargins:
        return PairMargins(self._dist_pairs, self._pair_names, self._pair_margin.tolist())

    def clearance(self, q: np.ndarray) -> tuple[float, Pair | None]:
        """Smallest robot-environment distance at ``q`` [m], and its pair."""
        return self._nearest.clearance(q)  # coal measures the pairs that may be nearest

    def check(self, q: Any, *, free: bool | None = None) -> StateReport:
        """Full report for one joint vector (see :class:`StateReport`); ``free``: what
        :meth:`proven_free` said of ``q`` (asked here when None).

        Raises:
            PoseError: ``q`` has the wrong length or a non-finite value.
        """
        q = self.robot.as_joint_vector(q, check_limits=False)
        violation = self.robot.limit_violation(q)
        # A state the sphere layer proves free has no colliding pair (its shapes enclose
        # the robot's and the pairs' margins): coal is asked for distances only.
        free = bool(self.proven_free(q[None])[0]) if free is None else free
        # coal measures the pairs the layer cannot rule out.
        collisions, clearance, pair, short = self._nearest.report(q, free)
        return StateReport(q=q, within_limits=violation is None, limit_violation=violation,
                           collisions=collisions, clearance=clearance, closest_pair=pair,
                           margin_violations=short)

    @functools.cached_property
    def _nearest(self) -> NearestPairs:
        """coal's figures from the pairs the sphere layer cannot rule out (every pair
        without a layer)."""
        return NearestPairs(self.robot.model, self.geometry_model, self._gdata,
                            self._distance_pairs, self._pair_names,
                            bounds_kernel(self.layer, self._security, self._distance_pairs))

    def proven_free(self, Q: np.ndarray) -> np.ndarray:  # noqa: N803
        """Whether the sphere layer proves each row of ``Q`` free (all False without one)."""
        if not self._layer_built:
            self._bind_layer()
        if self._layer is None:
            return np.zeros(len(Q), dtype=bool)
        return self._layer.classify_many(Q) == FREE

    # -- segments --------------------------------------------------------------------------
    def segment_states(self, q0: np.ndarray, q1: np.ndarray) -> int:
        """Number of intervals a segment is cut into to meet the resolution."""
        return max(1, int(np.ceil(self.displacement_bound(q0, q1) / self.options.resolution)))

    def segment_is_valid(self, q0: np.ndarray, q1: np.ndarray, *,
                         check_ends: bool = True) -> bool:
        """Whether the straight segment is valid at the checker's resolution (as
        :meth:`check_segment`, without a report: the planners' edge check)."""
        if not self._layer_built:
            self._bind_layer()
        if self._segment is None:
            return self.check_segment(q0, q1, check_ends=check_ends, details=False).valid
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        found = np.empty(_EARLY_UNSURE, dtype=np.int64)
        walk = self._segment(q0, q1, self._F, self._I, not check_ends, not check_ends, found)
        status, unsure = walk[0], walk[3]
        if status == FREE and unsure == 0:
            return True
        if status == COLLIDES or status == OUTSIDE:
            return False
        return self._settle(q0, q1, check_ends, not check_ends, walk, found, False).valid

    def check_segment(self, q0: Any, q1: Any, *, check_ends: bool = True,
                      check_start: bool | None = None, details: bool = True) -> SegmentReport:
        """Check the straight joint segment ``q0 -> q1``.

        States are checked in bisection order (ends, middle, quarters, ...) so that a
        collision is found early; together they are spaced so that no robot point
        moves more than ``options.resolution`` between neighbours. Joint limits are
        checked at the ends (the joint-limit box is convex, so the segment is inside
        it when both ends are, even with ``check_ends=False``).

        Args:
            q0: Start [rad].
            q1: End [rad].
            check_ends: Check the end states for collision too.
            check_start: Override for the start state alone (e.g. False along a
                polyline whose previous segment checked it).
            details: Collect the colliding pairs of a failure.
        """
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        if self.layer is not None:
            return self._certify_segment(q0, q1, check_ends, check_start, details)
        for s, end in ((0.0, q0), (1.0, q1)):
            if not self.robot.within_limits(end):
                return self._outside(end, s)
        n = self.segment_states(q0, q1)
        order = _bisection_order(n, check_ends)
        if check_start is False:
            order = [i for i in order if i != 0]
        elif check_start and not check_ends:
            order = [0, *order]
        if not order:
            return SegmentReport(True, 0)
        fractions = np.asarray(order, dtype=float) / n
        states = q0[None, :] + fractions[:, None] * (q1 - q0)[None, :]
        # Bisection order: a collision is found early, and the batch stops there.
        return self._check_states(states, fractions, details)

    def _certify_segment(self, q0: np.ndarray, q1: np.ndarray, check_ends: bool,
                         check_start: bool | None, details: bool) -> SegmentReport:
        """:meth:`check_segment` with the sphere layer: limits, grid count and the walk
        in one kernel call (the planners' common case). The states it leaves undecided
        go to coal; when the walk stopped at its first few undecided states and coal
        finds them free, the general polyline way walks the whole grid again (the walk
        is deterministic: it finds the same states first)."""
        layer = self.layer
        assert layer is not None
        skip_start = check_start is False or (not check_ends and not check_start)
        found = np.empty(_EARLY_UNSURE, dtype=np.int64)
        walk = layer.certify_segment(q0, q1, skip_start, not check_ends, found)
        return self._settle(q0, q1, check_ends, skip_start, walk, found, details)

    def _settle(self, q0: np.ndarray, q1: np.ndarray, check_ends: bool, skip_start: bool,
                walk: tuple[int, int, int, int, int], found: np.ndarray, details: bool
                ) -> SegmentReport:
        """The report of a segment from its one-call walk (``walk``: what the kernel
        returned; ``found``: the grid indices of the states it left undecided)."""
        status, i, evaluated, unsure, n = walk
        if status == OUTSIDE:
            return self._outside(q1 if i else q0, float(i))
        if status == COLLIDES:
            return self._failure(q0 + (i / n) * (q1 - q0), i / n, evaluated, details)
        if unsure == 0:
            return SegmentReport(True, evaluated)
        P = np.vstack([q0, q1])
        counts = np.array([n])
        early = self._exact_grid(P, counts, np.zeros(unsure, dtype=np.int64), found[:unsure],
                                 details, evaluated)
        if not early.valid or status == FREE:
            return early
        return self._certify(P, counts, np.array([1 if skip_start else 0]),
                             np.array([n if check_ends else n - 1]), details,
                             checked=unsure, evaluated=evaluated)

    def _outside(self, q: np.ndarray, fraction: float) -> SegmentReport:
        """The report of a motion whose state ``q`` (at ``fraction``) is outside the
        joint limits."""
        return SegmentReport(False, 0, fraction, q.copy(), (), self.robot.limit_violation(q))

    def _failure(self, q: np.ndarray, fraction: float, checked: int, details: bool
                 ) -> SegmentReport:
        """The report of a motion that collides at ``q`` (at ``fraction``), found after
        ``checked`` states; with ``details``, its colliding pairs."""
        if not details:
            return SegmentReport(False, checked, fraction, q)
        return SegmentReport(False, checked, fraction, q, tuple(self.collisions(q)),
                             self.robot.limit_violation(q))

    def check_path(self, path: Sequence[np.ndarray], *, details: bool = True,
                   check_start: bool = True, check_end: bool = True) -> SegmentReport:
        """Check a joint-space polyline at the checker's resolution.

        Every waypoint and, on every segment, states spaced as in :meth:`check_segment`
        are evaluated in one batch (in path order, stopping at the first collision).
        ``fraction`` of a failure is measured along the whole polyline (segments count
        equally). A waypoint outside the joint limits fails the path before any state is
        checked.

        Args:
            path: The waypoints [rad].
            details: Report the colliding pairs of a failure.
            check_start: Check the first waypoint (False: it was checked before, as the
                end of the motion before).
            check_end: Check the last waypoint.
        """
        P = np.asarray(path, dtype=float)
        if P.ndim != 2 or len(P) < 1:
            return SegmentReport(True, 0)
        robot = self.robot
        outside = ~np.all((P >= robot.lower) & (P <= robot.upper), axis=1)
        if outside.any():
            k = int(np.argmax(outside))
            return self._outside(P[k], k / max(1, len(P) - 1))
        # segment_states of every segment at once.
        counts = np.maximum(1, np.ceil(np.abs(np.diff(P, axis=0)) @ self._weights
                                       / self.options.resolution)).astype(np.int64)
        if len(P) == 1 and not (check_start and check_end):
            return SegmentReport(True, 0)
        if self.layer is not None and len(P) > 1:
            lo = np.ones(len(counts), dtype=np.int64)
            lo[0] = 0 if check_start else 1
            hi = counts
            if not check_end:
                hi = counts.copy()
                hi[-1] -= 1
            return self._certify(P, counts, lo, hi, details)
        chunks, where = [P[:1]], [np.zeros(1)]
        for k in range(len(P) - 1):
            f = np.arange(1, counts[k] + 1) / counts[k]
            chunks.append(P[k][None, :] + f[:, None] * (P[k + 1] - P[k])[None, :])
            where.append(k + f)
        states, fractions = np.vstack(chunks), np.concatenate(where) / max(1, len(P) - 1)
        first, stop = (0 if check_start else 1), len(states) - (0 if check_end else 1)
        return self._check_states(states[first:stop], fractions[first:stop], details)

    def check_states(self, states: Any, fractions: Any = None, *, details: bool = True
                     ) -> SegmentReport:
        """Check ``states`` exactly (coal), in the given order, stopping at the first
        collision (later states are then not evaluated): a few one by one, more in one
        batch. A state outside the joint limits fails the check before any is checked.

        Args:
            states: Joint positions, one state per row [rad].
            fractions: Where each state lies along the motion they sample, in [0, 1],
                for the report's ``fraction`` (default: k / (n - 1) for the k-th of n).
            details: Report the colliding pairs of a failure.

        Raises:
            InputError: ``fractions`` not one per state.
        """
        P = np.atleast_2d(np.asarray(states, dtype=float))
        if fractions is None:
            fractions = np.arange(len(P)) / max(1, len(P) - 1)
        fractions = np.asarray(fractions, dtype=float)
        if fractions.shape != (len(P),):
            raise InputError(f"fractions: {fractions.shape} for {len(P)} states, one per "
                             "state wanted", key="fractions")
        robot = self.robot
        outside = ~np.all((P >= robot.lower) & (P <= robot.upper), axis=1)
        if outside.any():
            k = int(np.argmax(outside))
            return self._outside(P[k], float(fractions[k]))
        return self._check_states(P, fractions, details)

    def _certify(self, P: np.ndarray, counts: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 details: bool, checked: int = 0, evaluated: int = 0) -> SegmentReport:
        """Grid states ``lo[k]..hi[k]`` of every segment of the polyline ``P`` (segment
        ``k`` cut into ``counts[k]`` steps): certified by the sphere layer where it can,
        the rest checked exactly by coal in one batch. ``fraction`` of a failure is
        measured along the whole polyline. ``checked``: the walk's first undecided
        states already found free by coal (an earlier walk of the same grid, which
        evaluated ``evaluated`` states)."""
        layer = self.layer
        assert layer is not None
        span = max(1, len(P) - 1)
        status = UNSURE
        if not checked:
            # A blocked segment usually shows its first undecided states near the
            # obstacle: check a few exactly before certifying the rest.
            status, k, i, evaluated, useg, uidx = layer.certify(P, counts, lo, hi,
                                                                _EARLY_UNSURE)
            if status == UNSURE:
                early = self._exact_grid(P, counts, useg, uidx, details, evaluated)
                if not early.valid:
                    return early
                checked = len(useg)
        if status == UNSURE:
            # The walk is deterministic: it finds the same undecided states first again.
            status, k, i, again, useg, uidx = layer.certify(P, counts, lo, hi)
            evaluated += again
        if status == COLLIDES:
            q = P[k] + (i / counts[k]) * (P[k + 1] - P[k])
            return self._failure(q, (k + i / counts[k]) / span, evaluated, details)
        if len(useg) == checked:
            return SegmentReport(True, evaluated)
        return self._exact_grid(P, counts, useg[checked:], uidx[checked:], details, evaluated)

    def _exact_grid(self, P: np.ndarray, counts: np.ndarray, seg: np.ndarray,
                    idx: np.ndarray, details: bool, evaluated: int) -> SegmentReport:
        """Check grid states ``idx`` of segments ``seg`` of the polyline ``P`` with coal
        (one batch); ``evaluated`` states were already evaluated by the sphere layer,
        these among them."""
        t = (idx / counts[seg])[:, None]
        states = P[seg] + t * (P[seg + 1] - P[seg])
        report = self._check_states(states, (seg + t[:, 0]) / max(1, len(P) - 1), details)
        return replace(report, checked=evaluated - len(seg) + report.checked)

    def _check_states(self, states: np.ndarray, fractions: np.ndarray, details: bool
                      ) -> SegmentReport:
        """Collision-check ``states`` (rows, inside the limits) in one C++ batch call,
        in the given order, stopping at the first collision (later states are then not
        evaluated); ``fractions`` says where each state lies, for the report."""
        if len(states) <= _FEW:  # the sphere layer leaves a few: not worth a batch pool
            for k, q in enumerate(states):
                if self.exact_collides(q):
                    return self._failure(q, float(fractions[k]), k + 1, details)
            return SegmentReport(True, len(states))
        hits = np.asarray(pin.computeCollisionsInParallel(
            1, self._batch_pool(), np.asfortranarray(states.T), True, True), dtype=bool)
        if not hits.any():
            return SegmentReport(True, len(states))
        first = int(np.argmax(hits))
        return self._failure(states[first], float(fractions[first]), first + 1, details)


#: Up to this many states are checked one by one (coal's broad phase, ~12 µs each for the
#: Ned3 Pro in its cell) rather than in a batch, whose pool costs ~1-5 ms to make.
_FEW = 32


def _bisection_order(n: int, check_ends: bool) -> list[int]:
    """Indices 0..n in coarse-to-fine order: ends (if asked), middle, quarters, ..."""
    from collections import deque

    out = [0, n] if check_ends else []
    queue = deque([(0, n)])
    while queue:
        lo, hi = queue.popleft()
        if hi - lo < 2:
            continue
        mid = (lo + hi) // 2
        out.append(mid)
        queue.append((lo, mid))
        queue.append((mid, hi))
    return out
