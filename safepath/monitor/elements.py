"""Observations to world elements: frames, the workspace crop and the scene filter."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..cell import Cell
from ..model.shapes import SHAPES
from .observations import Cloud, Counts, ObservationError, Obstacles, Scan
from .options import MonitorOptions

__all__ = ["OBSTACLES", "SceneArrays", "scene_arrays", "to_elements"]

#: Source name of obstacles from user code.
OBSTACLES = "obstacles"
#: Static scene primitives: kinds (0 box, 1 cylinder, 2 sphere, 3 capsule), placements
#: (k, 4, 4) and dimensions (k, 3) (half sizes; radius, half length; radius).
SceneArrays = tuple[np.ndarray, np.ndarray, np.ndarray]


def to_elements(obs: Any, now: float, o: MonitorOptions, scene: SceneArrays
                ) -> tuple[str, float, np.ndarray, Counts]:
    """An observation as world elements: (source, stamp [s], elements (n, 4), counts).

    Raises:
        ObservationError: Malformed, unknown frame, or a stamp from the future.
    """
    if isinstance(obs, Obstacles):
        source, stamp, E, counts = OBSTACLES, obs.stamp, obs.elements(), Counts()
        counts = replace(counts, used=len(E))
    else:
        if not isinstance(obs, (Scan, Cloud)):
            typename = type(obs).__name__
            if hasattr(obs, "ranges"):
                obs = Scan.from_ros(obs)
            elif hasattr(obs, "fields") and hasattr(obs, "data"):
                obs = Cloud.from_ros(obs)
            else:
                raise ObservationError(f"cannot observe a {typename}", key="observation")
        if obs.frame_id not in o.sensors:
            raise ObservationError(f"unknown frame '{obs.frame_id}' (sensors: "
                                   f"{', '.join(o.sensors) or 'none'})",
                                   key="header.frame_id")
        P, counts = obs.points() if isinstance(obs, Scan) else obs.valid_points()
        T = o.sensors[obs.frame_id]
        W = P @ T[:3, :3].T + T[:3, 3]
        E = np.column_stack([W, np.zeros(len(W))])
        source, stamp = obs.frame_id, obs.stamp
    if stamp > now + o.future_tolerance:
        raise ObservationError(f"stamp {stamp:.3f} s is {stamp - now:.3f} s in the "
                               "future", key="header.stamp")
    E, counts = _filter(E, counts, o, scene)
    return source, stamp, E, counts


def _filter(E: np.ndarray, counts: Counts, o: MonitorOptions, scene: SceneArrays  # noqa: N803
            ) -> tuple[np.ndarray, Counts]:
    """Crop to the workspace and drop elements of the static scene."""
    cropped = 0
    if o.workspace is not None and len(E):
        w = np.asarray(o.workspace)
        inside = np.all((E[:, :3] >= w[:3]) & (E[:, :3] <= w[3:]), axis=1)
        cropped = int((~inside).sum())
        E = E[inside]
    in_scene = 0
    if o.scene_filter is not None and len(E) and scene[0].size:
        from . import _kernels

        d = np.empty(len(E))
        kinds, Ts, dims = scene
        reach = dims.sum(axis=1) + 1e-9  # holds a box, cylinder, capsule, sphere
        within = o.scene_filter + float(E[:, 3].max())
        _kernels.scene_distance(np.ascontiguousarray(E[:, :3]), kinds, Ts, dims, reach,
                                within, d)
        near = d - E[:, 3] <= o.scene_filter
        in_scene = int(near.sum())
        E = E[~near]
    return np.ascontiguousarray(E), replace(counts, used=len(E), scene=in_scene,
                                            cropped=cropped)


def scene_arrays(cell: Cell) -> SceneArrays:
    """Static scene primitives for the scene filter: kinds, placements, dimensions."""
    kinds, Ts, dims = [], [], []
    for obj in cell.scene.objects.values():
        if obj.movable:
            continue
        kind = SHAPES[obj.shape.kind]
        kinds.append(kind.code)
        Ts.append(obj.T_world_object)
        dims.append(kind.half(obj.shape.size))
    return (np.array(kinds, dtype=np.int64), np.array(Ts, dtype=float).reshape(-1, 4, 4),
            np.array(dims, dtype=float).reshape(-1, 3))
