"""ROS 2 interface of safepath: goals, bags and the cell's decision logic.

Messages are built with the pure-Python ``rosbags`` type system, so this package
works without a ROS 2 installation; in a sourced ROS 2 workspace the goal builders
return the native ``rclpy`` message classes instead (``backend="auto"``).

* :mod:`safepath.ros.goals`: ``JointTrajectory``, ``FollowJointTrajectory``,
  Niryo ``RobotMove`` and ``Tool`` goals from a :class:`~safepath.model.trajectory.Trajectory`;
  the controller's names, tolerances and timing come from the trajectory's robot
  (its folder's ``controller.yaml``).
* :mod:`safepath.ros.gripper`: ``control_msgs/GripperCommand`` goals from the ``gripper``
  section of the robot's ``controller.yaml`` (the Gen3 Lite under ros2_kortex).
* :mod:`safepath.ros.bag`: write and read a ROS 2 bag (MCAP) of a cycle.
* :mod:`safepath.ros.commands`: the commands every cell's controller may return
  (:class:`CancelGoal`, :class:`Fault`).
* The cells' state machines are applications of this package, in their own packages:
  the quality-check cell's (``QualityCheckController`` and its commands) in
  :mod:`safepath.cells.quality_check`, the pouring cell's (``PourController`` and its
  commands) in :mod:`safepath.cells.pouring`.
* :mod:`safepath.ros.messages`: the type stores and CDR (de)serialisation; the classes of
  the messages safepath writes are generated ahead of time and kept on disk.
"""

from __future__ import annotations

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
from .messages import deserialize, message_factory, serialize, typestore, written_typestore

__all__ = [
    "BagContents",
    "BagMessage",
    "CancelGoal",
    "Fault",
    "ROBOT_MOVE_ACTION",
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
    "written_typestore",
]
