"""safepath: safe, fast robot motions from taught joint poses.

Collision-checked paths (Pinocchio + coal, OMPL when the direct way is blocked),
time-optimal timing under the robot's limits (TOPPRA), an independent re-check of
the timed result (python-fcl) before release, ROS 2 goals, and browser review (viser).
"""

from __future__ import annotations

import logging

from .cell import (
    Cell,
    PoseCheck,
    Route,
    Step,
    Target,
    check_poses,
    dump_poses,
    load_cell,
    load_poses,
    load_routes,
    load_scene,
    save_poses,
)
from .collision import CheckOptions, CollisionChecker, SegmentReport, StateReport
from .description import load_robot, robot_names
from .errors import (
    CollisionError,
    ConfigError,
    FrameNotFound,
    IKError,
    InputError,
    PlannerTimeout,
    PlanningError,
    PoseError,
    RobotNotFound,
    RobotNotSupported,
    RosError,
    SafepathError,
    TimingError,
    TrajectoryError,
    UnprovenClearance,
    VerificationError,
)
from .kinematics import LineOptions
from .model.controller_spec import ControllerSpec
from .model.limits import MotionLimits
from .model.robot import Robot
from .model.scene import AllowedContact, Grasp, Scene, SceneObject, Shape, placement
from .model.tool import ToolSpec
from .model.trajectory import GripperEvent, Trajectory, load_trajectory
from .planning import PlannerOptions, PlanOptions, WorldState, plan, plan_cell, plan_route
from .timing import TimingOptions

logging.getLogger(__name__).addHandler(logging.NullHandler())

__version__ = "0.1.0"

__all__ = [
    "AllowedContact",
    "Cell",
    "CheckOptions",
    "CollisionChecker",
    "CollisionError",
    "ConfigError",
    "FrameNotFound",
    "Grasp",
    "GripperEvent",
    "LineOptions",
    "MotionLimits",
    "PlanOptions",
    "PlannerOptions",
    "Route",
    "Step",
    "Target",
    "TimingOptions",
    "Trajectory",
    "WorldState",
    "IKError",
    "InputError",
    "PlannerTimeout",
    "PlanningError",
    "PoseCheck",
    "PoseError",
    "Robot",
    "RobotNotFound",
    "RobotNotSupported",
    "RosError",
    "SafepathError",
    "Scene",
    "SceneObject",
    "SegmentReport",
    "Shape",
    "StateReport",
    "TimingError",
    "ToolSpec",
    "ControllerSpec",
    "TrajectoryError",
    "UnprovenClearance",
    "VerificationError",
    "check_poses",
    "dump_poses",
    "load_cell",
    "load_poses",
    "load_robot",
    "load_routes",
    "load_scene",
    "load_trajectory",
    "plan",
    "plan_cell",
    "plan_route",
    "placement",
    "robot_names",
    "save_poses",
]
