"""The settings of a robot's ROS 2 trajectory controller (a specification, not a
controller): what :mod:`safepath.ros` addresses goals to and how the controller joins them.

These are facts about a robot, not about safepath, so they live in the robot's data
folder as ``controller.yaml`` (``robots/ned3pro/controller.yaml``)::

    follow_joint_trajectory_action: /my_arm_controller/follow_joint_trajectory
    joint_names: [joint_1, joint_2, joint_3, joint_4, joint_5, joint_6]
    goal_tolerance: [0.002, 0.001, 0.001, 0.03, 0.03, 0.03]   # [rad], or null
    goal_time_tolerance: 1.0                                 # [s]
    period: 0.04                                             # [s] largest between points
    interpolation: quintic                                   # how it joins points
    cycle: 0.04                                              # [s] its update period
    joint_state_rate: 50.0                                   # [Hz] of /joint_states
    gripper:                                                 # optional: robots with one
      action: /my_gripper_controller/gripper_cmd             # control_msgs/GripperCommand
      joint: finger_joint
      unit: rad                                              # rad (revolute) or m
      position_range: [0.0, 0.8]                             # what the controller accepts
      open_position: 0.0
      closed_position: 0.8
      max_effort: 100.0                                      # sent with every goal

Every key but ``follow_joint_trajectory_action`` may be left out; a robot without a
gripper (or whose gripper is not driven through ``control_msgs/GripperCommand``) has no
``gripper`` section. A robot without a ``controller.yaml`` (an ``example-robot-data`` arm
without a folder, a robot built in Python) gets :meth:`ControllerSpec.derived`:
the robot's own joint names, ros2_controllers' conventional
``/joint_trajectory_controller/follow_joint_trajectory``, the controller's
own goal tolerances, points every 10 ms.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ..errors import ConfigError, InputError
from ..files._io import as_float, as_str, as_vector, check_keys, get_key, read_mapping
from ..files._paths import ROBOTS_DIR
from .interpolation import QUINTIC, Interpolation, interpolation_named

__all__ = ["GripperSpec", "ControllerSpec", "controller_for", "read_controller"]

#: The file in a robot folder.
FILE_NAME = "controller.yaml"
_KEYS = ("follow_joint_trajectory_action", "joint_names", "goal_tolerance",
         "goal_time_tolerance", "period", "joint_state_rate", "interpolation", "cycle",
         "gripper")
_GRIPPER_KEYS = ("action", "joint", "unit", "position_range", "open_position",
                 "closed_position", "max_effort")
#: ros2_controllers' conventional name of a joint trajectory controller's action.
GENERIC_ACTION = "/joint_trajectory_controller/follow_joint_trajectory"


def _action_name(action: object, key: str, example: str, where: dict[str, Any]) -> str:
    if not isinstance(action, str) or not action.startswith("/") or " " in action:
        raise ConfigError(f"expected an absolute action name such as '{example}', got "
                          f"{action!r}", key=key, **where)
    return action


@dataclass(frozen=True, kw_only=True)
class GripperSpec:
    """The settings of a gripper driven through ``control_msgs/action/GripperCommand``
    (ros2_controllers' ``GripperActionController``, as MoveIt's gripper interface uses it).

    Attributes:
        action: The ``GripperCommand`` action's name.
        joint: The joint the controller drives (its position is the command's).
        unit: ``rad`` for a revolute joint, ``m`` for a prismatic one.
        position_range: (lowest, highest) position the controller accepts [rad or m].
        open_position: Position of the open gripper [rad or m].
        closed_position: Position of the closed gripper [rad or m].
        max_effort: The goal's ``max_effort`` (the controller's own unit; 0 leaves it to
            the controller).
        source: The file these settings came from (None: built in Python).
    """

    action: str
    joint: str
    unit: Literal["rad", "m"]
    position_range: tuple[float, float]
    open_position: float
    closed_position: float
    max_effort: float
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        where: dict[str, Any] = {"path": self.source}
        _action_name(self.action, "gripper.action", "/gripper_controller/gripper_cmd", where)
        if not isinstance(self.joint, str) or not self.joint:
            raise ConfigError(f"expected a joint name, got {self.joint!r}", key="gripper.joint",
                              **where)
        if self.unit not in ("rad", "m"):
            raise ConfigError(f"expected 'rad' or 'm', got {self.unit!r}", key="gripper.unit",
                              **where)
        rng = tuple(self.position_range)
        if len(rng) != 2 or not all(_finite(v) for v in rng) or not rng[0] < rng[1]:
            raise ConfigError(f"expected [lowest, highest] finite positions, lowest < highest, "
                              f"got {list(rng)}", key="gripper.position_range", **where)
        object.__setattr__(self, "position_range", (float(rng[0]), float(rng[1])))
        for key in ("open_position", "closed_position"):
            self.check_position(getattr(self, key), key=f"gripper.{key}", error=ConfigError)
        if self.open_position == self.closed_position:
            raise ConfigError(f"open and closed positions are both {self.open_position}",
                              key="gripper.closed_position", **where)
        if not _finite(self.max_effort) or self.max_effort < 0:
            raise ConfigError(f"expected a finite number >= 0, got {self.max_effort!r}",
                              key="gripper.max_effort", **where)

    def check_position(self, position: float, *, key: str = "position",
                       error: type[InputError] = InputError) -> float:
        """``position`` as a float, or a typed error if it is outside :attr:`position_range`.

        Raises:
            InputError: (or ``error``) Not a finite number, or outside the range.
        """
        low, high = self.position_range
        if not _finite(position):
            raise error(f"expected a finite number [{self.unit}], got {position!r}", key=key,
                        path=self.source if error is ConfigError else None)
        if not low <= float(position) <= high:
            raise error(f"{float(position):g} {self.unit} is outside the range of "
                        f"'{self.joint}' [{low:g}, {high:g}] {self.unit}", key=key,
                        path=self.source if error is ConfigError else None)
        return float(position)


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


@dataclass(frozen=True, kw_only=True)
class ControllerSpec:
    """The settings of a robot's joint trajectory controller, as ROS 2 goals and bags
    address it.

    Attributes:
        joint_names: The controller's joints, in the order its messages use.
        follow_joint_trajectory_action: Its ``control_msgs/FollowJointTrajectory`` action.
        goal_tolerance: Final position tolerance per joint [rad], or None to leave the
            controller's own.
        goal_time_tolerance: Time allowed after the trajectory's end to reach the goal [s].
        period: Largest time between the points of a ``JointTrajectory`` [s] (goals send
            every knot of a trajectory, and more points where knots are farther apart).
        joint_state_rate: Rate of ``/joint_states`` written into bags [Hz].
        interpolation: How the controller joins points (``quintic``: position, velocity
            and acceleration matched at both ends, ros2_control's
            ``joint_trajectory_controller`` when points carry all three; ``cubic``;
            ``linear``): the motion goals are checked as (:mod:`safepath.model.execution`).
        cycle: The controller's update period [s]: how often it samples the joined
            motion and commands the joints (the twin runs it at this rate).
        gripper: The gripper's ``GripperCommand`` controller (None: no such gripper).
        source: The file these settings came from (None: derived or built in Python).
    """

    joint_names: tuple[str, ...]
    follow_joint_trajectory_action: str
    goal_tolerance: tuple[float, ...] | None = None
    goal_time_tolerance: float = 1.0
    period: float = 0.01
    joint_state_rate: float = 50.0
    interpolation: Interpolation = QUINTIC
    cycle: float = 0.001
    gripper: GripperSpec | None = None
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        where = {"path": self.source}
        names = tuple(self.joint_names)
        if not names or not all(isinstance(n, str) and n for n in names) \
                or len(set(names)) != len(names):
            raise ConfigError(f"expected distinct joint names, got {list(names)}",
                              key="joint_names", **where)
        object.__setattr__(self, "joint_names", names)
        _action_name(self.follow_joint_trajectory_action, "follow_joint_trajectory_action",
                     GENERIC_ACTION, where)
        if self.gripper is not None and not isinstance(self.gripper, GripperSpec):
            raise ConfigError(f"expected a GripperSpec, got {self.gripper!r}",
                              key="gripper", **where)
        if self.goal_tolerance is not None:
            tol = tuple(float(v) for v in self.goal_tolerance)
            if len(tol) != len(names) or not all(math.isfinite(v) and v >= 0 for v in tol):
                raise ConfigError(f"expected {len(names)} finite tolerances >= 0 [rad], got "
                                  f"{list(self.goal_tolerance)}", key="goal_tolerance", **where)
            object.__setattr__(self, "goal_tolerance", tol)
        if not isinstance(self.interpolation, Interpolation):  # a name, as the file has it
            object.__setattr__(self, "interpolation",
                               interpolation_named(self.interpolation, path=self.source))
        for key, low in (("goal_time_tolerance", 0.0), ("period", None),
                         ("joint_state_rate", None), ("cycle", None)):
            value = getattr(self, key)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) \
                and math.isfinite(value) and (value >= low if low is not None else value > 0)
            if not ok:
                raise ConfigError(f"expected a finite number {'>= 0' if low is not None else '> 0'}"
                                  f", got {value!r}", key=key, **where)

    @classmethod
    def derived(cls, joint_names: Sequence[str]) -> ControllerSpec:
        """Settings for a robot whose folder says nothing about its controller.

        The joint names are the robot's (its URDF's, which ``/joint_states`` uses), the
        action is ros2_controllers' conventional one, goal tolerances are left to the
        controller, and points come every 10 ms (ros2_controllers' joint trajectory
        controller joins them with quintic splines through positions, velocities and
        accelerations). Give a robot a ``controller.yaml`` to change any of these.
        """
        return cls(joint_names=tuple(joint_names), follow_joint_trajectory_action=GENERIC_ACTION)

    def check_joints(self, joint_names: Sequence[str], *, path: Path | None = None) -> None:
        """Refuse settings whose joints are not the robot's (order may differ).

        Raises:
            ConfigError: Naming the joints that differ.
        """
        if sorted(self.joint_names) != sorted(joint_names):
            raise ConfigError(f"controller joints {list(self.joint_names)} are not the robot's "
                              f"{list(joint_names)}", path=path or self.source,
                              key="joint_names")


def read_controller(path: str | Path, joint_names: Sequence[str] | None = None
                    ) -> ControllerSpec:
    """Read a robot folder's ``controller.yaml``.

    Args:
        path: The file.
        joint_names: The robot's joints: the default of ``joint_names`` and what the
            file's joint names must match (None: the file must list them, unchecked).

    Raises:
        ConfigError: Malformed file, an unknown key (naming the closest known one), joint
            names that are not the robot's, a bad number.
    """
    path = Path(path)
    data = read_mapping(path, _KEYS)
    action = as_str(get_key(data, "follow_joint_trajectory_action", path=path), path=path,
                    key="follow_joint_trajectory_action")
    raw_names = data.get("joint_names") if joint_names is None \
        else data.get("joint_names", list(joint_names))
    if not isinstance(raw_names, list) or not all(isinstance(n, str) for n in raw_names):
        raise ConfigError("expected a list of joint names", path=path, key="joint_names")
    raw_tol = data.get("goal_tolerance")
    tol = None if raw_tol is None else tuple(as_vector(raw_tol, len(raw_names), path=path,
                                                       key="goal_tolerance"))
    numbers: dict[str, Any] = {
        key: as_float(data[key], path=path, key=key, positive=key != "goal_time_tolerance",
                      non_negative=True)
        for key in ("goal_time_tolerance", "period", "joint_state_rate", "cycle")
        if key in data}
    if "interpolation" in data:
        numbers["interpolation"] = interpolation_named(
            as_str(data["interpolation"], path=path, key="interpolation"), path=path)
    gripper = _read_gripper(data["gripper"], path) if data.get("gripper") is not None else None
    spec = ControllerSpec(joint_names=tuple(raw_names),
                                follow_joint_trajectory_action=action, goal_tolerance=tol,
                                gripper=gripper, source=path, **numbers)
    if joint_names is not None:
        spec.check_joints(joint_names, path=path)
    return spec


def _read_gripper(raw: Any, path: Path) -> GripperSpec:
    """The ``gripper`` section of a ``controller.yaml``."""
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key="gripper")
    check_keys(raw, _GRIPPER_KEYS, path=path, prefix="gripper")

    def value(key: str) -> Any:
        return get_key(raw, key, path=path, prefix="gripper")

    low, high = as_vector(value("position_range"), 2, path=path, key="gripper.position_range")
    return GripperSpec(
        action=as_str(value("action"), path=path, key="gripper.action"),
        joint=as_str(value("joint"), path=path, key="gripper.joint"),
        unit=as_str(value("unit"), path=path, key="gripper.unit"),  # type: ignore[arg-type]
        position_range=(low, high),
        **{key: as_float(value(key), path=path, key=f"gripper.{key}")
           for key in ("open_position", "closed_position", "max_effort")},
        source=path)


def controller_for(robot: str, joint_names: Sequence[str]) -> ControllerSpec:
    """The controller of the bundled robot named ``robot``, else :meth:`derived` settings.

    This is how :mod:`safepath.ros` finds a trajectory's controller from the robot name
    the trajectory records; a robot loaded from a folder elsewhere carries its own as
    :attr:`safepath.Robot.controller` (pass it as ``controller=``). The file's joint names
    are not checked against ``joint_names`` here: the goal builders refuse a trajectory
    whose joints are not the controller's, with the trajectory as the culprit.

    Raises:
        ConfigError: The bundled file is malformed.
    """
    path = ROBOTS_DIR / robot / FILE_NAME if robot and "/" not in robot else None
    if path is not None and path.is_file():
        return _read_cached(path)
    return ControllerSpec.derived(joint_names)


@functools.lru_cache(maxsize=32)
def _read_cached(path: Path) -> ControllerSpec:
    return read_controller(path)
