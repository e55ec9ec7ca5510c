"""Robots of ``example-robot-data`` as safepath robots.

Fingers are locked joints (the user gives their positions, else their whole travel is
covered, see :func:`safepath.load_robot`); joints of more than one DoF are locked at the
reference posture; mesh collision
geometry is replaced by its convex hull (which encloses it: a wrapped non-convex mesh
misses contacts); the SRDF's disabled pairs and adjacent links are skipped.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pinocchio as pin

from ._locked import lock_joints, read_mimics
from .errors import ConfigError
from .robot import Robot, adjacent_link_pairs
from .trajectory_controller import read_controller

__all__ = ["load_erd"]

# Acceleration limits [rad/s^2] for example-robot-data arms, whose URDFs carry none.
# Panda: Franka Emika's published joint limits. Others: see _default_acceleration.
_KNOWN_ACCELERATION = {
    "panda": [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0],
}


def _default_acceleration(velocity: np.ndarray) -> np.ndarray:
    # No vendor data: assume the arm reaches its top speed in 0.5 s. Conservative for
    # industrial arms; override with load_robot(..., acceleration_limits=...).
    return 2.0 * velocity


def load_erd(name: str, *, controller_path: Path | None = None,
             locked_joints: Mapping[str, float | str] | None = None) -> Robot:
    """Load an example-robot-data robot as a safepath :class:`Robot` (arm joints only).

    Args:
        name: The example-robot-data name (``ur5``, ``panda``, ...).
        controller_path: A ``controller.yaml`` with its ROS 2 trajectory controller
            (None: settings derived from its joint names).
        locked_joints: Finger positions (see :func:`safepath.load_robot`).
    """
    import example_robot_data as erd
    from example_robot_data.robots_loader import ROBOTS

    loader = ROBOTS[name]()
    wrapper = loader.robot
    model, geom, visual = wrapper.model, wrapper.collision_model, wrapper.visual_model
    srdf = getattr(loader, "srdf_path", None)
    # Joints of more than one DoF: locked at the neutral posture.
    lock = [j for j in range(1, model.njoints) if model.joints[j].nq != 1]
    if lock:
        model, (geom, visual) = pin.buildReducedModel(model, [geom, visual], lock,
                                                      pin.neutral(model))
    geom = _convexify(geom)
    # Fingers: locked where the user says (whole travel if not said).
    arm = [n for n in model.names[1:] if "finger" not in n]
    model, (geom, visual), locked = lock_joints(
        model, [geom, visual], arm, locked_joints,
        mimics=read_mimics(getattr(loader, "df_path", None)), key="locked_joints")
    pairs = adjacent_link_pairs(model, geom)
    if srdf and Path(srdf).exists():
        pairs += _srdf_disabled_pairs(Path(srdf))
    vel = np.array(model.velocityLimit, dtype=float)
    acc = np.array(_KNOWN_ACCELERATION.get(name, _default_acceleration(vel)), dtype=float)
    tcp = _guess_tcp(model, name)
    del erd
    joints = tuple(model.names[1:])
    controller = read_controller(controller_path, joints) if controller_path else None
    return Robot(name=name, model=model, collision_model=geom, visual_model=visual,
                 velocity_limits=vel, acceleration_limits=acc, tcp_frame=tcp,
                 allowed_self_pairs=pairs, source=None, controller=controller,
                 locked_joints=locked,
                 urdf_path=Path(loader.df_path) if getattr(loader, "df_path", None) else None)


def _convexify(geom: pin.GeometryModel) -> pin.GeometryModel:
    """Replace mesh geometry by its convex hull, which encloses it (never misses a contact)."""
    import coal

    for g in geom.geometryObjects:
        shape = g.geometry
        if isinstance(shape, coal.BVHModelBase):
            shape.buildConvexHull(True, "Qt")
            g.geometry = shape.convex
    return geom


def _srdf_disabled_pairs(path: Path) -> list[tuple[str, str]]:
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"malformed SRDF ({exc})", path=path) from None
    return [(e.get("link1", ""), e.get("link2", "")) for e in root.iter("disable_collisions")]


def _guess_tcp(model: pin.Model, name: str) -> str:
    for candidate in ("panda_hand_tcp", "panda_hand", "tool0", "ee_link", "tcp"):
        if model.existFrame(candidate):
            return candidate
    return str(model.frames[len(model.frames) - 1].name)
