"""From a route to a verified, timed trajectory.

For each motion step: the direct joint segment if it is free, else OMPL (``move``), or
a straight TCP line by inverse kinematics (``line``). Motion steps between two stops
are timed together with TOPPRA through a spline that blends through the via poses;
if the blended path is not collision-free, the robot stops at the step boundaries
instead (and, if still needed, at every corner of the checked polyline). Every timed
piece is then re-checked by the independent FCL verifier; only a trajectory that
passes leaves :func:`plan_route`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..cell import Cell
from ..collision import CheckOptions, CollisionChecker
from ..errors import IKError, PlanningError, TimingError, VerificationError
from ..scene import AllowedContact
from ..trajectory import GripperEvent, Trajectory
from .cartesian import LineOptions, cartesian_line
from .routes import Route, Step, load_routes
from .sampling import PlannerOptions, plan_joint_path
from .timing import TimedPiece, TimingOptions, spline_path, time_path
from .verify import FclVerifier, VerifyResult

__all__ = ["PlanOptions", "WorldState", "plan_route", "plan_cell", "route_order",
           "initial_world", "rest_to_rest_time"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlanOptions:
    """Options of route planning (each part has its own options object).

    Attributes:
        check: Collision checking (resolution, margin); margins are enforced.
        planner: Sampling planner (name, time budget, seed).
        line: Cartesian lines.
        timing: Time parameterisation (global speed scale).
        grasp_tolerance: How far the object may be from the gripper when it closes [m].
        baseline: Also time the stop-and-go baseline (every motion step rest to rest
            along its own path, same limits) into ``info["baseline_duration"]``.
    """

    check: CheckOptions = field(default_factory=lambda: CheckOptions(enforce_margin=True))
    planner: PlannerOptions = field(default_factory=PlannerOptions)
    line: LineOptions = field(default_factory=LineOptions)
    timing: TimingOptions = field(default_factory=TimingOptions)
    grasp_tolerance: float = 0.005
    baseline: bool = False


@dataclass
class WorldState:
    """Which object the gripper holds and where the others rest.

    Attributes:
        held: Held object, or None.
        resting: World placement (4x4) of movable objects that are not held.
    """

    held: str | None = None
    resting: dict[str, np.ndarray] = field(default_factory=dict)

    def copy(self) -> WorldState:
        """An independent copy."""
        return WorldState(self.held, {k: v.copy() for k, v in self.resting.items()})

    def key(self) -> tuple:
        """Hashable identity of the state."""
        return (self.held, tuple(sorted((k, v.round(9).tobytes())
                                        for k, v in self.resting.items())))


@dataclass
class _Segment:
    step_index: int
    step: Step
    waypoints: list[np.ndarray]
    allowed: tuple[AllowedContact, ...]


class _Checkers:
    """Checkers and verifiers, built once per world state and allowed-contact set."""

    def __init__(self, cell: Cell, options: PlanOptions) -> None:
        self.cell = cell
        self.options = options
        # Kept on the cell (per thread) so that planning again, as a node or a review
        # session does, does not rebuild them; they depend on the world state and the
        # allowed contacts (the keys), never on the taught poses.
        self._checkers: dict[tuple, CollisionChecker] = cell.cache(("checkers", options.check))
        self._verifiers: dict[tuple, FclVerifier] = cell.cache(("verifiers", options.check))

    def checker(self, world: WorldState, allowed: tuple[AllowedContact, ...]) -> CollisionChecker:
        key = (world.key(), allowed)
        if key not in self._checkers:
            self._checkers[key] = CollisionChecker(
                self.cell.robot, self.cell.scene, held=world.held, resting=world.resting,
                allowed=allowed, options=self.options.check)
        return self._checkers[key]

    def verifier(self, world: WorldState, allowed: tuple[AllowedContact, ...]) -> FclVerifier:
        key = (world.key(), allowed)
        if key not in self._verifiers:
            opts = self.options.check
            self._verifiers[key] = FclVerifier(
                self.cell.robot, self.cell.scene, held=world.held, resting=dict(world.resting),
                allowed=allowed, resolution=opts.resolution, margin=opts.margin,
                enforce_margin=opts.enforce_margin)
        return self._verifiers[key]


def initial_world(cell: Cell) -> WorldState:
    """The scene's world: nothing held, movable objects at their scene placement."""
    return WorldState(None, {o.name: o.T_world_object.copy()
                             for o in cell.scene.objects.values() if o.movable})


def route_order(routes: Mapping[str, Route]) -> list[str]:
    """Route names so that every route comes after the one it follows."""
    order: list[str] = []

    def visit(name: str) -> None:
        if name in order:
            return
        after = routes[name].after
        if after is not None:
            visit(after)
        order.append(name)

    for name in routes:
        visit(name)
    return order


def plan_cell(cell: Cell, options: PlanOptions | None = None, *,
              routes: Mapping[str, Route] | None = None) -> dict[str, Trajectory]:
    """Plan, time and verify every route of the cell (``routes.yaml`` of its folder)."""
    options = options or PlanOptions()
    if routes is None:
        routes = load_routes(cell.folder, poses=list(cell.poses),
                             objects=list(cell.scene.objects))
    cache = _Checkers(cell, options)
    worlds: dict[str, WorldState] = {}
    out: dict[str, Trajectory] = {}
    for name in route_order(routes):
        route = routes[name]
        world = worlds[route.after].copy() if route.after else initial_world(cell)
        traj, end_world = _plan(cell, route, world, options, cache)
        worlds[name] = end_world
        out[name] = traj
    return out


def plan_route(cell: Cell, route: Route, options: PlanOptions | None = None, *,
               world: WorldState | None = None) -> Trajectory:
    """Plan, time and verify one route.

    Args:
        cell: The cell.
        route: The route.
        options: Planning options.
        world: World state at the start (default: the scene's).

    Raises:
        PlanningError: A step cannot be planned (step, pose and reason).
        TimingError: No timing within the limits.
        VerificationError: The timed result failed the independent re-check.
    """
    options = options or PlanOptions()
    traj, _ = _plan(cell, route, world.copy() if world else initial_world(cell), options,
                    _Checkers(cell, options))
    return traj


def _plan(cell: Cell, route: Route, world: WorldState, options: PlanOptions,
          cache: _Checkers) -> tuple[Trajectory, WorldState]:
    t_start = time.perf_counter()
    robot, scene = cell.robot, cell.scene
    labels = route.labels()
    q = cell.pose(route.start)
    pose_name: str | None = route.start
    chunks: list[tuple[list[_Segment], WorldState]] = []
    actions: list[tuple[int, int, Step]] = []  # (after chunk, step index, step)
    current: list[_Segment] = []
    planner_opts = options.planner
    for i, step in enumerate(route.steps):
        label = labels[i]
        if step.is_motion:
            assert step.target is not None
            goal, goal_name = _resolve(cell, step, q, label, options)
            if step.kind == "line":
                allowed = scene.contacts_at(pose_name) + scene.contacts_at(goal_name)
                checker = cache.checker(world, allowed)
                waypoints = cartesian_line(robot, q, goal, options=options.line, step_name=label)
                report = checker.check_path(waypoints)
                if not report.valid:
                    why = report.limit_violation or ", ".join(f"{a} / {b}"
                                                              for a, b in report.collisions)
                    raise IKError(f"the line collides ({why})", step=label,
                                  fraction=report.fraction or 0.0,
                                  position=robot.tcp_position(report.q)
                                  if report.q is not None else None)
            else:
                allowed = ()
                checker = cache.checker(world, allowed)
                seeded = PlannerOptions(planner_opts.planner, planner_opts.time_limit,
                                        planner_opts.seed + i, planner_opts.range,
                                        planner_opts.shortcut_iterations)
                waypoints = plan_joint_path(checker, q, goal, options=seeded, step=label)
            current.append(_Segment(i, step, waypoints, allowed))
            q, pose_name = goal, goal_name
            if step.stop:
                chunks.append((current, world.copy()))
                current = []
        else:
            if current:
                chunks.append((current, world.copy()))
                current = []
            actions.append((len(chunks), i, step))
            world = _gripper(cell, world, step, q, label, options)
    if current:
        chunks.append((current, world.copy()))
    plan_time = time.perf_counter() - t_start

    # Timing and verification, chunk by chunk.
    pieces: list[tuple[TimedPiece, list[int]]] = []
    min_clear, closest = float("inf"), None
    for segments, chunk_world in chunks:
        for piece, steps_of_knots, result in _time_chunk(cell, segments, chunk_world, options,
                                                         cache, labels):
            if result.min_clearance < min_clear:
                min_clear, closest = result.min_clearance, result.closest_pair
            pieces.append((piece, steps_of_knots))
    traj = _assemble(cell, route, labels, pieces, chunks, actions)
    _check_position_limits(cell, traj)
    traj.info.update({
        "planning_time": plan_time,
        "total_time": time.perf_counter() - t_start,
        "min_clearance": min_clear,
        "closest_pair": list(closest) if closest else None,
        "seed": options.planner.seed,
        "speed_scale": options.timing.speed_scale,
        "resolution": options.check.resolution,
    })
    if options.baseline:
        # A figure for comparison only: the same steps' paths, each timed rest to rest.
        # Its failure must not throw away the verified trajectory.
        total: float | None = 0.0
        try:
            for segments, chunk_world in chunks:
                for seg in segments:
                    piece, _ = _time_segments(cell, [seg], chunk_world, options, cache,
                                              check=False, blend=0.0)
                    total = (total or 0.0) + float(piece.t[-1])
        except TimingError as exc:
            log.warning("route %s: no stop-and-go baseline (%s)", route.name, exc)
            total = None
        traj.info["baseline_duration"] = total
    return traj, world


def _check_position_limits(cell: Cell, traj: Trajectory) -> None:
    robot = cell.robot
    tol = 1e-9
    low = traj.q < robot.lower - tol
    high = traj.q > robot.upper + tol
    if low.any() or high.any():
        k, j = np.argwhere(low | high)[0]
        raise TimingError(f"{robot.joint_names[j]} leaves its limits at t={traj.t[k]:.3f} s "
                          f"({traj.q[k, j]:.5f} rad) in step '{traj.steps[traj.step_index[k]]}'")


def _resolve(cell: Cell, step: Step, q: np.ndarray, label: str, options: PlanOptions
             ) -> tuple[np.ndarray, str | None]:
    """Joint goal of a motion step, and the taught pose it is exactly (or None)."""
    from .cartesian import solve_ik

    target = step.target
    assert target is not None
    if target.exact_pose is not None:
        return cell.pose(target.exact_pose), target.exact_pose
    seed = cell.pose(target.pose) if target.pose is not None else q
    T = cell.robot.frame_pose(seed)
    T.translation = T.translation + np.asarray(target.offset)
    goal = solve_ik(cell.robot, T, seed, options=options.line)
    if goal is None:
        raise IKError("no inverse-kinematics solution for the target", step=label,
                      fraction=1.0, position=T.translation.copy())
    return goal, None


def _gripper(cell: Cell, world: WorldState, step: Step, q: np.ndarray, label: str,
             options: PlanOptions) -> WorldState:
    scene, robot = cell.scene, cell.robot
    grasp = scene.grasp
    world = world.copy()
    obj = step.object or (grasp.object if grasp else None)
    if obj is None or grasp is None or grasp.object != obj:
        if step.kind == "close" and obj is not None:
            raise PlanningError(f"the scene defines no grasp for '{obj}'", step=label)
        return world
    T_world_grasp = robot.frame_pose(q).homogeneous @ grasp.T_tcp_object
    if step.kind == "close":
        if world.held is not None:
            raise PlanningError(f"the gripper already holds '{world.held}'", step=label)
        rest = world.resting.get(obj)
        gap = float(np.linalg.norm(rest[:3, 3] - T_world_grasp[:3, 3])) if rest is not None \
            else float("inf")
        if gap > options.grasp_tolerance:
            raise PlanningError(f"'{obj}' is {gap * 1000:.1f} mm from the gripper, "
                                f"more than {options.grasp_tolerance * 1000:.1f} mm", step=label)
        world.held = obj
        world.resting.pop(obj, None)
    else:
        if world.held == obj:
            world.held = None
            world.resting[obj] = T_world_grasp
    return world


def _time_chunk(cell: Cell, segments: list[_Segment], world: WorldState, options: PlanOptions,
                cache: _Checkers, labels: list[str]
                ) -> list[tuple[TimedPiece, list[int], VerifyResult]]:
    """Time and verify a chunk: blended through its via points (large blends first, then
    smaller, then passing exactly); if no blend is collision-free or passes the
    independent re-check, stop at the step boundaries, then at every corner."""
    if len(segments) > 1 or len(segments[0].waypoints) > 2:
        for blend in options.timing.blend_radii:
            try:
                piece, seg_steps = _time_segments(cell, segments, world, options, cache,
                                                  blend=blend)
                return [_verified(piece, seg_steps, segments, world, cache, labels)]
            except _NotFree:
                log.debug("blend %.3f rad not collision-free", blend)
            except VerificationError as exc:
                log.debug("blend %.3f rad failed the re-check: %s", blend, exc)
    out = []
    for seg in segments:
        try:
            piece, seg_steps = _time_segments(cell, [seg], world, options, cache, blend=0.0)
            out.append(_verified(piece, seg_steps, [seg], world, cache, labels))
            continue
        except (_NotFree, VerificationError) as exc:
            if seg.step.kind == "line":
                if isinstance(exc, VerificationError):
                    raise
                raise PlanningError("the smoothed line is not collision-free",
                                    step=seg.step.label(seg.step_index)) from None
        # Stop at every corner: each straight segment was checked by the planner.
        for a, b in zip(seg.waypoints[:-1], seg.waypoints[1:], strict=True):
            part = _Segment(seg.step_index, seg.step, [a, b], seg.allowed)
            piece, seg_steps = _time_segments(cell, [part], world, options, cache, check=False)
            out.append(_verified(piece, seg_steps, [part], world, cache, labels))
    return out


def _verified(piece: TimedPiece, seg_steps: list[int], segments: list[_Segment],
              world: WorldState, cache: _Checkers, labels: list[str]
              ) -> tuple[TimedPiece, list[int], VerifyResult]:
    """Re-check a timed piece with the independent verifier, step by step (each step
    with its own allowed contacts); raise VerificationError on failure."""
    steps_of_knots = [seg_steps[k] for k in piece.segment]
    worst: VerifyResult | None = None
    index = np.asarray(steps_of_knots)
    for sidx in sorted(set(steps_of_knots)):
        seg = next(s for s in segments if s.step_index == sidx)
        verifier = cache.verifier(world, seg.allowed)
        sel = np.flatnonzero(index == sidx)
        lo, hi = max(sel[0] - 1, 0), sel[-1] + 1
        result = verifier.verify(piece.t[lo:hi], piece.q[lo:hi], piece.qd[lo:hi],
                                 steps=[labels[sidx]] * (hi - lo))
        if worst is None or result.min_clearance < worst.min_clearance:
            worst = result
    assert worst is not None
    return piece, steps_of_knots, worst


class _NotFree(Exception):
    pass


def _time_segments(cell: Cell, segments: list[_Segment], world: WorldState,
                   options: PlanOptions, cache: _Checkers, *, check: bool = True,
                   blend: float = 0.0) -> tuple[TimedPiece, list[int]]:
    waypoints: list[np.ndarray] = []
    corners: list[tuple[int, float]] = []
    lengths: list[float] = [
        float(np.sum(np.linalg.norm(np.diff(np.asarray(s.waypoints), axis=0), axis=1)))
        for s in segments]
    seg_steps: list[int] = []
    scales: list[float] = []
    tcp: list[float | None] = []
    seg_of_poly: list[int] = []
    for n, seg in enumerate(segments):
        if waypoints and n > 0 and blend > 0:
            # A via pose between two steps: blend, within 40 % of either step.
            corners.append((len(waypoints) - 1, float(min(blend, 0.4 * lengths[n - 1],
                                                          0.4 * lengths[n]))))
        pts = seg.waypoints if not waypoints else seg.waypoints[1:]
        for j, p in enumerate(pts):
            if waypoints and np.max(np.abs(p - waypoints[-1])) < 1e-10:
                continue
            if waypoints:
                seg_of_poly.append(n)
            waypoints.append(p)
            inner = seg.step.kind == "move" and 0 < j < len(pts) - 1 and blend > 0
            if inner:  # a vertex of a planned detour
                a = float(np.linalg.norm(p - pts[j - 1]))
                b = float(np.linalg.norm(pts[j + 1] - p))
                corners.append((len(waypoints) - 1, min(blend, 0.4 * a, 0.4 * b)))
    for n in seg_of_poly:
        seg = segments[n]
        seg_steps.append(seg.step_index)
        scales.append(seg.step.speed)
        tcp.append(seg.step.tcp_speed)
    if len(waypoints) < 2:
        q = waypoints[0] if waypoints else segments[0].waypoints[0]
        z = np.zeros((1, q.size))
        return TimedPiece(np.zeros(1), q[None, :], z, z, np.zeros(1), np.zeros(1, dtype=int)), \
            [segments[0].step_index]
    spacing = options.timing.spacing
    path, s_way, _ = spline_path(waypoints, spacing, corners=corners)
    if check and len(waypoints) > 2:
        _check_spline(cell, path, s_way, seg_of_poly, segments, world, options, cache)
    piece = time_path(cell.robot, path, s_way, scales=scales, tcp_speeds=tcp,
                      options=options.timing, step=segments[0].step.label(segments[0].step_index))
    return piece, seg_steps


def _check_spline(cell: Cell, path: object, s_way: np.ndarray, seg_of_poly: Sequence[int],
                  segments: list[_Segment], world: WorldState, options: PlanOptions,
                  cache: _Checkers) -> None:
    """Raise _NotFree unless the spline is valid at the checker's resolution."""
    length = float(s_way[-1])
    n = max(2, int(np.ceil(length / 0.02)) + 1)
    s = np.linspace(0.0, length, n)
    Q = path(s)  # type: ignore[operator]
    poly = np.clip(np.searchsorted(s_way, s, side="right") - 1, 0, len(seg_of_poly) - 1)
    step_of = [seg_of_poly[p] for p in poly]
    # Consecutive chords of the same step share a checker: check them as one polyline.
    start = 0
    for k in range(1, n + 1):
        if k == n or step_of[k] != step_of[start]:
            checker = cache.checker(world, segments[step_of[start]].allowed)
            if not checker.check_path(Q[start:min(k + 1, n)], details=False).valid:
                raise _NotFree()
            start = k
    # The chords between samples are checked; the spline between two samples deviates
    # from its chord by far less than the verifier's resolution, which re-checks the
    # timed result anyway.


def _assemble(cell: Cell, route: Route, labels: list[str],
              pieces: list[tuple[TimedPiece, list[int]]], chunks: list, actions: list
              ) -> Trajectory:
    t_all: list[np.ndarray] = []
    q_all, qd_all, qdd_all, idx_all = [], [], [], []
    offset = 0.0
    for piece, steps_of_knots in pieces:
        start = 0 if not t_all else 1  # the first knot repeats the previous rest state
        t_all.append(piece.t[start:] + offset)
        q_all.append(piece.q[start:])
        qd_all.append(piece.qd[start:])
        qdd_all.append(piece.qdd[start:])
        idx_all.append(np.asarray(steps_of_knots[start:]))
        offset += float(piece.t[-1])
    t = np.concatenate(t_all)
    events = []
    # Gripper events happen at the end of the chunk before them (or at t = 0).
    chunk_time = _chunk_end_times(pieces, chunks)
    for after_chunk, i, step in actions:
        when = 0.0 if after_chunk == 0 else chunk_time[after_chunk - 1]
        obj = step.object or (cell.scene.grasp.object if cell.scene.grasp else None)
        events.append(GripperEvent(when, step.kind, labels[i], obj))  # type: ignore[arg-type]
    return Trajectory(cell.robot.joint_names, t, np.vstack(q_all), np.vstack(qd_all),
                      np.vstack(qdd_all), np.concatenate(idx_all), tuple(labels), tuple(events),
                      cell.robot.name, route.name, {})


def _chunk_end_times(pieces: list[tuple[TimedPiece, list[int]]], chunks: list) -> list[float]:
    """End time of each chunk: pieces are grouped by the steps the chunks contain."""
    out, offset, p = [], 0.0, 0
    for segments, _ in chunks:
        steps = {s.step_index for s in segments}
        while p < len(pieces) and set(pieces[p][1]) <= steps:
            offset += float(pieces[p][0].t[-1])
            p += 1
        out.append(offset)
    return out


def rest_to_rest_time(delta: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> float:
    """Time-optimal rest-to-rest duration of a straight joint move [s] (trapezoid)."""
    d = np.abs(np.asarray(delta, dtype=float))
    moving = d > 1e-12
    if not np.any(moving):
        return 0.0
    # Along the line, path speed <= min v_i/d_i, path acceleration <= min a_i/d_i (s in [0,1]).
    v = float(np.min(vmax[moving] / d[moving]))
    a = float(np.min(amax[moving] / d[moving]))
    if v * v / a >= 1.0:  # triangle profile
        return 2.0 * np.sqrt(1.0 / a)
    return 1.0 / v + v / a
