"""Whether the routes' inverse-kinematics targets can be reached, without planning.

``safepath check`` checks the taught poses; a route's TCP targets (a TCP pose, a pose
plus an offset, ``up:``) are only solved when the route is planned. :func:`check_targets`
solves each of them as the planner will (the same seed: the pose the robot is at after
the step before), so a target out of reach is reported by ``check`` rather than by
``plan``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cell import Cell
from ..cell.routes import Route
from ..errors import IKError
from .options import PlanOptions
from .route_planner import _resolve

__all__ = ["UnreachableTarget", "check_targets"]


@dataclass(frozen=True)
class UnreachableTarget:
    """A motion step whose target inverse kinematics does not reach.

    Attributes:
        route: Route name.
        step: The step's label (index, kind and target).
        error: Why, naming the routes file, route and step.
    """

    route: str
    step: str
    error: IKError


def check_targets(cell: Cell, routes: Mapping[str, Route], options: PlanOptions | None = None,
                  *, path: str | Path | None = None) -> list[UnreachableTarget]:
    """The targets of ``routes`` that inverse kinematics cannot reach (empty: all reach).

    Every motion step not going exactly to a taught pose is solved from the pose the robot
    is at after the step before, as :func:`~safepath.planning.plan_route` solves it. After
    a pour (``tilt`` / ``circle``), where the robot is is only known once the pour is
    planned: the route's remaining targets relative to the TCP are not checked (TCP poses
    and poses with an offset still are, seeded from their pose or the pour's start).

    Args:
        cell: The cell.
        routes: The routes to check.
        options: Planning options (their ``line`` options drive the solver).
        path: The routes file, named in the errors.
    """
    options = options or PlanOptions()
    out = []
    for route in routes.values():
        labels = route.labels()
        q: np.ndarray = cell.pose(route.start)
        known = True  # whether q is where the robot is
        for i, step in enumerate(route.steps):
            if step.kind in ("tilt", "circle"):
                known = False
                continue
            if not step.is_motion or step.target is None:
                continue
            target = step.target
            if target.exact_pose is not None:
                q, known = cell.pose(target.exact_pose), True
                continue
            if target.pose is None and target.cartesian is None and not known:
                continue  # relative to a TCP the pour leaves somewhere not yet planned
            try:
                q, _ = _resolve(cell, step, q, labels[i], options)
            except IKError as exc:
                exc.in_route(route.name, path)
                out.append(UnreachableTarget(route.name, labels[i], exc))
                break  # the steps after it start from nowhere
            known = True
    return out
