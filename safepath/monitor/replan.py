"""Re-plan around an obstacle that stays: the rest of the route, from where the robot rests.

The obstacle of a :class:`~safepath.monitor.ReplanRequest` (a box around the blocking
elements) is added to the scene with a margin (by default the protective distance the
monitor needs at its lowest speed, so that the new path lets the robot move), the rest
state becomes a temporary pose, and the route's remaining steps (from the one the robot
stopped in) are planned, timed and verified by the library's pipeline
(:func:`safepath.plan_route`: the independent re-check included) like every trajectory.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..cell import Cell
from ..errors import PlanningError
from ..planning import PlanOptions, Route, WorldState, plan_route
from ..scene import SceneObject, Shape
from ..trajectory import Trajectory
from .monitor import ReplanRequest

__all__ = ["replan", "REST_POSE", "OBSTACLE"]

#: Name of the temporary pose the re-planned route starts from.
REST_POSE = "monitor_rest"
#: Name of the obstacle added to the scene.
OBSTACLE = "monitor_obstacle"
#: Suffix of a re-planned route's name.
SUFFIX = "_replanned"


def _start_pose(route: Route, first: int) -> str | None:
    """The taught pose step ``first`` starts from (None: not exactly a taught pose)."""
    pose: str | None = route.start
    for step in route.steps[:first]:
        if step.is_motion and step.target is not None:
            pose = step.target.exact_pose
    return pose


def _step_index(route: Route, label: str) -> int | None:
    """Index of the step ``label`` names: exactly, or (in a re-planned route, whose steps
    are numbered from 0 again) by its text after the number, the last such step."""
    labels = route.labels()
    if label in labels:
        return labels.index(label)
    text = label.split(" ", 1)[-1]
    matches = [i for i, lab in enumerate(labels) if lab.split(" ", 1)[-1] == text]
    return matches[-1] if matches else None


def replan(cell: Cell, route_name: str, request: ReplanRequest, *, held: str | None,
           margin: float, options: PlanOptions | None = None,
           world: WorldState | None = None) -> Trajectory:
    """Plan the rest of route ``route_name`` from the request's rest state around its
    obstacle.

    Args:
        cell: The cell the route belongs to.
        route_name: The route (from the cell's ``routes.yaml``).
        request: The monitor's re-plan request.
        held: Object held at the rest state.
        margin: Clearance the new path keeps from the obstacle box [m].
        options: Planning options.
        world: World state at the rest state (default: the scene's, with ``held``).

    Raises:
        PlanningError: The step is unknown, or no verified path exists around it.
    """
    routes = cell.route_table()
    base = route_name
    while base.endswith(SUFFIX):  # a re-planned route: its steps are the original's tail
        base = base[:-len(SUFFIX)]
    route = routes.get(base)
    if route is None:
        raise PlanningError(f"unknown route '{route_name}'")
    first = _step_index(route, request.step)
    if first is None:
        raise PlanningError(f"route '{base}' has no step '{request.step}'")
    rest = Route(f"{base}{SUFFIX}", REST_POSE, route.steps[first:])
    T = np.eye(4)
    T[:3, 3] = request.obstacle_center
    box = SceneObject(OBSTACLE, Shape("box", tuple(float(v) for v in request.obstacle_size)),
                      T, margin=margin, color=(0.9, 0.2, 0.2))
    # A line leaving a pose keeps that pose's allowed contacts (a vial just lifted off its
    # support): so does its rest from the rest state, on the same line.
    start = _start_pose(route, first)
    contacts = tuple(replace(c, at=(*c.at, REST_POSE))
                     if route.steps[first].kind == "line" and start in c.at else c
                     for c in cell.scene.allowed_contacts)
    scene = replace(cell.scene, objects={**cell.scene.objects, OBSTACLE: box},
                    allowed_contacts=contacts)
    temp = Cell(robot=cell.robot, scene=scene,
                poses={**cell.poses, REST_POSE: np.asarray(request.q, dtype=float)},
                folder=cell.folder, poses_path=cell.poses_path)
    if world is None:
        world = WorldState(held, {o.name: o.T_world_object.copy()
                                  for o in cell.scene.objects.values()
                                  if o.movable and o.name != held})
    return plan_route(temp, rest, options or PlanOptions(), world=world)
