"""Path constraints of the held object, checked on the released samples like collisions.

A route step with ``max_tilt`` keeps the held object upright: at every timed sample of
that step the angle between the object's axis (its local z, carried by the grasp) and
the world's vertical stays at or below the bound. The check runs on the trajectory the
planner is about to release; a sample over the bound is a
:class:`~safepath.errors.PlanningError` naming the step, the time and the angle.

Where a pour lands is :mod:`safepath.planning.landing`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ConfigError, PlanningError

if TYPE_CHECKING:
    from ..cell import Cell
    from ..cell.routes import Route
    from ..model.trajectory import Trajectory

__all__ = ["tilt_profile", "check_tilt", "tilt_bound"]


def tilt_profile(cell: Cell, q: np.ndarray) -> np.ndarray:
    """Angle between the grasped object's axis and the vertical at each row of ``q`` [rad]."""
    grasp = cell.scene.grasp
    if grasp is None:
        raise ConfigError("max_tilt needs the scene's grasp (the object's axis)",
                          path=cell.scene.path, key="grasp")
    axis = np.asarray(grasp.T_tcp_object[:3, 2], dtype=float)
    up = np.array([cell.robot.frame_pose(qk).rotation @ axis for qk in np.atleast_2d(q)])
    return np.arccos(np.clip(up[:, 2], -1.0, 1.0))


def check_tilt(cell: Cell, route: Route, traj: Trajectory) -> float:
    """Check every step's ``max_tilt`` on the trajectory's samples.

    Returns:
        The largest tilt over the constrained samples [rad] (0 if none is constrained).

    Raises:
        PlanningError: A sample of a constrained step tilts more than its bound.
    """
    bounds = np.array([s.max_tilt if s.max_tilt is not None else np.inf for s in route.steps])
    if not np.isfinite(bounds).any():
        return 0.0
    limit = bounds[traj.step_index]
    rows = np.flatnonzero(np.isfinite(limit))
    tilt = tilt_profile(cell, traj.q[rows])
    over = tilt > limit[rows]
    if over.any():
        first = int(np.argmax(over))
        k = int(rows[first])
        i = int(traj.step_index[k])
        raise PlanningError(f"the held object tilts {math.degrees(float(tilt[first])):.2f}"
                            f" deg at t = {traj.t[k]:.3f} s, more than max_tilt "
                            f"{math.degrees(float(bounds[i])):.2f} deg", step=traj.steps[i])
    return float(tilt.max())


def tilt_bound(route: Route) -> float | None:
    """The smallest ``max_tilt`` of the route's steps [rad], or None if none has one."""
    bounds = [s.max_tilt for s in route.steps if s.max_tilt is not None]
    return min(bounds) if bounds else None
