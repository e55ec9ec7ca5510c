"""The pouring cell: pick and place with the cup kept upright, the slow tilt and the barista
pour as continuous timed trajectories, on real Pinocchio, OMPL, TOPP-RA and FCL.

Every figure is measured here from the released samples themselves (forward kinematics
of the timed joint positions), not taken from what the planner reports.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from safepath import Cell, PlanningError, load_cell
from safepath.cell.routes import Route, Step, Target
from safepath.model.trajectory import Trajectory
from safepath.planning import WorldState, plan_cell, plan_route
from safepath.planning.pour import PourMotion, PourOptions, plan_barista, plan_tilt, tilt_curve

REPO_ROOT = Path(__file__).resolve().parents[2]
POURING = REPO_ROOT / "scenes" / "pouring_cell"
LIP = np.array([0.0, 0.035, 0.04])  # the pour lip from the upright TCP [m], world axes
OPTIONS = PourOptions()


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_cell(POURING)


def _tilts(cell: Cell, q: np.ndarray) -> np.ndarray:
    assert cell.scene.grasp is not None
    axis = cell.scene.grasp.T_tcp_object[:3, 2]
    return np.array([math.acos(np.clip((cell.robot.frame_pose(qk).rotation @ axis)[2], -1, 1))
                     for qk in q])


def _within_joint_limits(cell: Cell, traj: Trajectory) -> None:
    robot = cell.robot
    assert np.all(traj.q >= robot.lower - 1e-9) and np.all(traj.q <= robot.upper + 1e-9)
    assert np.all(np.abs(traj.qd) <= robot.velocity_limits * (1 + 1e-9))
    assert np.all(np.abs(traj.qdd) <= robot.acceleration_limits * (1 + 1e-9))


@pytest.fixture(scope="module")
def planned(cell: Cell) -> dict[str, Trajectory]:
    return plan_cell(cell)


def test_pick_and_place_keep_the_cup_upright(cell: Cell, planned: dict[str, Trajectory]
                                             ) -> None:
    from safepath.cell import load_routes

    routes = load_routes(POURING, poses=list(cell.poses), objects=list(cell.scene.objects))
    assert set(planned) == {"pick_cup", "slow_pour", "barista_pour", "place_cup"}
    constrained = 0
    for name, traj in planned.items():
        _within_joint_limits(cell, traj)
        tilt = _tilts(cell, traj.q)
        for i, step in enumerate(routes[name].steps):
            rows = traj.step_index == i
            if step.max_tilt is not None and rows.any():
                constrained += int(rows.sum())
                assert tilt[rows].max() <= step.max_tilt, (name, traj.steps[i])
    assert constrained > 500  # the transport really is constrained, sample by sample
    # The cup is carried across, from the cup's side to the bowl's, never back (the
    # corner at above_cup is blended: the transport starts while the cup still rises).
    pick = planned["pick_cup"]
    last = pick.step_index == len(pick.steps) - 1
    y = np.array([cell.robot.tcp_position(q)[1] for q in pick.q[last]])
    assert np.all(np.diff(y) >= -1e-9) and y[-1] == pytest.approx(0.20, abs=1e-4)


def test_a_transport_that_tilts_the_cup_is_refused(cell: Cell) -> None:
    # A free joint move between the same two poses swings the wrist: the cup tilts.
    route = Route("swing", "above_cup",
                  (Step("move", Target("above_bowl"), max_tilt=math.radians(5)),))
    with pytest.raises(PlanningError, match="tilts") as info:
        plan_route(cell, route, world=WorldState(held="cup"))
    assert info.value.step == "0 move above_bowl"


def _tilt_setup(cell: Cell, degrees: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q0 = cell.pose("above_bowl")
    T0 = cell.robot.frame_pose(q0)
    pivot = T0.translation + LIP
    R1 = pin.exp3(np.array([-1.0, 0.0, 0.0]) * math.radians(degrees)) @ T0.rotation
    return q0, R1, pivot


@pytest.fixture(scope="module")
def slow_tilt(cell: Cell) -> PourMotion:
    q0, R1, pivot = _tilt_setup(cell, 115.0)
    return plan_tilt(cell, q0, R1, pivot, options=OPTIONS)


def test_slow_tilt_is_one_continuous_motion_about_the_pour_point(cell: Cell,
                                                                 slow_tilt: PourMotion) -> None:
    traj = slow_tilt.trajectory
    _within_joint_limits(cell, traj)
    tilt = _tilts(cell, traj.q)
    assert tilt[0] < math.radians(0.5)
    assert abs(math.degrees(tilt[-1]) - 115.0) < 1.0
    # No stop on the way (the brief's 20 separate moves stopped 19 times).
    speed = np.linalg.norm(traj.qd, axis=1)
    assert np.all(speed[5:-5] > 1e-4)
    # The lip (the fixed pour point) stays where it is.
    q0, _, pivot = _tilt_setup(cell, 115.0)
    T0 = cell.robot.frame_pose(q0)
    lip_tcp = T0.actInv(pivot)
    drift = [np.linalg.norm(cell.robot.frame_pose(q).act(lip_tcp) - pivot) for q in traj.q]
    assert max(drift) < 1e-3
    # The cup's angular speed stays under its bound (finite differences of the released
    # orientations: each is an average of the instantaneous speed between two knots).
    R = [cell.robot.frame_pose(q).rotation for q in traj.q]
    omega = [np.linalg.norm(pin.log3(a.T @ b)) / dt
             for a, b, dt in zip(R[:-1], R[1:], np.diff(traj.t), strict=True)]
    assert max(omega) <= OPTIONS.max_angular_speed * (1 + 1e-6)
    assert max(omega) >= 0.9 * OPTIONS.max_angular_speed  # and it is the binding limit
    assert slow_tilt.verify.samples >= len(traj.t) // 2


def test_barista_pour_follows_the_circle_with_the_tilt_held(cell: Cell) -> None:
    q0, R1, pivot = _tilt_setup(cell, 93.0)
    T1 = tilt_curve(cell.robot.frame_pose(q0).homogeneous, R1, pivot)(1.0)
    center = T1[:3, 3] - np.array([0.03, 0.0, 0.0])
    motion = plan_barista(cell, q0, R1, pivot, center, options=OPTIONS)
    traj = motion.trajectory
    assert traj.steps == ("tilt", "circle")
    _within_joint_limits(cell, traj)
    on_circle = traj.step_index == 1
    assert on_circle.sum() > 100
    p = np.array([cell.robot.tcp_position(q) for q in traj.q[on_circle]])
    radial = np.abs(np.hypot(p[:, 0] - center[0], p[:, 1] - center[1]) - 0.03)
    height = np.abs(p[:, 2] - center[2])
    assert np.hypot(radial, height).max() <= 1e-3
    tilt = _tilts(cell, traj.q[on_circle])
    assert np.abs(np.degrees(tilt) - 93.0).max() <= 1.0
    # A full turn, and the TCP speed limit held (finite differences, released samples).
    angle = np.unwrap(np.arctan2(p[:, 1] - center[1], p[:, 0] - center[0]))
    assert abs(abs(angle[-1] - angle[0]) - 2 * math.pi) < 0.05
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(traj.t[on_circle])
    assert v.max() <= OPTIONS.tcp_speed * (1 + 1e-6)
    # One motion: no stop between the tilt and the circle.
    boundary = int(np.argmax(on_circle))
    assert np.linalg.norm(traj.qd[boundary]) > 1e-3


def test_pour_options_are_checked() -> None:
    from safepath import ConfigError

    with pytest.raises(ConfigError, match="max_angular_speed"):
        PourOptions(max_angular_speed=0.0)
    with pytest.raises(ConfigError, match="speed"):
        PourOptions(speed=1.5)
