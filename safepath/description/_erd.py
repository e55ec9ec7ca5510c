"""Robots of ``example-robot-data`` as safepath robots.

Gripper joints (fingers, jaws: :func:`safepath.description._joint_roles.gripper_joints`) are locked
joints (the user gives their positions, else their whole travel is covered, see
:func:`safepath.load_robot`); continuous joints are planned as revolute joints without
position limits (:mod:`safepath.description._continuous`); a robot that is not a fixed-base arm of
1-DoF joints (legged robots and humanoids on a floating base) is refused
with :class:`~safepath.errors.RobotNotSupported`, never reduced to the joints that fit;
mesh collision geometry is replaced by its convex hull (which encloses it: a wrapped
non-convex mesh misses contacts); the SRDF's disabled pairs and adjacent links are skipped.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..model._locked import lock_joints, read_mimics
from ..model.controller_spec import read_controller
from ..model.robot import Robot, adjacent_link_pairs
from ._bare_urdf import Given, convexify, vector_argument, velocity_limits_of
from ._continuous import unbound_continuous
from ._joint_roles import gripper_joints, refuse_non_arm, tip_frame

__all__ = ["load_erd"]

log = logging.getLogger(__name__)

# Acceleration limits [rad/s^2] for example-robot-data arms, whose URDFs carry none.
# Panda: Franka Emika's published joint limits. Others: see _default_acceleration.
_KNOWN_ACCELERATION = {
    "panda": [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0],
}


# Jerk limits [rad/s^3]: Franka's published joint limits (libfranka / Franka's robot and
# interface specifications: 7500, 3750, 5000, 6250, 7500, 10000, 10000). Others: derived
# from the acceleration limits (safepath.model.robot.derived_jerk_limits).
_KNOWN_JERK = {
    "panda": [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0],
}


def _default_acceleration(velocity: np.ndarray) -> np.ndarray:
    # No vendor data: assume the arm reaches its top speed in 0.5 s. Conservative for
    # industrial arms; override with load_robot(..., acceleration_limits=...).
    return 2.0 * velocity


def load_erd(name: str, given: Given, *, controller_path: Path | None = None) -> Robot:
    """Load an example-robot-data robot as a safepath :class:`Robot` (arm joints only).

    Args:
        name: The example-robot-data name (``ur5``, ``panda``, ...).
        given: The arguments of :func:`safepath.load_robot`: velocity limits instead of
            the URDF's (required when those are zero), acceleration limits instead of the
            known or default ones, the TCP frame (default: a usual name, else the
            chain's last link), the tool (default: none), gripper joint positions.
        controller_path: A ``controller.yaml`` with its ROS 2 trajectory controller
            (None: settings derived from its joint names).

    Raises:
        RobotNotSupported: Not a fixed-base arm of 1-DoF joints (names them).
        ConfigError: example-robot-data or Pinocchio cannot load it, zero velocity limits.
    """
    from example_robot_data.robots_loader import ROBOTS

    try:
        loader = ROBOTS[name]()
        wrapper = loader.robot
    except (ValueError, RuntimeError, OSError, ImportError) as exc:
        raise ConfigError(f"example-robot-data cannot load '{name}' "
                          f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})",
                          key="robot") from None
    model, geom, visual = wrapper.model, wrapper.collision_model, wrapper.visual_model
    urdf = Path(loader.df_path).resolve() if getattr(loader, "df_path", None) else None
    srdf = getattr(loader, "srdf_path", None)
    mimics = read_mimics(urdf)
    gripper = gripper_joints(model, mimics)
    arm = [str(n) for n in model.names[1:] if n not in gripper]
    hint = (f"; if it is an arm on a fixed base, load its URDF: load_robot('{urdf}', "
            "acceleration_limits=[...])") if urdf else ""
    refuse_non_arm(model, robot=name, path=urdf, planned=arm, hint=hint)
    model, _ = unbound_continuous(model, arm)
    tcp = given.tcp_frame if given.tcp_frame is not None else _guess_tcp(model, name, arm)
    geom = convexify(geom)
    model, (geom, visual), locked = lock_joints(
        model, [geom, visual], arm, given.locked_joints, mimics=mimics, key="locked_joints")
    if gripper:
        log.info("%s: gripper joints %s locked (not planned)", name, gripper)
    pairs = adjacent_link_pairs(model, geom)
    if srdf and Path(srdf).exists():
        pairs += _srdf_disabled_pairs(Path(srdf))
    vel = velocity_limits_of(model, given.velocity_limits, robot=name, path=urdf)
    acc = (vector_argument(given.acceleration_limits, model.nq, key="acceleration_limits")
           if given.acceleration_limits is not None
           else np.array(_KNOWN_ACCELERATION.get(name, _default_acceleration(vel)), dtype=float))
    joints = tuple(model.names[1:])
    controller = read_controller(controller_path, joints) if controller_path else None
    return Robot(name=name, model=model, collision_model=geom, visual_model=visual,
                 velocity_limits=vel, acceleration_limits=acc, tcp_frame=tcp,
                 jerk_limits=_KNOWN_JERK.get(name), tool=given.tool,
                 allowed_self_pairs=pairs, source=None, controller=controller,
                 locked_joints=locked, urdf_path=urdf)


def _srdf_disabled_pairs(path: Path) -> list[tuple[str, str]]:
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"malformed SRDF ({exc})", path=path) from None
    return [(e.get("link1", ""), e.get("link2", "")) for e in root.iter("disable_collisions")]


def _guess_tcp(model: pin.Model, name: str, arm: Sequence[str]) -> str:
    """A frame of a usual TCP name (or one ending in ``end_effector``: Kinova's), else the
    last link of the arm's chain."""
    for candidate in ("panda_hand_tcp", "panda_hand", "tool0", "ee_link", "tcp"):
        if model.existFrame(candidate):
            return candidate
    ends = [str(f.name) for f in model.frames
            if f.type == pin.FrameType.BODY and str(f.name).endswith("end_effector")]
    if len(ends) == 1:
        return ends[0]
    return tip_frame(model, arm, robot=name)
