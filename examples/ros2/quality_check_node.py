#!/usr/bin/env python3
"""Quality-check cell on a Niryo Ned3 Pro: safepath routes, run by a ROS 2 node.

Every decision is taken by
:class:`safepath.cells.quality_check.controller.QualityCheckController`; this file connects
its events and commands to ROS 2. Conveyor and robot are two nodes in one
``MultiThreadedExecutor``; every call is asynchronous, answered via ``add_done_callback``.
Routes are planned once at start-up (``RuntimePlanner``); motions go to the arm's
trajectory controller (FollowJointTrajectory: safepath's verified timing is executed),
gripper events to the Tool action, and the verdict comes from the GetSafety service.
Cycle and trajectory times are published on ``/quality_check/cycle`` for the HMI.

Needs a sourced ROS 2 workspace with ``niryo_ned_ros2_interfaces``, ``control_msgs`` and
``rpi_manager``::

    python3 examples/ros2/quality_check_node.py --ros-args -p scene:=scenes/quality_check_cell
    ros2 service call /quality_check_robot/reset std_srvs/srv/Trigger   # after a fault
"""

from __future__ import annotations

import dataclasses
import json
import threading
import time
from collections.abc import Callable
from concurrent.futures import CancelledError, Future
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from niryo_ned_ros2_interfaces.action import Tool
from niryo_ned_ros2_interfaces.msg import DigitalIOState
from niryo_ned_ros2_interfaces.srv import ControlConveyor
from rclpy.action import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rpi_manager.srv import GetSafety
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from safepath import load_robot, runtime  # RuntimePlanner: plans routes in the background
from safepath.cells.quality_check.controller import (
    ActuateGripper,
    CancelGoal,
    Command,
    ControllerOptions,
    MoveArm,
    QualityCheckController,
    RequestVerdict,
    SetConveyor,
)
from safepath.errors import SafepathError
from safepath.model.trajectory import Trajectory
from safepath.ros import goals

NIRYO_SUCCESS = 1  # niryo_robot_msgs/CommandStatus.SUCCESS
SENSOR_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                        depth=10)


class Cell:
    """Feeds events to the controller one at a time and hands its commands to the nodes."""

    def __init__(self, options: ControllerOptions) -> None:
        self.ctrl = QualityCheckController(options)
        self._lock = threading.RLock()  # re-entrant: a done callback may fire inline
        self.robot: RobotNode
        self.conveyor: ConveyorNode
        self.planner: runtime.RuntimePlanner | None = None

    def dispatch(self, event: Callable[[float], list[Command]]) -> None:
        handlers: dict[type, Callable[[Any], None]] = {
            SetConveyor: self.conveyor.set_running, MoveArm: self.robot.move,
            ActuateGripper: self.robot.grip, RequestVerdict: self.robot.request_verdict,
            CancelGoal: self.robot.cancel}
        with self._lock:
            for cmd in event(time.monotonic()):
                handlers.get(type(cmd), self.robot.report)(cmd)  # else CycleReport, Fault

    def goal_done(self, goal_id: int, success: bool, message: str) -> None:
        self.dispatch(lambda now: self.ctrl.on_goal_result(goal_id, success, message, now))

    def plan(self, scene: str) -> None:
        self.planner = runtime.RuntimePlanner(scene)
        for name in self.ctrl.options.routes:
            future = self.planner.plan_route(name)
            future.add_done_callback(lambda f, name=name: self._planned(name, f))

    def _planned(self, name: str, future: Future[Trajectory]) -> None:
        try:
            traj = future.result()
        except (SafepathError, CancelledError) as exc:
            reason = str(exc)
            self.dispatch(lambda now: self.ctrl.on_route_failed(name, reason, now))
            return
        self.robot.get_logger().info(f"route '{name}' planned: {traj.duration:.2f} s")
        self.dispatch(lambda now: self.ctrl.on_route_ready(name, traj, now))


def _outcome(future: Future[Any], ok: Callable[[Any], bool]) -> tuple[bool, str]:
    """(success, message) of a finished service call; an exception is a failure."""
    try:
        response = future.result()
    except Exception as exc:  # noqa: BLE001 - any transport error means "not done"
        return False, f"call failed: {exc}"
    return ok(response), str(getattr(response, "message", ""))


class ConveyorNode(Node):
    """The conveyor (ControlConveyor service) and the IR sensor at its end."""

    def __init__(self, cell: Cell) -> None:
        super().__init__("quality_check_conveyor")
        self._cell = cell
        self._id = self.declare_parameter("conveyor_id", 9).value
        self._speed = self.declare_parameter("speed", 60).value
        self._sensor = self.declare_parameter("sensor_index", 4).value
        group = ReentrantCallbackGroup()
        self._client = self.create_client(
            ControlConveyor, self.declare_parameter(
                "conveyor_service", "/niryo_robot/conveyor/control_conveyor").value,
            callback_group=group)
        self.create_subscription(
            DigitalIOState, self.declare_parameter(
                "digital_state_topic", "/niryo_robot_rpi/digital_io_state").value,
            self._on_io, SENSOR_QOS, callback_group=group)

    def _on_io(self, msg: DigitalIOState) -> None:
        try:
            # The IR input reads 0 while an object is in front of it.
            blocked = not msg.digital_inputs[self._sensor].value
        except IndexError:
            self.get_logger().error(f"no digital input {self._sensor}")
            return
        self._cell.dispatch(lambda now: self._cell.ctrl.on_sensor(blocked, now))

    def set_running(self, cmd: SetConveyor) -> None:
        request = ControlConveyor.Request(id=self._id, control_on=True, speed=self._speed,
                                          direction=1 if cmd.running else 0)
        future = self._client.call_async(request)
        future.add_done_callback(lambda f: self._cell.goal_done(
            cmd.goal_id, *_outcome(f, lambda r: r.status == NIRYO_SUCCESS)))


class RobotNode(Node):
    """The arm's trajectory controller, the gripper, the verdict service and the HMI log."""

    def __init__(self, cell: Cell) -> None:
        super().__init__("quality_check_robot")
        self._cell = cell
        self._tool_id = self.declare_parameter("tool_id", goals.GRIPPER_1_TOOL_ID).value
        group = ReentrantCallbackGroup()
        # The robot's trajectory controller: robots/<robot>/controller.yaml.
        controller = load_robot(self.declare_parameter("robot", "ned3pro").value).controller
        self._arm = ActionClient(self, FollowJointTrajectory,
                                 controller.follow_joint_trajectory_action, callback_group=group)
        self._tool = ActionClient(self, Tool, goals.TOOL_ACTION, callback_group=group)
        self._safety = self.create_client(GetSafety, "/get_safety", callback_group=group)
        self._hmi = self.create_publisher(String, "/quality_check/cycle", 10)
        self._positions: dict[str, float] = {}
        self._handles: dict[int, Any] = {}
        self.create_subscription(JointState, "/joint_states", self._on_joints, 10,
                                 callback_group=group)
        self.create_timer(0.1, lambda: cell.dispatch(cell.ctrl.on_tick), callback_group=group)
        self.create_service(Trigger, "~/reset", self._on_reset, callback_group=group)

    def _on_joints(self, msg: JointState) -> None:
        self._positions = dict(zip(msg.name, msg.position, strict=False))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._cell.dispatch(self._cell.ctrl.reset)
        response.success = True
        response.message = self._cell.ctrl.state.value
        return response

    def move(self, cmd: MoveArm) -> None:
        try:  # never send a trajectory that does not start where the arm is
            goals.check_start(cmd.trajectory, self._positions)
            goal = goals.follow_joint_trajectory_goal(cmd.trajectory, backend="rclpy")
        except SafepathError as exc:
            self._cell.goal_done(cmd.goal_id, False, str(exc))
            return
        self._send(self._arm, goal, cmd.goal_id,
                   lambda r: (r.error_code == r.SUCCESSFUL, r.error_string))

    def grip(self, cmd: ActuateGripper) -> None:
        goal = goals.tool_goal(cmd.event.action, tool_id=self._tool_id, backend="rclpy")
        self._send(self._tool, goal, cmd.goal_id,
                   lambda r: (r.status == NIRYO_SUCCESS, r.message))

    def _send(self, client: ActionClient, goal: Any, goal_id: int,
              judge: Callable[[Any], tuple[bool, str]]) -> None:
        def on_result(future: Future[Any]) -> None:
            self._handles.pop(goal_id, None)
            try:
                answer = future.result()
                ok, message = judge(answer.result)
                ok = ok and answer.status == GoalStatus.STATUS_SUCCEEDED
            except Exception as exc:  # noqa: BLE001 - a lost result is a failed goal
                ok, message = False, f"no result: {exc}"
            self._cell.goal_done(goal_id, ok, message)

        def on_accepted(future: Future[Any]) -> None:
            try:
                handle = future.result()
            except Exception as exc:  # noqa: BLE001
                self._cell.goal_done(goal_id, False, f"not sent: {exc}")
                return
            if not handle.accepted:
                self._cell.goal_done(goal_id, False, "goal rejected")
                return
            self._handles[goal_id] = handle
            handle.get_result_async().add_done_callback(on_result)

        # An absent server never answers: the controller's time-out turns that into a fault.
        client.send_goal_async(goal).add_done_callback(on_accepted)

    def cancel(self, cmd: CancelGoal) -> None:
        handle = self._handles.pop(cmd.goal_id, None)
        if handle is not None:
            handle.cancel_goal_async()

    def request_verdict(self, cmd: RequestVerdict) -> None:
        def on_answer(future: Future[Any]) -> None:
            try:
                verdict: str | None = future.result().state
            except Exception as exc:  # noqa: BLE001 - no answer counts as unsafe
                self.get_logger().warning(f"GetSafety failed: {exc}")
                verdict = None
            self._cell.dispatch(lambda now: self._cell.ctrl.on_verdict(
                verdict, now, request_id=cmd.request_id))

        # No answer within the controller's time-out counts as 'unsafe'.
        self._safety.call_async(GetSafety.Request()).add_done_callback(on_answer)

    def report(self, cmd: Command) -> None:
        record = {"type": type(cmd).__name__, **dataclasses.asdict(cmd)}
        self._hmi.publish(String(data=json.dumps(record)))
        self.get_logger().info(json.dumps(record))


def main() -> None:
    rclpy.init()
    cell = Cell(ControllerOptions())
    cell.robot, cell.conveyor = RobotNode(cell), ConveyorNode(cell)
    cell.plan(cell.robot.declare_parameter("scene", "scenes/quality_check_cell").value)
    executor = MultiThreadedExecutor()
    executor.add_node(cell.robot)
    executor.add_node(cell.conveyor)
    try:
        executor.spin()
    except KeyboardInterrupt:
        pass
    finally:
        executor.shutdown()
        if cell.planner is not None:
            cell.planner.close()
        cell.robot.destroy_node()
        cell.conveyor.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
