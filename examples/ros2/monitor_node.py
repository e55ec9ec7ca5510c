#!/usr/bin/env python3
"""Speed and separation monitoring of the Ned3 Pro with a planar lidar, as a ROS 2 node.

Every decision is taken by :class:`safepath.monitor.node.MonitorNodeCore` (tested without
ROS); this file wires it to a lifecycle node, as the fourth brief recommends:

* ``configure``: loads the cell, validates the parameter file (``--params-file``) and warms
  the runtime planner by planning the route in its worker;
* ``activate``: starts the route's first motion (FollowJointTrajectory);
* ``deactivate``: stops along the path (a stop replacement goal), without latching.

Every goal leaves the core through its one gate (a latched kill or an inactive node lets
nothing out but a braking stop; refusals are logged here). Each goal is stamped with its
``start``: a replacement's t = 0 is where the monitor timed it, so the controller joins
it there. Only the newest goal's success reaches the core, which moves the route on only
when the monitor's motion has reached the end of its path (a stop's success does not).

``/scan`` comes on the sensor-data QoS (best effort, newest only: a lost scan is covered
by the silence rule); decisions (``std_msgs/String``, JSON) and goals are reliable. A
100 Hz timer lets silence stop the robot even when no scan arrives. A kill switch is a
``std_srvs/Trigger`` service (``~/kill``; ``~/reset`` releases it). An obstacle that
stays is planned around (:func:`safepath.monitor.replan.replan`) in a separate process,
so that planning never stalls the callbacks; the new route is verified before it runs.

Needs a sourced ROS 2 workspace with ``control_msgs``::

    python3 examples/ros2/monitor_node.py --ros-args --params-file examples/ros2/monitor_params.yaml
    ros2 lifecycle set /safepath_monitor configure
    ros2 lifecycle set /safepath_monitor activate
"""

from __future__ import annotations

import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import rclpy
from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from niryo_ned_ros2_interfaces.action import Tool
from rclpy.action import ActionClient
from rclpy.lifecycle import LifecycleNode, State, TransitionCallbackReturn
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String
from std_srvs.srv import Trigger

from safepath import runtime
from safepath.errors import SafepathError
from safepath.monitor.node import (
    NODE_NAME,
    Gripper,
    MonitorNodeCore,
    Publish,
    Replan,
    SendGoal,
    parameters_from_mapping,
)
from safepath.monitor.replan import replan
from safepath.monitor.ros import decision_dict
from safepath.ros import goals


def replan_in_process(scene: str, command: Replan):
    """Runs in the re-planning process (the cell is loaded there)."""
    from safepath import load_cell

    return replan(load_cell(scene), command.route, command.request, held=command.held,
                  margin=command.margin)


RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
PARAMETERS = ("scene", "route", "scan_topic", "scan_frame", "scan_xyz", "scan_rpy",
              "decision_topic", "approach_speed", "min_separation", "sensor_uncertainty",
              "robot_uncertainty", "stale_after", "command_latency", "hold_time",
              "replan_after", "replan_margin")


class MonitorNode(LifecycleNode):
    """The lifecycle node around :class:`MonitorNodeCore`."""

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        for name in PARAMETERS:
            self.declare_parameter(name, rclpy.Parameter.Type.NOT_SET)
        self.core: MonitorNodeCore | None = None
        self.planner: runtime.RuntimePlanner | None = None
        self.arm = ActionClient(self, FollowJointTrajectory,
                                goals.FOLLOW_JOINT_TRAJECTORY_ACTION)
        self.tool = ActionClient(self, Tool, goals.TOOL_ACTION)
        self.latest_goal = 0  # only the newest goal's success reaches the core
        self.refusals_logged = 0
        self.replanner = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        self.scan_sub = None
        self.timer = None
        self.decisions = self.create_publisher(String, "/safepath/monitor/decision", RELIABLE)
        self.create_service(Trigger, "~/kill", self.on_kill)
        self.create_service(Trigger, "~/reset", self.on_reset)

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # -- lifecycle ---------------------------------------------------------------------
    def on_configure(self, state: State) -> TransitionCallbackReturn:
        raw = {p.name: p.value for p in self.get_parameters(PARAMETERS) if p.value is not None}
        try:
            params = parameters_from_mapping(raw)
            self.planner = runtime.RuntimePlanner(params.scene)
            self.core = MonitorNodeCore(params)
            self.refusals_logged = 0
            self.core.configure(planner=self.planner)  # plans in the worker: warms it
        except SafepathError as exc:
            self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        self.scan_sub = self.create_subscription(LaserScan, params.scan_topic, self.on_scan,
                                                 qos_profile_sensor_data)
        self.get_logger().info(f"configured: {len(self.core.motions)} motions of "
                               f"route '{params.route}'")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        assert self.core is not None
        self.run(self.core.activate(self.now()))
        self.timer = self.create_timer(0.01, lambda: self.run(self.core.on_tick(self.now())))
        return super().on_activate(state)

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        assert self.core is not None
        if self.timer is not None:
            self.destroy_timer(self.timer)
        self.run(self.core.deactivate(self.now()))
        return super().on_deactivate(state)

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self.planner is not None:
            self.planner.close()
        self.core = None
        return TransitionCallbackReturn.SUCCESS

    # -- callbacks ---------------------------------------------------------------------
    def on_scan(self, msg: LaserScan) -> None:
        if self.core is None:
            return
        try:
            self.run(self.core.on_scan(msg, self.now()))
        except SafepathError as exc:  # a malformed scan: the last decision stands
            self.get_logger().warn(f"scan refused: {exc}")

    def on_kill(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.core is not None and self.core.monitor is not None:
            self.run(self.core.kill(self.now()))
        response.success = True
        response.message = "kill switch latched"
        return response

    def on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.core is not None:
            self.core.reset()
        response.success = True
        response.message = "kill switch released"
        return response

    def run(self, commands: list) -> None:
        for command in commands:
            if isinstance(command, Publish):
                self.decisions.publish(String(data=json.dumps(decision_dict(command.decision))))
            elif isinstance(command, SendGoal):
                # header.stamp: the ROS time of the goal's t = 0 (0: on receipt).
                stamp_ns = 0 if command.start is None else max(1, round(command.start * 1e9))
                goal = goals.follow_joint_trajectory_goal(command.trajectory,
                                                          stamp_ns=stamp_ns, backend="rclpy")
                self.latest_goal += 1
                number = self.latest_goal
                future = self.arm.send_goal_async(goal)  # replaces the running goal
                future.add_done_callback(lambda f, n=number: self.on_accepted(f, n))
            elif isinstance(command, Replan):
                # OMPL holds the interpreter lock while it plans: plan in another process.
                params = self.core.parameters
                future = self.replanner.submit(replan_in_process, params.scene, command)
                future.add_done_callback(lambda f, c=command: self.on_replanned(f, c))
            elif isinstance(command, Gripper):
                goal = goals.tool_goal(command.event.action, backend="rclpy")
                future = self.tool.send_goal_async(goal)
                future.add_done_callback(
                    lambda f: f.result().get_result_async().add_done_callback(
                        lambda _: self.run(self.core.on_gripper_done(self.now()))))
        if self.core is not None:
            for refusal in self.core.refused[self.refusals_logged:]:
                self.get_logger().info(f"goal refused at {refusal.time:.3f} s: {refusal.why}")
            self.refusals_logged = len(self.core.refused)

    def on_replanned(self, future, command: Replan) -> None:
        try:
            traj = future.result()
        except SafepathError as exc:  # stays stopped; the next request may succeed
            self.get_logger().error(f"re-plan failed: {exc}")
            return
        self.run(self.core.on_replanned(command.request, traj, self.now()))

    def on_accepted(self, future, number: int) -> None:
        handle = future.result()
        if not handle.accepted:
            self.get_logger().error("trajectory goal rejected")
            return
        handle.get_result_async().add_done_callback(lambda f: self.on_result(f, number))

    def on_result(self, future, number: int) -> None:
        # A replaced goal ends too; only the newest one's success reaches the core, which
        # moves the route on only at the end of the path (never after a stop at rest).
        result = future.result()
        if (number == self.latest_goal and result.status == GoalStatus.STATUS_SUCCEEDED
                and self.core is not None):
            self.run(self.core.on_motion_done(self.now()))


def main() -> None:
    rclpy.init()
    node = MonitorNode()
    try:
        rclpy.spin(node)
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
