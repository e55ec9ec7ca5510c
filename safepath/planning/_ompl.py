"""One OMPL planning call: the problem set up on safepath's checker, restarts until a
first path, then (optimizing planners) improvement for the rest of the budget.

Why restarts: a single-tree planner (RRT and the RRT* family grow one tree from the
start) gets stuck when the node nearest to the goal sees it only through an obstacle.
Every goal-biased extension starts from that node and fails, and the region behind the
obstacle belongs to that node's Voronoi cell, so random samples there extend from it too
and fail the same way: on the UR5 "post in the way" problem of
``tests/planning/test_planners.py`` RRT's tree grew to 10,764 nodes in 1 s without one
closer to the goal than the start (seed 4). Which runs get stuck is decided in their
first iterations, while most solved runs need a few dozen (the time to a first path is
heavy-tailed), so a run that has not found a path after a budget of iterations
is dropped and a new tree grown, with the budget doubled each time (a growing budget
keeps the planner probabilistically complete). Budgets count planner iterations, not
seconds, so the same seed gives the same path on a loaded machine.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..collision import CollisionChecker
from ..errors import PlannerTimeout, PlanningError
from ..model.robot import Robot

if TYPE_CHECKING:
    from .options import PlannerOptions

log = logging.getLogger(__name__)

#: Iterations of the first attempt; each further attempt gets twice as many. On the
#: detour problems of the tests (40 seeds of RRT, no restarts), half the runs found their
#: path within 60 iterations, a quarter needed 300 to 3,000 and one in ten none within
#: 1 s; with a budget of about 100 the expected iterations to a path are smallest.
FIRST_ATTEMPT_ITERATIONS = 100
#: Single-tree planners that keep improving their path until the time budget runs out:
#: restarted until a first path, then given the rest of the budget.
OPTIMIZING = frozenset({"RRTstar", "InformedRRTstar", "SORRTstar"})
#: Planners run once with the whole budget. AORRTC grows two trees (start and goal, as
#: RRTConnect), which is what gets the others stuck, and a second ``solve`` call on it
#: does not return (OMPL 2.0), so it cannot be stopped at its first path and resumed.
SINGLE_RUN = frozenset({"AORRTC"})


class Solution(NamedTuple):
    """What one planning call found.

    Attributes:
        path: The path, ``q_start`` to ``q_goal`` exactly [rad or m].
        first_path_time: Time to the first path [s] (restarts included).
        attempts: Trees grown to find it (1: no restart).
    """

    path: list[np.ndarray]
    first_path_time: float
    attempts: int


def solve(checker: CollisionChecker, q_start: np.ndarray, q_goal: np.ndarray,
          options: PlannerOptions, extension: float, step: str | None) -> Solution:
    """A path from ``q_start`` to ``q_goal`` by the OMPL planner ``options.planner``.

    OMPL's generator must have been seeded by the caller (under its lock).

    Args:
        checker: Decides states and edges (edges at its guaranteed resolution).
        q_start: Start joint positions [rad or m].
        q_goal: Goal joint positions [rad or m].
        options: Planner name, time budget [s].
        extension: Longest edge of one extension [rad]; 0 leaves OMPL's default.
        step: Route step named in errors.

    Raises:
        PlannerTimeout: No path within ``options.time_limit``.
        PlanningError: The planner gave up without a path before its time ran out.
    """
    from ompl import base as ob
    from ompl import geometric as og

    deadline = time.perf_counter() + options.time_limit
    setup, to_array, _edges = _setup(checker, q_start, q_goal)  # _edges: kept alive
    si = setup.getSpaceInformation()
    objective = ob.PathLengthOptimizationObjective(si)
    threshold = objective.getCostThreshold()
    # Any path satisfies the objective while looking for the first one: optimizing
    # planners then return at their first path instead of running out the clock.
    if options.planner in OPTIMIZING:
        objective.setCostThreshold(ob.Cost(float("inf")))
    setup.setOptimizationObjective(objective)
    planner = getattr(og, options.planner)(si)
    if extension > 0 and hasattr(planner, "setRange"):
        planner.setRange(extension)
    setup.setPlanner(planner)
    budget = None if options.planner in SINGLE_RUN else FIRST_ATTEMPT_ITERATIONS
    attempts, text = 0, ""
    t0 = time.perf_counter()
    while time.perf_counter() < deadline:
        attempts += 1
        if attempts > 1:
            setup.clear()  # a new tree, drawn from the same seeded generator
        text = str(setup.solve(_termination(ob, deadline, budget)))
        if setup.haveExactSolutionPath() or budget is None:
            break
        budget *= 2
    elapsed = time.perf_counter() - t0
    log.info("OMPL %s: %s in %.3f s, %d attempt(s)", options.planner, text, elapsed,
             attempts)
    if not setup.haveExactSolutionPath():
        # Out of time also when the budget ran out before the first attempt (setting the
        # problem up took it all): no planner ran, so nothing says the path does not exist.
        if time.perf_counter() >= deadline or attempts == 0 or "imeout" in text \
                or "Approximate" in text:
            raise PlannerTimeout(f"ran out of time: no path within the time_limit of "
                                 f"{options.time_limit:g} s ({attempts} attempt(s))",
                                 step=step, status=text or "no time to run")
        raise PlanningError("no collision-free path found", step=step, status=text)
    if options.planner in OPTIMIZING and time.perf_counter() < deadline:
        objective.setCostThreshold(threshold)
        setup.solve(_termination(ob, deadline, None))
    path = setup.getSolutionPath()
    states = [to_array(path.getState(i)) for i in range(path.getStateCount())]
    states[0], states[-1] = q_start.copy(), q_goal.copy()
    return Solution(states, elapsed, attempts)


def sampling_bounds(robot: Robot, q_start: np.ndarray, q_goal: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Where OMPL samples [rad or m]: the position limits, and for a continuous joint
    (no limits) the start and goal values widened by half a turn each way. That window
    holds every angle of the joint at least once, so no way round is left out, and a
    path stays within a turn and a half of its ends (it never winds up)."""
    lower, upper = robot.lower.copy(), robot.upper.copy()
    for j in np.flatnonzero(robot.continuous):
        lower[j] = min(q_start[j], q_goal[j]) - np.pi
        upper[j] = max(q_start[j], q_goal[j]) + np.pi
    return lower, upper


def _termination(ob: Any, deadline: float, iterations: int | None) -> Any:
    """Stop at ``deadline`` (``time.perf_counter``) or after ``iterations`` planner
    iterations (OMPL evaluates the condition once per iteration)."""
    count = 0

    def done() -> bool:
        nonlocal count
        count += 1
        return (iterations is not None and count > iterations) or \
            time.perf_counter() >= deadline

    return ob.PlannerTerminationCondition(done)


def _setup(checker: CollisionChecker, q_start: np.ndarray,
           q_goal: np.ndarray) -> tuple[Any, Callable[[Any], np.ndarray], Any]:
    """OMPL's SimpleSetup for the problem, the state -> array conversion and the edge
    validator (OMPL does not keep the Python object alive: the caller must)."""
    from ompl import base as ob
    from ompl import geometric as og

    robot = checker.robot
    n = robot.dof
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    lower, upper = sampling_bounds(robot, q_start, q_goal)
    for i in range(n):
        bounds.setLow(i, float(lower[i]))
        bounds.setHigh(i, float(upper[i]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)

    def to_array(state: object) -> np.ndarray:
        return np.fromiter((state[i] for i in range(n)), float, n)  # type: ignore[index]

    setup.setStateValidityChecker(lambda s: checker.is_valid(to_array(s)))
    si = setup.getSpaceInformation()

    class _Edges(ob.MotionValidator):  # type: ignore[misc]
        def checkMotion(self, s1: object, s2: object, *_: object) -> bool:  # noqa: N802
            return checker.segment_is_valid(to_array(s1), to_array(s2), check_ends=False)

    edges = _Edges(si)
    si.setMotionValidator(edges)
    start, goal = space.allocState(), space.allocState()
    for i in range(n):
        start[i] = float(q_start[i])
        goal[i] = float(q_goal[i])
    setup.setStartAndGoalStates(start, goal)
    return setup, to_array, edges
