"""Inverse kinematics: the joint vector that puts the TCP at a pose (damped least squares).

:func:`solve_ik` works on Pinocchio from Python (one target: a TCP pose target of the
poses file, a Cartesian step's goal). The Cartesian lines of the planner
(:mod:`safepath.planning.cartesian`) run the same algorithm in one numba call per line
(:mod:`._ik_kernel`), with the same :class:`LineOptions` and damping.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import IKError
from ..model.robot import Robot

__all__ = ["DAMPING", "LineOptions", "solve_ik"]

#: Damping of the least-squares step (added to the diagonal of J J^T).
DAMPING = 1e-6


@dataclass(frozen=True, kw_only=True)
class LineOptions:
    """Options of Cartesian lines.

    Attributes:
        step: Largest TCP translation between two IK waypoints [m].
        max_joint_step: Largest change of any joint between two waypoints [rad].
        position_tolerance: IK position tolerance [m].
        orientation_tolerance: IK orientation tolerance [rad].
        max_iterations: IK iterations per waypoint.
        goal_tolerance: Largest joint distance between the line's last IK solution and
            the taught goal pose [rad] (otherwise the line ends in another branch).
    """

    step: float = 0.004
    max_joint_step: float = 0.15
    position_tolerance: float = 1e-5
    orientation_tolerance: float = 1e-4
    max_iterations: int = 60
    goal_tolerance: float = 0.05


def solve_ik(robot: Robot, T_world_tcp: pin.SE3, q_init: np.ndarray, *,
             options: LineOptions = LineOptions(), data: pin.Data | None = None,
             step: str | None = None) -> np.ndarray:
    """Joint vector that puts the TCP at ``T_world_tcp`` [m, rad], near ``q_init`` [rad].

    Damped least squares on the 6-D frame error (LOCAL frame), joint limits enforced by
    clipping each iterate. ``data`` lets a caller reuse its Pinocchio workspace.

    Args:
        robot: The robot.
        T_world_tcp: The TCP pose to reach, in the world frame.
        q_init: Where the iteration starts [rad].
        options: Tolerances and the iteration budget.
        data: A Pinocchio workspace of ``robot.model`` to reuse.
        step: Route step (or pose) the target belongs to, for the error.

    Raises:
        IKError: No solution within ``options.max_iterations`` (the target out of reach,
            or not reachable from q_init within the joint limits); carries the target
            position and the remaining error.
    """
    model = robot.model
    if data is None:
        data = model.createData()
    fid = robot.tcp_frame_id
    q = q_init.copy()
    damping = DAMPING * np.eye(6)
    for _ in range(options.max_iterations):
        pin.forwardKinematics(model, data, q)
        T = pin.updateFramePlacement(model, data, fid)
        M = T.actInv(T_world_tcp)
        err = pin.log6(M).vector
        if (np.linalg.norm(T_world_tcp.translation - T.translation) < options.position_tolerance
                and np.linalg.norm(err[3:]) < options.orientation_tolerance):
            return q
        J = pin.Jlog6(M) @ pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        q = np.clip(q + J.T @ np.linalg.solve(J @ J.T + damping, err), robot.lower, robot.upper)
    pin.forwardKinematics(model, data, q)
    left = float(np.linalg.norm(T_world_tcp.translation
                                - pin.updateFramePlacement(model, data, fid).translation))
    raise IKError(f"no inverse-kinematics solution for the target in {options.max_iterations} "
                  f"iterations ({left * 1000:.1f} mm away)", step=step, fraction=None,
                  position=np.array(T_world_tcp.translation))
