"""Straight TCP lines followed by inverse kinematics (damped least squares).

The TCP moves on the segment between two positions while its orientation turns at
constant rate from the start orientation to the goal's (geodesic); for the taught
vertical moves of the cell the two orientations agree within a few degrees, so the
line "keeps orientation". Each TCP step is at most ``step`` long and no joint may
move more than ``max_joint_step`` for it: a branch switch (a joint jump) is a failure,
reported with the fraction of the line where it happened.

:func:`~safepath.kinematics.solve_ik` (in :mod:`safepath.kinematics`, below the planner)
works on Pinocchio from Python. A line runs the same algorithm in one numba call
(:mod:`safepath.kinematics._ik_kernel`, imported on the first line; the first call after
an install compiles it, a few seconds, later processes load it from numba's cache).
Each waypoint is seeded with the previous waypoints' motion continued quadratically,
so most are accepted at the seed or after one step (0.65 steps per waypoint on the
bundled cell's lines).
"""

from __future__ import annotations

import logging

import numpy as np
import pinocchio as pin

from ..errors import ConfigError, IKError
from ..kinematics.ik import DAMPING, LineOptions
from ..model._joint_table import Chain, chain_joints, not_a_screw
from ..model.robot import Robot

__all__ = ["cartesian_line"]

log = logging.getLogger(__name__)


def cartesian_line(robot: Robot, q_start: np.ndarray, q_goal: np.ndarray, *,
                   options: LineOptions = LineOptions(), step_name: str | None = None
                   ) -> list[np.ndarray]:
    """Joint waypoints that move the TCP in a straight line from its pose at
    ``q_start`` to its pose at ``q_goal``; the last waypoint is ``q_goal`` itself, its
    continuous joints (:attr:`Robot.continuous`) moved by whole turns to where the line
    took them (the joint values are continuous along the line, never a turn apart).

    Every waypoint before the last puts the TCP on the line within the IK tolerances.

    Raises:
        IKError: No continuous IK solution; says where along the line and why.
    """
    from ..kinematics import _ik_kernel as kernel

    chain = line_chain(robot)
    T0 = robot.frame_pose(q_start)
    T1 = robot.frame_pose(q_goal)
    p0, p1 = T0.translation, T1.translation
    length = float(np.linalg.norm(p1 - p0))
    w_line = pin.log3(T0.rotation.T @ T1.rotation)
    angle = float(np.linalg.norm(w_line))
    n = max(1, int(np.ceil(max(length / options.step, angle / 0.05))))
    path = np.empty((n + 1, robot.dof))
    path[0] = q_start
    params = np.array([options.position_tolerance, options.orientation_tolerance,
                       options.max_joint_step, DAMPING])
    status, k, iterations, jump = kernel.line_path(
        chain.joint_f, chain.joint_i, chain.frame_f, np.ascontiguousarray(T0.rotation),
        np.ascontiguousarray(w_line, dtype=float), np.ascontiguousarray(p0),
        np.ascontiguousarray(p1), np.ascontiguousarray(robot.lower, dtype=float),
        np.ascontiguousarray(robot.upper, dtype=float), params,
        int(options.max_iterations), path)
    log.debug("line %s: %d waypoints, %d IK steps", step_name, n, iterations)
    if status != kernel.OK:
        s = k / n
        position = (1 - s) * p0 + s * p1
        if status == kernel.NO_SOLUTION:
            raise IKError("no inverse-kinematics solution (out of reach or at a joint limit)",
                          step=step_name, fraction=s, position=position)
        raise IKError(f"joint jump of {jump:.3f} rad for a {length / n * 1000:.1f} mm TCP "
                      "step (singularity or branch switch)", step=step_name, fraction=s,
                      position=position)
    end = robot.nearest_turn(q_goal, path[-1])
    gap = float(np.max(np.abs(path[-1] - end)))
    if gap > options.goal_tolerance:
        raise IKError(f"the line ends {gap:.3f} rad away from the taught pose (another IK "
                      "branch)", step=step_name, fraction=1.0, position=p1.copy())
    path[-1] = end
    return list(path)


def line_chain(robot: Robot) -> Chain:
    """The robot's chain to its TCP (a joint table, :mod:`safepath.model._joint_table`, and
    the TCP's placement in its last joint), kept by the robot (:meth:`Robot.tcp_chain`).

    Raises:
        ConfigError: A joint on the chain does not move as a screw of constant axis
            (revolute, prismatic or helical), which the kernel assumes.
    """
    chain = robot.tcp_chain()
    if chain is None:
        model = robot.model
        j = not_a_screw(model, chain_joints(model, robot.tcp_frame_id), robot.chain_test_q())
        assert j is not None  # the one that made the chain None
        raise ConfigError(f"joint '{model.names[j]}' ({model.joints[j].shortname()}) is not a "
                          "revolute, prismatic or helical joint; Cartesian lines cannot "
                          "follow it", path=robot.source, key="urdf")
    return chain
