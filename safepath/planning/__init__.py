"""Planning: routes of taught poses to verified, timed trajectories."""

from .batch import PlanCellsTask
from .cartesian import cartesian_line
from .motion import plan
from .options import PLANNERS, PlannerOptions, PlanOptions
from .route_planner import plan_cell, plan_route
from .sampling import plan_joint_path
from .world import WorldState, initial_world

__all__ = [
    "PLANNERS",
    "PlanCellsTask",
    "PlanOptions",
    "PlannerOptions",
    "WorldState",
    "cartesian_line",
    "initial_world",
    "plan",
    "plan_cell",
    "plan_joint_path",
    "plan_route",
]
