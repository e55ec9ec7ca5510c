"""Pours: continuous Cartesian motions of a held cup, timed by TOPP-RA, checked per sample.

Two motions of the pouring cell (brief 001), each one continuous timed trajectory instead
of the brief's 20 separate MoveIt moves:

* :func:`plan_tilt`: from upright to the pour orientation about a fixed pour point (the
  cup's lip): the orientation is interpolated on SO(3) (geodesic,
  ``R(u) = R0 exp(u log(R0^T R1))``) and the TCP turns with it about the pivot, so the lip
  stays where it is. The cup's angular speed is bounded: on a rotation about a fixed
  point, the TCP speed is the angular speed times the TCP's distance to that point, so the
  bound is a TCP speed limit for TOPP-RA, and the released samples are re-measured.
* :func:`plan_barista`: the same tilt, ending at the start of a circle, then the TCP on a
  circle at constant height with the tilt held, as one trajectory with a TCP speed limit.

Each path is followed by inverse kinematics (waypoints every ``angle_step`` of rotation
and ``path_step`` of TCP travel, each seeded from the last; a joint jump larger than
``max_joint_step`` is an :class:`~safepath.errors.IKError`), splined through the waypoints,
timed by :func:`~safepath.timing.time_path`, then every released sample is checked:
joint limits (by the timing), TCP and angular speed (a uniform time stretch removes any
excess at the knots), distance to the reference path and tilt error (a
:class:`~safepath.errors.PlanningError` beyond ``position_tolerance`` or
``angle_tolerance``), collisions (the cell's checker), and the independent FCL verifier.

These are planning primitives, not the pouring cell's application: a route's ``tilt`` and
``circle`` steps (:mod:`safepath.cell.pour_steps`) are planned with them inside
:func:`~safepath.planning.plan_cell`, so they stay below it. What the pouring cell does with
them (the flow model, the scale, the controller that stops the tilt) is
:mod:`safepath.cells.pouring`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..errors import ConfigError, IKError, PlanningError
from ..kinematics import LineOptions, solve_ik
from ..model.trajectory import Trajectory
from ..timing import PathSpline, TimingOptions, spline_path, stretch_knots, time_path
from ..verify import FclVerifier, VerifyResult

if TYPE_CHECKING:
    from ..cell import Cell
    from ..collision import CollisionChecker

__all__ = ["PourOptions", "PourMotion", "PourWorld", "plan_tilt", "plan_barista", "tilt_of",
           "cup_axis_in_tcp"]

#: Poses along a motion: u in [0, 1] -> T_world_tcp (4x4).
PoseCurve = Callable[[float], np.ndarray]


@dataclass(frozen=True, kw_only=True)
class PourOptions:
    """Options of the pour motions.

    Attributes:
        max_angular_speed: Bound on the cup's angular speed during a tilt [rad/s].
        tcp_speed: TCP speed limit on the barista circle [m/s].
        speed: Fraction of the joint velocity and acceleration limits, in (0, 1].
        angle_step: Rotation between two IK waypoints [rad].
        path_step: TCP travel between two IK waypoints [m].
        max_joint_step: Largest joint change between two waypoints [rad] (more: a branch
            switch or a singularity, refused).
        position_tolerance: Largest distance of a released sample's TCP from the
            reference path [m].
        angle_tolerance: Largest orientation error of a released sample [rad].
        timing: TOPP-RA options.
    """

    max_angular_speed: float = math.radians(20.0)
    tcp_speed: float = 0.05
    speed: float = 1.0
    angle_step: float = math.radians(1.0)
    path_step: float = 0.002
    max_joint_step: float = 0.1
    position_tolerance: float = 0.001
    angle_tolerance: float = math.radians(1.0)
    timing: TimingOptions = field(default_factory=lambda: TimingOptions(spacing=0.2))

    def __post_init__(self) -> None:
        for name in ("max_angular_speed", "tcp_speed", "angle_step", "path_step",
                     "max_joint_step", "position_tolerance", "angle_tolerance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"must be a positive number, got {value!r}", key=name)
        if not 0 < self.speed <= 1:
            raise ConfigError(f"must lie in (0, 1], got {self.speed!r}", key="speed")


@dataclass(frozen=True)
class PourMotion:
    """A timed, verified pour motion and what was measured on its released samples.

    Attributes:
        trajectory: The trajectory (steps ``tilt`` and, for the barista pour, ``circle``).
        path: The joint path it follows (``q(s)``), for path-consistent stops.
        s: Path parameter of each knot.
        tilt: Angle between the cup's axis and the vertical at each knot [rad].
        position_error: Distance of the TCP from the reference path at each knot [m].
        angle_error: Orientation error from the reference at each knot [rad].
        tcp_speed: TCP speed at each knot [m/s].
        angular_speed: Cup angular speed at each knot [rad/s].
        verify: The independent re-check's result.
    """

    trajectory: Trajectory
    path: PathSpline
    s: np.ndarray
    tilt: np.ndarray
    position_error: np.ndarray
    angle_error: np.ndarray
    tcp_speed: np.ndarray
    angular_speed: np.ndarray
    verify: VerifyResult


def cup_axis_in_tcp(cell: Cell) -> np.ndarray:
    """The held object's axis (its local z) in the TCP frame (unit vector)."""
    if cell.scene.grasp is None:
        raise ConfigError("the scene defines no grasp", path=cell.scene.path, key="grasp")
    return np.asarray(cell.scene.grasp.T_tcp_object[:3, 2], dtype=float)


def tilt_of(R_world_tcp: np.ndarray, axis_tcp: np.ndarray) -> float:
    """Angle between the cup's axis and the world's +z [rad]."""
    up = np.asarray(R_world_tcp) @ axis_tcp
    return float(math.acos(max(-1.0, min(1.0, float(up[2])))))


def tilt_curve(T_start: np.ndarray, R_goal: np.ndarray, pivot: np.ndarray) -> PoseCurve:
    """TCP poses turning from ``T_start``'s orientation to ``R_goal`` on the SO(3)
    geodesic, about the fixed world point ``pivot``."""
    R0 = T_start[:3, :3]
    w = pin.log3(R0.T @ R_goal)
    lever = T_start[:3, 3] - pivot

    def pose(u: float) -> np.ndarray:
        R = R0 @ pin.exp3(u * w)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = pivot + R @ R0.T @ lever
        return T

    return pose


def circle_curve(T_start: np.ndarray, center: np.ndarray, turns: float) -> PoseCurve:
    """TCP poses on the horizontal circle about ``center`` through ``T_start``'s position,
    orientation held."""
    rel = T_start[:3, 3] - center
    radius = float(np.hypot(rel[0], rel[1]))
    phi0 = math.atan2(rel[1], rel[0])

    def pose(u: float) -> np.ndarray:
        phi = phi0 + 2 * math.pi * turns * u
        T = T_start.copy()
        T[:3, 3] = center + np.array([radius * math.cos(phi), radius * math.sin(phi), rel[2]])
        return T

    return pose


@dataclass(frozen=True)
class PourWorld:
    """The world a pour is checked in, as a route has it (default: the cell's grasped
    object held, the others where the scene puts them).

    Attributes:
        checker: The collision checker of released samples.
        verifier: The independent re-check.
        names: Step names of the motion's parts (``tilt`` and ``circle`` by default).
    """

    checker: CollisionChecker
    verifier: FclVerifier
    names: tuple[str, ...]


def plan_tilt(cell: Cell, q_start: np.ndarray, R_goal: np.ndarray, pivot: np.ndarray, *,
              options: PourOptions = PourOptions(), resting: dict | None = None,
              world: PourWorld | None = None) -> PourMotion:
    """Tilt the held cup from the orientation at ``q_start`` to ``R_goal`` (TCP frame in
    the world) about ``pivot`` [m], as one continuous timed trajectory.

    ``world`` (a route's step: its checker, verifier and step name) replaces the cell's
    default world and ``resting``.

    Raises:
        IKError: The path leaves the reachable set or switches branch.
        PlanningError: A released sample leaves the path or the tilt tolerance.
        TimingError: No timing within the limits.
        VerificationError: The independent re-check finds a collision.
    """
    T0 = cell.robot.frame_pose(q_start).homogeneous
    curve = tilt_curve(T0, R_goal, np.asarray(pivot, dtype=float))
    angle = float(np.linalg.norm(pin.log3(T0[:3, :3].T @ R_goal)))
    lever = float(np.linalg.norm(T0[:3, 3] - pivot))
    if lever < 1e-3:
        raise ConfigError("the pivot must lie away from the TCP (the angular speed is "
                          "bounded through the TCP speed about it)", key="pivot")
    n = max(2, math.ceil(angle / options.angle_step))
    return _plan(cell, q_start, [(curve, n, options.max_angular_speed * lever, "tilt")],
                 options, resting, world)


def plan_barista(cell: Cell, q_start: np.ndarray, R_goal: np.ndarray, pivot: np.ndarray,
                 center: np.ndarray, *, turns: float = 1.0, options: PourOptions = PourOptions(),
                 resting: dict | None = None, world: PourWorld | None = None) -> PourMotion:
    """Tilt about ``pivot`` as :func:`plan_tilt`, then move the TCP ``turns`` times round
    the horizontal circle about ``center`` [m] through the tilted TCP, tilt held, as one
    continuous trajectory (TCP speed at most ``options.tcp_speed`` on the circle)."""
    robot = cell.robot
    T0 = robot.frame_pose(q_start).homogeneous
    pivot = np.asarray(pivot, dtype=float)
    tilt = tilt_curve(T0, R_goal, pivot)
    T1 = tilt(1.0)
    center = np.asarray(center, dtype=float)
    radius = float(np.hypot(*(T1[:2, 3] - center[:2])))
    if radius < 1e-3:
        raise ConfigError("the circle's centre must lie away from the tilted TCP",
                          key="center")
    circle = circle_curve(T1, center, turns)
    angle = float(np.linalg.norm(pin.log3(T0[:3, :3].T @ R_goal)))
    lever = float(np.linalg.norm(T0[:3, 3] - pivot))
    n_tilt = max(2, math.ceil(angle / options.angle_step))
    n_circle = max(8, math.ceil(2 * math.pi * radius * abs(turns) / options.path_step))
    return _plan(cell, q_start, [(tilt, n_tilt, options.max_angular_speed * lever, "tilt"),
                                 (circle, n_circle, options.tcp_speed, "circle")],
                 options, resting, world)


def _follow(cell: Cell, q_start: np.ndarray, parts: list[tuple[PoseCurve, int, float, str]],
            options: PourOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """IK waypoints along the parts; their part index and parameter, and the target poses."""
    robot = cell.robot
    line = LineOptions(position_tolerance=1e-6, orientation_tolerance=1e-5,
                       max_iterations=100)
    data = robot.model.createData()
    qs, part_of, u_of, poses = [np.asarray(q_start, dtype=float)], [0], [0.0], \
        [parts[0][0](0.0)]
    q = qs[0]
    for k, (curve, n, _, name) in enumerate(parts):
        for i in range(1, n + 1):
            u = i / n
            T = curve(u)
            try:
                sol = solve_ik(robot, pin.SE3(T[:3, :3], T[:3, 3]), q, options=line,
                               data=data, step=name)
            except IKError:
                raise IKError("no inverse-kinematics solution on the pour path", step=name,
                              fraction=u, position=T[:3, 3].copy()) from None
            jump = float(np.max(np.abs(sol - q)))
            if jump > options.max_joint_step:
                raise IKError(f"joint jump of {jump:.3f} rad (singularity or branch switch)",
                              step=name, fraction=u, position=T[:3, 3].copy())
            q = sol
            qs.append(q)
            part_of.append(k)
            u_of.append(u)
            poses.append(T)
    return np.array(qs), np.array(part_of), np.array(u_of), np.array(poses)


def _plan(cell: Cell, q_start: np.ndarray, parts: list[tuple[PoseCurve, int, float, str]],
          options: PourOptions, resting: dict | None, world: PourWorld | None) -> PourMotion:
    robot = cell.robot
    kinds = np.array([p[3] for p in parts])  # "tilt", "circle"
    if world is not None:
        parts = [(c, n, v, name) for (c, n, v, _), name in zip(parts, world.names, strict=True)]
    W, part_of, u_of, _ = _follow(cell, q_start, parts, options)
    path, s_way, _ = spline_path(list(W), options.timing.spacing)
    seg_part = part_of[1:]  # polyline segment k ends at waypoint k + 1
    piece = time_path(robot, path, s_way, scales=[options.speed] * len(seg_part),
                      tcp_speeds=[parts[p][2] for p in seg_part], options=options.timing,
                      step=parts[0][3])
    t, q, qd, qdd, s = piece.t, piece.q, piece.qd, piece.qdd, piece.s
    axis = cup_axis_in_tcp(cell)
    # Where each knot is on the reference: its polyline segment, and the fraction there.
    seg = np.clip(np.searchsorted(s_way, s, side="right") - 1, 0, len(seg_part) - 1)
    frac = np.clip((s - s_way[seg]) / np.maximum(s_way[seg + 1] - s_way[seg], 1e-300), 0, 1)
    T_knots = np.array([robot.frame_pose(qk).homogeneous for qk in q])
    v_lim = np.array([parts[p][2] for p in seg_part])[seg]
    v_tcp, w_cup = _speeds(robot, q, qd, T_knots)
    w_lim = np.where(kinds[seg_part][seg] == "tilt",
                     options.max_angular_speed, np.inf)
    stretch = max(1.0, float(np.max(v_tcp / v_lim)), float(np.max(w_cup / w_lim)))
    if stretch > 1.0:  # knots between TOPP-RA's gridpoints: stretch time uniformly
        t, qd, qdd, stretch = stretch_knots(t, qd, qdd, stretch * (1.0 + 1e-9))
        v_tcp, w_cup = v_tcp / stretch, w_cup / stretch
    pos_err, ang_err = np.empty(len(t)), np.empty(len(t))
    # Dense polylines of the reference paths: chords of 1/4000 of a part stay within
    # nanometres of a circle of a few centimetres.
    dense = [np.array([c(float(x))[:3, 3] for x in np.linspace(0.0, 1.0, 4001)])
             for c, *_ in parts]
    for k in range(len(t)):
        p = seg_part[seg[k]]
        u0 = u_of[seg[k]] if part_of[seg[k]] == p else 0.0
        u = u0 + frac[k] * (u_of[seg[k] + 1] - u0)
        ref = parts[p][0](u)
        ang_err[k] = float(np.linalg.norm(pin.log3(ref[:3, :3].T @ T_knots[k, :3, :3])))
        pos_err[k] = _distance_to_curve(dense[p], u, T_knots[k, :3, 3])
    worst = int(np.argmax(pos_err))
    names = [p[3] for p in parts]
    if pos_err[worst] > options.position_tolerance:
        raise PlanningError(f"the TCP leaves the path by {pos_err[worst] * 1000:.2f} mm at "
                            f"t = {t[worst]:.3f} s", step=names[seg_part[seg[worst]]])
    worst = int(np.argmax(ang_err))
    if ang_err[worst] > options.angle_tolerance:
        raise PlanningError(f"the orientation is off by {math.degrees(ang_err[worst]):.2f} "
                            f"deg at t = {t[worst]:.3f} s", step=names[seg_part[seg[worst]]])
    step_index = seg_part[seg]
    held = cell.scene.grasp.object if cell.scene.grasp else None
    checker = world.checker if world else cell.checker(held=held is not None)
    report = checker.check_path(list(q))
    if not report.valid:
        why = report.limit_violation or ", ".join(f"{a} / {b}" for a, b in report.collisions)
        raise PlanningError(f"the pour collides ({why})", step=names[0])
    verifier = world.verifier if world else FclVerifier(robot, cell.scene, held=held,
                                                        resting=resting or {})
    result = verifier.verify(t, q, qd, steps=[names[i] for i in step_index])
    traj = Trajectory(robot.joint_names, t, q, qd, qdd, step_index, tuple(names),
                      robot=robot.name, route="+".join(names),
                      info={"min_clearance": result.min_clearance, "time_stretch": stretch},
                      limits=robot.motion_limits, interpolation=robot.controller.interpolation)
    tilt = np.array([tilt_of(T[:3, :3], axis) for T in T_knots])
    return PourMotion(traj, path, s, tilt, pos_err, ang_err, v_tcp, w_cup, result)


def _speeds(robot: object, q: np.ndarray, qd: np.ndarray, T_knots: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """TCP speed [m/s] and angular speed [rad/s] at the knots (Jacobian times qd)."""
    from ..model.robot import Robot

    assert isinstance(robot, Robot)
    model, data = robot.model, robot.model.createData()
    v, w = np.empty(len(q)), np.empty(len(q))
    for k in range(len(q)):
        J = pin.computeFrameJacobian(model, data, q[k], robot.tcp_frame_id,
                                     pin.LOCAL_WORLD_ALIGNED)
        twist = J @ qd[k]
        v[k], w[k] = np.linalg.norm(twist[:3]), np.linalg.norm(twist[3:])
    return v, w


def _distance_to_curve(points: np.ndarray, u: float, p: np.ndarray, window: int = 12
                       ) -> float:
    """Distance from ``p`` to a dense polyline of a curve (``points`` at evenly spaced
    parameters over [0, 1]), searched near parameter ``u``."""
    n = len(points) - 1
    i = int(round(u * n))
    a = points[max(0, i - window):min(n, i + window)]
    b = points[max(1, i - window + 1):min(n, i + window) + 1]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab),
                                                              1e-300), 0, 1)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))
