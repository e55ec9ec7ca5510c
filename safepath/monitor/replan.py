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
from ..planning import PlanOptions, Route, WorldState, load_routes, plan_route
from ..scene import SceneObject, Shape
from ..trajectory import Trajectory
from .monitor import ReplanRequest

__all__ = ["replan", "REST_POSE", "OBSTACLE"]

#: Name of the temporary pose the re-planned route starts from.
REST_POSE = "monitor_rest"
#: Name of the obstacle added to the scene.
OBSTACLE = "monitor_obstacle"


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
    routes = load_routes(cell.folder / "routes.yaml", poses=list(cell.poses),
                         objects=list(cell.scene.objects))
    route = routes.get(route_name)
    if route is None:
        raise PlanningError(f"unknown route '{route_name}'")
    labels = route.labels()
    if request.step not in labels:
        raise PlanningError(f"route '{route_name}' has no step '{request.step}'")
    first = labels.index(request.step)
    rest = Route(f"{route_name}_replanned", REST_POSE, route.steps[first:])
    T = np.eye(4)
    T[:3, 3] = request.obstacle_center
    box = SceneObject(OBSTACLE, Shape("box", tuple(float(v) for v in request.obstacle_size)),
                      T, margin=margin, color=(0.9, 0.2, 0.2))
    scene = replace(cell.scene, objects={**cell.scene.objects, OBSTACLE: box})
    temp = Cell(robot=cell.robot, scene=scene,
                poses={**cell.poses, REST_POSE: np.asarray(request.q, dtype=float)},
                folder=cell.folder, poses_path=cell.poses_path)
    if world is None:
        world = WorldState(held, {o.name: o.T_world_object.copy()
                                  for o in cell.scene.objects.values()
                                  if o.movable and o.name != held})
    return plan_route(temp, rest, options or PlanOptions(), world=world)
