"""The definitions of the ROS 2 messages safepath builds: rosbags' standard store, the
types it lacks, and the Python source of the classes safepath writes.

The standard types come from the rosbags store of ROS 2 Humble; :data:`DEFINITIONS` adds
the types it lacks:

* ``control_msgs``: FollowJointTrajectory and GripperCommand goal/result/feedback, the
  tolerances and ``GripperCommand``, as in control_msgs 4.x (Humble).
* ``niryo_ned_ros2_interfaces``: RobotMove and Tool actions, ArmMoveCommand, ToolCommand,
  ShiftPose, RPY, RobotState, DigitalIO(State), ControlConveyor and SetConveyor services,
  with the field lists of Niryo's Ned ROS 2 driver.
* ``rpi_manager/srv/GetSafety``: the quality-check cell's verdict service (the package
  name of Niryo's ROSCon 2025 workshop).

Field names, types and order decide the CDR bytes, so they follow the upstream
interfaces exactly; comments are ours.

Building that store imports every Humble type and parses the definitions (about 0.1 s);
:func:`written_source` turns the types safepath writes (:data:`WRITTEN_TYPES` and what
they nest) into the Python source of their classes, which :mod:`._type_cache` keeps on
disk so that a process writing a bag loads a few classes instead.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.codegen import generate_python_code
from rosbags.typesys.store import Typestore

__all__ = ["DEFINITIONS", "ROS_DISTRO_STORE", "WRITTEN_TYPES", "standard_store",
           "written_source"]

#: The rosbags store the standard types come from (the Ned ROS 2 driver targets Humble).
ROS_DISTRO_STORE = Stores.ROS2_HUMBLE

_NIRYO = "niryo_ned_ros2_interfaces"

#: Our definitions of the types that rosbags' standard store lacks: type name -> msg text.
#: Nested types are always fully qualified, so that names resolve the same for msg,
#: srv and action parts.
DEFINITIONS: dict[str, str] = {
    # -- control_msgs (Humble) -------------------------------------------------------------
    "control_msgs/msg/JointTolerance": """
string name
float64 position      # [rad] or [m]; 0 = server default, -1 = no limit
float64 velocity      # [rad/s] or [m/s]
float64 acceleration  # [rad/s^2] or [m/s^2]
""",
    "control_msgs/msg/JointComponentTolerance": """
uint16 X_AXIS=1
uint16 Y_AXIS=2
uint16 Z_AXIS=3
uint16 TRANSLATION=4
uint16 ROTATION=5
string joint_name
uint16 component
float64 position
float64 velocity
float64 acceleration
""",
    "control_msgs/action/FollowJointTrajectory_Goal": """
trajectory_msgs/JointTrajectory trajectory
trajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory
control_msgs/JointTolerance[] path_tolerance
control_msgs/JointComponentTolerance[] component_path_tolerance
control_msgs/JointTolerance[] goal_tolerance
control_msgs/JointComponentTolerance[] component_goal_tolerance
builtin_interfaces/Duration goal_time_tolerance
""",
    "control_msgs/action/FollowJointTrajectory_Result": """
int32 SUCCESSFUL=0
int32 INVALID_GOAL=-1
int32 INVALID_JOINTS=-2
int32 OLD_HEADER_TIMESTAMP=-3
int32 PATH_TOLERANCE_VIOLATED=-4
int32 GOAL_TOLERANCE_VIOLATED=-5
int32 error_code
string error_string
""",
    "control_msgs/action/FollowJointTrajectory_Feedback": """
std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint desired
trajectory_msgs/JointTrajectoryPoint actual
trajectory_msgs/JointTrajectoryPoint error
string[] multi_dof_joint_names
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error
""",
    "control_msgs/msg/GripperCommand": """
float64 position    # [m] or [rad], the gripper joint's unit
float64 max_effort  # the controller's unit
""",
    "control_msgs/action/GripperCommand_Goal": "control_msgs/GripperCommand command\n",
    "control_msgs/action/GripperCommand_Result": """
float64 position    # where the gripper ended [m] or [rad]
float64 effort
bool stalled        # stopped before the goal (an object in the way)
bool reached_goal
""",
    "control_msgs/action/GripperCommand_Feedback": """
float64 position
float64 effort
bool stalled
bool reached_goal
""",
    # -- Niryo Ned ROS 2 driver -----------------------------------------------------------
    f"{_NIRYO}/msg/RPY": """
float64 roll   # [rad]
float64 pitch  # [rad]
float64 yaw    # [rad]
""",
    f"{_NIRYO}/msg/ShiftPose": """
int32 axis_number
float64 value
""",
    f"{_NIRYO}/msg/ArmMoveCommand": f"""
int32 JOINTS=0
int32 POSE=1
int32 POSITION=2
int32 RPY=3
int32 POSE_QUAT=4
int32 LINEAR_POSE=5
int32 SHIFT_POSE=6
int32 SHIFT_LINEAR_POSE=7
int32 EXECUTE_TRAJ=8
int32 DRAW_SPIRAL=9
int32 DRAW_CIRCLE=10
int32 EXECUTE_FULL_TRAJ=11  # re-timed by the robot
int32 EXECUTE_RAW_TRAJ=12   # fails on the robot with a JointTrajectory
int32 cmd_type
int32 LEGACY=1
int32 DH_CONVENTION=2
int32 tcp_version
float64[] joints
geometry_msgs/Point position
{_NIRYO}/RPY rpy
geometry_msgs/Quaternion orientation
{_NIRYO}/ShiftPose shift
geometry_msgs/Pose[] list_poses
float32 dist_smoothing
trajectory_msgs/JointTrajectory trajectory
float64[] args
""",
    f"{_NIRYO}/msg/RobotState": f"""
geometry_msgs/Point position
{_NIRYO}/RPY rpy
geometry_msgs/Quaternion orientation
geometry_msgs/Twist twist
float64 tcp_speed
""",
    f"{_NIRYO}/action/RobotMove_Goal": f"{_NIRYO}/ArmMoveCommand cmd\n",
    f"{_NIRYO}/action/RobotMove_Result": "int32 status\nstring message\n",
    f"{_NIRYO}/action/RobotMove_Feedback": f"{_NIRYO}/RobotState state\n",
    f"{_NIRYO}/msg/ToolCommand": """
int8 OPEN_GRIPPER=1
int8 CLOSE_GRIPPER=2
int8 PULL_AIR_VACUUM_PUMP=10
int8 PUSH_AIR_VACUUM_PUMP=11
int8 SETUP_DIGITAL_IO=20
int8 ACTIVATE_DIGITAL_IO=21
int8 DEACTIVATE_DIGITAL_IO=22
uint8 cmd_type
int8 tool_id                  # Gripper 1 = 11
uint16 speed                  # Ned / One grippers only
uint8 max_torque_percentage   # Ned 2 / Ned 3 grippers
uint8 hold_torque_percentage
bool activate                 # vacuum pump, electromagnet
string gpio                   # tools driven by digital outputs
""",
    f"{_NIRYO}/action/Tool_Goal": f"{_NIRYO}/ToolCommand cmd\n",
    f"{_NIRYO}/action/Tool_Result": "int32 status\nstring message\n",
    f"{_NIRYO}/action/Tool_Feedback": "int32 progression\n",
    f"{_NIRYO}/msg/DigitalIO": "string name\nbool value\n",
    f"{_NIRYO}/msg/DigitalIOState": f"""
{_NIRYO}/DigitalIO[] digital_inputs
{_NIRYO}/DigitalIO[] digital_outputs
""",
    f"{_NIRYO}/srv/ControlConveyor_Request": """
uint8 id
bool control_on
int16 speed      # [% of max speed]
int8 direction   # 1 towards the robot, 0 stopped, -1 away
""",
    f"{_NIRYO}/srv/ControlConveyor_Response": "int16 status\nstring message\n",
    f"{_NIRYO}/srv/SetConveyor_Request": """
uint8 ADD=1
uint8 REMOVE=2
uint8 cmd
uint8 id
""",
    f"{_NIRYO}/srv/SetConveyor_Response": """
int16 id
int16 status
string message
string hardware_id
""",
    # -- the quality-check cell -----------------------------------------------------------
    # An empty request still holds one byte on the wire (rosidl adds this member).
    "rpi_manager/srv/GetSafety_Request": "uint8 structure_needs_at_least_one_member\n",
    "rpi_manager/srv/GetSafety_Response": 'string state  # "safe" or "unsafe"\n',
}

#: The messages safepath writes to its bags and builds as the arm's and gripper's goals;
#: their classes, and those of every type they nest, come from :func:`written_source`.
WRITTEN_TYPES = (
    "trajectory_msgs/msg/JointTrajectory",
    "sensor_msgs/msg/JointState",
    "std_msgs/msg/String",
    "control_msgs/action/FollowJointTrajectory_Goal",
    "control_msgs/action/GripperCommand_Goal",
)


def _parse(typename: str, text: str) -> dict[str, Any]:
    """Parse one msg text under its full name (srv parts included)."""
    # rosbags' msg parser files anything that is not msg/action under 'msg'; parse
    # service parts under a msg alias and put them back under their real name.
    alias = typename.replace("/srv/", "/msg/")
    parsed = get_types_from_msg(text, alias)
    return {typename: parsed[alias]}


@functools.lru_cache(maxsize=1)
def standard_store() -> Typestore:
    """rosbags' store of the ROS 2 Humble types plus :data:`DEFINITIONS`, with classes of
    its own (:func:`safepath.ros.messages.typestore` swaps in the written ones). Built
    once a process."""
    store = get_typestore(ROS_DISTRO_STORE)
    types: dict[str, Any] = {}
    for name, text in DEFINITIONS.items():
        types.update(_parse(name, text))
    store.register(types)
    return store


def _nested(desc: Any) -> Iterator[str]:
    """The type names a field descriptor refers to (a message, or arrays of them)."""
    if desc[0] == Nodetype.NAME:
        yield desc[1]
    elif desc[0] in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        yield from _nested(desc[1][0])


def written_source(store: Typestore) -> str:
    """The Python source of the classes of :data:`WRITTEN_TYPES` and of every type they
    nest, as rosbags' code generator writes a type store module (``FIELDDEFS`` and one
    dataclass per type), from ``store``'s definitions (:func:`standard_store`'s)."""
    found: dict[str, Any] = {}
    todo = list(WRITTEN_TYPES)
    while todo:
        name = todo.pop()
        if name not in found:
            found[name] = store.fielddefs[name]
            todo += [n for _, desc in found[name][1] for n in _nested(desc)]
    return generate_python_code(dict(sorted(found.items())))
