"""From a route to a verified, timed trajectory.

For each motion step: the direct joint segment if it is free, else OMPL (``move``), or
a straight TCP line by inverse kinematics (``line``). Motion steps between two stops
are timed together with TOPPRA through a spline that blends through the via poses.
Every timed piece is then re-checked by the independent FCL verifier; where a blended
piece fails (the blend is not collision-free), smaller blends are tried, then the robot
stops at the step boundaries (and, if still needed, at every corner of the checked
polyline). Only a trajectory that passes leaves :func:`plan_route`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..cell import Cell
from ..cell.routes import Route, Step, after_chain
from ..collision import CollisionChecker, Pair, SegmentReport
from ..errors import (
    ConfigError,
    IKError,
    PlanningError,
    SafepathError,
    TimingError,
    VerificationError,
)
from ..model.trajectory import Trajectory
from ..timing import TimedPiece
from ..verify import check_verifiable
from . import _repeats
from ._chunks import Segment, TimedPieces, assemble, time_chunk, time_segments
from ._pour_chunk import PourChunk, plan_pour_chunk
from .cartesian import cartesian_line
from .constraints import check_tilt, tilt_bound
from .landing import check_landing
from .options import PlannerOptions, PlanOptions
from .sampling import plan_joint_path
from .world import CheckerCache, WorldState, initial_world

__all__ = ["PlanOptions", "WorldState", "plan_route", "plan_cell", "route_order",
           "initial_world"]

log = logging.getLogger(__name__)


def route_order(routes: Mapping[str, Route]) -> list[str]:
    """Route names so that every route comes after the one it follows.

    Raises:
        ConfigError: A route follows one that is not given, or routes follow each other
            in a cycle (key ``routes.<name>.after``).
    """
    order: list[str] = []
    for name in routes:
        for link in after_chain(routes, name):
            if link not in order:
                order.append(link)
    return order


def plan_cell(cell: Cell, options: PlanOptions | None = None, *,
              routes: Mapping[str, Route] | None = None) -> dict[str, Trajectory]:
    """Plan, time and verify every route of the cell (its routes, or ``routes.yaml`` of
    its folder: :meth:`Cell.route_table`).

    Raises:
        ConfigError: The robot or the scene has geometry the independent verifier does
            not handle (before anything is planned), or ``routes.yaml`` is invalid.
        PlanningError, TimingError, VerificationError: As :func:`plan_route` (a
            PlanningError names the route and the routes file, see
            :meth:`~safepath.errors.PlanningError.in_route`).
    """
    options = options or PlanOptions()
    check_verifiable(cell.robot, cell.scene)
    if routes is None:
        routes = cell.route_table()
    elif not isinstance(routes, Mapping) or not all(
            isinstance(r, Route) for r in routes.values()):
        raise ConfigError("expected a mapping of route names to Routes (e.g. "
                          "{'phase1': cell.route_table()['phase1']}), got "
                          f"{type(routes).__name__}", key="routes")
    cache = CheckerCache(cell, options)
    timed = TimedPieces()
    worlds: dict[str, WorldState] = {}
    out: dict[str, Trajectory] = {}
    for name in route_order(routes):
        route = routes[name]
        world = worlds[route.after].copy() if route.after else initial_world(cell)
        traj, end_world = _plan_named(cell, route, world, options, cache, timed)
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
        ConfigError: The robot or the scene has geometry the independent verifier does
            not handle (before anything is planned).
        PlanningError: A step cannot be planned (route, routes file when the route is the
            cell's, step, pose and reason).
        TimingError: No timing within the limits.
        VerificationError: The timed result failed the independent re-check.
    """
    options = options or PlanOptions()
    check_verifiable(cell.robot, cell.scene)
    traj, _ = _plan_named(cell, route, world.copy() if world else initial_world(cell),
                          options, CheckerCache(cell, options), TimedPieces())
    return traj


def _plan_named(cell: Cell, route: Route, world: WorldState, options: PlanOptions,
                cache: CheckerCache, timed: TimedPieces) -> tuple[Trajectory, WorldState]:
    """:func:`_plan`, its planning errors naming the route and its routes file: in a cell
    of several routes, a step's name alone does not say where it is."""
    try:
        return _plan(cell, route, world, options, cache, timed)
    except PlanningError as exc:
        exc.in_route(route.name, _routes_file(cell, route))
        raise


def _routes_file(cell: Cell, route: Route) -> Path | None:
    """The cell's ``routes.yaml`` if ``route`` is the route of that name in it, else None
    (a route built in Python, or changed since it was read)."""
    if cell.routes is not None or cell.folder is None:
        return None
    path = cell.folder / "routes.yaml"
    try:
        same = path.is_file() and cell.route_table().get(route.name) == route
    except (SafepathError, ValueError):  # an unreadable file names nothing
        return None
    return path if same else None


@dataclass
class _Paths:
    """A route's checked paths, before timing.

    Attributes:
        chunks: The motion between two stops: its segments and the world they move in.
        actions: Gripper actions as (chunks before it, step index, step).
        world: The world when the route ends.
        shortcut_time: Time spent shortcutting OMPL's paths [s].
    """

    chunks: list[tuple[list[Segment], WorldState] | PourChunk]
    actions: list[tuple[int, int, Step]]
    world: WorldState
    shortcut_time: float


def _plan(cell: Cell, route: Route, world: WorldState, options: PlanOptions,
          cache: CheckerCache, timed: TimedPieces) -> tuple[Trajectory, WorldState]:
    """Paths, then timing and verification, then the trajectory and its figures; once
    more keeping :data:`REPLAN_CLEARANCE` from every object where the release check
    refused the first plan."""
    t_start = time.perf_counter()
    labels = route.labels()
    start = world.copy()
    paths = _plan_paths(cell, route, world, options, cache, labels)
    plan_time = time.perf_counter() - t_start
    try:
        pieces, chunk_ends, (min_clear, bound), closest, deviation = _time_and_verify(
            cell, paths.chunks, options, cache, labels, timed)
    except VerificationError as exc:  # a sample in contact, or its clearance unproven
        kept = _keeping_clearance(cell, REPLAN_CLEARANCE)
        if kept is None:
            raise
        log.info("re-planning %s %.1f mm clear of every object: %s",
                 route.name or "the route", 1e3 * REPLAN_CLEARANCE, exc)
        try:
            traj, end = _plan(kept, route, start, options,
                              CheckerCache(kept, options, verified_in=cell), TimedPieces())
        except SafepathError:
            raise exc from None
        traj.info["replanned_clear"] = {"clearance": REPLAN_CLEARANCE, "after": str(exc)}
        return traj, end
    traj = assemble(cell, route, labels, pieces, chunk_ends, paths.actions)
    _check_position_limits(cell, traj)
    carried = check_tilt(cell, route, traj)  # orientation path constraints (max_tilt)
    if tilt_bound(route) is not None:
        traj.info["carried_tilt"] = {"max": carried, "bound": tilt_bound(route)}
    landing = check_landing(cell, route, traj)  # no pour can spill outside (into)
    pours = [c.figures for c in paths.chunks if isinstance(c, PourChunk)]
    if pours:
        traj.info["pours"] = {k: v for f in pours for k, v in f.items()}
        for label, figures in landing.items():
            traj.info["pours"][label]["landing"] = figures
    traj.info.update({
        "planning_time": plan_time,
        "shortcut_time": paths.shortcut_time,
        "total_time": time.perf_counter() - t_start,
        "min_clearance": min_clear,
        # The verifier's certified lower bound of the clearance at every instant of the
        # motion the controller executes, the smallest of the pieces': never negative
        # (the release criterion; safepath.verify._between).
        "clearance_bound": bound,
        "knot_deviation": deviation,
        "closest_pair": list(closest) if closest else None,
        "seed": options.planner.seed,
        "speed_scale": options.timing.speed_scale,
        "resolution": options.check.resolution,
    })
    if options.baseline:
        traj.info["baseline_duration"] = _baseline(cell, route, paths.chunks, options, cache,
                                                   timed)
    return traj, paths.world


#: The clearance [m] a route's paths, blends and their checks keep from every object
#: (where its margin is smaller) when it is planned again because the release check
#: refused the first plan (its clearance between samples not proven, or a sample in
#: contact): with a margin of 0, a path can graze an obstacle (a shortcut pulled tight
#: around it) closer than the check can certify, or by micrometres between the states
#: the planner checks at its resolution, and the same seed would find it again. The
#: release check still checks the scene's own margins. 1 mm is far above the check's
#: finest step (0.01 mm of motion).
REPLAN_CLEARANCE = 1e-3


def _keeping_clearance(cell: Cell, clearance: float) -> Cell | None:
    """The cell with every object's margin at least ``clearance`` [m], or None if every
    margin is that large already."""
    scene = cell.scene
    smaller = {name: obj for name, obj in scene.objects.items()
               if obj.margin is not None and obj.margin < clearance}
    if scene.margin >= clearance and not smaller:
        return None
    objects = {**scene.objects, **{name: replace(obj, margin=clearance)
                                   for name, obj in smaller.items()}}
    return replace(cell, scene=replace(scene, margin=max(scene.margin, clearance),
                                       objects=objects))


def _plan_paths(cell: Cell, route: Route, world: WorldState, options: PlanOptions,
                cache: CheckerCache, labels: list[str]) -> _Paths:
    """Every motion step's checked path, cut into chunks at the stops and the gripper
    actions (which change the world)."""
    q = cell.pose(route.start)
    pose_name: str | None = route.start
    chunks: list[tuple[list[Segment], WorldState] | PourChunk] = []
    actions: list[tuple[int, int, Step]] = []
    current: list[Segment] = []
    times: dict[str, float] = {}
    for i, step in enumerate(route.steps):
        if step.kind in ("tilt", "circle"):  # rest to rest; a circle goes with its tilt
            if current:
                chunks.append((current, world.copy()))
                current = []
            if step.kind == "tilt":
                chunks.append(plan_pour_chunk(cell, route, i, q, world, options, cache,
                                              labels))
                q, pose_name = chunks[-1].piece.q[-1], None  # type: ignore[union-attr]
            continue
        if not step.is_motion:
            if current:
                chunks.append((current, world.copy()))
                current = []
            actions.append((len(chunks), i, step))
            world = _gripper(cell, world, step, q, labels[i], options)
            continue
        goal, goal_name = _resolve(cell, step, q, labels[i], options)
        # A continuous joint goes the short way round: its goal is the value a whole number
        # of turns from the pose's nearest the joint's value now (the same placement).
        goal = cell.robot.nearest_turn(goal, q)
        if step.kind == "line":
            allowed = cell.scene.contacts_at(pose_name) + cell.scene.contacts_at(goal_name)
            waypoints = _line_path(cell, cache.checker(world, allowed), q, goal, options,
                                   labels[i])
            goal = waypoints[-1]  # a turn away from ``goal`` if the line turned that far
        else:
            allowed = ()
            seeded = replace(options.planner, seed=options.planner.seed + i)
            checker = cache.checker(world, allowed)
            waypoints = _repeats.joint_path(checker, q, goal, seeded, _move(
                checker, q, goal, seeded, labels[i], times))
        current.append(Segment(i, step, waypoints, allowed))
        q, pose_name = goal, goal_name
        if step.stop:
            chunks.append((current, world.copy()))
            current = []
    if current:
        chunks.append((current, world.copy()))
    return _Paths(chunks, actions, world, times.get("shortcut", 0.0))


def _move(checker: CollisionChecker, q: np.ndarray, goal: np.ndarray,
          options: PlannerOptions, label: str, times: dict[str, float]
          ) -> Callable[[], list[np.ndarray]]:
    """The joint move from ``q`` to ``goal``, planned when called."""
    return lambda: plan_joint_path(checker, q, goal, options=options, step=label, times=times)


def _line_path(cell: Cell, checker: CollisionChecker, q: np.ndarray, goal: np.ndarray,
               options: PlanOptions, label: str) -> list[np.ndarray]:
    """The straight TCP line from ``q`` to ``goal``, checked; IKError where it collides."""
    robot = cell.robot

    def checked() -> list[np.ndarray]:
        waypoints = cartesian_line(robot, q, goal, options=options.line, step_name=label)
        report = checker.check_path(waypoints)
        if not report.valid:
            raise IKError(_line_failure(checker, report), step=label,
                          fraction=report.fraction or 0.0,
                          position=robot.tcp_position(report.q) if report.q is not None
                          else None)
        return waypoints

    # The same line in the same world is the same checked line (_repeats).
    return _repeats.checked_line(checker, q, goal, options.line, checked)


def _line_failure(checker: CollisionChecker, report: SegmentReport) -> str:
    """Why a line's state is refused, as ``safepath check`` would say it: outside the
    limits, in contact (the pairs), or closer than a pair's margin (how close)."""
    if report.limit_violation:
        return f"the line leaves the joint limits ({report.limit_violation})"
    state = checker.check(report.q) if report.q is not None else None
    if state is not None and state.clearance > 0.0 and state.margin_violations:
        worst = min(state.margin_violations, key=lambda v: v[1] - v[2])
        (a, b), distance, margin = worst
        return (f"the line comes within {1000 * distance:.1f} mm of {a} / {b}, below its "
                f"margin of {1000 * margin:.0f} mm (no contact)")
    return f"the line collides ({', '.join(f'{a} / {b}' for a, b in report.collisions)})"


def _time_and_verify(cell: Cell, chunks: list[tuple[list[Segment], WorldState] | PourChunk],
                     options: PlanOptions, cache: CheckerCache, labels: list[str],
                     timed: TimedPieces
                     ) -> tuple[list[tuple[TimedPiece, list[int]]], list[float],
                                tuple[float, float], Pair | None, float]:
    """Time and verify chunk by chunk: the timed pieces (with the step of each knot),
    when each chunk ends [s] (gripper events happen there), the smallest clearance the
    verifier found and the smallest of its certified clearance bounds [m], the pair of
    that clearance, and the largest distance [m] a point of the robot or held object may
    stray between two knots from where the knots' straight joint segments put it (see
    :func:`_knot_deviation`)."""
    pieces: list[tuple[TimedPiece, list[int]]] = []
    chunk_ends: list[float] = []
    elapsed = 0.0
    min_clear, closest = float("inf"), None
    bound, deviation = float("inf"), 0.0
    for chunk in chunks:
        verified = [(chunk.piece, chunk.steps_of_knots, chunk.result)] \
            if isinstance(chunk, PourChunk) else time_chunk(cell, *chunk, options, cache, labels,
                                                            min_clear, timed=timed)
        # A point's motion per joint turn depends on the robot and what it holds, not on
        # the allowed contacts: the chunk's own checker (the first step's) tells.
        weights = (cache.checker(chunk.world, ()) if isinstance(chunk, PourChunk)
                   else cache.checker(chunk[1], chunk[0][0].allowed)).displacement_weights
        for piece, steps_of_knots, result in verified:
            if result.min_clearance < min_clear:
                min_clear, closest = result.min_clearance, result.closest_pair
            bound = min(bound, result.clearance_bound)
            pieces.append((piece, steps_of_knots))
            elapsed += float(piece.t[-1])
            deviation = max(deviation, _knot_deviation(cell, piece, weights))
        chunk_ends.append(elapsed)
    return pieces, chunk_ends, (min_clear, bound), closest, deviation


def _knot_deviation(cell: Cell, piece: TimedPiece, weights: np.ndarray) -> float:
    """How far [m] a point of the robot (or held object) may be, between two knots of
    ``piece``, from where the straight joint segment between them puts it: the knots'
    quintic join keeps |q''_j| <= amax_j (checked), so it departs from the segment by at
    most amax_j h^2 / 8 in joint j over an interval h long, and a point moves at most
    ``weights_j`` [m/rad] per radian of joint j."""
    if piece.t.size < 2:
        return 0.0
    h = float(np.max(np.diff(piece.t)))
    return float(weights @ cell.robot.acceleration_limits) * h * h / 8.0


def _baseline(cell: Cell, route: Route,
              chunks: list[tuple[list[Segment], WorldState] | PourChunk],
              options: PlanOptions, cache: CheckerCache, timed: TimedPieces) -> float | None:
    """The stop-and-go duration [s]: the same steps' paths, each timed rest to rest (a
    pour counts as itself). A figure for comparison only: its failure must not throw
    away the verified trajectory."""
    total = 0.0
    try:
        for chunk in chunks:
            if isinstance(chunk, PourChunk):
                total += chunk.duration
                continue
            segments, chunk_world = chunk
            for seg in segments:
                piece, _ = time_segments(cell, [seg], chunk_world, options, cache,
                                         check=False, blend=0.0, timed=timed)
                total += float(piece.t[-1])
    except TimingError as exc:
        log.warning("route %s: no stop-and-go baseline (%s)", route.name, exc)
        return None
    return total


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
    from ..kinematics import solve_ik

    target = step.target
    assert target is not None
    if target.exact_pose is not None:
        return cell.pose(target.exact_pose), target.exact_pose
    q_init = cell.pose(target.pose) if target.pose is not None else q
    if target.cartesian is not None:
        T = target.cartesian.tcp_pose(cell.robot)
    else:
        T = cell.robot.frame_pose(q_init)
        T.translation = T.translation + np.asarray(target.offset)
    try:
        return _repeats.ik_goal(cell.robot, T.homogeneous, q_init, options.line, lambda: solve_ik(
            cell.robot, T, q_init, options=options.line, step=label)), None
    except IKError as exc:
        if step.kind != "line":
            raise
        # A line's target is its end: where along the line it failed.
        raise IKError(str(exc.reason), step=label, fraction=1.0,
                      position=exc.position) from None


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
