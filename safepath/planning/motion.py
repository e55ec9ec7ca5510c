"""One motion between two joint configurations: ``plan(robot, scene, q_start, q_goal)``.

The shortest way from a robot and a scene to a verified trajectory, for a user who has
no taught poses or routes: the two configurations become the poses ``start`` and
``goal`` of an in-memory :class:`~safepath.cell._cell.Cell`, with one route of one step, and
go through the same planner, timing and independent re-check as a cell's routes.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

from ..cell import Cell
from ..cell.routes import Route, Step, Target
from ..errors import ConfigError
from ..files._io import check_names
from ..model.robot import Robot
from ..model.scene import Scene
from ..model.trajectory import Trajectory
from .route_planner import PlanOptions, WorldState, initial_world, plan_route

__all__ = ["plan"]

#: The pose and route names of the motion, as the trajectory reports them.
START, GOAL, ROUTE = "start", "goal", "plan"


def plan(robot: Robot, scene: Scene, q_start: Any, q_goal: Any, *,
         kind: Literal["move", "line"] = "move", speed: float = 1.0,
         tcp_speed: float | None = None, held: bool = False,
         start_pose: str | None = None, goal_pose: str | None = None,
         options: PlanOptions | None = None) -> Trajectory:
    """Plan, time and verify one motion from ``q_start`` to ``q_goal``.

    Args:
        robot: The robot (``safepath.load_robot("ur5")``, ...).
        scene: Its surroundings; ``scene.robot`` is not consulted. Allowed contacts tied to
            taught poses apply only where ``start_pose`` / ``goal_pose`` say so.
        q_start: Start configuration [rad], in the order of ``robot.joint_names``.
        q_goal: Goal configuration [rad], same order.
        kind: ``move`` (any collision-free joint path: direct, else OMPL) or ``line`` (a
            straight TCP line, orientation interpolated).
        speed: Fraction of the joint velocity and acceleration limits, in (0, 1].
        tcp_speed: TCP speed limit [m/s], or None.
        held: Whether the gripper holds the scene's grasped object (``scene.grasp``) on
            the way; it is then checked against the scene and the robot too.
        start_pose: The taught pose (a name the scene's ``allowed_contacts`` or grasp
            use) that ``q_start`` is: its allowed contacts apply there and on a line
            leaving it, as on a route. None: none apply.
        goal_pose: The same for ``q_goal`` (e.g. ``"pick"``, where the jaws touch the
            part).
        options: Checking, planner, line and timing options.

    Returns:
        A trajectory whose timed samples passed the independent re-check (poses
        ``start`` and ``goal``, route ``plan``).

    Raises:
        PoseError: A configuration of the wrong length, not finite or outside the limits
            (key ``q_start`` or ``q_goal``).
        ConfigError: A bad ``kind``, ``speed`` or ``tcp_speed``; ``held`` without a grasp;
            a ``start_pose`` or ``goal_pose`` the scene never names.
        PlanningError, IKError, TimingError, VerificationError: As for a route (the start
            or goal in collision, naming the pairs; no path; no timing; a failed re-check).
    """
    if not isinstance(robot, Robot):
        raise ConfigError(f"expected a safepath.Robot, got {type(robot).__name__}", key="robot")
    if not isinstance(scene, Scene):
        raise ConfigError(f"expected a safepath.Scene, got {type(scene).__name__}", key="scene")
    q0 = robot.as_joint_vector(q_start, name="q_start")
    q1 = robot.as_joint_vector(q_goal, name="q_goal")
    if kind not in ("move", "line"):
        raise ConfigError(f"expected 'move' or 'line', got {kind!r}", key="kind")
    step = Step(kind, Target(GOAL), speed=speed, tcp_speed=tcp_speed)
    if held and scene.grasp is None:
        raise ConfigError("held=True needs a scene with a grasp", key="held")
    # The contacts and grasp poses of a scene name its taught poses; here there are only
    # start and goal: an allowance holds there only if the caller names the pose it is.
    named = _scene_pose_names(scene)
    for key, name in (("start_pose", start_pose), ("goal_pose", goal_pose)):
        if name is not None:
            check_names([name], sorted(named), path=None, key=key, what="pose the scene names")
    rename = {p: q for p, q in ((start_pose, START), (goal_pose, GOAL)) if p is not None}

    def here(at: tuple[str, ...]) -> tuple[str, ...]:
        return tuple(rename[p] for p in rename if p in at)

    local = dataclasses.replace(
        scene,
        allowed_contacts=tuple(dataclasses.replace(c, at=here(c.at))
                               for c in scene.allowed_contacts),
        grasp=dataclasses.replace(scene.grasp, poses=here(scene.grasp.poses))
        if held and scene.grasp else None)
    route = Route(ROUTE, START, (step,))
    cell = Cell(robot, local, {START: q0, GOAL: q1}, routes={ROUTE: route})
    world = initial_world(cell)
    if held and scene.grasp is not None:
        resting = {k: v for k, v in world.resting.items() if k != scene.grasp.object}
        world = WorldState(scene.grasp.object, resting)
    return plan_route(cell, route, options, world=world)


def _scene_pose_names(scene: Scene) -> set[str]:
    """The taught poses a scene's allowed contacts and grasp name."""
    names = {p for c in scene.allowed_contacts for p in c.at}
    if scene.grasp is not None:
        names.update(scene.grasp.poses)
    return names
