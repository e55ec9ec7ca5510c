"""The robot's ROS 2 trajectory controller: what :mod:`safepath.ros` sends goals to.

These are facts about a robot, not about safepath, so they live in the robot's data
folder as ``controller.yaml`` (``robots/ned3pro/controller.yaml``)::

    follow_joint_trajectory_action: /my_arm_controller/follow_joint_trajectory
    joint_names: [joint_1, joint_2, joint_3, joint_4, joint_5, joint_6]
    goal_tolerance: [0.002, 0.001, 0.001, 0.03, 0.03, 0.03]   # [rad], or null
    goal_time_tolerance: 1.0                                 # [s]
    period: 0.04                                             # [s] between points
    joint_state_rate: 50.0                                   # [Hz] of /joint_states

Every key but ``follow_joint_trajectory_action`` may be left out. A robot without such a
file (an ``example-robot-data`` arm without a folder, a robot built in Python) gets
:meth:`TrajectoryController.derived`: the robot's own joint names, ros2_controllers'
conventional ``/joint_trajectory_controller/follow_joint_trajectory``, the controller's
own goal tolerances, points every 10 ms.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ._io import as_float, as_str, as_vector, check_keys, get_key, read_yaml
from ._paths import ROBOTS_DIR
from .errors import ConfigError

__all__ = ["TrajectoryController", "controller_for", "read_controller"]

#: The file in a robot folder.
FILE_NAME = "controller.yaml"
_KEYS = ("follow_joint_trajectory_action", "joint_names", "goal_tolerance",
         "goal_time_tolerance", "period", "joint_state_rate")
#: ros2_controllers' conventional name of a joint trajectory controller's action.
GENERIC_ACTION = "/joint_trajectory_controller/follow_joint_trajectory"


@dataclass(frozen=True, kw_only=True)
class TrajectoryController:
    """A robot's joint trajectory controller, as ROS 2 goals and bags address it.

    Attributes:
        joint_names: The controller's joints, in the order its messages use.
        follow_joint_trajectory_action: Its ``control_msgs/FollowJointTrajectory`` action.
        goal_tolerance: Final position tolerance per joint [rad], or None to leave the
            controller's own.
        goal_time_tolerance: Time allowed after the trajectory's end to reach the goal [s].
        period: Time between the points of a ``JointTrajectory`` [s].
        joint_state_rate: Rate of ``/joint_states`` written into bags [Hz].
        source: The file these settings came from (None: derived or built in Python).
    """

    joint_names: tuple[str, ...]
    follow_joint_trajectory_action: str
    goal_tolerance: tuple[float, ...] | None = None
    goal_time_tolerance: float = 1.0
    period: float = 0.01
    joint_state_rate: float = 50.0
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        where = {"path": self.source}
        names = tuple(self.joint_names)
        if not names or not all(isinstance(n, str) and n for n in names) \
                or len(set(names)) != len(names):
            raise ConfigError(f"expected distinct joint names, got {list(names)}",
                              key="joint_names", **where)
        object.__setattr__(self, "joint_names", names)
        action = self.follow_joint_trajectory_action
        if not isinstance(action, str) or not action.startswith("/") or " " in action:
            raise ConfigError(f"expected an absolute action name such as "
                              f"'{GENERIC_ACTION}', got {action!r}",
                              key="follow_joint_trajectory_action", **where)
        if self.goal_tolerance is not None:
            tol = tuple(float(v) for v in self.goal_tolerance)
            if len(tol) != len(names) or not all(math.isfinite(v) and v >= 0 for v in tol):
                raise ConfigError(f"expected {len(names)} finite tolerances >= 0 [rad], got "
                                  f"{list(self.goal_tolerance)}", key="goal_tolerance", **where)
            object.__setattr__(self, "goal_tolerance", tol)
        for key, low in (("goal_time_tolerance", 0.0), ("period", None),
                         ("joint_state_rate", None)):
            value = getattr(self, key)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) \
                and math.isfinite(value) and (value >= low if low is not None else value > 0)
            if not ok:
                raise ConfigError(f"expected a finite number {'>= 0' if low is not None else '> 0'}"
                                  f", got {value!r}", key=key, **where)

    @classmethod
    def derived(cls, joint_names: Sequence[str]) -> TrajectoryController:
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
                    ) -> TrajectoryController:
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
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping at the top level", path=path)
    check_keys(data, _KEYS, path=path)
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
        for key in ("goal_time_tolerance", "period", "joint_state_rate") if key in data}
    spec = TrajectoryController(joint_names=tuple(raw_names),
                                follow_joint_trajectory_action=action, goal_tolerance=tol,
                                source=path, **numbers)
    if joint_names is not None:
        spec.check_joints(joint_names, path=path)
    return spec


def controller_for(robot: str, joint_names: Sequence[str]) -> TrajectoryController:
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
    return TrajectoryController.derived(joint_names)


@functools.lru_cache(maxsize=32)
def _read_cached(path: Path) -> TrajectoryController:
    return read_controller(path)
