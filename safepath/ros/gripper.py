"""``control_msgs/GripperCommand`` goals from the robot's ``controller.yaml``.

A gripper driven by ros2_controllers' ``GripperActionController`` (the Gen3 Lite's under
ros2_kortex, and most grippers MoveIt drives) takes one position (the driven joint's, in
[rad] or [m]) and a ``max_effort``. The action name, the joint, its range and the open and
closed positions are facts about the robot: the ``gripper`` section of its folder's
``controller.yaml`` (:class:`~safepath.model.controller_spec.GripperSpec`). Robots
without one (the Ned3 Pro, driven through Niryo's tools commander, see
:func:`safepath.ros.goals.tool_goal`) get a typed error, never a guessed action.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from ..errors import InputError
from ..files._io import check_names
from ..files._paths import ROBOTS_DIR
from ..model.controller_spec import (
    FILE_NAME,
    ControllerSpec,
    GripperSpec,
    controller_for,
)
from ..model.trajectory import GripperEvent, Trajectory
from .messages import Backend, message_factory

if TYPE_CHECKING:
    from ..model.robot import Robot

__all__ = ["GRIPPER_COMMAND_TYPES", "gripper_command_goal", "gripper_command_goals",
           "gripper_of"]

#: The message types a ``GripperCommand`` goal is built from.
GRIPPER_COMMAND_TYPES = ("control_msgs/action/GripperCommand_Goal",
                         "control_msgs/msg/GripperCommand")


def gripper_of(robot: Robot | ControllerSpec | str) -> GripperSpec:
    """The ``GripperCommand`` controller of ``robot``.

    Args:
        robot: A loaded robot, its trajectory controller settings, or the name of a
            bundled robot (its ``robots/<name>/controller.yaml``).

    Raises:
        InputError: ``robot`` has no ``gripper`` section in its ``controller.yaml``
            (key ``robot``), or is not a robot, controller or name.
    """
    from ..model.robot import Robot

    if isinstance(robot, Robot):
        controller, name = robot.controller, robot.name
    elif isinstance(robot, ControllerSpec):
        controller, name = robot, str(robot.source or "the given controller")
    elif isinstance(robot, str) and robot:
        path = ROBOTS_DIR / robot / FILE_NAME
        if "/" in robot or not path.is_file():
            raise InputError(f"no bundled robot '{robot}' with a {FILE_NAME}; pass the loaded "
                             f"robot instead", key="robot")
        controller, name = controller_for(robot, ()), robot
    else:
        raise InputError(f"expected a Robot, a ControllerSpec or a robot name, got "
                         f"{robot!r}", key="robot")
    if controller.gripper is None:
        where = controller.source or "its controller settings"
        raise InputError(f"robot '{name}' has no GripperCommand gripper: no 'gripper' section "
                         f"in {where}", key="robot")
    return controller.gripper


def gripper_command_goal(robot: Robot | ControllerSpec | str,
                         position: float | Literal["open", "close"], *,
                         max_effort: float | None = None, backend: Backend = "auto") -> Any:
    """``control_msgs/action/GripperCommand_Goal`` for the robot's gripper controller.

    Send it to ``gripper_of(robot).action`` (the Gen3 Lite:
    ``/gen3_lite_2f_gripper_controller/gripper_cmd``).

    Args:
        robot: The robot (see :func:`gripper_of`).
        position: The driven joint's target [rad or m, per ``gripper.unit``], or
            ``open`` / ``close`` for the positions its ``controller.yaml`` gives.
        max_effort: The goal's ``max_effort``; default: the ``controller.yaml``'s.
        backend: ``auto``, ``rosbags`` or ``rclpy`` (see
            :func:`safepath.ros.messages.message_factory`).

    Raises:
        InputError: No gripper section (key ``robot``), a position that is not a number
            within ``gripper.position_range`` or an unknown word (key ``position``), a
            negative or non-finite ``max_effort`` (key ``max_effort``).
        RosError: ``backend='rclpy'`` without control_msgs.
    """
    gripper = gripper_of(robot)
    if isinstance(position, str):
        check_names([position], ("open", "close"), path=None, key="position",
                    what="gripper position", error=InputError)
        target = gripper.open_position if position == "open" else gripper.closed_position
    else:
        target = gripper.check_position(position, key="position")
    effort = gripper.max_effort if max_effort is None else max_effort
    if isinstance(effort, bool) or not isinstance(effort, (int, float)) \
            or not effort >= 0 or effort == float("inf"):
        raise InputError(f"expected a finite number >= 0, got {effort!r}", key="max_effort")
    f = message_factory(backend, GRIPPER_COMMAND_TYPES)
    command = f.new("control_msgs/msg/GripperCommand", position=float(target),
                    max_effort=float(effort))
    return f.new("control_msgs/action/GripperCommand_Goal", command=command)


def gripper_command_goals(traj: Trajectory, robot: Robot | ControllerSpec | str | None
                          = None, *, backend: Backend = "auto"
                          ) -> list[tuple[GripperEvent, Any]]:
    """A :func:`gripper_command_goal` for each gripper event of ``traj``, in time order.

    Args:
        traj: A route with gripper events (``open`` / ``close``).
        robot: Its robot; default: the bundled robot ``traj`` names.
        backend: ``auto``, ``rosbags`` or ``rclpy``.

    Raises:
        InputError: The robot has no gripper section.
    """
    who = traj.robot if robot is None else robot
    return [(event, gripper_command_goal(who, event.action, backend=backend))
            for event in sorted(traj.events, key=lambda e: e.time)]
