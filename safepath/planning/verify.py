"""Independent re-check of timed trajectories with python-fcl, before release.

The verifier shares nothing with the planner's checker but the *data*: it builds its
own FCL shapes from the robot's collision geometry and the scene, derives its own list
of pairs from the robot's allowed self-collision pairs, the tool's contact links and the
allowed contacts, and checks the timed samples with FCL (not coal).

Resolution guarantee: the timed trajectory is sampled so densely that no point of the
robot (or the held object) moves more than ``resolution`` between two samples; between
full checks, samples are skipped only while the accumulated motion bound stays below
the clearance measured at the last full check, which certifies the skipped samples
(and the motion between them) collision-free.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import VerificationError
from ..robot import Robot
from ..scene import GRIPPER, AllowedContact, Scene

__all__ = ["FclVerifier", "VerifyResult"]

Pair = tuple[str, str]


@dataclass(frozen=True)
class VerifyResult:
    """Outcome of a successful verification.

    Attributes:
        samples: Samples on the resolution grid.
        checked: Samples fully checked (the others were certified by clearance).
        min_clearance: Smallest robot-environment distance seen [m].
        closest_pair: Its pair.
    """

    samples: int
    checked: int
    min_clearance: float
    closest_pair: Pair | None


def _fcl_shape(geometry: object) -> object:
    import coal
    import fcl

    if isinstance(geometry, coal.Box):
        return fcl.Box(*(2 * np.asarray(geometry.halfSide)))
    if isinstance(geometry, coal.Sphere):
        return fcl.Sphere(float(geometry.radius))
    if isinstance(geometry, coal.Cylinder):
        return fcl.Cylinder(float(geometry.radius), 2 * float(geometry.halfLength))
    if isinstance(geometry, coal.Capsule):
        return fcl.Capsule(float(geometry.radius), 2 * float(geometry.halfLength))
    if isinstance(geometry, coal.ConvexBase):
        pts = np.asarray(geometry.points(), dtype=float)
        from scipy.spatial import ConvexHull

        hull = ConvexHull(pts)
        faces = np.hstack([np.full((len(hull.simplices), 1), 3), hull.simplices]).ravel()
        return fcl.Convex(pts, len(hull.simplices), faces)
    raise VerificationError(f"unsupported geometry {type(geometry).__name__}", time=0.0,
                            q=None, pairs=[])


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
    """

    def __init__(self, robot: Robot, scene: Scene | None, *, held: str | None = None,
                 resting: dict[str, np.ndarray | None] | None = None,
                 allowed: Iterable[AllowedContact] = (), resolution: float = 0.002,
                 margin: float | None = None, enforce_margin: bool = True) -> None:
        import fcl

        self.robot = robot
        self.resolution = resolution
        self.enforce_margin = enforce_margin
        self._data = robot.model.createData()
        gm = robot.collision_model
        # Moving bodies: (name, joint id, placement in the joint frame, fcl object).
        self._movers: list[tuple[str, int, np.ndarray, object]] = []
        self._radius: list[float] = []
        for g in gm.geometryObjects:
            name = robot.model.frames[g.parentFrame].name
            self._movers.append((name, int(g.parentJoint), g.placement.homogeneous.copy(),
                                 fcl.CollisionObject(_fcl_shape(g.geometry), fcl.Transform())))
            self._radius.append(_radius(g.geometry))
        self._joint_of = [int(g.parentJoint) for g in gm.geometryObjects]
        self._env: list[tuple[str, object]] = []
        if scene is not None:
            for obj in scene.objects.values():
                placed: np.ndarray | None = obj.T_world_object
                if obj.movable:
                    if obj.name == held:
                        continue
                    placed = (resting or {}).get(obj.name, obj.T_world_object)
                if placed is None:
                    continue
                T = np.asarray(placed)
                shape = _fcl_shape(obj.shape.to_coal())
                self._env.append((obj.name, fcl.CollisionObject(
                    shape, fcl.Transform(np.asarray(T)[:3, :3], np.asarray(T)[:3, 3]))))
        if held is not None and scene is not None and scene.grasp is not None:
            obj = scene.objects[held]
            tcp = robot.model.frames[robot.tcp_frame_id]
            T_joint_obj = tcp.placement.homogeneous @ scene.grasp.T_tcp_object
            self._movers.append((held, int(tcp.parentJoint), T_joint_obj, fcl.CollisionObject(
                _fcl_shape(obj.shape.to_coal()), fcl.Transform())))
            self._radius.append(obj.shape.bounding_radius())
            self._joint_of.append(int(tcp.parentJoint))
        # Allowed contacts -> max depth (None: any).
        contact_links = set(robot.tool.contact_links) if robot.tool else set()
        depth: dict[Pair, float | None] = {}
        for c in allowed:
            a_side = sorted(contact_links) if c.between[0] == GRIPPER else [c.between[0]]
            b_side = sorted(contact_links) if c.between[1] == GRIPPER else [c.between[1]]
            for a, b in itertools.product(a_side, b_side):
                key: Pair = (min(a, b), max(a, b))
                old = depth.get(key, 0.0)
                depth[key] = None if (old is None or c.max_depth is None) else max(old,
                                                                                    c.max_depth)
        self._pairs: list[tuple[int, int, bool, float]] = []  # (i, j, j_is_env, depth)
        n = len(self._movers)
        for i, j in itertools.combinations(range(n), 2):
            a, b = self._movers[i][0], self._movers[j][0]
            if a == b or self._joint_of[i] == self._joint_of[j]:
                continue
            is_held = held is not None and held in (a, b)
            if is_held and (a in contact_links or b in contact_links):
                continue
            if not is_held and (min(a, b), max(a, b)) in robot.allowed_self_pairs:
                continue
            d = depth.get((min(a, b), max(a, b)), 0.0)
            if d is None:
                continue
            self._pairs.append((i, j, False, d))
        for i in range(n):
            if self._joint_of[i] == 0:
                continue
            for j, (env_name, _) in enumerate(self._env):
                a = self._movers[i][0]
                d = depth.get((min(a, env_name), max(a, env_name)), 0.0)
                if d is None:
                    continue
                self._pairs.append((i, j, True, d))
        self._placements = [pin.SE3(T) for _, _, T, _ in self._movers]
        default_margin = margin if margin is not None else (scene.margin if scene else 0.0)
        self._margin = {name: (margin if margin is not None else
                               (scene.margin_for(name) if scene else default_margin))
                        for name, _ in self._env}
        self._prepare()

    def _prepare(self) -> None:
        """What every verification of this world state uses: the motion bounds, and the
        units of work: ("env", body) = one body against all the environment objects it
        must avoid (one FCL broad-phase query), ("pair", p) = one self pair or one pair
        allowed to touch up to a depth."""
        import fcl

        pairs = self._pairs
        self._weights = _weights(self.robot, self._movers, self._radius)
        self._per_mover = _mover_weights(self.robot, self._movers, self._radius)
        self._env_of: dict[int, list[int]] = {}
        self._units: list[tuple[str, int]] = []
        for p, (i, _j, env, depth) in enumerate(pairs):
            if env and depth == 0.0:
                self._env_of.setdefault(i, []).append(p)
            else:
                self._units.append(("pair", p))
        self._managers = {}
        for i, plist in self._env_of.items():
            manager = fcl.DynamicAABBTreeCollisionManager()
            manager.registerObjects([self._env[pairs[p][1]][1] for p in plist])
            manager.setup()
            self._managers[i] = manager
            self._units.append(("env", i))
        self._required = [self._margin[self._env[j][0]]
                          if env and self.enforce_margin and d == 0.0 else 0.0
                          for _, j, env, d in pairs]
        self._objects_of = [self._objects(i, j, env) for i, j, env, _ in pairs]
        self._names_of = [self._pair_names(i, j, env) for i, j, env, _ in pairs]

    def _place(self, q: np.ndarray, movers: Iterable[int] | None = None) -> None:
        import fcl

        model, data = self.robot.model, self._data
        pin.forwardKinematics(model, data, q)
        for m in range(len(self._movers)) if movers is None else movers:
            _, joint, _, obj = self._movers[m]
            M = data.oMi[joint] * self._placements[m]
            obj.setTransform(fcl.Transform(M.rotation, M.translation))  # type: ignore[attr-defined]

    def _pair_names(self, i: int, j: int, env: bool) -> Pair:
        return (self._movers[i][0], self._env[j][0] if env else self._movers[j][0])

    def _objects(self, i: int, j: int, env: bool) -> tuple[object, object]:
        return self._movers[i][3], (self._env[j][1] if env else self._movers[j][3])

    def verify(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, *,
               steps: Sequence[str] | None = None) -> VerifyResult:
        """Check a timed trajectory; raise on the first collision.

        The knots are first cut into a grid on which no point moves more than the
        resolution between samples. A check is repeated only when the motion its bodies
        can have made since the last one (a bound from the joints that move them)
        reaches the distance found then (minus the margin): until that sample the
        distance cannot have closed, so the samples in between are certified. Each
        moving body is checked against all the environment objects it must avoid with
        one FCL broad-phase distance query; self pairs and pairs allowed to touch up to
        a depth are checked one by one.

        Args:
            t: Knot times [s].
            q: Knot positions [rad].
            qd: Knot velocities [rad/s] (unused, kept for the interface).
            steps: Step name of each knot (for the error).

        Raises:
            VerificationError: A sample collides or comes closer than a margin.
        """
        import heapq

        import fcl

        weights, per_mover = self._weights, self._per_mover
        pairs = self._pairs
        units, env_of, managers = self._units, self._env_of, self._managers
        required, objects, names = self._required, self._objects_of, self._names_of
        # The resolution grid.
        dq = np.abs(np.diff(q, axis=0))
        bounds = dq @ weights
        cuts = np.maximum(1, np.ceil(bounds / self.resolution)).astype(int)
        knot_of = np.concatenate([[0], np.repeat(np.arange(1, len(t)), cuts)])
        frac = np.concatenate([[1.0]] + [np.arange(1, c + 1) / c for c in cuts])
        # Motion bound of every mover, accumulated along the grid [m].
        step_motion = np.repeat(dq @ per_mover.T / cuts[:, None], cuts, axis=0)
        travel = np.vstack([np.zeros(len(self._movers)), step_motion]).cumsum(axis=0)
        samples = len(travel)
        dist_req = fcl.DistanceRequest()

        def column(unit: tuple[str, int]) -> np.ndarray:
            kind, x = unit
            if kind == "env":
                return travel[:, x]
            i, j, env, _ = pairs[x]
            return travel[:, i] if env else travel[:, i] + travel[:, j]

        columns = [column(u) for u in units]

        def due(u: int, index: int, budget: float) -> int:
            target = columns[u][index] + budget
            return max(index + 1, int(np.searchsorted(columns[u], target, side="left")))

        def check_pair(p: int) -> tuple[bool, float]:
            """(bad, budget) for one pair."""
            o1, o2 = objects[p]
            max_depth = pairs[p][3]
            if max_depth > 0.0:
                req = fcl.CollisionRequest(enable_contact=True, num_max_contacts=4)
                res = fcl.CollisionResult()
                if fcl.collide(o1, o2, req, res):
                    depth = max(c.penetration_depth for c in res.contacts)
                    return depth > max_depth, max(max_depth - depth, self.resolution / 2)
                gap = max(fcl.distance(o1, o2, dist_req, fcl.DistanceResult()), 0.0)
                return False, gap + max_depth
            d = fcl.distance(o1, o2, dist_req, fcl.DistanceResult())
            if d <= 0.0 and fcl.collide(o1, o2, fcl.CollisionRequest(), fcl.CollisionResult()):
                return True, 0.0
            return d < required[p], d - required[p]

        queue = [(0, u) for u in range(len(units))]
        heapq.heapify(queue)
        checked = 0
        min_clear, closest = float("inf"), None
        while queue and queue[0][0] < samples:
            index = queue[0][0]
            todo = []
            while queue and queue[0][0] == index:
                todo.append(heapq.heappop(queue)[1])
            k = int(knot_of[index])
            qs = q[0] if index == 0 else q[k - 1] + frac[index] * (q[k] - q[k - 1])
            checked += 1
            movers: set[int] = set()
            for u in todo:
                kind, x = units[u]
                if kind == "env":
                    movers.add(x)
                else:
                    movers.add(pairs[x][0])
                    if not pairs[x][2]:
                        movers.add(pairs[x][1])
            self._place(qs, movers)
            bad: list[Pair] = []
            for u in todo:
                kind, x = units[u]
                if kind == "pair":
                    is_bad, budget = check_pair(x)
                    if is_bad:
                        bad.append(names[x])
                    else:
                        heapq.heappush(queue, (due(u, index, budget), u))
                    continue
                data = fcl.DistanceData()
                managers[x].distance(self._movers[x][3], data, fcl.defaultDistanceCallback)
                d = float(data.result.min_distance)
                worst_margin = max(required[p] for p in env_of[x])
                if d > worst_margin and d >= min_clear:
                    heapq.heappush(queue, (due(u, index, d - worst_margin), u))
                    continue
                # Close to something (or a new closest): find the exact pairs.
                budget = float("inf")
                for p in env_of[x]:
                    is_bad, b = check_pair(p)
                    if is_bad:
                        bad.append(names[p])
                    budget = min(budget, b)
                    dp = b + required[p]
                    if dp < min_clear:
                        min_clear, closest = dp, names[p]
                if not bad:
                    heapq.heappush(queue, (due(u, index, budget), u))
            if bad:
                bad = list(dict.fromkeys(bad))  # a link may have several shapes
                step = steps[k] if steps is not None else None
                raise VerificationError(
                    "timed sample in collision or inside a margin: "
                    + ", ".join(f"{a} / {b}" for a, b in bad),
                    time=float(t[k]), q=qs, pairs=bad, step=step)
        return VerifyResult(samples, checked, min_clear, closest)


def _mover_weights(robot: Robot, movers: list[tuple[str, int, np.ndarray, object]],
                   radius: list[float]) -> np.ndarray:
    """Per mover and joint, a bound on how far the mover's points lie from the joint [m]
    (zero for joints that do not move it): shape (movers, dof)."""
    model = robot.model
    out = np.zeros((len(movers), model.nv))
    for m, ((_, joint, T_joint_geom, _), r) in enumerate(zip(movers, radius, strict=True)):
        reach = float(np.linalg.norm(T_joint_geom[:3, 3])) + r
        j = joint
        while j > 0:
            prismatic = model.joints[j].shortname().startswith(("JointModelP",
                                                                 "JointModelPrismatic"))
            out[m, model.joints[j].idx_v] = 1.0 if prismatic else reach
            reach += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = model.parents[j]
    return out


def _weights(robot: Robot, movers: list[tuple[str, int, np.ndarray, object]],
             radius: list[float]) -> np.ndarray:
    """Per joint, a bound on how far any moving point lies from the joint [m]."""
    model = robot.model
    reach = np.zeros(model.njoints)
    for (_, joint, T_joint_geom, _), r in zip(movers, radius, strict=True):
        if joint == 0:
            continue
        reach[joint] = max(reach[joint], float(np.linalg.norm(T_joint_geom[:3, 3])) + r)
    for j in range(model.njoints - 1, 0, -1):
        parent = model.parents[j]
        if parent > 0:
            reach[parent] = max(reach[parent], float(np.linalg.norm(
                model.jointPlacements[j].translation)) + reach[j])
    return np.array([1.0 if model.joints[j].shortname().startswith("JointModelP")
                     else reach[j] for j in range(1, model.njoints)])


def _radius(geometry: object) -> float:
    """Radius of a sphere about the geometry's origin that holds it [m] (own code, not the
    planner checker's)."""
    import coal

    if isinstance(geometry, coal.Box):
        return float(np.linalg.norm(geometry.halfSide))
    if isinstance(geometry, coal.Sphere):
        return float(geometry.radius)
    if isinstance(geometry, (coal.Cylinder, coal.Capsule)):
        return float(geometry.radius + geometry.halfLength)
    if isinstance(geometry, coal.ConvexBase):
        return float(np.max(np.linalg.norm(np.asarray(geometry.points()), axis=1)))
    raise VerificationError(f"unsupported geometry {type(geometry).__name__}", time=0.0,
                            q=None, pairs=[])
