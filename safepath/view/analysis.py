"""What a review shows about a trajectory, computed without any GUI.

For every route: the world state of every step (which object the gripper holds, where
the others rest, which contacts are allowed), replayed from the trajectory's gripper
events exactly as the planner saw it; and samples on a regular time grid with the TCP
position, the clearance, the safety level (green / yellow / red) and the joint
speeds relative to their limits. Plans read from files are checked against the cell
first: a plan made for another robot is refused with a typed error.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..cell import Cell, Route
from ..collision import CheckOptions, CollisionChecker, StateReport
from ..errors import ConfigError, TrajectoryError
from ..model._knots import interval_index
from ..model.scene import AllowedContact
from ..model.trajectory import Trajectory, load_trajectory
from ..planning import WorldState, initial_world

__all__ = ["GREEN", "YELLOW", "RED", "CLEAR_ENOUGH", "RouteReview", "analyse_routes",
           "check_plan", "load_plans", "affected_routes", "routes_of"]

log = logging.getLogger(__name__)

#: Safety levels of a state.
GREEN, YELLOW, RED = 0, 1, 2
#: Clearance above which a state is green [m].
CLEAR_ENOUGH = 0.020
#: How close a trajectory state must be to a taught pose to count as it [rad].
_POSE_TOLERANCE = 1e-6


@dataclass
class RouteReview:
    """A trajectory and what the review shows about it.

    Attributes:
        name: Route name.
        trajectory: The timed trajectory.
        worlds: World state of every step (index as ``trajectory.steps``).
        allowed: Contacts allowed in every step.
        times: Sample times [s].
        tcp: TCP position at every sample [m], shape (n, 3).
        clearance: Clearance at every sample [m].
        level: Safety level of every sample (GREEN, YELLOW, RED).
        velocity_ratio: ``|qd| / velocity limit`` at every sample, shape (n, dof).
        closest: Closest (or colliding) pair at every sample.
    """

    name: str
    trajectory: Trajectory
    worlds: list[WorldState]
    allowed: list[tuple[AllowedContact, ...]]
    times: np.ndarray = field(repr=False)
    tcp: np.ndarray = field(repr=False)
    clearance: np.ndarray = field(repr=False)
    level: np.ndarray = field(repr=False)
    velocity_ratio: np.ndarray = field(repr=False)
    closest: list[tuple[str, str] | None] = field(repr=False)

    @property
    def duration(self) -> float:
        """Motion time [s]."""
        return self.trajectory.duration

    def step_index_at(self, time: float) -> int:
        """Index of the step being executed at ``time`` [s]."""
        traj = self.trajectory
        k = int(interval_index(traj.t, time, traj.t.size))
        return int(traj.step_index[k])


def check_plan(cell: Cell, traj: Trajectory, *, path: Path | None = None) -> None:
    """Refuse a trajectory that was not made for the cell's robot.

    Raises:
        TrajectoryError: Another robot, or other joint names (names the file).
    """
    robot = cell.robot
    if traj.robot and traj.robot != robot.name:
        raise TrajectoryError(f"plan for robot '{traj.robot}', but the cell's robot is "
                              f"'{robot.name}'", path=path, key="robot")
    if tuple(traj.joint_names) != tuple(robot.joint_names):
        raise TrajectoryError(f"joints {list(traj.joint_names)} differ from the robot's "
                              f"{list(robot.joint_names)}", path=path, key="joint_names")


def load_plans(cell: Cell, source: str | Path) -> dict[str, Trajectory]:
    """Read the trajectories written by ``safepath plan`` (a folder of ``*.json``, or one).

    ``summary.json`` is skipped. Routes are keyed by their route name (the file stem
    when the trajectory names none).

    Raises:
        TrajectoryError: No such folder or file, no trajectory in it, a malformed file,
            or a plan for another robot.
    """
    source = Path(source)
    if source.is_dir():
        files = sorted(p for p in source.glob("*.json") if p.name != "summary.json")
        if not files:
            raise TrajectoryError("no trajectory (*.json) in the plan folder", path=source)
    elif source.exists():
        files = [source]
    else:
        raise TrajectoryError("plan folder or file not found", path=source)
    out: dict[str, Trajectory] = {}
    for file in files:
        traj = load_trajectory(file)
        check_plan(cell, traj, path=file)
        out[traj.route or file.stem] = traj
    return out


def routes_of(cell: Cell) -> dict[str, Route]:
    """The cell's routes (``routes.yaml``), or none when it has no such file."""
    if cell.routes is None and (cell.folder is None or not (cell.folder / "routes.yaml").exists()):
        return {}
    return cell.route_table()


def affected_routes(routes: Mapping[str, Route], poses: Sequence[str]) -> list[str]:
    """Routes that use any of ``poses``, and the routes that start where they end."""
    names = set(poses)
    hit = {name for name, r in routes.items()
           if r.start in names or any(s.target is not None and s.target.pose in names
                                      for s in r.steps)}
    changed = True
    while changed:
        changed = False
        for name, r in routes.items():
            if name not in hit and r.after in hit:
                hit.add(name)
                changed = True
    return [name for name in routes if name in hit]


def _pose_named(poses: Mapping[str, np.ndarray], q: np.ndarray) -> str | None:
    for name, p in poses.items():
        if p.shape == q.shape and float(np.max(np.abs(p - q))) < _POSE_TOLERANCE:
            return name
    return None


def _step_worlds(cell: Cell, traj: Trajectory, world: WorldState,
                 poses: Mapping[str, np.ndarray], start: str | None
                 ) -> tuple[list[WorldState], list[tuple[AllowedContact, ...]], WorldState]:
    """Replay the gripper events and allowed contacts step by step, as the planner did."""
    scene, robot = cell.scene, cell.robot
    events = {e.step: e for e in traj.events}
    worlds: list[WorldState] = []
    allowed: list[tuple[AllowedContact, ...]] = []
    pose_name = start if start is not None else _pose_named(poses, traj.q[0])
    for label in traj.steps:
        parts = label.split(" ", 2)
        kind = parts[1] if len(parts) > 1 else ""
        target = parts[2] if len(parts) > 2 else ""
        worlds.append(world.copy())
        if kind == "line":
            goal = target if target in poses else None
            allowed.append(scene.contacts_at(pose_name) + scene.contacts_at(goal))
            pose_name = goal
        elif kind in ("move", "via"):
            allowed.append(())
            pose_name = target if target in poses else None
        else:
            allowed.append(())
        event = events.get(label)
        if event is None or scene.grasp is None or event.object != scene.grasp.object:
            continue
        world = world.copy()
        if event.action == "close":
            world.held = event.object
            world.resting.pop(event.object, None)
        elif world.held == event.object:
            q_event = traj.sample([event.time])[0][0]
            world.held = None
            world.resting[event.object] = (robot.frame_pose(q_event).homogeneous
                                           @ scene.grasp.T_tcp_object)
    return worlds, allowed, world


def _order(trajectories: Mapping[str, Trajectory], routes: Mapping[str, Route]) -> list[str]:
    known = [name for name in routes if name in trajectories]
    return known + sorted(name for name in trajectories if name not in routes)


def analyse_routes(cell: Cell, trajectories: Mapping[str, Trajectory], *,
                   poses: Mapping[str, np.ndarray] | None = None,
                   routes: Mapping[str, Route] | None = None,
                   period: float = 0.02) -> dict[str, RouteReview]:
    """Review data of every trajectory, in route order.

    Args:
        cell: The cell.
        trajectories: Trajectories by route name (checked with :func:`check_plan`).
        poses: Taught poses the trajectories were planned with (default: the cell's).
        routes: The cell's routes (default: read from its folder); a route that
            follows another starts in the world state the other one ends in.
        period: Sample period of the clearance and speed curves [s].

    Raises:
        TrajectoryError: A trajectory made for another robot.
        ConfigError: ``period`` is not positive.
    """
    if not np.isfinite(period) or period <= 0:
        raise ConfigError(f"sample period must be > 0, got {period}", key="period")
    poses = dict(cell.poses if poses is None else poses)
    routes = routes_of(cell) if routes is None else routes
    end_worlds: dict[str, WorldState] = {}
    out: dict[str, RouteReview] = {}
    pending = _order(trajectories, routes)
    # A route that follows another one needs that one's end world: visit in chain order.
    for name in sorted(pending, key=lambda n: _depth(routes, n)):
        traj = trajectories[name]
        check_plan(cell, traj)
        route = routes.get(name)
        after = route.after if route is not None else None
        world = (end_worlds[after].copy() if after in end_worlds else initial_world(cell))
        labels_match = route is not None and tuple(route.labels()) == tuple(traj.steps)
        start = route.start if labels_match and route is not None else None
        worlds, allowed, end = _step_worlds(cell, traj, world, poses, start)
        end_worlds[name] = end
        out[name] = _sample(cell, name, traj, worlds, allowed, period)
    return {name: out[name] for name in pending}


def _depth(routes: Mapping[str, Route], name: str) -> int:
    depth, after = 0, routes[name].after if name in routes else None
    while after is not None and after in routes and depth < len(routes):
        depth += 1
        after = routes[after].after
    return depth


class StepCheckers:
    """Collision checkers of a route's steps, built on first use (not thread-safe)."""

    def __init__(self, cell: Cell, worlds: Sequence[WorldState],
                 allowed: Sequence[tuple[AllowedContact, ...]]) -> None:
        self.cell = cell
        self.worlds = list(worlds)
        self.allowed = list(allowed)
        self._cache: dict[tuple, CollisionChecker] = {}

    def __call__(self, step: int) -> CollisionChecker:
        """The checker of step ``step``."""
        world, allowed = self.worlds[step], self.allowed[step]
        key = (world.key(), allowed)
        checker = self._cache.get(key)
        if checker is None:
            checker = CollisionChecker(self.cell.robot, self.cell.scene, held=world.held,
                                       resting=world.resting, allowed=allowed,
                                       options=CheckOptions())
            self._cache[key] = checker
        return checker


def level_of(report: StateReport) -> int:
    """Safety level of a checked state: red below its margin (or invalid), yellow
    closer than :data:`CLEAR_ENOUGH`, green otherwise."""
    if not report.margin_ok:
        return RED
    return YELLOW if report.clearance < CLEAR_ENOUGH else GREEN


def _sample(cell: Cell, name: str, traj: Trajectory, worlds: list[WorldState],
            allowed: list[tuple[AllowedContact, ...]], period: float) -> RouteReview:
    robot = cell.robot
    times = np.arange(0.0, traj.duration, period)
    if times.size == 0 or traj.duration - times[-1] > 1e-9:
        times = np.append(times, traj.duration)
    q, qd, _ = traj.sample(times + traj.t[0])
    checkers = StepCheckers(cell, worlds, allowed)
    k = interval_index(traj.t, times + traj.t[0], traj.t.size)
    steps = traj.step_index[k]
    n = times.size
    tcp = np.empty((n, 3))
    clearance = np.empty(n)
    level = np.empty(n, dtype=int)
    closest: list[tuple[str, str] | None] = []
    for i in range(n):
        report = checkers(int(steps[i])).check(q[i])
        tcp[i] = robot.tcp_position(q[i])
        clearance[i] = min(report.clearance, 0.0) if report.collisions else report.clearance
        level[i] = level_of(report)
        closest.append(report.collisions[0] if report.collisions else report.closest_pair)
    ratio = np.abs(qd) / robot.velocity_limits
    log.debug("route %s: %d samples, min clearance %.4f m", name, n, float(clearance.min()))
    return RouteReview(name, traj, worlds, allowed, times, tcp, clearance, level, ratio,
                       closest)
