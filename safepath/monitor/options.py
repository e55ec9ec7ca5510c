"""Options of the separation monitor (the protective-distance parameters among them)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["MonitorOptions"]


def _positive(name: str, value: float, *, zero: bool = False) -> None:
    ok = math.isfinite(value) and (value >= 0 if zero else value > 0)
    if not ok:
        raise ConfigError(f"must be {'>= 0' if zero else '> 0'} and finite, got {value}",
                          key=name)


@dataclass(frozen=True, kw_only=True)
class MonitorOptions:
    """How the monitor measures, decides and re-times.

    Protective separation distance (ISO/TS 15066 speed and separation monitoring,
    section 5.5.4)::

        S_p = v_h * (T_age + T_cmd + T_next + T_s) + C + Z_d + Z_r

    compared with the separation between the observed elements and every state the
    robot can occupy until it is at rest (see :mod:`safepath.monitor.monitor`).

    Attributes:
        sensors: World pose (4x4) of every sensor frame, by ``frame_id``; each one must
            keep reporting (silence for ``stale_after`` stops the robot).
        approach_speed: ``v_h``, how fast a person approaches [m/s] (ISO 13855: 1.6 for
            the body, 2.0 for a hand reaching).
        min_separation: ``C``, the separation never to be crossed [m] (ISO's intrusion
            distance belongs here for sensors that cannot see a reaching hand).
        sensor_uncertainty: ``Z_d``, position uncertainty of observed points [m].
        robot_uncertainty: ``Z_r``, position uncertainty of the robot [m].
        stale_after: ``T_next``: an observation older than this is stale; without a
            fresh one from every sensor the robot stops [s]. The next decision comes at
            most this late, so the robot may keep its timing this long.
        command_latency: ``T_cmd``, from a decision to the controller acting on it [s].
        hold_time: The area must stay clear this long before the robot speeds up [s].
        replan_after: Stopped by an obstacle this long: ask for a re-plan [s] (once the
            obstacle is at rest: see ``rest_speed``).
        min_scale: Below this speed scale the robot stops instead of crawling.
        scale_step: Speed scales are multiples of this (fewer replacement goals).
        horizon: Look-ahead of the reported path separation [s of motion].
        sweep_spacing: Largest robot motion between sampled path states [m].
        sphere_cell: Cell of the robot's enclosing spheres [m].
        cell_size: Cell of the observed elements' buckets [m].
        range_cap: Separations beyond this are not refined (reported as inf) [m].
        scene_filter: Elements within this of a static scene object belong to the
            scene and are ignored [m]; None keeps them all.
        self_filter: Elements within this of the robot's enclosing spheres, at the states
            it passed since the observation was captured, are the robot's own and
            ignored [m]; None (default) keeps them. Anything that close to the arm is
            then invisible: use it only for sensors that see the arm.
        workspace: Axis-aligned box (xmin, ymin, zmin, xmax, ymax, zmax) [m] outside
            which elements are ignored; None keeps them all.
        future_tolerance: Stamps later than now by more than this are refused [s].
        replan_cluster: Link distance of a body [m]: the elements linked to the blocking
            one (grid cells of half this edge that touch, in a chain) form the body a
            re-plan goes around, and an element this close to a parked body's belongs to
            it (:mod:`safepath.monitor.parked`).
        rest_speed: A body is re-planned around only at rest: the least-squares velocity
            of its centroid and of each side of its box, over the observations of the
            last ``rest_window``, at most this [m/s] (and no side of its latest box
            more than ``REPLAN_MOVED`` from the window's median).
        rest_window: How long a body must be seen at rest before a re-plan [s].
        parked_speed: How fast a body re-planned around (parked, at rest) can start to
            move [m/s]: its elements stay in the protective-distance test with this
            ``v_h``. None (default): ``approach_speed``; a person standing still may
            walk off at once, so the arm keeps the same protective distance from a
            parked body as from any other, and a re-plan only changes the path. Set it
            lower only for bodies that cannot move faster (objects that nobody carries
            or that only a slow conveyor moves): the guarantee holds under that
            assumption.
    """

    sensors: Mapping[str, Any] = field(default_factory=dict)
    approach_speed: float = 1.6
    min_separation: float = 0.05
    sensor_uncertainty: float = 0.02
    robot_uncertainty: float = 0.005
    stale_after: float = 0.15
    command_latency: float = 0.02
    hold_time: float = 1.0
    replan_after: float = 2.0
    min_scale: float = 0.1
    scale_step: float = 0.05
    horizon: float = 1.0
    sweep_spacing: float = 0.02
    sphere_cell: float = 0.04
    cell_size: float = 0.05
    range_cap: float = 3.0
    scene_filter: float | None = 0.02
    self_filter: float | None = None
    workspace: tuple[float, float, float, float, float, float] | None = None
    future_tolerance: float = 0.05
    replan_cluster: float = 0.1
    rest_speed: float = 0.02
    rest_window: float = 1.0
    parked_speed: float | None = None

    def __post_init__(self) -> None:
        sensors = {}
        for name, T in dict(self.sensors).items():
            M = np.asarray(T, dtype=float)
            if M.shape != (4, 4) or not np.all(np.isfinite(M)) or \
                    not np.allclose(M[:3, :3] @ M[:3, :3].T, np.eye(3), atol=1e-6):
                raise ConfigError("a sensor pose must be a finite 4x4 rigid transform",
                                  key=f"sensors.{name}")
            sensors[str(name)] = M
        object.__setattr__(self, "sensors", sensors)
        for name in ("approach_speed", "stale_after", "horizon", "sweep_spacing",
                     "sphere_cell", "cell_size", "range_cap", "scale_step", "replan_cluster",
                     "rest_speed", "rest_window"):
            _positive(name, float(getattr(self, name)))
        for name in ("min_separation", "sensor_uncertainty", "robot_uncertainty",
                     "command_latency", "hold_time", "replan_after", "future_tolerance"):
            _positive(name, float(getattr(self, name)), zero=True)
        if not 0 < self.min_scale <= 1:
            raise ConfigError(f"must lie in (0, 1], got {self.min_scale}", key="min_scale")
        if self.parked_speed is not None:
            _positive("parked_speed", float(self.parked_speed), zero=True)
        if self.scene_filter is not None:
            _positive("scene_filter", float(self.scene_filter), zero=True)
        if self.self_filter is not None:
            _positive("self_filter", float(self.self_filter), zero=True)
        if self.workspace is not None:
            w = np.asarray(self.workspace, dtype=float)
            if w.shape != (6,) or not np.all(np.isfinite(w)) or np.any(w[:3] >= w[3:]):
                raise ConfigError("workspace is (xmin, ymin, zmin, xmax, ymax, zmax) with "
                                  "min < max", key="workspace")

    @property
    def parked_approach_speed(self) -> float:
        """``v_h`` of parked bodies [m/s] (``parked_speed``, else ``approach_speed``)."""
        return self.approach_speed if self.parked_speed is None else float(
            min(self.parked_speed, self.approach_speed))

    @property
    def constant_terms(self) -> float:
        """``C + Z_d + Z_r`` [m]."""
        return self.min_separation + self.sensor_uncertainty + self.robot_uncertainty
