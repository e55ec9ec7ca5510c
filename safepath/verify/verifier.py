"""Independent re-check of timed trajectories with python-fcl, before release.

The verifier shares nothing with the planner's checker but the *data*: it builds its
own FCL shapes from the robot's collision geometry and the scene, derives its own list
of pairs from the robot's allowed self-collision pairs, the tool's contact links and the
allowed contacts, computes its own kinematics and its own conservative bounds
(``_bounds``, ``_kernel``, ``_distance``), and lets FCL (not coal)
judge every sample those bounds cannot clear.

Resolution guarantee: the timed trajectory is cut into a grid on which no point of the
robot (or the held object) moves more than ``resolution`` between two samples. For
every pair and every grid sample, either FCL judges the pair there, or the sample is
certified: at an earlier (or the same) sample, the conservative layer bounded the
pair's distance from below, and that bound minus how much the pair's bodies can have
moved it since still exceeds what the pair must keep (its margin, zero, or, for a pair
allowed to touch, zero: in contact, FCL's penetration depth decides).

Geometry: boxes, spheres, cylinders, capsules, convex meshes and triangle meshes (FCL
checks the mesh itself; the conservative layer bounds it by the hull of its vertices,
which encloses it). :func:`check_verifiable` refuses anything else before planning
starts, naming the object.
"""

from __future__ import annotations

import copy
import functools
import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import VerificationError
from ..model.robot import Robot
from ..model.scene import GRIPPER, AllowedContact, Scene
from ._between import Strays, clearance_bound, unproven
from ._bodies import (
    Body,
    check_verifiable,
    environment_bodies,
    held_bodies,
    robot_bodies,
)
from ._bounds import (
    Grid,
    Layer,
    PoseCache,
    WalkMemory,
    motion_weights,
    pair_weights,
    undominated,
)

__all__ = ["CheckedPair", "FclVerifier", "StagedVerifier", "StateBounds", "VerifyResult",
           "check_verifiable"]

Pair = tuple[str, str]
#: Margin kept between the clearance walk's threshold and the tolerance [m], so that
#: FCL and GJK may disagree that little about the same closest points.
_SLACK = 1e-5


@dataclass(frozen=True)
class VerifyResult:
    """Outcome of a successful verification.

    Attributes:
        samples: Samples on the resolution grid.
        checked: Samples at which FCL judged or measured at least one pair (every other
            pair there, and every pair at the other samples, was certified).
        min_clearance: Smallest robot-environment distance over the grid samples [m]:
            FCL's distance at one of them, every other sample being certified, or
            measured by FCL, no closer than that minus half the resolution (inf
            without environment pairs; inf as well when it is not below the
            ``known`` clearance the verification was given: then every sample is no
            closer than ``known`` minus half the resolution).
        closest_pair: Its pair (None with an inf clearance).
        pair_checks: Pair checks made with FCL.
        bound_checks: Pair bounds evaluated by the conservative layer.
        clearance_bound: Certified lower bound on the clearance at every instant of the
            executed motion, between samples too [m]: never negative, the release
            criterion (inf without environment pairs; :mod:`safepath.verify._between`).
    """

    samples: int
    checked: int
    min_clearance: float
    closest_pair: Pair | None
    pair_checks: int = 0
    bound_checks: int = 0
    clearance_bound: float = float("inf")


@dataclass(frozen=True)
class CheckedPair:
    """One pair of bodies the release check judges (:attr:`FclVerifier.pairs`).

    Attributes:
        names: The bodies' names: a link or the held object, then a link, the held
            object or an environment object.
        first: The first body's index in :attr:`FclVerifier.movers`.
        second: The second body's index in :attr:`FclVerifier.environment` if
            ``environment``, else in :attr:`FclVerifier.movers`.
        environment: Whether the second body is an environment object.
        allowed_depth: How deep the bodies may touch [m] (0: not at all).
        keep: What the signed distance must not fall below [m]: minus the allowed depth
            of a contact, else the object's margin if margins are enforced, else 0.
        certified_above: What the conservative layer must prove the distance exceeds
            to certify a sample [m]: ``keep``, or 0 for a pair allowed to touch (in
            contact, FCL's penetration depth decides).
        clearance: Whether the pair's distance counts for the clearance (a moving body
            against an environment object, no contact allowed).
    """

    names: Pair
    first: int
    second: int
    environment: bool
    allowed_depth: float
    keep: float
    certified_above: float
    clearance: bool


@dataclass(frozen=True)
class StateBounds:
    """The conservative layer's reading of one robot state (:meth:`FclVerifier.bounds_at`).

    Attributes:
        bounds: Per pair of :attr:`FclVerifier.pairs`, its lower bound on the signed
            distance [m] (the finest the layer computes; at most 0 in collision).
        T_world_geom: Per moving body of :attr:`FclVerifier.movers`, its geometry frame
            in the world as the layer's own kinematics place it (bodies x 3 x 4) [m].
    """

    bounds: np.ndarray
    T_world_geom: np.ndarray


class FclVerifier:
    """Re-checks timed samples with FCL for one world state.

    Args:
        robot: The robot.
        scene: The scene (None: self-collision only).
        held: Held object name, or None.
        resting: World placements of movable objects not held (None: absent).
        allowed: Allowed contacts in this state.
        resolution: Largest motion between samples [m].
        margin: Safety margin override [m]; None uses the scene's.
        enforce_margin: Count a sample closer to an object than its margin as a failure.

    Raises:
        ConfigError: A geometry or joint the verifier does not handle (see
            :func:`check_verifiable`).
    """

    def __init__(self, robot: Robot, scene: Scene | None, *, held: str | None = None,
                 resting: dict[str, np.ndarray | None] | None = None,
                 allowed: Iterable[AllowedContact] = (), resolution: float = 0.002,
                 margin: float | None = None, enforce_margin: bool = True) -> None:
        self.robot = robot
        self.resolution = resolution
        self.enforce_margin = enforce_margin
        self._scene, self._held, self._margin = scene, held, margin
        bodies, weights, self._joint_tables = robot_bodies(robot)
        held_ones = held_bodies(robot, scene, held)
        self._movers = bodies + held_ones
        self._env = environment_bodies(scene, held, resting)
        self._use_pairs(self._pair_list(allowed))
        self._weights = np.vstack([weights, motion_weights(
            robot.model, [b.joint for b in held_ones], [b.T for b in held_ones],
            [b.spec for b in held_ones])])
        self._grid_weights = undominated(self._weights)  # the same grids, cut faster
        self._layer = self._conservative_layer()

    def with_allowed(self, allowed: Iterable[AllowedContact]) -> FclVerifier:
        """This verifier with other allowed contacts (the same robot, scene, world state,
        resolution and margins): its bodies and its layer's tables are taken from this
        one (to be used in the same thread); the pairs, their weights and what each must
        keep are made anew. Judges as a new verifier does (tested)."""
        new = copy.copy(self)
        new._use_pairs(new._pair_list(allowed))
        same = np.array_equal(new._table[:, :3], self._table[:, :3])
        new._layer = (self._layer.with_clearance(new._tracked) if same
                      else new._conservative_layer(self._layer))
        return new

    def _use_pairs(self, table: np.ndarray) -> None:
        """Check the pairs of ``table`` (see :meth:`_pair_list`): what each must keep."""
        self._table = table
        self._pair_rows: list[tuple[int, int, bool, float]] | None = None
        self._pair_records: tuple[CheckedPair, ...] | None = None
        env, depth = table[:, 2] != 0.0, table[:, 3]
        self._theta = self._thresholds(table[:, 1].astype(np.int64), env, depth)
        # The layer certifies a pair allowed to touch only where it is apart: in
        # contact, FCL's penetration depth decides.
        self._bound_theta = np.where(depth > 0.0, 0.0, self._theta)
        self._tracked = env & (depth == 0.0)

    def _thresholds(self, other: np.ndarray, env: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """What each pair (its second body or object ``other``, whether that is an
        environment object, its allowed depth [m]) must keep: its signed distance must
        not fall below this [m] (minus the allowed depth of a contact, the object's
        margin if enforced, else 0)."""
        keep = np.zeros(depth.size)
        if self.enforce_margin and self._env:
            keep = np.where(env, self._env_margins[np.where(env, other, 0)], 0.0)
        return np.where(depth > 0.0, -depth, keep)

    @functools.cached_property
    def _env_margins(self) -> np.ndarray:
        """Each environment object's margin [m]: the override, else the scene's."""
        scene, margin = self._scene, self._margin
        return np.array([margin if margin is not None else
                         (scene.margin_for(b.name) if scene else 0.0)
                         for b in self._env], dtype=float)

    @property
    def _pairs(self) -> list[tuple[int, int, bool, float]]:
        """(mover, mover or environment object, is environment, allowed depth [m]) of
        every pair checked, made from the table when first asked for."""
        if self._pair_rows is None:
            self._pair_rows = [(int(i), int(j), bool(env), float(depth))
                               for i, j, env, depth in self._table.tolist()]
        return self._pair_rows

    @property
    def pairs(self) -> tuple[CheckedPair, ...]:
        """Every pair this verifier judges, in the order of its bounds
        (:meth:`bounds_at`) and of :attr:`pair_weights`."""
        if self._pair_records is None:
            names = [b.name for b in self._movers], [b.name for b in self._env]
            self._pair_records = tuple(
                CheckedPair((names[0][i], names[int(env)][j]), i, j, env, depth,
                            float(keep), float(above), bool(tracked))
                for (i, j, env, depth), keep, above, tracked in zip(
                    self._pairs, self._theta, self._bound_theta, self._tracked,
                    strict=True))
        return self._pair_records

    @property
    def movers(self) -> tuple[Body, ...]:
        """The moving bodies: the robot's collision geometries, each on its joint, then
        the held object (if any). Their FCL objects are this verifier's own: placing
        one moves it for the verifier too (:meth:`verify` places them itself)."""
        return tuple(self._movers)

    @property
    def environment(self) -> tuple[Body, ...]:
        """The environment objects, placed in the world: the scene's fixed objects and
        the movable ones where they rest (not the held one)."""
        return tuple(self._env)

    @property
    def motion_weights(self) -> np.ndarray:
        """Per moving body and joint, a bound on how far a unit of that joint's motion
        moves the body's points [m/rad] or [m/m] (zero for joints that do not move it):
        (bodies x dof), read-only. The grid is cut with them."""
        weights = self._weights.view()
        weights.flags.writeable = False
        return weights

    @property
    def pair_weights(self) -> np.ndarray:
        """Per pair of :attr:`pairs` and joint, a bound on how much a unit of that
        joint's motion can change the pair's distance [m/rad] or [m/m], as the
        conservative layer walks it: (pairs x dof), read-only."""
        return self._layer.pair_weights

    def grid(self, q: np.ndarray) -> Grid:
        """The resolution grid :meth:`verify` cuts knots ``q`` [rad] (knots x dof) into:
        no point of a moving body moves more than :attr:`resolution` [m] between two
        samples."""
        return Grid.cut(np.asarray(q, dtype=float), self._grid_weights, self.resolution)

    def bounds_at(self, q: np.ndarray) -> StateBounds:
        """The conservative layer's lower bound on every pair's signed distance at the
        state ``q`` [rad], and where its own kinematics place the moving bodies: a
        diagnostic of how close the bounds :meth:`verify` certifies samples with come
        to FCL's distances. Each bound is at most FCL's distance (at most 0 in
        collision)."""
        bounds, poses = self._layer.bounds_at(q)
        return StateBounds(bounds, poses)

    def poses_at(self, states: np.ndarray, mover: int) -> np.ndarray:
        """Where the verifier's own kinematics place :attr:`movers` ``mover`` (its geometry
        frame in the world, states x 3 x 4 [m]) at ``states`` [rad], off its grid."""
        return self._layer.poses_at(states, mover)

    def _conservative_layer(self, like: Layer | None = None) -> Layer:
        """The layer that bounds every pair's distance from below (``_bounds``);
        made from ``like``'s tables if given (a layer of the same bodies and
        environment)."""
        joints = [b.joint for b in self._movers]
        pairs = self._table[:, :3]
        weights = pair_weights(self.robot.model, joints, self._weights, pairs)
        if like is not None:
            return like.with_pairs(pairs, weights, self._tracked)
        return Layer(joints, [b.T for b in self._movers],
                     [b.spec for b in self._movers], [b.T for b in self._env],
                     [b.spec for b in self._env], pairs, weights, self._tracked,
                     self._joint_tables)

    def _pair_list(self, allowed: Iterable[AllowedContact]) -> np.ndarray:
        """(mover, mover or environment object, is environment, allowed depth [m]) of
        every pair to check, as rows: the candidates (:meth:`_candidates`) not allowed to
        touch at any depth, with the depth each is allowed to."""
        contact_links = set(self.robot.tool.contact_links) if self.robot.tool else set()
        depth = _allowed_depths(allowed, contact_links)
        table, rows_of = self._candidates
        if not depth:
            return table
        table = table.copy()
        keep = np.ones(len(table), dtype=bool)
        for key, d in depth.items():
            at = rows_of.get(key)
            if at is None:
                continue  # never checked
            if d is None:
                keep[at] = False
            else:
                table[at, 3] = d
        return table[keep]

    @functools.cached_property
    def _candidates(self) -> tuple[np.ndarray, dict[Pair, list[int]]]:
        """The pairs to check where no contact is allowed, as rows (mover, mover or
        environment object, is environment, 0), and the rows of each pair of names
        (sorted): not on the same joint, not an allowed self pair, not the held object
        against the jaws; every moving body against every environment object. Made once
        for a world state (its verifiers for other allowed contacts share it)."""
        robot, held = self.robot, self._held
        contact_links = set(robot.tool.contact_links) if robot.tool else set()
        rows_of: dict[Pair, list[int]] = {}
        pairs: list[tuple[int, int, bool, float]] = []
        names = [b.name for b in self._movers]
        joints = [b.joint for b in self._movers]
        self_pairs = robot.allowed_self_pairs

        def add(key: Pair, i: int, j: int, env: bool) -> None:
            rows_of.setdefault(key, []).append(len(pairs))
            pairs.append((i, j, env, 0.0))

        for i, j in itertools.combinations(range(len(names)), 2):
            a, b = names[i], names[j]
            if a == b or joints[i] == joints[j]:
                continue
            key = (a, b) if a < b else (b, a)
            is_held = held is not None and held in key
            if is_held and (a in contact_links or b in contact_links):
                continue
            if not is_held and key in self_pairs:
                continue
            add(key, i, j, False)
        for i, a in enumerate(names):
            if joints[i] == 0:
                continue
            for j, e in enumerate(self._env):
                add((a, e.name) if a <= e.name else (e.name, a), i, j, True)
        return np.array(pairs, dtype=float).reshape(-1, 4), rows_of

    def _names(self, p: int) -> Pair:
        i, j, env, _ = self._pairs[p]
        return (self._movers[i].name, self._env[j].name if env else self._movers[j].name)

    def verify(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, *,
               steps: Sequence[str] | None = None, known: float = float("inf")
               ) -> VerifyResult:
        """Check a timed trajectory; raise on the first failing sample.

        The knots are first cut into a grid on which no point moves more than the
        resolution between samples. The conservative layer then walks every pair along
        the grid with its lower bound on the distance, certifying the samples until
        the pair's bodies can have moved that bound down to what the pair must keep;
        FCL judges the pair at every sample left, in time order. The clearance pairs
        are walked against the smallest clearance found so far instead, so that it comes
        out to within half the resolution, or against their margin or what the check
        between samples needs, whichever is highest.

        Args:
            t: Knot times [s].
            q: Knot positions [rad].
            qd: Knot velocities [rad/s] (unused, kept for the interface).
            steps: Step name of each knot (for the error).
            known: A clearance already found elsewhere [m] (the earlier pieces of the
                same route): this trajectory's is measured only where it is below that,
                to within half the resolution as always; above it, the walk certifies
                every sample no closer than ``known`` minus half the resolution and the
                result says inf. The route's smallest clearance comes out the same,
                for much less work where this trajectory keeps further away. The
                safety judgement (collisions, margins, allowed depths) does not
                depend on it.

        Release criterion: every sample keeps what its pairs must keep, and the
        certified clearance bound (:attr:`VerifyResult.clearance_bound`, between the
        samples too) is not negative; where the grid's figure does not prove it, a finer
        check subdivides the intervals (:mod:`safepath.verify._between`).

        Raises:
            VerificationError: A sample collides, comes closer than a margin, or
                penetrates deeper than an allowed contact's depth.
            UnprovenClearance: The certified clearance bound of a pair stays negative
                after the finer check (names the pair and the bound).
        """
        q = np.asarray(q, dtype=float)
        grid = self.grid(q)
        n = len(self._table)
        everywhere = (np.zeros(n, dtype=np.int64), np.full(n, grid.samples, dtype=np.int64))
        return self._check(t, q, grid, np.arange(n), everywhere, steps, known)

    def _check(self, t: np.ndarray, q: np.ndarray, grid: Grid, todo: np.ndarray,
               stretches: tuple[np.ndarray, np.ndarray], steps: Sequence[str] | None,
               known: float) -> VerifyResult:
        """:meth:`verify` on ``grid``, each pair of ``todo`` on its stretch of samples
        (first, after the last); a pair may come more than once."""
        run = _Run(self, q, grid, self._layer.cache(grid.samples), known, (todo, stretches))
        strays = Strays.of(t, self._weights[self._table[:, 0].astype(np.int64)],
                           self.robot.acceleration_limits, self.resolution)
        # Clearance pairs: held to what the finer check needs too, bounded at a few samples first.
        theta = np.where(self._tracked, np.maximum(self._bound_theta, strays.above),
                         self._bound_theta)
        keep = self._tracked[todo]
        clearance = (todo[keep], stretches[0][keep], stretches[1][keep])
        self._layer.pilot(clearance, theta, q, grid, run.cache, run.memory, run.drop)
        left = run.walk(todo, theta, stretches, drop=run.drop)
        fail_at, bad = run.safety(*left)
        if bad:
            k = int(grid.knot_of[fail_at])
            names = list(dict.fromkeys(self._names(p) for p in bad))  # a link: many shapes
            raise VerificationError(
                "timed sample in collision or inside a margin: "
                + ", ".join(f"{a} / {b}" for a, b in names),
                time=float(t[k]), q=grid.state(q, fail_at), pairs=names,
                step=steps[k] if steps is not None else None)
        run.clearance(*left)
        between = clearance_bound(run, grid, (np.asarray(t, dtype=float), q), clearance,
                                  left, strays, run.min_clear, self.resolution)
        if not between.proven:
            k = int(grid.knot_of[between.sample + 1])
            raise unproven(between, self._names(between.pair), grid, (t, q),
                           steps[k] if steps is not None else None)
        if run.closest < 0:  # none (or none below ``known``)
            return VerifyResult(grid.samples, len(run.checked), float("inf"), None,
                                run.pair_checks, int(run.memory.stats[0]), between.bound)
        return VerifyResult(grid.samples, len(run.checked), run.min_clear,
                            self._names(run.closest), run.pair_checks,
                            int(run.memory.stats[0]), between.bound)


class StagedVerifier:
    """Verifiers of one world state that differ only in their allowed contacts, as one
    check of a trajectory whose consecutive stretches each follow one of them.

    A route's piece often crosses steps that allow different contacts (a finger may
    touch the vial in one, must keep its margin in the next). Checked as one, the piece
    is cut into one grid (the same samples as its stretches' grids together: the grid
    cuts every knot interval on its own), each pair is walked once along the stretches
    where its rules hold (a pair whose rules are the same in two consecutive stages is
    walked across their boundary, its bound carried over), and the knot two stages
    share is judged under both, as when each stage is verified on its own.

    Args:
        stages: Verifiers made with :meth:`FclVerifier.with_allowed` from one another
            (the same robot, bodies, environment, resolution and margins).

    Raises:
        ValueError: Stages that are not of one world state and resolution.
    """

    def __init__(self, stages: Sequence[FclVerifier]) -> None:
        first = stages[0]
        for v in stages[1:]:
            if (v._movers is not first._movers or v._env is not first._env
                    or v.resolution != first.resolution
                    or v.enforce_margin != first.enforce_margin
                    or v._margin != first._margin):
                raise ValueError("staged verifiers must be of one world state, resolution "
                                 "and margin (made with FclVerifier.with_allowed)")
        # Every pair (with what it must keep) of any stage, in the order first seen, and
        # the stages each belongs to.
        rows = np.concatenate([v._table for v in stages])
        _, first_at, union_of = np.unique(_row_keys(rows), return_index=True,
                                          return_inverse=True)
        order = np.argsort(first_at)
        position = np.empty_like(order)
        position[order] = np.arange(len(order))
        if len(stages) == 1:
            self._joined = first
        else:
            self._joined = copy.copy(first)
            self._joined._use_pairs(rows[first_at[order]])
            self._joined._layer = self._joined._conservative_layer(first._layer)
        stage_of = np.repeat(np.arange(len(stages)), [len(v._table) for v in stages])
        member = np.zeros((len(order), len(stages)), dtype=np.bool_)
        member[position[union_of.reshape(-1)], stage_of] = True
        # Each pair's runs of consecutive stages it belongs to, pair by pair: the pair,
        # its first stage and its last.
        padded = np.zeros((len(order), len(stages) + 2), dtype=np.int8)
        padded[:, 1:-1] = member
        edges = np.diff(padded, axis=1)
        self._todo, self._from = (a.astype(np.int64) for a in np.nonzero(edges == 1))
        self._to = np.nonzero(edges == -1)[1].astype(np.int64) - 1
        self.verifiers = tuple(stages)

    def verify(self, t: np.ndarray, q: np.ndarray, starts: Sequence[int], *,
               steps: Sequence[str] | None = None, known: float = float("inf")
               ) -> VerifyResult:
        """Check a timed trajectory, stage ``k`` from knot ``starts[k]`` to knot
        ``starts[k + 1]`` (both included; the last stage to the last knot), as
        :meth:`FclVerifier.verify` checks each stretch with its stage's verifier.

        Raises:
            VerificationError: As :meth:`FclVerifier.verify`; the first failing sample
                in time.
            ValueError: ``starts`` not one per stage, from knot 0, not descending.
        """
        q = np.asarray(q, dtype=float)
        knots = [*map(int, starts), len(q) - 1]
        if (len(knots) != len(self.verifiers) + 1 or knots[0] != 0
                or any(b < a for a, b in itertools.pairwise(knots))):
            raise ValueError(f"stage starts {list(starts)}: one per stage "
                             f"({len(self.verifiers)}), from knot 0, not descending, before "
                             f"knot {len(q)}")
        joined = self._joined
        grid = joined.grid(q)
        # The sample at each knot (the last of its interval), and each stage's stretch.
        at = np.searchsorted(grid.knot_of, knots, side="right") - 1
        first, stop = at[:-1][self._from], at[1:][self._to] + 1
        return joined._check(t, q, grid, self._todo, (first, stop), steps, known)


class _Run:
    """The FCL side of one verification: places the bodies from the layer's pose cache
    and judges the pairs the layer could not certify."""

    def __init__(self, verifier: FclVerifier, q: np.ndarray, grid: Grid,
                 cache: PoseCache, known: float,
                 entries: tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]) -> None:
        import fcl

        self.v = verifier
        self.entries = entries  # the pairs walked and their stretches
        self.q = q
        self.grid = grid
        self.cache = cache
        self.memory = WalkMemory.empty(len(verifier._table))
        self.checked: set[int] = set()
        self.pair_checks = 0
        # A clearance known from elsewhere is what this one must beat: the walk holds the
        # clearance pairs to it from the start (as if GJK had found it here), and only a
        # distance below it is kept.
        self.min_clear, self.closest = known, -1
        self.memory.ceiling[0] = known
        self.drop = verifier.resolution / 2 - _SLACK  # the walk's, below the ceiling [m]
        self._placed = [-1] * len(verifier._movers)
        self._dist_req = fcl.DistanceRequest()

    def walk(self, todo: np.ndarray, theta: np.ndarray,
             stretches: tuple[np.ndarray, np.ndarray], drop: float = -1.0
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The layer's walk of pairs ``todo`` on their stretches against thresholds
        ``theta`` [m]."""
        return self.v._layer.walk(todo, theta, self.q, self.grid, self.cache, self.memory,
                                  drop, stretches)

    def _place(self, m: int, s: int) -> object:
        import fcl

        body = self.v._movers[m]
        if self._placed[m] != s:
            T = self.v._layer.pose(self.q, self.grid, self.cache, s, m)
            body.fcl.setTransform(fcl.Transform(T[:, :3], T[:, 3]))  # type: ignore[attr-defined]
            self._placed[m] = s
        return body.fcl

    def _objects(self, p: int, s: int) -> tuple[object, object]:
        i, j, env, _ = self.v._pairs[p]
        self.checked.add(s)
        self.pair_checks += 1
        return self._place(i, s), (self.v._env[j].fcl if env else self._place(j, s))

    def _measure(self, p: int, s: int) -> float:
        """FCL distance of pair p at sample s [m] (negative: in collision); keeps the
        smallest one of the clearance pairs."""
        import fcl

        o1, o2 = self._objects(p, s)
        d = float(fcl.distance(o1, o2, self._dist_req, fcl.DistanceResult()))
        _, _, env, depth = self.v._pairs[p]
        if env and depth == 0.0 and d < self.min_clear:
            self.min_clear, self.closest = d, p
        return d

    def distances(self, p: int, samples: np.ndarray) -> np.ndarray:
        """FCL distances of environment pair p at the grid samples ``samples`` [m] (not
        kept as a clearance)."""
        i, j, _, _ = self.v._pairs[p]
        self.checked.update(samples.tolist())
        self._placed[i], self.pair_checks = -1, self.pair_checks + len(samples)
        poses = self.v._layer.poses(self.q, self.grid, self.cache, samples, i)
        return self.v._movers[i].distances(self.v._env[j], poses)

    def distances_at(self, p: int, states: np.ndarray) -> np.ndarray:
        """FCL distances of environment pair p at the joint positions ``states`` [m]
        (states x dof [rad]; off the grid: the layer places its body, :meth:`Layer.poses_at`)."""
        i, j, _, _ = self.v._pairs[p]
        self._placed[i], self.pair_checks = -1, self.pair_checks + len(states)
        poses = self.v._layer.poses_at(states, i)
        return self.v._movers[i].distances(self.v._env[j], poses)

    def _fails(self, p: int, s: int) -> bool:
        """FCL's judgement of pair p at sample s: in collision, inside its margin, or
        deeper than its allowed depth."""
        import fcl

        max_depth = self.v._pairs[p][3]
        if max_depth > 0.0:
            req = fcl.CollisionRequest(enable_contact=True, num_max_contacts=4)
            res = fcl.CollisionResult()
            if not fcl.collide(*self._objects(p, s), req, res):
                return False
            return max(c.penetration_depth for c in res.contacts) > max_depth
        d = self._measure(p, s)
        if d <= 0.0 and fcl.collide(*self._objects(p, s), fcl.CollisionRequest(),
                                    fcl.CollisionResult()):
            return True
        return d < float(self.v._theta[p])

    def safety(self, pairs: np.ndarray, samples: np.ndarray, bounds: np.ndarray
               ) -> tuple[int, list[int]]:
        """Judge with FCL every couple the walk left whose bound does not clear its
        pair's threshold, in sample order; return the first failing sample and the
        pairs failing there (none: the number of samples)."""
        fail_at, bad = self.grid.samples, list[int]()
        judge = np.flatnonzero(bounds <= self.v._bound_theta[pairs])
        if not judge.size:
            return fail_at, bad
        for k in judge[np.lexsort((pairs[judge], samples[judge]))]:
            s, p = int(samples[k]), int(pairs[k])
            if s > fail_at:
                break
            if self._fails(p, s):
                fail_at = s
                bad.append(p)
        return fail_at, bad

    def clearance(self, pairs: np.ndarray, samples: np.ndarray, bounds: np.ndarray
                  ) -> None:
        """Find the smallest clearance to within half the resolution.

        The walk held every clearance pair to the closest distance GJK had found so far
        (the ceiling) minus that; FCL measures where GJK found it and every couple the
        walk left, the closest first, until their bounds clear FCL's minimum minus
        that. Should FCL read more than GJK's points there, the walk is done again
        against FCL's minimum.
        """
        v, tol, ceiling = self.v, self.v.resolution / 2, self.memory.ceiling
        if not v._tracked.any():
            return
        if ceiling[1] >= 0:
            self._measure(int(ceiling[1]), int(ceiling[2]))
        for k in np.argsort(bounds, kind="stable"):  # the closest first: fewer checks
            if bounds[k] > self.min_clear - tol:
                break
            if v._tracked[pairs[k]]:
                self._measure(int(pairs[k]), int(samples[k]))
        if ceiling[0] >= self.min_clear - _SLACK:
            return
        todo, (first, stop) = self.entries
        theta = np.maximum(v._theta, self.min_clear - tol)
        redo = np.flatnonzero(v._tracked[todo] & (v._theta[todo] < self.min_clear - tol))
        again = self.walk(todo[redo], theta, (first[redo], stop[redo]))
        for p, s in zip(*again[:2], strict=True):
            self._measure(int(p), int(s))


def _row_keys(rows: np.ndarray) -> np.ndarray:
    """One integer per pair row (mover, mover or environment object, is environment,
    allowed depth), equal for equal rows only."""
    i, j, env = (rows[:, c].astype(np.int64) for c in range(3))
    _, depth = np.unique(rows[:, 3], return_inverse=True)
    bodies = int(max(i.max(initial=0), j.max(initial=0))) + 1
    return ((i * bodies + j) * 2 + env) * (int(depth.max(initial=0)) + 1) + depth.reshape(-1)


def _allowed_depths(allowed: Iterable[AllowedContact], contact_links: set[str]
                    ) -> dict[Pair, float | None]:
    """Per pair of names (sorted), how deep it may touch [m] (None: at any depth)."""
    depth: dict[Pair, float | None] = {}
    for c in allowed:
        a_side = sorted(contact_links) if c.between[0] == GRIPPER else [c.between[0]]
        b_side = sorted(contact_links) if c.between[1] == GRIPPER else [c.between[1]]
        for a, b in itertools.product(a_side, b_side):
            key: Pair = (min(a, b), max(a, b))
            old = depth.get(key, 0.0)
            depth[key] = None if (old is None or c.max_depth is None) else max(old,
                                                                                c.max_depth)
    return depth
