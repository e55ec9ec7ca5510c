"""A robot from a URDF alone (``load_robot("path/to/arm.urdf")``), without a robot folder.

What a URDF says is taken from it: the joints (gripper joints locked, see
:mod:`safepath.description._joint_roles`), the position and velocity limits, the
collision shapes, the links that touch at their joints (never self-checked); mesh shapes
are replaced by their convex hulls (which enclose them), as for example-robot-data's
robots, and ``package://`` meshes are looked for in the folders above the URDF. What it
cannot say must be given as arguments, or the load is refused with a
:class:`ConfigError` naming the key and how to give it: acceleration limits always
(``acceleration_limits=``), velocity limits when the URDF's are zero
(``velocity_limits=``). The TCP is the chain's last link unless ``tcp_frame=`` names
another frame; a tool is given with ``tool=``. For more (a controller, sampled
self-collision pairs) write a robot folder: ``robot.yaml`` next to the URDF.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from ..files._io import check_readable
from ..model._locked import lock_joints, read_mimics
from ..model.robot import Robot, adjacent_link_pairs
from ..model.tool import ToolSpec
from ._continuous import unbound_continuous
from ._joint_roles import gripper_joints, refuse_non_arm, tip_frame

__all__ = ["Given", "convexify", "load_urdf", "vector_argument", "velocity_limits_of"]


@dataclass(frozen=True, kw_only=True)
class Given:
    """What the arguments of :func:`safepath.load_robot` say about a robot described
    without a ``robot.yaml`` (a URDF alone, an example-robot-data name).

    Attributes:
        velocity_limits: Instead of the URDF's [rad/s or m/s].
        acceleration_limits: [rad/s^2] (required for a URDF alone).
        tcp_frame: The TCP frame (default: guessed, see the loaders).
        tool: The tool that holds objects.
        locked_joints: Values of the locked (gripper) joints, see :mod:`safepath.model._locked`.
    """

    velocity_limits: Sequence[float] | None = None
    acceleration_limits: Sequence[float] | None = None
    tcp_frame: str | None = None
    tool: ToolSpec | None = None
    locked_joints: Mapping[str, float | str] | None = None


def vector_argument(values: Sequence[float] | np.ndarray, n: int, *, key: str) -> np.ndarray:
    """``n`` finite positive values given as an argument of :func:`safepath.load_robot`.

    Raises:
        ConfigError: Another count, a value not finite or not positive (names ``key``).
    """
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"expected {n} numbers, got {values!r}", key=key) from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ConfigError(f"need {n} finite positive values, got {arr.tolist()}", key=key)
    return arr


def velocity_limits_of(model: pin.Model, override: Sequence[float] | None, *, robot: str,
                       path: Path | None) -> np.ndarray:
    """The velocity limits [rad/s or m/s]: ``override``, else the URDF's.

    Raises:
        ConfigError: The URDF gives a joint no positive velocity limit and none is given
            (names the joints and the ``velocity_limits=`` argument).
    """
    if override is not None:
        return vector_argument(override, model.nq, key="velocity_limits")
    vel = np.array(model.velocityLimit, dtype=float)
    names = [str(n) for n in model.names[1:]]
    bad = [j for j in range(model.nq) if not (np.isfinite(vel[j]) and vel[j] > 0)]
    if bad:
        raise ConfigError(
            f"the URDF gives {[names[j] for j in bad]} no velocity limit (<limit velocity>: "
            f"{[float(vel[j]) for j in bad]}): give them with "
            f"load_robot({robot!r}, velocity_limits=[...]) [rad/s], {model.nq} values in "
            f"the order {names}", path=path, key="velocity_limits")
    return vel


def load_urdf(urdf: Path, given: Given) -> Robot:
    """A robot from ``urdf`` and the arguments ``given`` (see the module doc).

    Raises:
        ConfigError: A URDF Pinocchio cannot read, a missing mesh, missing acceleration
            limits, zero velocity limits (each names the key and how to give it).
        RobotNotSupported: A floating base, multi-DoF joints, a branching
            robot without ``tcp_frame``.
    """
    # ``package://NAME/...`` meshes are looked for in the folders above the URDF (the
    # URDF of a ROS package lies inside it).
    packages = [str(folder) for folder in urdf.resolve().parents]
    check_readable(urdf)
    try:
        full = pin.buildModelFromUrdf(str(urdf))
        geom = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.COLLISION,
                                     package_dirs=packages)
        visual = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.VISUAL,
                                       package_dirs=packages)
    except (ValueError, RuntimeError, OSError) as exc:
        raise ConfigError(f"cannot load URDF ({str(exc).splitlines()[0]})", path=urdf) from None
    name = str(full.name) or urdf.stem
    geom = convexify(geom)
    mimics = read_mimics(urdf)
    gripper = gripper_joints(full, mimics)
    arm = [str(n) for n in full.names[1:] if n not in gripper]
    refuse_non_arm(full, robot=name, path=urdf, planned=arm)
    full, _ = unbound_continuous(full, arm)
    tcp = given.tcp_frame if given.tcp_frame is not None \
        else tip_frame(full, arm, robot=name, path=urdf)
    model, (geom, visual), locked = lock_joints(full, [geom, visual], arm, given.locked_joints,
                                                mimics=mimics, path=urdf)
    vel = velocity_limits_of(model, given.velocity_limits, robot=str(urdf), path=urdf)
    if given.acceleration_limits is None:
        raise ConfigError(
            f"a URDF carries no acceleration limits: give them with load_robot({str(urdf)!r}, "
            f"acceleration_limits=[...]) [rad/s^2], {model.nq} values in the order "
            f"{list(model.names[1:])}, or write a robot folder (robot.yaml with "
            "acceleration_limits, see docs/your_own_robot_and_cell.md)", path=urdf,
            key="acceleration_limits")
    acc = vector_argument(given.acceleration_limits, model.nq, key="acceleration_limits")
    return Robot(name=name, model=model, collision_model=geom, visual_model=visual,
                 velocity_limits=vel, acceleration_limits=acc, tcp_frame=tcp, tool=given.tool,
                 allowed_self_pairs=adjacent_link_pairs(model, geom), source=urdf,
                 urdf_path=urdf, locked_joints=locked)


def convexify(geom: pin.GeometryModel) -> pin.GeometryModel:
    """Replace mesh geometry by its convex hull, which encloses it (never misses a contact)."""
    import coal

    for g in geom.geometryObjects:
        shape = g.geometry
        if isinstance(shape, coal.BVHModelBase):
            shape.buildConvexHull(True, "Qt")
            g.geometry = shape.convex
    return geom
