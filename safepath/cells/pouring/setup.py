"""A gravimetric pour from parameters: what ``examples/ros2/pour_node.py`` reads and builds.

:class:`PourParameters` are the node's ROS parameters (every one checked where it enters,
a typed error naming it); :func:`build_pour` plans the tilt (and the pick and place routes,
if named) and returns the :class:`~safepath.cells.pouring.controller.PourController` that runs
it. Nothing here knows a robot or a cell: the scene folder names its robot, whose
``controller.yaml`` names the actions; the tilt (axis, angle, pivot) is the cell's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import InputError
from ...files._io import check_keys
from ...model.trajectory import GripperEvent, Trajectory

if TYPE_CHECKING:
    from ...cell import Cell
    from ...planning.pour import PourMotion
    from .controller import PourController

__all__ = ["PourParameters", "PourSetup", "build_pour"]

_VECTORS = ("tilt_axis", "pivot_offset")
_NAMES = ("robot", "scene", "pour_pose", "pick_route", "place_route", "weight_topic")


@dataclass(frozen=True, kw_only=True)
class PourParameters:
    """The pour node's parameters.

    Attributes:
        robot: The robot the scene must hold (its ``controller.yaml`` names the actions).
        scene: The cell's folder (or a bundled scene's name).
        pour_pose: The cell's pose where the tilt starts (cup upright above the bowl).
        tilt_axis: Axis the cup turns about, in the world frame (normalised here).
        tilt_angle: Tilt at the end of the pour motion [rad].
        pivot_offset: The cup's lip from the TCP at ``pour_pose``, in the world [m].
        tilt_speed: Bound on the cup's angular speed while pouring [rad/s].
        return_speed: Bound on its angular speed on the way back [rad/s].
        target: Mass to pour [g].
        weight_topic: The scale's topic (``std_msgs/Float32`` [g]).
        scale_latency: The scale's reading delay [s].
        fall_time: Time from the lip to the bowl [s].
        spill_angle: Tilt at which material starts to leave the cup [rad].
        stop_lead: Time from a decision to the start of braking [s].
        weight_timeout: Longest gap between readings while pouring [s].
        pick_route: Route of the scene run before the pour ("" for none).
        place_route: Route run after the return upright ("" for none).
    """

    robot: str
    scene: str
    pour_pose: str
    tilt_axis: tuple[float, float, float]
    tilt_angle: float
    pivot_offset: tuple[float, float, float]
    tilt_speed: float = math.radians(5.0)
    return_speed: float = math.radians(30.0)
    target: float = 100.0
    weight_topic: str = "/weight"
    scale_latency: float = 0.1
    fall_time: float = 0.15
    spill_angle: float = math.radians(70.0)
    stop_lead: float = 0.05
    weight_timeout: float = 0.5
    pick_route: str = ""
    place_route: str = ""

    def __post_init__(self) -> None:
        for name in _NAMES:
            value = getattr(self, name)
            optional = name in ("pick_route", "place_route")
            if not isinstance(value, str) or (not value and not optional):
                raise InputError(f"expected a{'' if optional else ' non-empty'} string, got "
                                 f"{value!r}", key=name)
        for name in _VECTORS:
            raw = getattr(self, name)
            if isinstance(raw, (str, bytes)) or not hasattr(raw, "__len__") or len(raw) != 3 \
                    or not all(_number(v) for v in raw):
                raise InputError(f"expected 3 finite numbers, got {raw!r}", key=name)
            object.__setattr__(self, name, tuple(float(v) for v in raw))
        if not float(np.linalg.norm(self.tilt_axis)) > 1e-9:
            raise InputError("the axis must not be zero", key="tilt_axis")
        for f in fields(self):
            if f.name in _NAMES or f.name in _VECTORS:
                continue
            value = getattr(self, f.name)
            if not _number(value) or value <= 0:
                raise InputError(f"expected a finite number > 0, got {value!r}", key=f.name)
        if not self.tilt_angle < math.pi:
            raise InputError(f"expected a tilt below pi rad, got {self.tilt_angle}",
                             key="tilt_angle")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> PourParameters:
        """From a mapping (a params file's ``ros__parameters``); unknown keys refused.

        Raises:
            InputError: An unknown or missing key, or a bad value (naming the key).
        """
        known = [f.name for f in fields(cls)]
        check_keys(values, known, path=None, error=InputError)
        for f in fields(cls):
            if f.name not in values and f.default is MISSING:
                raise InputError("missing parameter", key=f.name)
        return cls(**{k: v for k, v in values.items()})


@dataclass(frozen=True)
class PourSetup:
    """What :func:`build_pour` made.

    Attributes:
        cell: The cell.
        tilt: The planned, verified tilt.
        controller: The pour's controller.
        before: Steps before the pour (the pick route split at its gripper events).
        after: Steps after the return upright (the place route).
        routes: The planned pick and place routes, whole (with their gripper events).
    """

    cell: Cell
    tilt: PourMotion
    controller: PourController
    before: tuple[Trajectory | GripperEvent, ...]
    after: tuple[Trajectory | GripperEvent, ...]
    routes: Mapping[str, Trajectory]


def build_pour(params: PourParameters) -> PourSetup:
    """Load the cell, plan the tilt (and the named routes) and build the controller.

    Raises:
        InputError: The scene's robot is not ``params.robot``; an unknown pose or route.
        SafepathError: Planning failed (IK, timing, verification).
    """
    import pinocchio as pin

    from ...cell import load_cell
    from ...planning.pour import PourOptions, plan_tilt
    from ...planning.route_planner import plan_cell
    from ...ros.goals import split_at_gripper_events
    from .controller import PourController, PourControllerOptions
    from .flow import FlowModel

    cell = load_cell(params.scene)
    if cell.robot.name != params.robot:
        raise InputError(f"scene '{params.scene}' holds robot '{cell.robot.name}', not "
                         f"'{params.robot}'", key="robot")
    q0 = cell.pose(params.pour_pose)
    T0 = cell.robot.frame_pose(q0)
    axis = np.asarray(params.tilt_axis) / np.linalg.norm(params.tilt_axis)
    R1 = pin.exp3(axis * params.tilt_angle) @ T0.rotation
    tilt = plan_tilt(cell, q0, R1, T0.translation + np.asarray(params.pivot_offset),
                     options=PourOptions(max_angular_speed=params.tilt_speed))
    names = [r for r in (params.pick_route, params.place_route) if r]
    table = cell.route_table() if names else {}
    for key, name in (("pick_route", params.pick_route), ("place_route", params.place_route)):
        if name and name not in table:
            raise InputError(f"the scene has no route '{name}' (known: {', '.join(table)})",
                             key=key)
    planned = plan_cell(cell, routes={n: table[n] for n in names}) if names else {}
    before = tuple(split_at_gripper_events(planned[params.pick_route])) \
        if params.pick_route else ()
    after = tuple(split_at_gripper_events(planned[params.place_route])) \
        if params.place_route else ()
    flow = FlowModel(latency=params.scale_latency, fall_time=params.fall_time,
                     spill_angle=params.spill_angle)
    options = PourControllerOptions(target=params.target, stop_lead=params.stop_lead,
                                    weight_timeout=params.weight_timeout)
    controller = PourController(cell, tilt, flow, options=options, before=before,
                                after=after, return_angular_speed=params.return_speed)
    return PourSetup(cell, tilt, controller, before, after, planned)


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)
