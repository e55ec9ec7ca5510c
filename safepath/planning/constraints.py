"""Path constraints of the held object, checked on the released samples like collisions.

A route step with ``max_tilt`` keeps the held object upright: at every timed sample of
that step the angle between the object's axis (its local z, carried by the grasp) and
the world's vertical stays at or below the bound. The check runs on the trajectory the
planner is about to release; a sample over the bound is a
:class:`~safepath.errors.PlanningError` naming the step, the time and the angle.

A pour step with ``into`` lands in its receptacle: at every timed sample of the step the
cup's pouring lip (the tilt's ``pivot``, a point of the cup given in the TCP frame; a
circle carries the pivot of its tilt) lies above the receptacle's top and, seen from
above, inside its opening (a vertical cylinder's disc, an upright box's rectangle). What
leaves the lip falls straight down into it. A sample outside is a
:class:`~safepath.errors.PourLandingError` naming the step, the receptacle, the time and
how far outside.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError, PlanningError, PourLandingError

if TYPE_CHECKING:
    from ..cell import Cell
    from ..routes import Route
    from ..trajectory import Trajectory

__all__ = ["tilt_profile", "check_tilt", "tilt_bound", "check_landing"]


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


def _lip_of(route: Route, i: int) -> np.ndarray | None:
    """The pouring lip of pour step ``i`` in the TCP frame [m]: its tilt's pivot."""
    from ..pour_steps import Tilt

    for step in (route.steps[i], route.steps[i - 1] if i > 0 else None):
        if step is not None and isinstance(step.pour, Tilt):
            return np.asarray(step.pour.pivot, dtype=float)
    return None


def _outside(cell: Cell, name: str, lip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each lip position [m] (rows, world frame): how far it is outside the opening
    of the receptacle ``name`` seen from above (<= 0: inside) and its height above the
    receptacle's top [m]."""
    obj = cell.scene.objects[name]
    T = np.asarray(obj.T_world_object)
    kind, size = obj.shape.kind, obj.shape.size
    if kind not in ("cylinder", "box"):
        raise ConfigError(f"a receptacle is an upright cylinder or box, '{name}' is a {kind}",
                          path=cell.scene.path, key=f"objects.{name}")
    if abs(T[2, 2]) < 1.0 - 1e-9:
        raise ConfigError(f"a receptacle stands upright, '{name}' does not",
                          path=cell.scene.path, key=f"objects.{name}")
    local = (lip - T[:3, 3]) @ T[:3, :3]  # in the object's frame
    if kind == "cylinder":
        length = size[1]
        side = np.hypot(local[:, 0], local[:, 1]) - size[0]
    else:
        length = size[2]
        side = np.max(np.abs(local[:, :2]) - np.asarray(size[:2]) / 2.0, axis=1)
    return side, lip[:, 2] - float(T[2, 3] + length / 2.0)


def check_landing(cell: Cell, route: Route, traj: Trajectory) -> dict[str, dict[str, Any]]:
    """Check every pour step's ``into`` on the trajectory's samples.

    Returns:
        Per constrained step label: the receptacle (``into``), the smallest distance of
        the lip inside the opening's edge seen from above (``margin`` [m]) and its
        smallest height above the receptacle's top (``height`` [m]).

    Raises:
        PourLandingError: A sample of a constrained step has its lip outside the
            receptacle's opening or not above its top.
        ConfigError: The receptacle is not an upright cylinder or box.
    """
    out: dict[str, dict[str, Any]] = {}
    for i, step in enumerate(route.steps):
        if step.into is None:
            continue
        lip_tcp = _lip_of(route, i)
        rows = np.flatnonzero(np.asarray(traj.step_index) == i)
        if lip_tcp is None or rows.size == 0:
            continue
        poses = [cell.robot.frame_pose(q).homogeneous for q in traj.q[rows]]
        lip = np.array([T[:3, :3] @ lip_tcp + T[:3, 3] for T in poses])
        side, height = _outside(cell, step.into, lip)
        outside = np.maximum(side, -height)
        worst = int(np.argmax(outside))
        if outside[worst] > 0.0:
            k = int(rows[worst])
            where = (f"{side[worst] * 1000:.1f} mm outside its opening" if side[worst] > 0
                     else f"{-height[worst] * 1000:.1f} mm below its top")
            raise PourLandingError(
                f"the pour lands outside '{step.into}': the cup's lip is {where} at "
                f"t = {traj.t[k]:.3f} s ({np.mean(outside > 0.0):.0%} of the step's samples "
                "outside)", step=traj.steps[i], receptacle=step.into, time=float(traj.t[k]),
                lip=lip[worst], overshoot=float(outside[worst]))
        out[traj.steps[i]] = {"into": step.into, "margin": float(-side.max()),
                              "height": float(height.min())}
    return out
