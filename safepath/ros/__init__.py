"""ROS 2 interface of safepath: goals, bags and the cell's decision logic.

Messages are built with the pure-Python ``rosbags`` type system, so this package
works without a ROS 2 installation; in a sourced ROS 2 workspace the goal builders
return the native ``rclpy`` message classes instead (``backend="auto"``).

* :mod:`safepath.ros.goals`: ``JointTrajectory``, ``FollowJointTrajectory``,
  Niryo ``RobotMove`` and ``Tool`` goals from a :class:`~safepath.trajectory.Trajectory`;
  the controller's names, tolerances and timing come from the trajectory's robot
  (its folder's ``controller.yaml``).
* :mod:`safepath.ros.gripper`: ``control_msgs/GripperCommand`` goals from the ``gripper``
  section of the robot's ``controller.yaml`` (the Gen3 Lite under ros2_kortex).
* :mod:`safepath.ros.bag`: write and read a ROS 2 bag (MCAP) of a cycle.
* :mod:`safepath.ros.commands`: the commands every cell's controller may return
  (:class:`CancelGoal`, :class:`Fault`).
* The cells' state machines are applications of this package: the quality-check cell's
  (:class:`QualityCheckController` and its commands) lives in
  :mod:`safepath.cells.quality_check`, the pouring cell's (:class:`PourController` and its
  commands) in :mod:`safepath.cells.pouring`; their names are still importable from here,
  loaded on first use.
* :mod:`safepath.ros.messages`: the type store and CDR (de)serialisation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .bag import BagContents, BagMessage, read_bag, write_bag
from .commands import CancelGoal, Fault
from .goals import (
    ROBOT_MOVE_ACTION,
    TOOL_ACTION,
    check_start,
    controller_of,
    follow_joint_trajectory_goal,
    joint_trajectory,
    robot_move_goal,
    split_at_gripper_events,
    tool_goal,
    tool_goals,
    trajectory_between,
)
from .gripper import gripper_command_goal, gripper_command_goals, gripper_of
from .messages import deserialize, message_factory, serialize, typestore

if TYPE_CHECKING:
    from ..cells.pouring.controller import (
        PourController,
        PourControllerOptions,
        PourReport,
        PourState,
        SendArmGoal,
        SendGripperGoal,
    )
    from ..cells.quality_check.controller import (
        ActuateGripper,
        CellState,
        Command,
        ControllerOptions,
        CycleReport,
        MoveArm,
        QualityCheckController,
        RequestVerdict,
        SetConveyor,
    )

#: The pouring cell's names kept importable from here (their home is an application above
#: this package, :mod:`safepath.cells.pouring`, so they load on first use).
_POURING = ("PourController", "PourControllerOptions", "PourReport", "PourState",
            "SendArmGoal", "SendGripperGoal")
#: The quality-check cell's names kept importable from here (their home is
#: :mod:`safepath.cells.quality_check`, loaded on first use as the pouring cell's are).
_QUALITY_CHECK = ("ActuateGripper", "CellState", "Command", "ControllerOptions",
                  "CycleReport", "MoveArm", "QualityCheckController", "RequestVerdict",
                  "SetConveyor")


def __getattr__(name: str) -> object:
    """The cells' controller names, imported on first use."""
    if name in _POURING:
        from ..cells.pouring import controller

        return getattr(controller, name)
    if name in _QUALITY_CHECK:
        from ..cells.quality_check import controller as quality_check

        return getattr(quality_check, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "ActuateGripper",
    "BagContents",
    "BagMessage",
    "CancelGoal",
    "CellState",
    "Command",
    "ControllerOptions",
    "CycleReport",
    "Fault",
    "MoveArm",
    "PourController",
    "PourControllerOptions",
    "PourReport",
    "PourState",
    "QualityCheckController",
    "ROBOT_MOVE_ACTION",
    "RequestVerdict",
    "SendArmGoal",
    "SendGripperGoal",
    "SetConveyor",
    "TOOL_ACTION",
    "check_start",
    "controller_of",
    "deserialize",
    "follow_joint_trajectory_goal",
    "gripper_command_goal",
    "gripper_command_goals",
    "gripper_of",
    "joint_trajectory",
    "message_factory",
    "read_bag",
    "robot_move_goal",
    "serialize",
    "split_at_gripper_events",
    "tool_goal",
    "tool_goals",
    "trajectory_between",
    "typestore",
    "write_bag",
]
