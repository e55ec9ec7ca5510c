"""Re-plan around an obstacle that stays: from where the robot rests, around it, back to
the route.

The obstacle of a :class:`~safepath.monitor.ReplanRequest` (a box around the blocking
body, inflated by ``C + Z_d`` except where cut back to the arm) is added to the scene with
a margin, the rest
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
Last, when the robot rests in a line that may be left, the first :data:`PARTIAL_LINES` of
that line followed by each of those moves (a vial just lifted off its support may leave
it only straight: a free move cannot start there). When none works,
:class:`~safepath.errors.PlanningError` says, for each way, why.

The start must be clear of the box (:mod:`safepath.monitor.escape`): the sides of the box
facing the robot at rest are cut back as little as needed, never inside the body's own
box (``request.body_center``, ``body_size``); when even that box is closer than the
margin, the route begins with a first stretch away from it (step
:data:`ESCAPE_SUFFIX`), planned with the clearance the robot has at rest, and the ways
are tried from its end. A cut is for the start only: when the box was cut and the robot
may leave its step, the first stretch goes on until the robot is the margin clear of the
whole box (the body's box inflated by ``request.inflation``), and the ways keep the
margin from that; when that finds no way, the ways from the cut box follow
(:func:`_clear_start`). The box the ways planned around is in ``info["replan"]["box"]``,
the first stretch's in ``info["replan"]["escape"]["box"]``.

Step names (:func:`rest_step`): the re-planned trajectory's steps carry the original
route's labels (``4 line low1``), the rest of the step the robot stopped in too; an
inserted move carries the label of the step whose end it reaches, with
:data:`MOVE_SUFFIX` (``2 line high1 (re-planned move)``), the first stretch away the label
of the step the robot rested in with :data:`ESCAPE_SUFFIX`. A request made in a
re-planned trajectory therefore names a step of the original route, and re-plans again.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..cell import Cell, Route, Step, Target
from ..errors import InputError, PlanningError, SafepathError
from ..model.scene import SceneObject, Shape
from ..model.trajectory import Trajectory
from ..planning import PlanOptions, WorldState, initial_world, plan_route
from .escape import START_SLACK, box_clearance, escape_state, start_box
from .monitor import ReplanRequest

__all__ = ["replan", "ways", "step_role", "world_at", "obstacle_scene", "start_pose",
           "step_index", "rest_step", "Way", "StepRole", "REST_POSE", "OBSTACLE",
           "MOVE_SUFFIX", "ESCAPE_SUFFIX", "ESCAPE_POSE"]

#: Name of the temporary pose the re-planned route starts from.
REST_POSE = "monitor_rest"
#: Name of the obstacle added to the scene.
OBSTACLE = "monitor_obstacle"
#: Suffix of a re-planned route's name.
SUFFIX = "_replanned"
#: Suffix of an inserted move's step name (after the label of the step it ends with).
MOVE_SUFFIX = " (re-planned move)"
#: Suffix of the first stretch away's step name (after the label of the step the robot
#: rested in).
ESCAPE_SUFFIX = " (re-planned escape)"
#: Name of the temporary pose the first stretch away ends at.
ESCAPE_POSE = "monitor_escape"
#: Thinnest edge of a body's box [m]: a body seen in one plane (a planar scan) has a box
#: of no height, and a box cut back to it keeps this much (a box needs edges > 0).
THINNEST = 1e-3
#: Lengths of the partial lines tried from a rest in a line that may be left [m].
PARTIAL_LINES = (0.01, 0.02, 0.04)

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
        labels: The names its steps get in the re-planned trajectory (the original
            route's labels; see the module doc).
    """

    description: str
    steps: tuple[Step, ...]
    joins: int
    keeps_line: bool
    labels: tuple[str, ...] = ()


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


def rest_step(route: Route, label: str) -> tuple[int, bool] | None:
    """Index of the original step a (possibly re-planned) step name ``label`` stands for,
    and whether it is an inserted move to that step's end (None: no such step).

    A re-planned trajectory's names are the original labels (an inserted move's with
    :data:`MOVE_SUFFIX`); other names are looked up by :func:`step_index`."""
    labels = route.labels()
    for suffix in (MOVE_SUFFIX, ESCAPE_SUFFIX):
        if label.endswith(suffix) and label[:-len(suffix)] in labels:
            return labels.index(label[:-len(suffix)]), True
    index = step_index(route, label)
    return None if index is None else (index, False)


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

    from ..cell.tcp_targets import CartesianTarget

    T = cell.robot.frame_pose(cell.pose(start))
    x, y, z, w = (float(v) for v in pin.Quaternion(T.rotation).coeffs())
    position = T.translation + np.asarray(target.offset)
    return Target(None, cartesian=CartesianTarget(
        (float(position[0]), float(position[1]), float(position[2])), (x, y, z, w)))


def _label(step: Step) -> str:
    return f"{step.kind} {step.target}"


def ways(cell: Cell, routes: Mapping[str, Route], route: Route, first: int, *,
         in_move: bool = False, q_rest: np.ndarray | None = None
         ) -> tuple[list[Way], str | None]:
    """The ways back to ``route`` from a rest inside step ``first`` (``in_move``: inside
    a move a re-plan inserted to that step's end; ``q_rest``: the rest state [rad], for
    the partial lines of a line that may be left), in the order tried.

    Returns:
        The ways, and why there are no others (an approach, a gripper action or a pour
        ends the steps that may be left), or None.
    """
    steps = route.steps
    labels = route.labels()
    own = steps[first]
    continued = replace(own, target=_absolute(cell, route, first)) \
        if own.kind == "line" and _absolute(cell, route, first) is not None else own
    out: list[Way] = []
    if not in_move or own.kind == "move":  # an inserted move is a free move anyway
        out.append(Way(f"the rest of '{_label(own)}', then the route",
                       (continued, *steps[first + 1:]), first, own.kind == "line",
                       tuple(labels[first:])))
    role = step_role(routes, route, first)
    if role not in ("free", "leavable"):
        return out, f"'{_label(own)}' is {_ROLE_WORDS[role]}: it is not left"
    moves, limit = _free_moves(cell, routes, route, first)
    partial = _partial_lines(cell, route, first, q_rest, moves) \
        if own.kind == "line" and q_rest is not None and not in_move else []
    return out + moves + partial, limit


def _free_moves(cell: Cell, routes: Mapping[str, Route], route: Route, first: int
                ) -> tuple[list[Way], str | None]:
    """The free moves from the rest (inside step ``first``, which may be left) to the end
    of that step and of each following one that may be left (see :func:`ways`)."""
    steps, labels, own = route.steps, route.labels(), route.steps[first]
    out: list[Way] = []
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
        out.append(Way(f"{what}, then the route", (move, *steps[k + 1:]), k, False,
                       (labels[k] + MOVE_SUFFIX, *labels[k + 1:])))
    return out, None


def _partial_lines(cell: Cell, route: Route, first: int, q_rest: np.ndarray,
                   moves: Sequence[Way]) -> list[Way]:
    """Ways for a rest in a line that may be left where the rest of the line is blocked
    and a free move cannot start (the robot rests in a contact allowed only on the line:
    a vial just lifted off its support): the first :data:`PARTIAL_LINES` of the line,
    then each of the free ``moves`` (to the end of the line or of a step after it)."""
    import pinocchio as pin

    from ..cell.tcp_targets import CartesianTarget

    own, labels = route.steps[first], route.labels()
    end = _absolute(cell, route, first)
    if end is None:
        return []
    if end.cartesian is not None:
        p_end = np.asarray(end.cartesian.position, dtype=float)
        x, y, z, w = end.cartesian.orientation
        r_end = pin.Quaternion(w, x, y, z)
    else:
        assert end.pose is not None
        T = cell.robot.frame_pose(cell.pose(end.pose))
        p_end, r_end = T.translation + np.asarray(end.offset), pin.Quaternion(T.rotation)
    T_rest = cell.robot.frame_pose(np.asarray(q_rest, dtype=float))  # noqa: N806
    r_rest = pin.Quaternion(T_rest.rotation)
    length = float(np.linalg.norm(p_end - T_rest.translation))
    out = []
    for d in PARTIAL_LINES:
        if d >= length - 1e-3:
            break
        f = d / length
        p = T_rest.translation + f * (p_end - T_rest.translation)
        qx, qy, qz, qw = (float(v) for v in r_rest.slerp(f, r_end).coeffs())
        piece = Step("line", Target(None, cartesian=CartesianTarget(
            (float(p[0]), float(p[1]), float(p[2])), (qx, qy, qz, qw))), None, own.speed,
            own.tcp_speed)
        out += [Way(f"the first {1000 * d:.0f} mm of '{_label(own)}', then {m.description}",
                    (piece, *m.steps), m.joins, True, (labels[first], *m.labels))
                for m in moves]
    return out


_ROLE_WORDS: dict[StepRole, str] = {
    "approach": "an approach line (it must be entered straight, from its start)",
    "action": "a gripper action", "pour": "a pour step", "free": "a free move",
    "leavable": "a line that may be left"}


def obstacle_scene(cell: Cell, request: ReplanRequest, *, margin: float,
                   keep_contacts_of: str | None = None,
                   extra_poses: Mapping[str, np.ndarray] | None = None) -> Cell:
    """The cell with the request's obstacle box (``margin`` [m] around it) and the rest
    state as the pose :data:`REST_POSE`, with ``extra_poses`` (the contacts allowed at
    ``keep_contacts_of``, the pose a line the robot rests in began at, allowed there
    too)."""
    extra = {k: np.asarray(v, dtype=float) for k, v in (extra_poses or {}).items()}
    T = np.eye(4)
    T[:3, 3] = request.obstacle_center
    box = SceneObject(OBSTACLE, Shape("box", tuple(float(v) for v in request.obstacle_size)),
                      T, margin=margin, color=(0.9, 0.2, 0.2))
    contacts = tuple(replace(c, at=(*c.at, REST_POSE, *extra))
                     if keep_contacts_of is not None and keep_contacts_of in c.at else c
                     for c in cell.scene.allowed_contacts)
    scene = replace(cell.scene, objects={**cell.scene.objects, OBSTACLE: box},
                    allowed_contacts=contacts)
    return Cell(robot=cell.robot, scene=scene,
                poses={**cell.poses, REST_POSE: np.asarray(request.q, dtype=float), **extra},
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
    keys = ["obstacle_center", "obstacle_size"]
    if (request.body_center is None) != (request.body_size is None):
        raise InputError("body_center and body_size are given together or not at all",
                         key="request.body_size")
    if request.body_center is not None:
        keys += ["body_center", "body_size"]
    for key in keys:
        v = np.asarray(getattr(request, key), dtype=float)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise InputError(f"expected 3 finite numbers [m], got {v!r}", key=f"request.{key}")
    if np.any(np.asarray(request.obstacle_size) <= 0):
        raise InputError("edge lengths must be > 0 [m]", key="request.obstacle_size")
    if request.body_size is not None and np.any(np.asarray(request.body_size) < 0):
        raise InputError("edge lengths must be >= 0 [m]", key="request.body_size")
    if not (isinstance(margin, (int, float)) and np.isfinite(margin) and margin >= 0):
        raise InputError(f"must be a number >= 0 [m], got {margin!r}", key="margin")


def replan(cell: Cell, route_name: str, request: ReplanRequest, *, held: str | None,
           margin: float, options: PlanOptions | None = None,
           world: WorldState | None = None) -> Trajectory:
    """Plan from the request's rest state around its obstacle back to route
    ``route_name``, and on to the route's end.

    The result's ``info["replan"]`` holds the way taken (``way``, ``joins``: the
    original step rejoined), why the ways before it failed (``failed``) and the box
    planned around (``box``: ``center``, ``size`` [m], ``shrunk``: what the monitor and
    :func:`start_box` cut back, in words); with a first stretch away, ``escape``: where
    it ends (``to``), the margin it keeps (``margin``) and from which box (``box``). Its
    steps carry the original route's labels (see the module doc), so that a request made
    in it re-plans again.

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
        PlanningError: The route or step is unknown, the rest state is within the
            margin of the body itself (:func:`start_box`), or no way works: the reason
            lists every way tried and why it failed, and what may not be left.
    """
    _check_request(cell, request, margin)
    routes = cell.route_table()
    base = route_name
    while base.endswith(SUFFIX):  # a re-planned route: its steps are the original's tail
        base = base[:-len(SUFFIX)]
    route = routes.get(base)
    if route is None:
        raise PlanningError(f"unknown route '{route_name}' (routes: {', '.join(routes)})")
    found = rest_step(route, request.step)
    if found is None:
        raise PlanningError(f"route '{base}' has no step '{request.step}'")
    first, in_move = found
    if world is None:
        world = WorldState(held, {o.name: o.T_world_object.copy()
                                  for o in cell.scene.objects.values()
                                  if o.movable and o.name != held})
    options = options or PlanOptions()
    starts = _clear_start(cell, routes, route, first, request, held=held, world=world,
                          margin=margin)
    failed: list[str] = []
    last: PlanningError | None = None  # why the start tried last found no way
    for ways_request, stretch in starts:
        if last is not None:
            failed.append(f"keeping the margin from the whole box: {last}")
        try:
            head = None if stretch is None else _plan_escape(cell, route, first, stretch,
                                                               world, options)
            traj, way = _plan_ways(cell, routes, route, first, in_move, ways_request, margin,
                                   world, options)
            break
        except PlanningError as exc:
            last = exc
    else:
        assert last is not None  # (_clear_start yields a start or raises)
        raise last
    traj = _named(traj, way.labels)
    traj.info["replan"] = {"way": way.description, "joins": route.labels()[way.joins],
                           "failed": [*failed, *traj.info.pop("replan_failed")],
                           "box": _box_info(ways_request)}
    if head is not None:
        assert stretch is not None
        traj = _joined(head, traj, route.labels()[first] + ESCAPE_SUFFIX)
        traj.info["replan"]["escape"] = {"to": stretch.to.tolist(), "margin": stretch.margin,
                                         "box": _box_info(stretch.request)}
    return traj


@dataclass(frozen=True)
class _Stretch:
    """A first stretch away from the rest state: to ``to`` [rad], keeping ``margin`` [m]
    from the box of ``request``."""

    to: np.ndarray
    margin: float
    request: ReplanRequest


def _box_info(request: ReplanRequest) -> dict[str, object]:
    return {"center": request.obstacle_center.tolist(), "size": request.obstacle_size.tolist(),
            "shrunk": request.shrunk}


def _clear_start(cell: Cell, routes: Mapping[str, Route], route: Route, first: int,
                 request: ReplanRequest, *, held: str | None, world: WorldState,
                 margin: float) -> Iterator[tuple[ReplanRequest, _Stretch | None]]:
    """Where the ways may start, in the order to try them (each worked out only once the
    one before found no way): the request the ways are planned with (its box, its rest
    state) and the first stretch away before them, if any (:mod:`safepath.monitor.escape`).

    The box is cut back from the rest state (:func:`start_box`). When the box was cut (by
    the monitor or here) and the robot may leave its step, the first stretch goes on
    until the robot is clear of the whole box, and the ways keep the margin from that;
    when no such stretch is found or no way plans from it, the ways from the cut box
    follow (a first stretch away when even that is needed: :func:`escape_state`)."""
    lo, hi = _corners(request.obstacle_center, request.obstacle_size)
    body = None if request.body_center is None or request.body_size is None else \
        _corners(request.body_center, np.maximum(request.body_size, THINNEST))
    whole = (lo, hi) if body is None or request.inflation is None else \
        (body[0] - request.inflation, body[1] + request.inflation)
    q = np.asarray(request.q, dtype=float)
    need = margin + START_SLACK
    box = start_box(cell, q, lo, hi, body, held=held, margin=margin)
    cut = replace(request, obstacle_center=(box.lo + box.hi) / 2,
                  obstacle_size=box.hi - box.lo,
                  shrunk="; ".join(w for w in (request.shrunk, box.cut) if w))
    whole_request = request if whole[0] is lo else replace(
        request, obstacle_center=(whole[0] + whole[1]) / 2, obstacle_size=whole[1] - whole[0],
        shrunk="")
    if box_clearance(cell, *whole, held=held).clearance(q)[0] >= need:
        yield whole_request, None
        return
    approach = step_role(routes, route, first) == "approach"
    if box.clearance < need:
        what = "the body's own box (as measured)" if body is not None else \
            "the obstacle box (the request has no measured body to cut it back to)"
        why = (f"the rest state is {1000 * box.clearance:.0f} mm from {what}, within the "
               f"margin {1000 * margin:.0f} mm")
        if box.clearance <= START_SLACK:
            raise PlanningError(f"{why}: no first stretch away from inside it",
                                step=request.step)
        if approach:
            raise PlanningError(f"{why}, in an approach line (it is not left): no first "
                                "stretch away", step=request.step)
    elif approach:
        yield cut, None
        return
    kept = min(margin, box.clearance - START_SLACK)  # the stretch's margin
    whole_away = escape_state(cell, q, box.lo, box.hi, held=held, resting=world.resting,
                              margin=margin, until=whole)
    if whole_away is not None:
        yield replace(whole_request, q=whole_away), _Stretch(whole_away, kept, cut)
    if box.clearance >= need:
        yield cut, None
        return
    away = escape_state(cell, q, box.lo, box.hi, held=held, resting=world.resting,
                        margin=margin)
    if away is not None:
        yield replace(cut, q=away), _Stretch(away, kept, cut)
    elif whole_away is None:
        raise PlanningError(f"{why}, and no first stretch away was found (the distance "
                            "to the box stops growing within the joint limits)",
                            step=request.step)


def _plan_escape(cell: Cell, route: Route, first: int, stretch: _Stretch, world: WorldState,
                 options: PlanOptions) -> Trajectory:
    """The first stretch away from the rest state to ``stretch.to``, keeping
    ``stretch.margin`` [m] from its box (at most the clearance it has at rest): a straight
    TCP line when the robot rests in a line (the contacts allowed where that line began
    hold on it: a vial just lifted off its support), else a free move."""
    own = route.steps[first]
    start = start_pose(route, first) if own.kind == "line" else None
    temp = obstacle_scene(cell, stretch.request, margin=stretch.margin,
                          keep_contacts_of=start, extra_poses={ESCAPE_POSE: stretch.to})
    step = Step("line" if own.kind == "line" else "move", Target(ESCAPE_POSE), None,
                own.speed, own.tcp_speed, True)
    try:
        return plan_route(temp, Route(f"{route.name}{SUFFIX}", REST_POSE, (step,)), options,
                          world=world)
    except SafepathError as exc:
        raise PlanningError(f"the first stretch away from the body "
                            f"({1000 * stretch.margin:.0f} mm from it): {exc}",
                            step=stretch.request.step) from None


def _plan_ways(cell: Cell, routes: Mapping[str, Route], route: Route, first: int,
               in_move: bool, request: ReplanRequest, margin: float, world: WorldState,
               options: PlanOptions) -> tuple[Trajectory, Way]:
    """The first way (:func:`ways`) that plans, from the request's rest state; its
    ``info["replan_failed"]`` lists why the ways before it failed."""
    candidates, limit = ways(cell, routes, route, first, in_move=in_move, q_rest=request.q)
    failed: list[str] = []
    start = start_pose(route, first)
    cells: dict[bool, Cell] = {}  # one per contact set: its checkers are built once
    for way in candidates:
        if way.keeps_line not in cells:
            cells[way.keeps_line] = obstacle_scene(
                cell, request, margin=margin, keep_contacts_of=start if way.keeps_line else None)
        try:
            traj = plan_route(cells[way.keeps_line],
                              Route(f"{route.name}{SUFFIX}", REST_POSE, way.steps), options,
                              world=world)
        except SafepathError as exc:
            failed.append(f"{way.description}: {exc}")
            continue
        traj.info["replan_failed"] = failed
        return traj, way
    why = "; ".join(f"({i + 1}) {f}" for i, f in enumerate(failed))
    if limit is not None:
        why += f"; no other way: {limit}"
    raise PlanningError(f"no way around the obstacle: {why}", step=request.step)


def _corners(center: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, e = np.asarray(center, dtype=float), np.asarray(size, dtype=float)
    return c - e / 2, c + e / 2


def _joined(head: Trajectory, tail: Trajectory, label: str) -> Trajectory:
    """``head`` (the first stretch away, named ``label``) then ``tail``: both rest where
    they meet."""
    if not np.allclose(head.q[-1], tail.q[0], atol=1e-9):
        raise PlanningError("the first stretch away does not end where the way back starts")
    n, t0 = head.t.size, float(head.t[-1])
    info = dict(tail.info)
    info["replan"] = {**info["replan"], "head_duration": t0}
    return Trajectory(tail.joint_names, np.concatenate([head.t, t0 + tail.t[1:] - tail.t[0]]),
                      np.vstack([head.q, tail.q[1:]]), np.vstack([head.qd, tail.qd[1:]]),
                      np.vstack([head.qdd, tail.qdd[1:]]),
                      np.concatenate([np.zeros(n, dtype=int), tail.step_index[1:] + 1]),
                      (label, *tail.steps),
                      tuple(replace(e, time=e.time + t0 - float(tail.t[0]))
                            for e in tail.events),
                      tail.robot, tail.route, info, tail.limits, tail.interpolation)


def _named(traj: Trajectory, labels: Sequence[str]) -> Trajectory:
    """``traj`` (planned for a way) with its steps, its gripper events' steps and its
    pours named ``labels`` (the original route's names, see the module doc)."""
    names = dict(zip(traj.steps, labels, strict=True))
    info = dict(traj.info)
    if "pours" in info:
        info["pours"] = {names.get(k, k): v for k, v in info["pours"].items()}
    return replace(traj, steps=tuple(labels),
                   events=tuple(replace(e, step=names.get(e.step, e.step))
                                for e in traj.events), info=info)
