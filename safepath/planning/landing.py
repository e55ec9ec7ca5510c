"""Where a pour lands: the whole opening of the held container, whenever it is tipped past
its spill angle, over the receptacle's opening inside its walls.

What can pour is the content, through the container's opening (its local +z face: the
rim of a cylinder's top, the edge of a box's), once the container is tipped past its
spill angle (:attr:`~safepath.model.scene.SceneObject.spill_angle`, the tilt of its axis from
the vertical at which its content reaches the rim; a container a pour step tilts without
one may spill at any tilt, :data:`~safepath.model.scene.DEFAULT_SPILL_ANGLE`). Up to 90 deg the
content leaves over the rim's lowest part; past it the opening faces down and it may fall
through the whole of it: the check follows every point of the rim. What leaves the rim is
taken to fall straight down (the rim's own horizontal speed is not added).

So at every released sample of a pour step (``tilt``, ``circle``) where the container is
tipped past its spill angle, every rim point must lie, seen from above, inside the
opening of the step's receptacle (``into``: an upright cylinder's disc, an upright box's
rectangle) less its wall (:attr:`~safepath.model.scene.SceneObject.wall`, else
:data:`~safepath.model.scene.DEFAULT_WALL`), and above its top. Two allowances are added to each
rim point's distance: the rim is followed at :data:`RIM_POINTS` points (a point of a
circle between two of them is at most ``2 r sin(pi / 2n)`` from one), and the rim moves
between released samples (a rim point between two is within half its step of one of
them: half the largest step to the samples beside it).
A pour step past the spill angle with no ``into`` pours into nothing. Either is a
:class:`~safepath.errors.PourLandingError` naming the step, the distance and the limit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cell.pour_steps import POUR_KINDS
from ..errors import ConfigError, PourLandingError
from ..model.scene import DEFAULT_SPILL_ANGLE, DEFAULT_WALL

if TYPE_CHECKING:
    from ..cell import Cell
    from ..cell.routes import Route
    from ..model.scene import SceneObject
    from ..model.trajectory import Trajectory

__all__ = ["RIM_POINTS", "check_landing", "rim_points"]

#: Points a circular rim is followed at.
RIM_POINTS = 360


def rim_points(obj: SceneObject) -> tuple[np.ndarray, float]:
    """The rim of a container's opening in its own frame (rows, homogeneous) [m], and
    how far a point of the rim may be from the nearest of them [m].

    Raises:
        ConfigError: A container that is not a cylinder or a box.
    """
    kind, size = obj.shape.kind, obj.shape.size
    if kind == "cylinder":
        radius, top = size[0], size[1] / 2.0
        phi = np.linspace(0.0, 2.0 * math.pi, RIM_POINTS, endpoint=False)
        pts = np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=1)
        sag = 2.0 * radius * math.sin(math.pi / (2 * RIM_POINTS))
    elif kind == "box":
        hx, hy, top = size[0] / 2.0, size[1] / 2.0, size[2] / 2.0
        pts, sag = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]]), 0.0  # convex:
        # the corners are the farthest points
    else:
        raise ConfigError(f"a container that pours is an upright cylinder or box, "
                          f"'{obj.name}' is a {kind}", key=f"objects.{obj.name}")
    ones = np.ones((len(pts), 1))
    return np.hstack([pts, top * ones, ones]), sag


def _opening(cell: Cell, name: str) -> tuple[np.ndarray, str, np.ndarray, float, float]:
    """The receptacle ``name``: its world placement, kind, opening half-sizes inside its
    wall [m], its wall [m] and the height of its top [m].

    Raises:
        ConfigError: Not an upright cylinder or box, or a wall as wide as its opening.
    """
    obj = cell.scene.objects[name]
    T = np.asarray(obj.T_world_object)
    kind, size = obj.shape.kind, obj.shape.size
    path, key = cell.scene.path, f"objects.{name}"
    if kind not in ("cylinder", "box"):
        raise ConfigError(f"a receptacle is an upright cylinder or box, '{name}' is a {kind}",
                          path=path, key=key)
    if abs(T[2, 2]) < 1.0 - 1e-9:
        raise ConfigError(f"a receptacle stands upright, '{name}' does not", path=path, key=key)
    wall = DEFAULT_WALL if obj.wall is None else obj.wall
    half = np.array([size[0]] if kind == "cylinder" else [size[0] / 2, size[1] / 2])
    if wall >= half.min():
        raise ConfigError(f"the wall ({wall * 1000:.1f} mm) leaves '{name}' no opening",
                          path=path, key=key)
    length = size[1] if kind == "cylinder" else size[2]
    return T, kind, half - wall, wall, float(T[2, 3] + length / 2.0)


def _distances(rim: np.ndarray, T: np.ndarray, kind: str, inner: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Per rim point (samples x points x 3, world) [m]: its distance from the
    receptacle's axis (a box's: along the side it overshoots most) and the limit on it."""
    local = (rim - T[:3, 3]) @ T[:3, :3]
    if kind == "cylinder":
        return np.hypot(local[..., 0], local[..., 1]), np.full(local.shape[:-1], inner[0])
    side = np.abs(local[..., :2])
    worst = np.argmax(side - inner, axis=-1)
    return np.take_along_axis(side, worst[..., None], -1)[..., 0], inner[worst]


def _moved(rim: np.ndarray) -> np.ndarray:
    """Per sample (samples x points x 3), half the largest step of a rim point to the
    samples beside it [m]."""
    step = np.zeros(len(rim))
    if len(rim) > 1:
        d = np.linalg.norm(np.diff(rim, axis=0), axis=-1).max(axis=1)
        step[:-1], step[1:] = d, np.maximum(step[1:], d)
    return step / 2.0


def check_landing(cell: Cell, route: Route, traj: Trajectory) -> dict[str, dict[str, Any]]:
    """Check where every pour step of the route can spill (see the module's docstring).

    Returns:
        Per pour step label that tips the container past its spill angle or names a
        receptacle: the receptacle (``into``), the smallest room left between the rim
        and the opening's inner edge (``margin`` [m]), the rim's smallest height above
        the receptacle's top (``height`` [m]) (both None if it never tips past), the
        spill angle [rad] and the time past it [s].

    Raises:
        PourLandingError: A rim point outside the opening or below the top while tipped
            past the spill angle; or tipped past it by a step with no ``into``.
        ConfigError: A receptacle or container of another shape.
    """
    grasp = cell.scene.grasp
    out: dict[str, dict[str, Any]] = {}
    if grasp is None:
        return out
    obj = cell.scene.objects[grasp.object]
    for i, step in enumerate(route.steps):
        rows = np.flatnonzero(np.asarray(traj.step_index) == i)
        if step.kind not in POUR_KINDS or rows.size == 0 or (
                step.into is None and obj.spill_angle is None):
            continue
        out[traj.steps[i]] = _check_step(cell, traj, i, rows, obj, step.into)
    return out


def _check_step(cell: Cell, traj: Trajectory, i: int, rows: np.ndarray, obj: SceneObject,
                into: str | None) -> dict[str, Any]:
    """:func:`check_landing` for step ``i``, on its samples ``rows``."""
    assert cell.scene.grasp is not None  # checked by the caller
    spill = DEFAULT_SPILL_ANGLE if obj.spill_angle is None else obj.spill_angle
    T_world_obj = np.array([cell.robot.frame_pose(q).homogeneous @ cell.scene.grasp.T_tcp_object
                            for q in traj.q[rows]])
    tilt = np.arccos(np.clip(T_world_obj[:, 2, 2], -1.0, 1.0))
    past = tilt > spill
    t = np.asarray(traj.t, dtype=float)
    dt = np.diff(t[rows], append=t[rows[-1]])
    figures: dict[str, Any] = {"into": into, "margin": None, "height": None,
                               "spill_angle": spill, "pouring_time": float(dt[past].sum())}
    if not past.any():
        return figures
    first = int(np.argmax(past))
    if into is None:
        raise PourLandingError(
            f"the held '{obj.name}' tips {math.degrees(float(tilt[first])):.1f} deg, past its "
            f"spill angle {math.degrees(spill):.1f} deg, at t = {t[rows[first]]:.3f} s, and "
            "the step pours into nothing (give it `into`)", step=traj.steps[i],
            receptacle=None, time=float(t[rows[first]]), lip=T_world_obj[first, :3, 3],
            overshoot=float("inf"))
    local, sag = rim_points(obj)
    rim = np.einsum("sij,pj->spi", T_world_obj[:, :3], local)  # samples x points x 3
    T, kind, inner, wall, top = _opening(cell, into)
    distance, limit = _distances(rim, T, kind, inner)
    distance = distance + sag + _moved(rim)[:, None]
    over = np.where(past[:, None], distance - limit, -np.inf)
    below = np.where(past[:, None], top - rim[..., 2], -np.inf)
    k, p = (int(v) for v in np.unravel_index(int(np.argmax(np.maximum(over, below))),
                                              over.shape))
    if max(over[k, p], below[k, p]) > 0.0:
        raise _outside(traj, i, rows, (k, p), rim, (distance, limit, over, below),
                       (into, kind, wall), (past, tilt, spill))
    figures.update(margin=float(-over.max()), height=float(-below.max()))
    return figures


def _outside(traj: Trajectory, i: int, rows: np.ndarray, at: tuple[int, int],
             rim: np.ndarray, measures: tuple[np.ndarray, ...], receptacle: tuple[str, str, float],
             tipped: tuple[np.ndarray, np.ndarray, float]) -> PourLandingError:
    """The error for rim point ``at`` (sample, point) outside the opening or below the
    top."""
    k, p = at
    distance, limit, over, below = measures
    into, kind, wall = receptacle
    past, tilt, spill = tipped
    t = float(traj.t[rows[k]])
    axis = "axis" if kind == "cylinder" else "centre line"
    if over[k, p] >= below[k, p]:
        where = (f"reaches {distance[k, p] * 1000:.1f} mm from the {axis} of '{into}', beyond "
                 f"its opening ({limit[k, p] * 1000:.1f} mm inside its "
                 f"{wall * 1000:.1f} mm wall)")
    else:
        where = f"dips {below[k, p] * 1000:.1f} mm below the top of '{into}'"
    bad = np.maximum(over, below).max(axis=1) > 0.0
    return PourLandingError(
        f"the pour can spill outside '{into}': the container's opening {where} at t = "
        f"{t:.3f} s, tipped {math.degrees(float(tilt[k])):.1f} deg (spill angle "
        f"{math.degrees(spill):.1f} deg; {bad.sum()} of the {past.sum()} samples past it "
        "outside)", step=traj.steps[i], receptacle=into, time=t, lip=rim[k, p],
        overshoot=float(max(over[k, p], below[k, p])), distance=float(distance[k, p]),
        limit=float(limit[k, p]))
