"""Planning: routes of taught poses to verified, timed trajectories."""

from ..cell.routes import Route, Step, Target, load_routes
from ..kinematics import LineOptions, solve_ik
from ..timing import TimingOptions
from ..verify import FclVerifier, VerifyResult
from .cartesian import cartesian_line
from .motion import plan
from .options import PLANNERS, PlannerOptions, PlanOptions
from .route_planner import plan_cell, plan_route
from .sampling import plan_joint_path
from .world import WorldState, initial_world

__all__ = [
    "PLANNERS",
    "FclVerifier",
    "LineOptions",
    "PlanOptions",
    "PlannerOptions",
    "Route",
    "Step",
    "Target",
    "TimingOptions",
    "VerifyResult",
    "WorldState",
    "cartesian_line",
    "initial_world",
    "load_routes",
    "plan",
    "plan_cell",
    "plan_joint_path",
    "plan_route",
    "solve_ik",
]
