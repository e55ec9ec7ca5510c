"""Re-plan around an obstacle that stays: from where the robot rests, around it, back to
the route.

The obstacle of a :class:`~safepath.monitor.ReplanRequest` (a box around the blocking
elements, already inflated by ``C + Z_d``) is added to the scene with a margin, the rest
state becomes a temporary pose, and *ways* back to the route are tried in order; the
first that plans, times and verifies with the library's pipeline
(:func:`safepath.plan_route`: the independent re-check included) is the answer.

Which steps may be left (:func:`step_role`):

* a ``move`` or ``via`` step is free anyway: it is planned again around the obstacle;
* a ``line`` that ends at a gripper action (or at the route's end where another route
  begins with one) is an **approach** (an insertion, a placement, a grasp): it is never
  left and never entered anywhere but at its start, so a blocked approach has no way
  around it: the robot waits;
* any other ``line`` (a lift off a support, a retreat, a transit) may be **left**: its
  purpose ends where the next step begins;
* gripper actions and pour steps (``tilt``, ``circle``) are not re-planned.

The ways tried, in order (:func:`ways`): first the rest of the route as it is (the rest
of the step the robot stopped in, then the steps after it); then, when that step may be
left, a free joint move from the rest state to the end of that step, and further to the
end of each following step while the steps skipped may be left too (never past an
approach, a gripper action or a pour); the route then goes on with its next step. The
inserted move keeps the slowest speed and TCP speed limit of the steps it replaces.
When none works, :class:`~safepath.errors.PlanningError` says, for each way, why.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..cell import Cell
from ..errors import InputError, PlanningError, SafepathError
from ..planning import PlanOptions, Route, Step, Target, WorldState, initial_world, plan_route
from ..scene import SceneObject, Shape
from ..trajectory import Trajectory
from .monitor import ReplanRequest

__all__ = ["replan", "ways", "step_role", "world_at", "obstacle_scene", "start_pose",
           "step_index", "Way", "StepRole", "REST_POSE", "OBSTACLE"]

#: Name of the temporary pose the re-planned route starts from.
REST_POSE = "monitor_rest"
#: Name of the obstacle added to the scene.
OBSTACLE = "monitor_obstacle"
#: Suffix of a re-planned route's name.
SUFFIX = "_replanned"

StepRole = Literal["free", "leavable", "approach", "action", "pour"]


@dataclass(frozen=True)
class Way:
    """One way back to the route from the rest state.

    Attributes:
        description: What it does, in words.
        steps: The steps from the rest state.
        joins: Index of the original step whose end the way rejoins (the steps after it
            are the route's own).
        keeps_line: Whether the way goes on along the line the robot stopped in (it
            then keeps the contacts allowed where that line began).
    """

    description: str
    steps: tuple[Step, ...]
    joins: int
    keeps_line: bool


def step_role(routes: Mapping[str, Route], route: Route, index: int) -> StepRole:
    """What a re-plan may do with step ``index`` of ``route`` (see the module doc).

    Args:
        routes: All routes of the cell (a line ending a route is an approach when another
            route begins there with a gripper action).
        route: The route.
        index: The step's index.
    """
    step = route.steps[index]
    if step.kind in ("open", "close"):
        return "action"
    if step.kind in ("tilt", "circle"):
        return "pour"
    if step.kind == "move":
        return "free"
    following = route.steps[index + 1] if index + 1 < len(route.steps) else None
    if following is not None:
        return "approach" if following.kind in ("open", "close") else "leavable"
    end = step.target.exact_pose if step.target is not None else None
    if any(r.start == end and r.steps[0].kind in ("open", "close") for r in routes.values()):
        return "approach"
    return "leavable"


def start_pose(route: Route, first: int) -> str | None:
    """The taught pose step ``first`` starts from (None: not exactly a taught pose)."""
    pose: str | None = route.start
    for step in route.steps[:first]:
        if step.is_motion and step.target is not None:
            pose = step.target.exact_pose
    return pose


def step_index(route: Route, label: str) -> int | None:
    """Index of the step ``label`` names: exactly, or (in a re-planned route, whose steps
    are numbered from 0 again) by its text after the number, the last such step."""
    labels = route.labels()
    if label in labels:
        return labels.index(label)
    text = label.split(" ", 1)[-1]
    matches = [i for i, lab in enumerate(labels) if lab.split(" ", 1)[-1] == text]
    return matches[-1] if matches else None


def _absolute(cell: Cell, route: Route, index: int) -> Target | None:
    """Step ``index``'s target as one that does not depend on where the robot is (a
    target relative to the TCP becomes the TCP pose it reaches from the taught pose the
    step starts at); None when that pose is not a taught one."""
    target = route.steps[index].target
    if target is None or target.pose is not None or target.cartesian is not None:
        return target
    start = start_pose(route, index)
    if start is None:
        return None
    import pinocchio as pin

    from ..tcp_targets import CartesianTarget

    T = cell.robot.frame_pose(cell.pose(start))
    x, y, z, w = (float(v) for v in pin.Quaternion(T.rotation).coeffs())
    position = T.translation + np.asarray(target.offset)
    return Target(None, cartesian=CartesianTarget(
        (float(position[0]), float(position[1]), float(position[2])), (x, y, z, w)))


def _label(step: Step) -> str:
    return f"{step.kind} {step.target}"


def ways(cell: Cell, routes: Mapping[str, Route], route: Route, first: int
         ) -> tuple[list[Way], str | None]:
    """The ways back to ``route`` from a rest inside step ``first``, in the order tried.

    Returns:
        The ways, and why there are no others (an approach, a gripper action or a pour
        ends the steps that may be left), or None.
    """
    steps = route.steps
    own = steps[first]
    continued = replace(own, target=_absolute(cell, route, first)) \
        if own.kind == "line" and _absolute(cell, route, first) is not None else own
    out = [Way(f"the rest of '{_label(own)}', then the route", (continued, *steps[first + 1:]),
               first, own.kind == "line")]
    role = step_role(routes, route, first)
    if role not in ("free", "leavable"):
        return out, f"'{_label(own)}' is {_ROLE_WORDS[role]}: it is not left"
    speed, tcp = own.speed, own.tcp_speed
    for k in range(first, len(steps)):
        role_k = step_role(routes, route, k)
        if k > first and role_k not in ("free", "leavable"):
            return out, (f"'{_label(steps[k])}' is {_ROLE_WORDS[role_k]}: no way skips it")
        speed = min(speed, steps[k].speed)
        limit = steps[k].tcp_speed
        if limit is not None:
            tcp = limit if tcp is None else min(tcp, limit)
        target = _absolute(cell, route, k)
        if target is None or (k == first and own.kind == "move"):
            continue  # a move is re-planned by the first way already
        move = Step("move", target, None, speed, tcp, steps[k].stop)
        skipped = ", ".join(f"'{_label(s)}'" for s in steps[first + 1:k + 1])
        what = f"a free move to {target}" + (f" (instead of {skipped})" if skipped else "")
        out.append(Way(f"{what}, then the route", (move, *steps[k + 1:]), k, False))
    return out, None


_ROLE_WORDS: dict[StepRole, str] = {
    "approach": "an approach line (it must be entered straight, from its start)",
    "action": "a gripper action", "pour": "a pour step", "free": "a free move",
    "leavable": "a line that may be left"}


def obstacle_scene(cell: Cell, request: ReplanRequest, *, margin: float,
                   keep_contacts_of: str | None = None) -> Cell:
    """The cell with the request's obstacle box (``margin`` [m] around it) and the rest
    state as the pose :data:`REST_POSE` (with the contacts allowed at
    ``keep_contacts_of``, the pose a line the robot rests in began at)."""
    T = np.eye(4)
    T[:3, 3] = request.obstacle_center
    box = SceneObject(OBSTACLE, Shape("box", tuple(float(v) for v in request.obstacle_size)),
                      T, margin=margin, color=(0.9, 0.2, 0.2))
    contacts = tuple(replace(c, at=(*c.at, REST_POSE))
                     if keep_contacts_of is not None and keep_contacts_of in c.at else c
                     for c in cell.scene.allowed_contacts)
    scene = replace(cell.scene, objects={**cell.scene.objects, OBSTACLE: box},
                    allowed_contacts=contacts)
    return Cell(robot=cell.robot, scene=scene,
                poses={**cell.poses, REST_POSE: np.asarray(request.q, dtype=float)},
                folder=cell.folder, poses_path=cell.poses_path)


def world_at(cell: Cell, trajectories: Sequence[Trajectory], time: float | None = None
             ) -> WorldState:
    """The world after the gripper events of ``trajectories`` (routes run in this order
    from the scene's world), the last one's only up to ``time`` [s of that trajectory]
    (None: all of them): which object is held, where the released ones rest."""
    world = initial_world(cell)
    grasp = cell.scene.grasp
    for n, traj in enumerate(trajectories):
        for event in traj.events:
            if n == len(trajectories) - 1 and time is not None and event.time > time:
                break
            obj = event.object or (grasp.object if grasp else None)
            if grasp is None or obj != grasp.object:
                continue
            if event.action == "close":
                world.held = obj
                world.resting.pop(obj, None)
            elif world.held == obj:
                q = traj.sample([event.time])[0][0]
                world.held = None
                world.resting[obj] = cell.robot.frame_pose(q).homogeneous @ grasp.T_tcp_object
    return world


def _check_request(cell: Cell, request: ReplanRequest, margin: float) -> None:
    if not isinstance(request, ReplanRequest):
        raise InputError(f"expected a ReplanRequest, got {type(request).__name__}",
                         key="request")
    q = np.asarray(request.q, dtype=float)
    if q.shape != (cell.robot.dof,) or not np.all(np.isfinite(q)):
        raise InputError(f"the rest state needs {cell.robot.dof} finite joint values, got "
                         f"shape {q.shape}", key="request.q")
    for key in ("obstacle_center", "obstacle_size"):
        v = np.asarray(getattr(request, key), dtype=float)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise InputError(f"expected 3 finite numbers [m], got {v!r}", key=f"request.{key}")
    if np.any(np.asarray(request.obstacle_size) <= 0):
        raise InputError("edge lengths must be > 0 [m]", key="request.obstacle_size")
    if not (isinstance(margin, (int, float)) and np.isfinite(margin) and margin >= 0):
        raise InputError(f"must be a number >= 0 [m], got {margin!r}", key="margin")


def replan(cell: Cell, route_name: str, request: ReplanRequest, *, held: str | None,
           margin: float, options: PlanOptions | None = None,
           world: WorldState | None = None) -> Trajectory:
    """Plan from the request's rest state around its obstacle back to route
    ``route_name``, and on to the route's end.

    The result's ``info["replan"]`` holds the way taken (``way``, ``joins``: the
    original step rejoined) and why the ways before it failed (``failed``).

    Args:
        cell: The cell the route belongs to.
        route_name: The route (from the cell's ``routes.yaml``; a re-planned route's name
            is understood as its original's).
        request: The monitor's re-plan request.
        held: Object held at the rest state.
        margin: Clearance the new path keeps from the obstacle box [m].
        options: Planning options.
        world: World state at the rest state (default: the scene's, with ``held``).

    Raises:
        InputError: A malformed request or margin (naming the key).
        PlanningError: The route or step is unknown, or no way works: the reason lists
            every way tried and why it failed, and what may not be left.
    """
    _check_request(cell, request, margin)
    routes = cell.route_table()
    base = route_name
    while base.endswith(SUFFIX):  # a re-planned route: its steps are the original's tail
        base = base[:-len(SUFFIX)]
    route = routes.get(base)
    if route is None:
        raise PlanningError(f"unknown route '{route_name}' (routes: {', '.join(routes)})")
    first = step_index(route, request.step)
    if first is None:
        raise PlanningError(f"route '{base}' has no step '{request.step}'")
    if world is None:
        world = WorldState(held, {o.name: o.T_world_object.copy()
                                  for o in cell.scene.objects.values()
                                  if o.movable and o.name != held})
    options = options or PlanOptions()
    candidates, limit = ways(cell, routes, route, first)
    failed: list[str] = []
    start = start_pose(route, first)
    cells: dict[bool, Cell] = {}  # one per contact set: its checkers are built once
    for way in candidates:
        if way.keeps_line not in cells:
            cells[way.keeps_line] = obstacle_scene(
                cell, request, margin=margin, keep_contacts_of=start if way.keeps_line else None)
        temp = cells[way.keeps_line]
        try:
            traj = plan_route(temp, Route(f"{base}{SUFFIX}", REST_POSE, way.steps), options,
                              world=world)
        except SafepathError as exc:
            failed.append(f"{way.description}: {exc}")
            continue
        traj.info["replan"] = {"way": way.description, "joins": route.labels()[way.joins],
                               "failed": failed}
        return traj
    why = "; ".join(f"({i + 1}) {f}" for i, f in enumerate(failed))
    if limit is not None:
        why += f"; no other way: {limit}"
    raise PlanningError(f"no way around the obstacle: {why}", step=request.step)
