"""Options of route planning: one object holding each stage's own options."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..collision import CheckOptions
from ..errors import ConfigError
from ..files._io import check_names
from ..kinematics import LineOptions
from ..timing import TimingOptions
from .pour import PourOptions

__all__ = ["PLANNERS", "PlanOptions", "PlannerOptions"]

#: OMPL geometric planners selectable by name.
PLANNERS = ("RRTConnect", "RRT", "RRTstar", "InformedRRTstar", "AORRTC", "SORRTstar")


@dataclass(frozen=True, kw_only=True)
class PlannerOptions:
    """Options of the sampling planner.

    Attributes:
        planner: OMPL planner name (see :data:`PLANNERS`).
        time_limit: Planning time budget [s].
        seed: Seed of OMPL's generator and of the shortcutter.
        range: Longest edge a planner adds in one extension [rad]; None derives it from
            the robot's joint ranges (:func:`default_range`), 0 leaves it to OMPL (a fifth
            of the joint-space diagonal, too long for arms whose joints turn twice round,
            like the UR5's).
        shortcut_iterations: Random shortcut attempts after planning.
        shortcut_min_gain: A shortcut is checked only if it would shorten the path by at
            least this share of its length (checking is what a shortcut costs; the many
            that would gain little are not worth it: 2 % was chosen on the Panda set,
            faster than 1 % with motions as long; ``benchmarks/panda_set.py --seeds 3``
            measures it).

    The optimizing planners (``RRTstar``, ``InformedRRTstar``, ``AORRTC``,
    ``SORRTstar``) keep improving their path until ``time_limit`` runs out; the others
    stop at their first path. Until a first path is found, a tree that finds none within
    an iteration budget is dropped and a new one grown with twice the budget (all but
    AORRTC; :mod:`safepath.planning._ompl` says why): single-tree planners otherwise get
    stuck behind an obstacle near the start or the goal on some seeds. Budgets count
    iterations, not seconds, so a seed gives the same path however loaded the machine.
    """

    planner: str = "RRTConnect"
    time_limit: float = 2.0
    seed: int = 0
    range: float | None = None
    shortcut_iterations: int = 100
    shortcut_min_gain: float = 0.02

    def __post_init__(self) -> None:
        check_names([self.planner], PLANNERS, path=None, key="planner", what="planner")
        if not _real(self.time_limit) or not self.time_limit > 0:
            raise ConfigError(f"time_limit must be > 0 [s], got {self.time_limit!r}",
                              key="time_limit")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise ConfigError(f"seed must be an integer, got {self.seed!r}", key="seed")
        if self.range is not None and not (_real(self.range) and self.range >= 0
                                           and np.isfinite(self.range)):
            raise ConfigError(f"range must be None or >= 0 [rad], got {self.range!r}",
                              key="range")
        if isinstance(self.shortcut_iterations, bool) or not isinstance(
                self.shortcut_iterations, (int, np.integer)) or self.shortcut_iterations < 0:
            raise ConfigError(f"shortcut_iterations must be an integer >= 0, got "
                              f"{self.shortcut_iterations!r}", key="shortcut_iterations")
        if not _real(self.shortcut_min_gain) or not 0.0 <= self.shortcut_min_gain < 1.0:
            raise ConfigError(f"shortcut_min_gain must be in [0, 1), got "
                              f"{self.shortcut_min_gain!r}", key="shortcut_min_gain")


def _real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


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
