"""Straight TCP lines followed by inverse kinematics (Pinocchio, damped least squares).

The TCP moves on the segment between two positions while its orientation turns at
constant rate from the start orientation to the goal's (geodesic); for the taught
vertical moves of the cell the two orientations agree within a few degrees, so the
line "keeps orientation". Each TCP step is at most ``step`` long and no joint may
move more than ``max_joint_step`` for it: a branch switch (a joint jump) is a failure,
reported with the fraction of the line where it happened.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import IKError
from ..robot import Robot

__all__ = ["LineOptions", "solve_ik", "cartesian_line"]


@dataclass(frozen=True)
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


def solve_ik(robot: Robot, T_world_tcp: pin.SE3, q_seed: np.ndarray, *,
             options: LineOptions = LineOptions(), data: pin.Data | None = None
             ) -> np.ndarray | None:
    """Joint vector that puts the TCP at ``T_world_tcp``, near ``q_seed``; None if none.

    Damped least squares on the 6-D frame error (LOCAL frame), joint limits enforced by
    clipping each iterate. ``data`` lets a caller reuse its Pinocchio workspace.
    """
    model = robot.model
    if data is None:
        data = model.createData()
    fid = robot.tcp_frame_id
    q = q_seed.copy()
    damping = 1e-6
    for _ in range(options.max_iterations):
        pin.forwardKinematics(model, data, q)
        T = pin.updateFramePlacement(model, data, fid)
        err = pin.log6(T.actInv(T_world_tcp)).vector
        if (np.linalg.norm(T_world_tcp.translation - T.translation) < options.position_tolerance
                and np.linalg.norm(err[3:]) < options.orientation_tolerance):
            return q
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        Jlog = pin.Jlog6(T.actInv(T_world_tcp))
        Jt = Jlog @ J
        dq = Jt.T @ np.linalg.solve(Jt @ Jt.T + damping * np.eye(6), err)
        q = np.clip(q + dq, robot.lower, robot.upper)
    return None


def cartesian_line(robot: Robot, q_start: np.ndarray, q_goal: np.ndarray, *,
                   options: LineOptions = LineOptions(), step_name: str | None = None
                   ) -> list[np.ndarray]:
    """Joint waypoints that move the TCP in a straight line from its pose at
    ``q_start`` to its pose at ``q_goal``; the last waypoint is ``q_goal`` itself.

    Raises:
        IKError: No continuous IK solution; says where along the line and why.
    """
    T0 = robot.frame_pose(q_start)
    T1 = robot.frame_pose(q_goal)
    length = float(np.linalg.norm(T1.translation - T0.translation))
    angle = float(np.linalg.norm(pin.log3(T0.rotation.T @ T1.rotation)))
    n = max(1, int(np.ceil(max(length / options.step, angle / 0.05))))
    path = [q_start.copy()]
    q = q_start.copy()
    data = robot.model.createData()
    for k in range(1, n + 1):
        s = k / n
        rotation = _interp(T0, T1, s).rotation
        T = pin.SE3(rotation, (1 - s) * T0.translation + s * T1.translation)
        # Seed with the previous step's motion continued (fewer iterations); the jump
        # bound below is still measured from the previous waypoint.
        seed = q if len(path) < 2 else np.clip(2 * q - path[-2], robot.lower, robot.upper)
        q_next = solve_ik(robot, T, seed, options=options, data=data)
        if q_next is None:
            raise IKError("no inverse-kinematics solution (out of reach or at a joint limit)",
                          step=step_name, fraction=s, position=T.translation.copy())
        jump = float(np.max(np.abs(q_next - q)))
        if jump > options.max_joint_step:
            raise IKError(f"joint jump of {jump:.3f} rad for a {length / n * 1000:.1f} mm TCP "
                          "step (singularity or branch switch)", step=step_name, fraction=s,
                          position=T.translation.copy())
        path.append(q_next)
        q = q_next
    gap = float(np.max(np.abs(path[-1] - q_goal)))
    if gap > options.goal_tolerance:
        raise IKError(f"the line ends {gap:.3f} rad away from the taught pose (another IK "
                      "branch)", step=step_name, fraction=1.0, position=T1.translation.copy())
    path[-1] = q_goal.copy()
    return path


def _interp(T0: pin.SE3, T1: pin.SE3, s: float) -> pin.SE3:
    return T0 * pin.exp6(s * pin.log6(T0.actInv(T1)))
