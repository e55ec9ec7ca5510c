"""Options of route planning: one object holding each stage's own options."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..collision import CheckOptions
from ..timing import TimingOptions
from .cartesian import LineOptions
from .pour import PourOptions
from .sampling import PlannerOptions

__all__ = ["PlanOptions"]


@dataclass(frozen=True, kw_only=True)
class PlanOptions:
    """Options of route planning (each part has its own options object).

    Attributes:
        check: Collision checking (resolution, margin); margins are enforced.
        planner: Sampling planner (name, time budget, seed).
        line: Cartesian lines.
        timing: Time parameterisation (global speed scale).
        pour: Pour steps (``tilt``, ``circle``): waypoint spacing and the tolerances
            checked on the released samples (their bounds come from the steps).
        grasp_tolerance: How far the object may be from the gripper when it closes [m].
        baseline: Also time the stop-and-go baseline (every motion step rest to rest
            along its own path, same limits) into ``info["baseline_duration"]``.
    """

    check: CheckOptions = field(default_factory=lambda: CheckOptions(enforce_margin=True))
    planner: PlannerOptions = field(default_factory=PlannerOptions)
    line: LineOptions = field(default_factory=LineOptions)
    timing: TimingOptions = field(default_factory=TimingOptions)
    pour: PourOptions = field(default_factory=PourOptions)
    grasp_tolerance: float = 0.005
    baseline: bool = False
