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
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ..cell import Cell
from ..errors import IKError, PlanningError, TimingError
from ..routes import Route, Step
from ..trajectory import Trajectory
from ._chunks import Segment, assemble, time_chunk, time_segments
from .cartesian import cartesian_line
from .options import PlanOptions
from .sampling import plan_joint_path
from .timing import TimedPiece
from .world import CheckerCache, WorldState, initial_world

__all__ = ["PlanOptions", "WorldState", "plan_route", "plan_cell", "route_order",
           "initial_world"]

log = logging.getLogger(__name__)


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
    """Plan, time and verify every route of the cell (its routes, or ``routes.yaml`` of
    its folder: :meth:`Cell.route_table`)."""
    options = options or PlanOptions()
    if routes is None:
        routes = cell.route_table()
    cache = CheckerCache(cell, options)
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
                    CheckerCache(cell, options))
    return traj


def _plan(cell: Cell, route: Route, world: WorldState, options: PlanOptions,
          cache: CheckerCache) -> tuple[Trajectory, WorldState]:
    t_start = time.perf_counter()
    robot, scene = cell.robot, cell.scene
    labels = route.labels()
    q = cell.pose(route.start)
    pose_name: str | None = route.start
    chunks: list[tuple[list[Segment], WorldState]] = []
    actions: list[tuple[int, int, Step]] = []  # (after chunk, step index, step)
    current: list[Segment] = []
    planner_opts = options.planner
    times: dict[str, float] = {}
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
                seeded = replace(planner_opts, seed=planner_opts.seed + i)
                waypoints = plan_joint_path(checker, q, goal, options=seeded, step=label,
                                            times=times)
            current.append(Segment(i, step, waypoints, allowed))
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
    chunk_ends: list[float] = []  # when each chunk ends [s]: gripper events happen there
    elapsed = 0.0
    min_clear, closest = float("inf"), None
    for segments, chunk_world in chunks:
        for piece, steps_of_knots, result in time_chunk(cell, segments, chunk_world, options,
                                                        cache, labels):
            if result.min_clearance < min_clear:
                min_clear, closest = result.min_clearance, result.closest_pair
            pieces.append((piece, steps_of_knots))
            elapsed += float(piece.t[-1])
        chunk_ends.append(elapsed)
    traj = assemble(cell, route, labels, pieces, chunk_ends, actions)
    _check_position_limits(cell, traj)
    traj.info.update({
        "planning_time": plan_time,
        "shortcut_time": times.get("shortcut", 0.0),
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
                    piece, _ = time_segments(cell, [seg], chunk_world, options, cache,
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
    return solve_ik(cell.robot, T, seed, options=options.line, step=label), None


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
