#!/usr/bin/env python3
"""Gravimetric pour on a Kinova Gen3 Lite (or any robot with a controller.yaml): the
safepath tilt, stopped on the scale's reading and brought back upright, run by a ROS 2 node.

Every decision is taken by :class:`safepath.cells.pouring.controller.PourController`, built from
the node's parameters by :func:`safepath.cells.pouring.setup.build_pour`; this file connects its
events and commands to ROS 2: the scale on ``/weight`` (``std_msgs/Float32``
[g], as the brief's Arduino node publishes it), the arm's trajectory controller
(FollowJointTrajectory, safepath's verified timing executed, each goal stamped with the
clock time of its first point), the gripper (GripperCommand) and a 50 Hz timer. Robot,
scene, tilt and scale are parameters (``pour_params.yaml``, the fields of
``PourParameters``); the actions come from the robot's ``controller.yaml``
(``robots/gen3_lite``: ros2_kortex's ``joint_trajectory_controller`` and
``gen3_lite_2f_gripper_controller``). The pour begins on ``~/start``.

With ``pick_route`` / ``place_route`` set, the node plans those routes of the scene first
(their gripper events become GripperCommand goals) and runs pick, pour, place; without,
the arm must already hold the cup at ``pour_pose``.

Needs a sourced ROS 2 workspace with ``control_msgs`` and a running driver, e.g.
``ros2 launch kortex_bringup gen3_lite.launch.py robot_ip:=<ip>``::

    python3 examples/ros2/pour_node.py --ros-args --params-file examples/ros2/pour_params.yaml
    ros2 service call /safepath_pour/start std_srvs/srv/Trigger   # pick, pour, place
    ros2 service call /safepath_pour/kill std_srvs/srv/Trigger    # stop now (brakes on the path)
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory, GripperCommand
from rclpy.action import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32, String
from std_srvs.srv import Trigger

from safepath.cells.pouring.controller import PourCommand, SendArmGoal, SendGripperGoal
from safepath.cells.pouring.setup import PourParameters, build_pour
from safepath.errors import SafepathError
from safepath.ros import goals, gripper_command_goal, gripper_of
from safepath.ros.commands import CancelGoal

_NS = 1_000_000_000


class PourNode(Node):
    """The pour controller's events and commands, on ROS 2."""

    def __init__(self) -> None:
        super().__init__("safepath_pour")
        # Every field of PourParameters is a parameter; those without a default must be
        # given (pour_params.yaml), and each is checked with a typed error naming it.
        values = {}
        for f in dataclasses.fields(PourParameters):
            default = None if f.default is dataclasses.MISSING else f.default
            value = self.declare_parameter(f.name, default).value
            if value is not None:
                values[f.name] = list(value) if isinstance(value, (tuple, list)) else value
        params = PourParameters.from_mapping(values)
        setup = build_pour(params)  # plans the tilt (and pick/place) before anything moves
        self.robot, self.ctrl = setup.cell.robot, setup.controller
        self.get_logger().info(f"tilt planned: {setup.tilt.trajectory.duration:.2f} s to "
                               f"{math.degrees(setup.tilt.tilt[-1]):.1f} deg")
        self._lock = threading.RLock()  # re-entrant: a done callback may fire inline
        self._handles: dict[int, Any] = {}
        self._positions: dict[str, float] = {}
        group = ReentrantCallbackGroup()
        spec = self.robot.controller  # robots/<robot>/controller.yaml
        self._arm = ActionClient(self, FollowJointTrajectory,
                                 spec.follow_joint_trajectory_action, callback_group=group)
        self._gripper = ActionClient(self, GripperCommand, gripper_of(self.robot).action,
                                     callback_group=group) if spec.gripper else None
        self._log = self.create_publisher(String, "~/events", 10)
        self.create_subscription(Float32, params.weight_topic, self._on_weight, 10,
                                 callback_group=group)
        self.create_subscription(JointState, "/joint_states", self._on_joints, 10,
                                 callback_group=group)
        self.create_timer(0.02, lambda: self.dispatch(self.ctrl.on_tick), callback_group=group)
        self.create_service(Trigger, "~/kill", self._on_kill, callback_group=group)
        self.create_service(Trigger, "~/start", self._on_start, callback_group=group)

    # -- events ----------------------------------------------------------------------------
    def now(self) -> float:
        """The ROS clock [s]: the controller's time and the goals' stamps."""
        return self.get_clock().now().nanoseconds / _NS

    def dispatch(self, event: Callable[[float], list[PourCommand]]) -> None:
        with self._lock:
            for cmd in event(self.now()):
                if isinstance(cmd, SendArmGoal):
                    self.move(cmd)
                elif isinstance(cmd, SendGripperGoal):
                    self.grip(cmd)
                elif isinstance(cmd, CancelGoal):
                    self.cancel(cmd)
                else:  # PourReport, Fault
                    self.report(cmd)

    def goal_done(self, goal_id: int, success: bool, message: str) -> None:
        self.dispatch(lambda now: self.ctrl.on_goal_result(goal_id, success, message, now))

    def _on_weight(self, msg: Float32) -> None:
        stamp = self.now()  # Float32 has no header: the reading is stamped on arrival
        self.dispatch(lambda now: self.ctrl.on_weight(float(msg.data), stamp, now))

    def _on_joints(self, msg: JointState) -> None:
        self._positions = dict(zip(msg.name, msg.position, strict=False))

    def _on_start(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        self.dispatch(self.ctrl.start)
        response.success, response.message = True, self.ctrl.state.value
        return response

    def _on_kill(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        self.dispatch(self.ctrl.kill)
        response.success, response.message = True, self.ctrl.state.value
        return response

    # -- commands --------------------------------------------------------------------------
    def move(self, cmd: SendArmGoal) -> None:
        try:
            if cmd.purpose != "stop":  # a stop joins the running motion where it is
                goals.check_start(cmd.trajectory, self._positions)
            goal = goals.follow_joint_trajectory_goal(
                cmd.trajectory, controller=self.robot.controller,
                stamp_ns=round(cmd.start_time * _NS), backend="rclpy")
        except SafepathError as exc:
            self.goal_done(cmd.goal_id, False, str(exc))
            return
        if cmd.purpose == "pour":
            handle_feedback = self._feedback(cmd.goal_id)
        else:
            handle_feedback = None
        self._send(self._arm, goal, cmd.goal_id,
                   lambda r: (r.error_code == r.SUCCESSFUL, r.error_string), handle_feedback)

    def _feedback(self, goal_id: int) -> Callable[[Any], None]:
        def on_feedback(msg: Any) -> None:
            tfs = msg.feedback.desired.time_from_start
            progress = tfs.sec + tfs.nanosec / _NS
            self.dispatch(lambda now: self.ctrl.on_arm_feedback(goal_id, progress, now))
        return on_feedback

    def grip(self, cmd: SendGripperGoal) -> None:
        if self._gripper is None:
            self.goal_done(cmd.goal_id, False, f"robot '{self.robot.name}' has no gripper "
                           f"section in its controller.yaml")
            return
        goal = gripper_command_goal(self.robot, cmd.event.action, backend="rclpy")
        self._send(self._gripper, goal, cmd.goal_id,
                   lambda r: (bool(r.reached_goal or r.stalled), f"at {r.position:.3f}"), None)

    def _send(self, client: ActionClient, goal: Any, goal_id: int,
              judge: Callable[[Any], tuple[bool, str]],
              feedback: Callable[[Any], None] | None) -> None:
        def on_result(future: Future[Any]) -> None:
            self._handles.pop(goal_id, None)
            try:
                answer = future.result()
                ok, message = judge(answer.result)
                ok = ok and answer.status == GoalStatus.STATUS_SUCCEEDED
            except Exception as exc:  # noqa: BLE001 - a lost result is a failed goal
                ok, message = False, f"no result: {exc}"
            self.goal_done(goal_id, ok, message)

        def on_accepted(future: Future[Any]) -> None:
            try:
                handle = future.result()
            except Exception as exc:  # noqa: BLE001
                self.goal_done(goal_id, False, f"not sent: {exc}")
                return
            if not handle.accepted:
                self.goal_done(goal_id, False, "goal rejected")
                return
            self._handles[goal_id] = handle
            handle.get_result_async().add_done_callback(on_result)

        # An absent server never answers: the controller's time-out turns that into a fault.
        client.send_goal_async(goal, feedback_callback=feedback).add_done_callback(on_accepted)

    def cancel(self, cmd: CancelGoal) -> None:
        handle = self._handles.pop(cmd.goal_id, None)
        if handle is not None:
            handle.cancel_goal_async()

    def report(self, cmd: PourCommand) -> None:
        record = {"type": type(cmd).__name__, **dataclasses.asdict(cmd)}  # type: ignore[call-overload]
        self._log.publish(String(data=json.dumps(record)))
        self.get_logger().info(json.dumps(record))


def main() -> None:
    rclpy.init()
    node = PourNode()
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
