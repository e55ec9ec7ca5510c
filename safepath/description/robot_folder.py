"""Loading robots: by name (a bundled folder or an ``example-robot-data`` arm) or folder.

A robot folder (see ``robots/ned3pro``) holds a URDF with primitive collision shapes,
a ``robot.yaml`` with what a URDF cannot say (velocity and acceleration limits, the
TCP frame, the tool), the computed list of link pairs that never need checking, and
optionally a ``controller.yaml`` (its ROS 2 trajectory controller, see
:mod:`safepath.model.controller_spec`). Robots of ``example-robot-data`` (``ur5``,
``panda``, ...) load by name too; a bundled folder of the same name that holds only a
``controller.yaml`` adds their controller settings. A URDF file loads alone too
(:mod:`safepath.description._bare_urdf`), with the limits it lacks given as arguments.
"""

from __future__ import annotations

import copyreg
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError, FrameNotFound, RobotNotFound
from ..files._io import as_str, as_vector, check_readable, get_key, read_mapping, read_yaml
from ..files._paths import ROBOTS_DIR
from ..model._locked import TRAVEL, lock_joints, read_mimics
from ..model.controller_spec import FILE_NAME as CONTROLLER_FILE
from ..model.controller_spec import ControllerSpec, read_controller
from ..model.robot import Robot, adjacent_link_pairs, frame_id
from ..model.tool import ToolSpec, check_tool, read_tool
from ._bare_urdf import Given, vector_argument
from ._continuous import unbound_continuous
from ._joint_roles import refuse_non_arm

__all__ = ["ROBOTS_DIR", "load_robot", "robot_names"]

log = logging.getLogger(__name__)

_ROBOT_KEYS = ("name", "urdf", "joints", "locked_joints", "velocity_limits",
               "acceleration_limits", "jerk_limits", "tcp_frame", "tool", "allowed_collisions")


def robot_names() -> list[str]:
    """Names that :func:`load_robot` accepts: project folders, then example-robot-data."""
    names = sorted(p.parent.name for p in ROBOTS_DIR.glob("*/robot.yaml"))
    return names + _erd_names()


def _erd_names() -> list[str]:
    try:
        from example_robot_data.robots_loader import ROBOTS
    except ImportError:  # pragma: no cover - dependency is declared
        return []
    return sorted(ROBOTS)


def load_robot(name_or_path: str | Path, *, acceleration_limits: Sequence[float] | None = None,
               jerk_limits: Sequence[float] | None = None,
               locked_joints: Mapping[str, float | str] | None = None,
               velocity_limits: Sequence[float] | None = None,
               tcp_frame: str | None = None, tool: ToolSpec | None = None) -> Robot:
    """Load a robot by name (``"ned3pro"``, ``"ur5"``, ``"panda"``), robot folder or URDF.

    Joints that the URDF moves but safepath does not plan (fingers: the Panda's
    ``panda_finger_joint1``, the Gen3 Lite's ``right_finger_bottom_joint``) are *locked*:
    held still during every motion, at the value given here. A joint not given covers its
    whole travel: the collision geometry of the links it moves then encloses every place
    they can take, so a path stays collision-free whatever the gripper does. Joints that
    mimic another (URDF ``<mimic>``) follow it. :attr:`Robot.locked_joints` tells what
    was chosen. Without a ``robot.yaml`` (a URDF file, an example-robot-data name),
    gripper joints are found by name (``finger``, ``gripper``, ``jaw``, ...) and locked.

    A continuous (unbounded) joint is planned as a revolute joint of one unwrapped angle
    without position limits (:attr:`Robot.continuous`; the short way round). A description
    that is not a fixed-base arm of 1-DoF joints (a floating base, a spherical joint) is
    refused with :class:`~safepath.errors.RobotNotSupported` naming the joints; no joint is
    ever dropped.

    Args:
        name_or_path: A folder under ``robots/``, a path to a robot folder or its
            ``robot.yaml``, an ``example-robot-data`` name (its controller settings
            from ``robots/<name>/controller.yaml`` when there is one), or a ``.urdf``
            file alone (see :mod:`safepath.description._bare_urdf`: ``acceleration_limits`` are then
            required).
        velocity_limits: Override the velocity limits [rad/s or m/s] (required for a URDF
            whose ``<limit velocity>`` is zero).
        acceleration_limits: Override the acceleration limits [rad/s^2].
        jerk_limits: Override the jerk limits [rad/s^3] (default: the folder's
            ``jerk_limits``, else derived from the acceleration limits, see
            :func:`safepath.model.robot.derived_jerk_limits`).
        locked_joints: ``{joint: position [rad or m] or "travel"}`` for locked joints,
            e.g. ``{"panda_finger_joint1": 0.04}`` (Panda fingers open).
        tcp_frame: Override the TCP frame (default: the folder's ``tcp_frame``, else a
            usual TCP name, else the chain's last link).
        tool: The tool that holds objects (:class:`~safepath.ToolSpec`), instead of the
            folder's ``tool`` (default: none for a URDF or an example-robot-data name).

    Raises:
        RobotNotFound: The name is neither a folder nor an example-robot-data robot
            (names the closest, in any case).
        RobotNotSupported: Not a fixed-base arm of 1-DoF joints.
        ConfigError: The robot files are malformed (names file and key), a limit is
            missing (names the argument that gives it), or a locked joint is unknown,
            not lockable, or given a value outside its limits.
    """
    text = str(name_or_path)
    candidate = Path(text)
    if candidate.name == "robot.yaml":
        candidate = candidate.parent
    given = Given(velocity_limits=velocity_limits, acceleration_limits=acceleration_limits,
                  tcp_frame=tcp_frame, tool=tool, locked_joints=locked_joints)
    if candidate.is_dir() and (candidate / "robot.yaml").exists():
        robot = _load_folder(candidate, locked_joints)
    elif candidate.is_dir() and (candidate / CONTROLLER_FILE).is_file() \
            and candidate.name in _erd_names():
        # A folder that only adds controller settings to an example-robot-data arm.
        from ._erd import load_erd

        robot = load_erd(candidate.name, given, controller_path=candidate / CONTROLLER_FILE)
    elif candidate.is_file() and candidate.suffix.lower() == ".urdf":
        from ._bare_urdf import load_urdf

        robot = load_urdf(candidate, given)
    elif (ROBOTS_DIR / text / "robot.yaml").exists():
        robot = _load_folder(ROBOTS_DIR / text, locked_joints)
    elif text in _erd_names():
        from ._erd import load_erd

        robot = load_erd(text, given, controller_path=_bundled_controller(text))
    elif candidate.is_dir():
        urdfs = sorted(candidate.glob("*.urdf"))
        alone = (f"; to load a URDF alone, give its file: load_robot('{urdfs[0]}', "
                 "acceleration_limits=[...])") if urdfs else ""
        raise ConfigError(f"not a robot folder (no robot.yaml){alone}", path=candidate)
    elif candidate.exists():
        raise ConfigError("not a robot folder, robot.yaml or .urdf file", path=candidate)
    else:
        raise RobotNotFound(text, robot_names())
    _override(robot, velocity_limits=velocity_limits, acceleration_limits=acceleration_limits,
              tcp_frame=tcp_frame, tool=tool)
    if jerk_limits is not None:
        robot.jerk_limits = jerk_limits  # checked by the robot (ConfigError naming the key)
    robot.reference = str(Path(text).resolve()) if Path(text).exists() else text
    return robot


def _override(robot: Robot, *, velocity_limits: Sequence[float] | None,
              acceleration_limits: Sequence[float] | None, tcp_frame: str | None,
              tool: ToolSpec | None) -> None:
    """Apply the arguments of :func:`load_robot` that replace what the files say."""
    if velocity_limits is not None:
        robot.velocity_limits = vector_argument(velocity_limits, robot.dof,
                                                key="velocity_limits")
    if acceleration_limits is not None:
        robot.acceleration_limits = vector_argument(acceleration_limits, robot.dof,
                                                    key="acceleration_limits")
    if tcp_frame is not None:
        if not robot.model.existFrame(tcp_frame):
            raise FrameNotFound(tcp_frame, [f.name for f in robot.model.frames],
                                key="tcp_frame")
        robot.tcp_frame, robot.tcp_frame_id = tcp_frame, frame_id(robot.model, tcp_frame)
    if tool is not None:
        robot.tool = check_tool(tool, robot.model)


#: What a user may change on a loaded robot, carried to the process that loads it again.
CARRIED = ("name", "lower", "upper", "velocity_limits", "acceleration_limits", "jerk_limits",
           "tcp_frame",
           "tcp_frame_id", "tool", "allowed_self_pairs", "controller")


def _reduce_robot(robot: Robot) -> tuple[Any, ...]:
    """Pickle a robot as the reference it was loaded from, its locked joints and every
    attribute of :data:`CARRIED` as it is now (pinocchio's models, coal's shapes and
    per-thread workspaces stay behind; the receiver loads them itself)."""
    if robot.reference is None:
        raise ConfigError(f"robot '{robot.name}' was built in Python and cannot be sent to "
                          "another process; load it with safepath.load_robot (a folder or "
                          "a name)", key="robot")
    locked = {j.name: (TRAVEL if j.value is None else j.value) for j in robot.locked_joints
              if j.follows is None}
    carried = {key: getattr(robot, key) for key in CARRIED}
    return (_load_again, (robot.reference, locked, carried))


def _load_again(reference: str, locked: dict[str, float | str] | None,
                carried: dict[str, Any]) -> Robot:
    """The robot of ``reference`` loaded again, with the values it was sent with."""
    robot = load_robot(reference, locked_joints=locked,
                       velocity_limits=carried["velocity_limits"],
                       acceleration_limits=carried["acceleration_limits"],
                       tcp_frame=carried["tcp_frame"])
    for key in ("lower", "upper", "velocity_limits", "acceleration_limits", "jerk_limits"):
        value = np.array(carried[key], dtype=float)
        if value.shape != (robot.dof,):
            raise ConfigError(f"need {robot.dof} values, got {value.tolist()}", key=key)
        setattr(robot, key, value)
    for key in ("name", "tcp_frame", "tcp_frame_id", "tool", "allowed_self_pairs",
                "controller"):
        setattr(robot, key, carried[key])
    robot.reference = reference
    return robot


copyreg.pickle(Robot, _reduce_robot)


def _bundled_controller(name: str) -> Path | None:
    """A bundled ``robots/<name>/controller.yaml`` for an example-robot-data arm."""
    path = ROBOTS_DIR / name / CONTROLLER_FILE
    return path if path.is_file() else None


def _load_folder(folder: Path, locked_values: Mapping[str, float | str] | None = None
                 ) -> Robot:
    spec_path = folder / "robot.yaml"
    spec = read_mapping(spec_path, _ROBOT_KEYS)
    name = as_str(get_key(spec, "name", path=spec_path), path=spec_path, key="name")
    urdf_rel = as_str(get_key(spec, "urdf", path=spec_path), path=spec_path, key="urdf")
    urdf = folder / urdf_rel
    if not urdf.exists():
        raise ConfigError(f"URDF file not found: {urdf}", path=spec_path, key="urdf")
    check_readable(urdf)
    try:
        full = pin.buildModelFromUrdf(str(urdf))
        geom = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.COLLISION,
                                     package_dirs=[str(folder)])
        visual = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.VISUAL,
                                       package_dirs=[str(folder)])
    except (ValueError, RuntimeError, OSError) as exc:
        raise ConfigError(f"cannot load URDF ({str(exc).splitlines()[0]})", path=urdf) from None

    joints = get_key(spec, "joints", path=spec_path)
    if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
        raise ConfigError("expected a list of joint names", path=spec_path, key="joints")
    locked_names = get_key(spec, "locked_joints", path=spec_path, default=[]) or []
    if not isinstance(locked_names, list) or not all(isinstance(j, str) for j in locked_names):
        raise ConfigError("expected a list of joint names", path=spec_path, key="locked_joints")
    refuse_non_arm(full, robot=name, path=urdf, planned=joints)
    full, _ = unbound_continuous(full, joints)
    model_joints = list(full.names[1:])
    if joints != [j for j in model_joints if j not in locked_names]:
        raise ConfigError(f"joints {joints} and locked_joints {locked_names} are not the "
                          f"URDF's movable joints {model_joints} (joints in that order)",
                          path=spec_path, key="joints")
    unlocked = full
    full, (geom, visual), locked = lock_joints(
        full, [geom, visual], joints, locked_values, mimics=read_mimics(urdf))
    model_joints = list(full.names[1:])
    n = len(joints)
    vel = as_vector(get_key(spec, "velocity_limits", path=spec_path), n, path=spec_path,
                    key="velocity_limits")
    acc = as_vector(get_key(spec, "acceleration_limits", path=spec_path), n, path=spec_path,
                    key="acceleration_limits")
    jerk = None if spec.get("jerk_limits") is None else as_vector(
        spec["jerk_limits"], n, path=spec_path, key="jerk_limits")
    tcp = as_str(get_key(spec, "tcp_frame", path=spec_path), path=spec_path, key="tcp_frame")
    tool = None if spec.get("tool") is None else check_tool(
        read_tool(spec["tool"], path=spec_path), full, path=spec_path)
    # Links that touch at their joints are never checked, with or without a pairs file.
    pairs = adjacent_link_pairs(full, geom)
    pairs_file = spec.get("allowed_collisions")
    pairs_path = folder / "allowed_collisions.yaml"
    if pairs_file is not None:
        pairs_path = folder / as_str(pairs_file, path=spec_path, key="allowed_collisions")
        if pairs_path.exists():
            pairs += _read_pairs(pairs_path, full)
        else:
            log.warning("%s: allowed_collisions file %s missing; only adjacent links skipped "
                        "(write it with `safepath robot-pairs %s`)", spec_path,
                        pairs_path.name, folder)
    controller: ControllerSpec | None = None
    if (folder / CONTROLLER_FILE).is_file():
        controller = read_controller(folder / CONTROLLER_FILE, model_joints)
        _check_gripper_joint(controller, unlocked)
    return Robot(name=name, model=full, collision_model=geom, visual_model=visual,
                 velocity_limits=vel, acceleration_limits=acc, jerk_limits=jerk,
                 tcp_frame=tcp, tool=tool,
                 allowed_self_pairs=pairs, source=spec_path, urdf_path=urdf,
                 allowed_collisions_path=pairs_path, controller=controller,
                 locked_joints=locked)


def _check_gripper_joint(controller: ControllerSpec, model: pin.Model) -> None:
    """The gripper's joint exists, moves in its unit, and its range is within the URDF's."""
    gripper = controller.gripper
    if gripper is None:
        return
    where = {"path": controller.source}
    if not model.existJointName(gripper.joint):
        raise ConfigError(f"'{gripper.joint}' is not a joint of the robot's URDF",
                          key="gripper.joint", **where)
    joint = model.joints[model.getJointId(gripper.joint)]
    kind = joint.shortname()
    unit = "m" if "Prismatic" in kind or kind.startswith("JointModelP") else "rad"
    if joint.nq != 1 or gripper.unit != unit:
        raise ConfigError(f"'{gripper.joint}' ({kind}) moves in [{unit}], not "
                          f"[{gripper.unit}]", key="gripper.unit", **where)
    low = float(model.lowerPositionLimit[joint.idx_q])
    high = float(model.upperPositionLimit[joint.idx_q])
    g_low, g_high = gripper.position_range
    if g_low < low - 1e-9 or g_high > high + 1e-9:
        raise ConfigError(f"[{g_low:g}, {g_high:g}] {unit} exceeds the URDF's limits of "
                          f"'{gripper.joint}' [{low:g}, {high:g}] {unit}",
                          key="gripper.position_range", **where)


def _read_pairs(path: Path, model: pin.Model) -> list[tuple[str, str]]:
    data = read_yaml(path)
    entries = get_key(data, "pairs", path=path)
    if not isinstance(entries, list):
        raise ConfigError("expected a list", path=path, key="pairs")
    out = []
    for i, entry in enumerate(entries):
        key = f"pairs[{i}]"
        if not isinstance(entry, dict) or "links" not in entry:
            raise ConfigError("expected {links: [a, b], reason: ...}", path=path, key=key)
        links = entry["links"]
        if not (isinstance(links, list) and len(links) == 2):
            raise ConfigError("expected two link names", path=path, key=f"{key}.links")
        for link in links:
            if not model.existFrame(str(link)):
                raise FrameNotFound(str(link), [f.name for f in model.frames], path=path,
                                    key=f"{key}.links")
        out.append((str(links[0]), str(links[1])))
    return out


