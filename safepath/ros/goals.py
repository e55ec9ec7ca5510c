"""ROS 2 goals from a timed :class:`~safepath.model.trajectory.Trajectory`.

The robot's trajectory controller (action name, joint order, goal tolerances, point
spacing) comes from the trajectory's own robot: the ``controller.yaml`` of its folder
(:class:`~safepath.model.controller_spec.ControllerSpec`), looked up by the robot
name the trajectory records, or given as ``controller=robot.controller``. Robots without
such a file get settings derived from their joint names.

* :func:`follow_joint_trajectory_goal` for the arm's trajectory controller
  (``control_msgs/FollowJointTrajectory``), on any robot. The controller keeps our timing,
  the goal's points are the trajectory's knots, and the motion the controller makes of
  them (its quintic join) is checked against the speed, acceleration and jerk limits
  before the goal is returned.
* :func:`robot_move_goal` for Niryo's arm commander (``RobotMove`` with
  ``EXECUTE_FULL_TRAJ``): the robot keeps the path but re-times it itself.
  ``EXECUTE_RAW_TRAJ`` is not offered: on the robot it reads a field that
  ``JointTrajectory`` does not have and fails.

Gripper events are not part of a trajectory message: the goal builders refuse a
trajectory with an event strictly inside it (a ``TrajectoryError``; the controller would
run through it). :func:`split_at_gripper_events` cuts a trajectory at its (resting)
gripper events so that a node can run motion, gripper, motion, ... each after the
previous one has finished, and :func:`tool_goal` builds Niryo's gripper goals.

Every builder takes ``backend``: ``rosbags`` messages (always available, serialisable
with :func:`safepath.ros.messages.serialize`), native ``rclpy`` messages, or ``auto``.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Collection, Mapping, Sequence
from typing import Any, Literal

import numpy as np

from ..errors import InputError, TrajectoryError
from ..files._io import check_names
from ..model._knots import interval_index
from ..model.controller_spec import ControllerSpec, controller_for
from ..model.execution import check_executed
from ..model.interpolation import Interpolation
from ..model.limits import MotionLimits
from ..model.robot import Robot
from ..model.trajectory import GripperEvent, Trajectory
from ._cdr import check_seconds, joint_trajectory_cdr
from .messages import Backend, MessageFactory, message_factory, serialize

__all__ = [
    "CLOSE_GRIPPER",
    "EXECUTE_FULL_TRAJ",
    "GRIPPER_1_TOOL_ID",
    "OPEN_GRIPPER",
    "ROBOT_MOVE_ACTION",
    "TOOL_ACTION",
    "check_start",
    "controller_of",
    "follow_joint_trajectory_goal",
    "joint_trajectory",
    "robot_move_goal",
    "split_at_gripper_events",
    "tool_goal",
    "tool_goals",
    "trajectory_between",
]

#: Niryo's arm commander action (``RobotMove``), Ned robots only.
ROBOT_MOVE_ACTION = "/niryo_robot_arm_commander/robot_action"
#: Niryo's tools commander action (``Tool``), Ned robots only.
TOOL_ACTION = "/niryo_robot_tools_commander/action_server"
EXECUTE_FULL_TRAJ = 11
OPEN_GRIPPER = 1
CLOSE_GRIPPER = 2
GRIPPER_1_TOOL_ID = 11
#: Largest joint speed at a gripper event that still counts as "at rest" [rad/s].
REST_SPEED = 1e-3

_NS = 1_000_000_000
_NIRYO = "niryo_ned_ros2_interfaces"
_JT = "trajectory_msgs/msg/JointTrajectory"
_JT_TYPES = (_JT, "trajectory_msgs/msg/JointTrajectoryPoint",
             "std_msgs/msg/Header", "builtin_interfaces/msg/Time",
             "builtin_interfaces/msg/Duration")


@dataclasses.dataclass(frozen=True)
class _Points:
    """Trajectory samples in the robot's joint order, times in integer [ns], and how the
    controller they are for joins them (which fields its points carry)."""

    names: tuple[str, ...]
    time_ns: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    interpolation: Interpolation


def _validated(traj: Trajectory) -> Trajectory:
    """Re-run the Trajectory checks: its arrays may have been changed in place since."""
    return dataclasses.replace(traj)


def _refuse_events_inside(traj: Trajectory) -> None:
    """Refuse a trajectory with a gripper event strictly inside its time span.

    A goal carries the arm's motion only: sent whole, the controller runs straight
    through the event and the gripper never acts. Events at its very start or end are
    fine (the node runs them before or after the goal).
    """
    t0, t1 = float(traj.t[0]), float(traj.t[-1])
    for k, event in enumerate(sorted(traj.events, key=lambda e: e.time)):
        if t0 + 1e-9 < event.time < t1 - 1e-9:
            raise TrajectoryError(
                f"gripper event '{event.action}' of step '{event.step}' at t={event.time:.3f} "
                f"s lies inside route '{traj.route or traj.robot or 'trajectory'}' "
                f"([{t0:.3f}, {t1:.3f}] s): one goal would run through it and the gripper "
                "would never act; send the motions of split_at_gripper_events(traj) one "
                "after another", key=f"events[{k}]")


def controller_of(traj: Trajectory, controller: ControllerSpec | None = None
                  ) -> ControllerSpec:
    """The trajectory controller that ``traj``'s goals address.

    ``controller`` if given, else the ``controller.yaml`` of the bundled robot the
    trajectory names, else settings derived from the trajectory's joint names.

    Raises:
        ConfigError: The robot's ``controller.yaml`` is malformed or names other joints.
    """
    if controller is not None:
        return controller
    return controller_for(traj.robot, traj.joint_names)


def _robot_columns(traj: Trajectory, robot_joint_names: Sequence[str]) -> tuple[
        tuple[str, ...], list[int]]:
    """The robot's joint names and, for each, its column in ``traj``."""
    robot = tuple(robot_joint_names)
    if len(set(robot)) != len(robot):
        raise TrajectoryError(f"duplicate robot joint names {list(robot)}",
                              key="robot_joint_names")
    if sorted(traj.joint_names) != sorted(robot):
        raise TrajectoryError(f"trajectory joints {list(traj.joint_names)} do not match the "
                              f"robot's {list(robot)}", key="joint_names")
    return robot, [traj.joint_names.index(name) for name in robot]


def _period_ns(period: float) -> int:
    if isinstance(period, bool) or not isinstance(period, (int, float)) \
            or not math.isfinite(period) or period <= 0:
        raise TrajectoryError(f"sampling period must be a number > 0 [s], got {period!r}",
                              key="period")
    period_ns = round(period * _NS)
    if period_ns < 1:
        raise TrajectoryError(f"sampling period {period!r} s is below 1 ns", key="period")
    return period_ns


def _points(traj: Trajectory, period: float | None, robot_joint_names: Sequence[str] | None,
            controller: ControllerSpec | None,
            limits: MotionLimits | None = None) -> _Points:
    """The goal's points: every knot of ``traj`` (times from its start), and where two
    knots are more than ``period`` [s] apart, points of their join between them (which
    joins them into the same polynomial), in the controller's joint order; then the motion
    the controller executes from them is checked against the joint limits."""
    spec = controller_of(traj, controller)
    period = spec.period if period is None else period
    robot_joint_names = spec.joint_names if robot_joint_names is None else robot_joint_names
    period_ns = _period_ns(period)
    traj = _validated(traj)
    names, cols = _robot_columns(traj, robot_joint_names)
    # Integer nanoseconds, as the message carries them.
    knot_ns = np.round((traj.t - traj.t[0]) * _NS).astype(np.int64)
    gaps = np.diff(knot_ns)
    extra = np.maximum(-(-gaps // period_ns) - 1, 0)
    if traj.t.size > 1 and extra.any():
        # Inserted points on whole nanoseconds too, sampled from the knots' own join
        # at exactly those times (which keeps the join what it was).
        inserted = np.concatenate([knot_ns[k] + (np.arange(1, e + 1) * gaps[k]) // (e + 1)
                                   for k, e in enumerate(extra)])
        time_ns = np.sort(np.concatenate([knot_ns, inserted]))
        q, qd, qdd = traj.sample(traj.t[0] + time_ns / _NS)
        keep = np.isin(time_ns, knot_ns)
        q[keep], qd[keep], qdd[keep] = traj.q, traj.qd, traj.qdd
    else:
        time_ns, q, qd, qdd = knot_ns, traj.q, traj.qd, traj.qdd
    if time_ns.size > 1 and np.any(np.diff(time_ns) <= 0):
        raise TrajectoryError("two points less than 1 ns apart", key="t")
    pts = _Points(names, time_ns, q[:, cols], qd[:, cols], qdd[:, cols], spec.interpolation)
    _check_executed(traj, pts, spec, limits, cols)
    return pts


def _check_executed(traj: Trajectory, pts: _Points, spec: ControllerSpec,
                    limits: MotionLimits | None, cols: list[int]) -> None:
    """Check the motion ``spec``'s controller executes from ``pts`` against the limits the
    trajectory was timed under (``limits``, else its own :attr:`~Trajectory.limits`)."""
    limits = limits if limits is not None else traj.limits
    if limits is None:
        raise TrajectoryError(
            "the trajectory carries no joint limits to check the motion the controller "
            "executes against: pass limits=robot (or its motion_limits)", key="limits")
    if limits.dof != traj.dof:
        raise TrajectoryError(f"expected the limits of {traj.dof} joints, got {limits.dof}",
                              key="limits")
    vmax, amax, jmax = (x[cols] for x in limits.arrays())
    check_executed(pts.time_ns / _NS, pts.q, pts.qd, pts.qdd, velocity_limits=vmax,
                   acceleration_limits=amax, jerk_limits=jmax,
                   interpolation=pts.interpolation,
                   what=f"goal of '{traj.route or traj.robot or 'trajectory'}'")


def _limits(limits: MotionLimits | Robot | None) -> MotionLimits | None:
    """``limits=`` of the goal builders: a robot or its :class:`MotionLimits`, or None for
    the trajectory's own."""
    if limits is None or isinstance(limits, MotionLimits):
        return limits
    if isinstance(limits, Robot):
        return limits.motion_limits
    raise TrajectoryError(f"expected a robot or MotionLimits, got {type(limits).__name__}",
                          key="limits")


def _duration(f: MessageFactory, time_ns: int) -> Any:
    sec, nanosec = divmod(int(time_ns), _NS)
    return f.new("builtin_interfaces/msg/Duration", sec=sec, nanosec=nanosec)


def _fields(pts: _Points) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The points' positions, velocities, accelerations and efforts as their message
    carries them: the fields the controller's interpolation reads, no others (a
    controller joins points carrying accelerations as quintics, whatever it was
    configured for)."""
    qd = pts.qd if pts.interpolation.uses_velocities else pts.qd[:, :0]
    qdd = pts.qdd if pts.interpolation.uses_accelerations else pts.qdd[:, :0]
    return pts.q, qd, qdd, pts.q[:, :0]


def _build_joint_trajectory(f: MessageFactory, pts: _Points, stamp_ns: int) -> Any:
    sec, nanosec = divmod(int(stamp_ns), _NS)
    header = f.new("std_msgs/msg/Header", frame_id="",
                   stamp=f.new("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec))
    # Thousands of points per goal: the classes are looked up once, the arrays cut into
    # rows once.
    point, duration = (f.cls(name) for name in ("trajectory_msgs/msg/JointTrajectoryPoint",
                                                "builtin_interfaces/msg/Duration"))
    points = [
        point(positions=q, velocities=v, accelerations=a, effort=e,
              time_from_start=duration(sec=sec, nanosec=nanosec))
        for q, v, a, e, (sec, nanosec) in zip(
            *(f.float_rows(x) for x in _fields(pts)),
            (divmod(int(t), _NS) for t in pts.time_ns), strict=True)
    ]
    return f.new(_JT, header=header, joint_names=list(pts.names), points=points)


def _joint_trajectory_cdr(traj: Trajectory, *, period: float | None,
                          robot_joint_names: Sequence[str] | None, stamp_ns: int
                          ) -> tuple[bytes, int]:
    """The CDR bytes of :func:`joint_trajectory`'s rosbags message (the same bytes, its
    points laid out at once: :mod:`._cdr`, for a bag's thousands of points), checked and
    refused as :func:`joint_trajectory` checks and refuses, and its last point's
    ``time_from_start`` [ns].

    Raises:
        RosError: ``stamp_ns`` past what a ROS 2 Time holds; as :func:`joint_trajectory`.
    """
    check_seconds(stamp_ns, "header.stamp")
    _refuse_events_inside(traj)
    pts = _points(traj, period, robot_joint_names, None)
    none = dataclasses.replace(pts, time_ns=pts.time_ns[:0], q=pts.q[:0], qd=pts.qd[:0],
                               qdd=pts.qdd[:0])
    prefix = serialize(_build_joint_trajectory(MessageFactory("rosbags"), none, stamp_ns), _JT)
    return joint_trajectory_cdr(prefix, _fields(pts), pts.time_ns), int(pts.time_ns[-1])


def joint_trajectory(traj: Trajectory, *, period: float | None = None,
                     robot_joint_names: Sequence[str] | None = None,
                     controller: ControllerSpec | None = None, stamp_ns: int = 0,
                     limits: MotionLimits | Robot | None = None, backend: Backend = "auto") -> Any:
    """``trajectory_msgs/msg/JointTrajectory`` of ``traj``'s knots.

    Points carry positions [rad], velocities [rad/s], accelerations [rad/s^2] and
    ``time_from_start`` (rounded to the nanosecond): every knot of ``traj``, so that the
    controller's quintic join of the points (position, velocity and acceleration matched
    at both ends, as ros2_control's ``joint_trajectory_controller`` joins them) is the
    trajectory's own motion, the one safepath verified. Where two knots are more than
    ``period`` apart, points of that quintic are added (they join into the same quintic).
    Columns come in the controller's joint order, whatever the order in ``traj``.

    Before the message is built, the motion the controller executes from these points is
    checked at every instant (:func:`safepath.model.execution.check_executed`: speed on a >= 1
    kHz grid with a bound between samples, acceleration and jerk exactly) against the
    joint limits the trajectory was timed under; nothing over a limit is ever returned.

    Args:
        traj: The timed trajectory.
        period: Largest time between points [s]; default: the controller's.
        robot_joint_names: The controller's joint names; default: the controller's.
        controller: The robot's trajectory controller; default: the one of the robot
            ``traj`` names (see :func:`controller_of`).
        stamp_ns: ``header.stamp`` [ns]; 0 asks the controller to start on receipt.
        limits: The robot (or its :class:`~safepath.model.limits.MotionLimits`) whose
            velocity, acceleration and jerk limits the executed motion is checked
            against; default: the trajectory's own :attr:`~Trajectory.limits`.
        backend: ``auto``, ``rosbags`` or ``rclpy`` (see
            :func:`safepath.ros.messages.message_factory`).

    Raises:
        TrajectoryError: A gripper event strictly inside ``traj`` (send the motions of
            :func:`split_at_gripper_events`), joint names that do not match the robot's,
            times not strictly increasing, non-finite values, a period that is not > 0,
            or no limits.
        ExecutedLimitError: The controller's join of the points would break a limit.
        RosError: ``backend='rclpy'`` without a ROS 2 installation.
    """
    _refuse_events_inside(traj)
    pts = _points(traj, period, robot_joint_names, controller, _limits(limits))
    return _build_joint_trajectory(message_factory(backend, _JT_TYPES), pts, stamp_ns)


def follow_joint_trajectory_goal(
        traj: Trajectory, *, period: float | None = None,
        robot_joint_names: Sequence[str] | None = None,
        goal_tolerance: Sequence[float] | None | Literal["controller"] = "controller",
        goal_time_tolerance: float | None = None,
        controller: ControllerSpec | None = None, stamp_ns: int = 0,
        limits: MotionLimits | Robot | None = None, backend: Backend = "auto") -> Any:
    """``control_msgs/action/FollowJointTrajectory_Goal`` for the arm's trajectory controller.

    Send it to the controller's ``follow_joint_trajectory_action``
    (``controller_of(traj).follow_joint_trajectory_action``). The controller executes the
    points with our timing. Path tolerances are left to the controller's defaults.

    Args:
        traj: The timed trajectory.
        period: Largest time between points [s] (see :func:`joint_trajectory`).
        robot_joint_names: The controller's joint names; default: the controller's.
        goal_tolerance: Final position tolerance per controller joint [rad]; None sends
            none (the controller's own apply); default: the robot's ``controller.yaml``.
        goal_time_tolerance: Time allowed after the end to reach the goal [s]; default:
            the controller's.
        controller: The robot's trajectory controller; default: the one of the robot
            ``traj`` names (see :func:`controller_of`).
        limits: The robot (or its limits) the executed motion is checked against (see
            :func:`joint_trajectory`); default: the trajectory's own.
        stamp_ns: ``trajectory.header.stamp`` [ns]: the clock time of the trajectory's
            t = 0 (0: start on receipt). A stamp in the past makes the controller join the
            trajectory where it is by then (how a stop replaces a running motion).
        backend: ``auto``, ``rosbags`` or ``rclpy``.

    Raises:
        TrajectoryError: A gripper event strictly inside ``traj`` (see
            :func:`split_at_gripper_events`), a bad trajectory, period or tolerances.
        RosError: ``backend='rclpy'`` without control_msgs.
    """
    _refuse_events_inside(traj)
    spec = controller_of(traj, controller)
    pts = _points(traj, period, robot_joint_names, spec, _limits(limits))
    if isinstance(goal_tolerance, str):
        if goal_tolerance != "controller":
            raise TrajectoryError(f"expected tolerances [rad], None or 'controller', got "
                                  f"{goal_tolerance!r}", key="goal_tolerance")
        goal_tolerance = _reordered(spec.goal_tolerance, spec.joint_names, pts.names)
    tolerance = [] if goal_tolerance is None else [float(v) for v in goal_tolerance]
    if tolerance and (len(tolerance) != len(pts.names)
                      or not all(math.isfinite(v) and v >= 0 for v in tolerance)):
        raise TrajectoryError(f"expected {len(pts.names)} finite tolerances >= 0 [rad], "
                              f"got {list(goal_tolerance or [])}", key="goal_tolerance")
    if goal_time_tolerance is None:
        goal_time_tolerance = spec.goal_time_tolerance
    if not math.isfinite(goal_time_tolerance) or goal_time_tolerance < 0:
        raise TrajectoryError(f"must be >= 0 [s], got {goal_time_tolerance}",
                              key="goal_time_tolerance")
    f = message_factory(backend, (*_JT_TYPES, "control_msgs/msg/JointTolerance",
                                  "control_msgs/action/FollowJointTrajectory_Goal",
                                  "trajectory_msgs/msg/MultiDOFJointTrajectory"))
    no_multi_dof = f.new("trajectory_msgs/msg/MultiDOFJointTrajectory",
                         header=f.new("std_msgs/msg/Header", frame_id="",
                                      stamp=f.new("builtin_interfaces/msg/Time", sec=0,
                                                  nanosec=0)),
                         joint_names=[], points=[])
    goal_tol = [f.new("control_msgs/msg/JointTolerance", name=name, position=value,
                      velocity=0.0, acceleration=0.0)
                for name, value in zip(pts.names, tolerance, strict=True)] if tolerance else []
    return f.new("control_msgs/action/FollowJointTrajectory_Goal",
                 trajectory=_build_joint_trajectory(f, pts, stamp_ns),
                 multi_dof_trajectory=no_multi_dof, path_tolerance=[],
                 component_path_tolerance=[], goal_tolerance=goal_tol,
                 component_goal_tolerance=[],
                 goal_time_tolerance=_duration(f, round(goal_time_tolerance * _NS)))


def _reordered(values: Sequence[float] | None, names: Sequence[str], order: Sequence[str]
               ) -> list[float] | None:
    """Per-joint ``values`` given in ``names`` order, in ``order`` instead."""
    if values is None:
        return None
    by_name = dict(zip(names, values, strict=True))
    if set(by_name) != set(order):
        raise TrajectoryError(f"controller tolerances are for {list(names)}, the goal's joints "
                              f"are {list(order)}", key="goal_tolerance")
    return [by_name[n] for n in order]


def robot_move_goal(traj: Trajectory, *, period: float | None = None,
                    robot_joint_names: Sequence[str] | None = None,
                    controller: ControllerSpec | None = None,
                    backend: Backend = "auto") -> Any:
    """Niryo ``RobotMove`` goal running ``traj`` as ``EXECUTE_FULL_TRAJ`` (Ned robots).

    Send it to :data:`ROBOT_MOVE_ACTION`. The arm commander checks the points against
    the position limits, moves from where the arm is to the first point, then **re-times
    the whole path itself**: our velocities and times are dropped, so the executed
    speeds are not the ones safepath verified. The dense points keep the path (and so
    its collision check); prefer :func:`follow_joint_trajectory_goal`.

    Raises:
        TrajectoryError: A gripper event strictly inside ``traj``, a bad trajectory or
            period.
        RosError: ``backend='rclpy'`` without niryo_ned_ros2_interfaces.
    """
    _refuse_events_inside(traj)
    pts = _points(traj, period, robot_joint_names, controller)
    f = message_factory(backend, (*_JT_TYPES, f"{_NIRYO}/action/RobotMove_Goal",
                                  f"{_NIRYO}/msg/ArmMoveCommand", f"{_NIRYO}/msg/RPY",
                                  f"{_NIRYO}/msg/ShiftPose", "geometry_msgs/msg/Point",
                                  "geometry_msgs/msg/Quaternion"))
    cmd = f.new(f"{_NIRYO}/msg/ArmMoveCommand", cmd_type=EXECUTE_FULL_TRAJ,
                tcp_version=0,  # read for pose commands only
                joints=f.floats([]), position=f.new("geometry_msgs/msg/Point", x=0.0, y=0.0,
                                                    z=0.0),
                rpy=f.new(f"{_NIRYO}/msg/RPY", roll=0.0, pitch=0.0, yaw=0.0),
                orientation=f.new("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
                shift=f.new(f"{_NIRYO}/msg/ShiftPose", axis_number=0, value=0.0),
                list_poses=[], dist_smoothing=0.0,
                trajectory=_build_joint_trajectory(f, pts, 0), args=f.floats([]))
    return f.new(f"{_NIRYO}/action/RobotMove_Goal", cmd=cmd)


def _check_int(value: int, low: int, high: int, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(f"expected an integer in [{low}, {high}], got {value!r}", key=key)
    return value


def tool_goal(action: Literal["open", "close"], *, tool_id: int = GRIPPER_1_TOOL_ID,
              max_torque: int = 100, hold_torque: int = 100,
              backend: Backend = "auto") -> Any:
    """Niryo ``Tool`` goal opening or closing a gripper (send to :data:`TOOL_ACTION`).

    Args:
        action: ``open`` or ``close``.
        tool_id: Niryo tool id (Gripper 1, the cell's custom gripper, is 11).
        max_torque: Torque while moving [% of max], 0..100.
        hold_torque: Torque once closed or open [% of max], 0..100.
        backend: ``auto``, ``rosbags`` or ``rclpy``.

    Raises:
        InputError: Unknown action or an out-of-range number.
        RosError: ``backend='rclpy'`` without niryo_ned_ros2_interfaces.
    """
    codes = {"open": OPEN_GRIPPER, "close": CLOSE_GRIPPER}
    check_names([action], codes, path=None, key="action", what="gripper action",
                error=InputError)
    f = message_factory(backend, (f"{_NIRYO}/action/Tool_Goal", f"{_NIRYO}/msg/ToolCommand"))
    cmd = f.new(f"{_NIRYO}/msg/ToolCommand", cmd_type=codes[action],
                tool_id=_check_int(tool_id, -128, 127, "tool_id"), speed=0,
                max_torque_percentage=_check_int(max_torque, 0, 100, "max_torque"),
                hold_torque_percentage=_check_int(hold_torque, 0, 100, "hold_torque"),
                activate=False, gpio="")
    return f.new(f"{_NIRYO}/action/Tool_Goal", cmd=cmd)


def tool_goals(traj: Trajectory, *, tool_id: int = GRIPPER_1_TOOL_ID, max_torque: int = 100,
               hold_torque: int = 100, backend: Backend = "auto"
               ) -> list[tuple[GripperEvent, Any]]:
    """A :func:`tool_goal` for each gripper event of ``traj``, in time order."""
    return [(event, tool_goal(event.action, tool_id=tool_id, max_torque=max_torque,
                              hold_torque=hold_torque, backend=backend))
            for event in sorted(traj.events, key=lambda e: e.time)]


def trajectory_between(traj: Trajectory, t_from: float, t_to: float,
                       index: int = 0) -> Trajectory:
    """The part of ``traj`` between two of its times [s], re-timed to start at 0.

    The knots of ``traj`` strictly inside ``(t_from, t_to)`` are kept, with the states
    sampled at both ends (the very last state of ``traj`` exactly, when ``t_to`` reaches
    its end); each knot keeps its route step. Gripper events are left out. ``info`` gets
    ``segment`` (``index``: which motion of the route this is, as
    :func:`split_at_gripper_events` counts them) and ``time_offset`` (``t_from``: where
    the part started in ``traj``).

    Args:
        traj: The trajectory.
        t_from: Start of the part, within ``traj``'s time span [s].
        t_to: End of the part, after ``t_from`` [s].
        index: The part's number, stored as ``info['segment']``.
    """
    inner = traj.t[(traj.t > t_from + 1e-9) & (traj.t < t_to - 1e-9)]
    times = np.concatenate([[t_from], inner, [t_to]])
    q, qd, qdd = traj.sample(times)
    if t_to >= traj.t[-1]:
        q[-1], qd[-1], qdd[-1] = traj.q[-1], traj.qd[-1], traj.qdd[-1]
    knot = interval_index(traj.t, times, traj.t.size)
    info = {**traj.info, "segment": index, "time_offset": t_from}
    return Trajectory(traj.joint_names, times - t_from, q, qd, qdd, traj.step_index[knot],
                      traj.steps, (), traj.robot, traj.route, info, traj.limits,
                      traj.interpolation)


def split_at_gripper_events(traj: Trajectory) -> list[Trajectory | GripperEvent]:
    """``traj`` as the sequence to execute: motions and gripper events, in time order.

    A motion goal that has succeeded means the arm is at its end, at rest; only then
    may the gripper act, and only once the gripper has finished may the next motion
    start. Firing the gripper on a clock while one long trajectory runs would instead
    bet on both ends keeping time. Motions of zero duration (an event at the very start
    or end) are left out; each motion keeps the route's step names and starts at t=0
    (``info['time_offset']`` holds where it started in ``traj``).

    Raises:
        TrajectoryError: An event outside the trajectory's time span, or where the arm
            is not at rest (a joint faster than :data:`REST_SPEED`).
    """
    traj = _validated(traj)
    events = sorted(traj.events, key=lambda e: e.time)
    for k, event in enumerate(events):
        if not (math.isfinite(event.time) and traj.t[0] - 1e-9 <= event.time <= traj.t[-1] + 1e-9):
            raise TrajectoryError(f"gripper event at t={event.time} s is outside "
                                  f"[{traj.t[0]}, {traj.t[-1]}] s", key=f"events[{k}]")
        speed = float(np.max(np.abs(traj.sample([event.time])[1])))
        if speed > REST_SPEED:
            raise TrajectoryError(f"arm not at rest at the '{event.action}' in step "
                                  f"'{event.step}' (t={event.time:.3f} s, joint speed "
                                  f"{speed:.3g} rad/s)", key=f"events[{k}]")
    cuts = sorted({float(np.clip(e.time, traj.t[0], traj.t[-1])) for e in events})
    bounds = [float(traj.t[0]), *cuts, float(traj.t[-1])]
    out: list[Trajectory | GripperEvent] = []
    done = n_motions = 0
    for t_from, t_to in itertools.pairwise(bounds):
        while done < len(events) and events[done].time <= t_from + 1e-9:
            out.append(events[done])
            done += 1
        if t_to - t_from > 1e-9:
            out.append(trajectory_between(traj, t_from, t_to, n_motions))
            n_motions += 1
    out.extend(events[done:])
    return out


def check_start(traj: Trajectory, positions: Mapping[str, float], *,
                tolerance: float = 0.05, continuous: Collection[str] = ()) -> None:
    """Refuse to start ``traj`` unless the arm is at its first point.

    A trajectory controller given a first point away from the arm's pose bridges the gap
    within one control cycle, a jump. Tracking error after a successful goal stays
    within the goal tolerance (<= 0.03 rad); the default catches an arm that is
    somewhere else (after a fault, a manual move), not tracking error.

    A continuous joint's measured angle may lie any number of whole turns from the
    trajectory's (``/joint_states`` may report it wrapped): its difference is taken
    modulo a turn, as ros2_control's joint_trajectory_controller does for a URDF
    ``continuous`` joint (it moves its own start by whole turns next to the goal's first
    point, then follows the points as they are: see docs/ros.md).

    Args:
        traj: The trajectory about to be sent.
        positions: Measured joint positions by name [rad] (e.g. from ``/joint_states``).
        tolerance: Largest allowed difference per joint [rad].
        continuous: Names of the continuous joints (``[n for n, c in
            zip(robot.joint_names, robot.continuous) if c]``).

    Raises:
        TrajectoryError: A joint missing from ``positions`` or too far from the start.
    """
    for k, name in enumerate(traj.joint_names):
        if name not in positions:
            raise TrajectoryError(f"no measured position for '{name}'", key="positions")
        error = abs(float(positions[name]) - float(traj.q[0, k]))
        if name in continuous:  # the nearest whole number of turns away
            error = abs(math.remainder(error, 2.0 * math.pi))
        if not error <= tolerance:
            raise TrajectoryError(f"'{name}' is {error:.4f} rad from the start of route "
                                  f"'{traj.route}' (tolerance {tolerance} rad)",
                                  key="positions")
