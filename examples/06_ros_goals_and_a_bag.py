"""06 - ROS 2 messages and a bag, without ROS: a route as a JointTrajectory goal (CDR
bytes, as the controller receives them) and the cycle as an MCAP bag.

    .venv/bin/python examples/06_ros_goals_and_a_bag.py
"""

import tempfile
from pathlib import Path

import safepath
from safepath.ros import joint_trajectory, read_bag, split_at_gripper_events, write_bag
from safepath.ros.messages import deserialize, serialize

cell = safepath.load_cell("scenes/quality_check_cell")
route = {"phase1": cell.route_table()["phase1"]}
phase1 = safepath.plan_cell(cell, safepath.PlanOptions(), routes=route)["phase1"]
first = next(p for p in split_at_gripper_events(phase1) if isinstance(p, safepath.Trajectory))
msg = joint_trajectory(first, backend="rosbags")
raw = serialize(msg, "trajectory_msgs/msg/JointTrajectory")
back = deserialize(raw, "trajectory_msgs/msg/JointTrajectory")
print(f"goal: {len(back.points)} points, {len(raw)} CDR bytes, joints {list(back.joint_names)}")
bag = write_bag(Path(tempfile.mkdtemp(prefix="safepath_")) / "phase1", [phase1])
contents = read_bag(bag)
print(f"bag {bag}: " + ", ".join(f"{t} x{len(contents.on(t))}" for t in contents.topics))
