"""Stop on a sensor event: the path-consistent stop, the simulated scale, the closed loop.

Real Pinocchio/TOPP-RA/FCL through the pouring cell's slow tilt; the flow model is the
documented simulation of ``safepath.cells.pouring.flow``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from safepath import ConfigError, load_cell
from safepath.cell import Cell
from safepath.cells.pouring.cup import Cup
from safepath.cells.pouring.flow import (
    FlowModel,
    plan_stops,
    simulate_pour,
    simulate_stepwise,
    stop_and_return,
)
from safepath.planning.pour import PourMotion, PourOptions, plan_tilt
from safepath.planning.stop import StopPlanner, path_state

REPO_ROOT = Path(__file__).resolve().parents[2]
LIP = np.array([0.0, 0.035, 0.04])


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_cell(REPO_ROOT / "scenes" / "pouring_cell")


@pytest.fixture(scope="module")
def tilt(cell: Cell) -> PourMotion:
    q0 = cell.pose("above_bowl")
    T0 = cell.robot.frame_pose(q0)
    R1 = pin.exp3(np.array([-1.0, 0.0, 0.0]) * math.radians(115)) @ T0.rotation
    # A quick tilt (20 deg/s) keeps the braking long enough to be worth checking.
    return plan_tilt(cell, q0, R1, T0.translation + LIP,
                     options=PourOptions(max_angular_speed=math.radians(20)))


def test_stops_stay_on_the_path_within_the_limits(cell: Cell, tilt: PourMotion) -> None:
    robot, traj = cell.robot, tilt.trajectory
    planner = StopPlanner(robot, tilt.path, timed=(traj.t, tilt.s, traj.q, traj.qd, traj.qdd))
    for event in np.linspace(0.1, traj.duration - 0.05, 25):
        s, sd = path_state(tilt.path, tilt.s, traj.qd, traj.t, float(event))
        stop = planner.stop(s, sd, time=float(event))
        # Starts where the motion is, at its speed; ends at rest.
        k = int(np.searchsorted(traj.t, event))
        assert np.linalg.norm(stop.q[0] - traj.q[k]) < 0.01
        qd_event = [np.interp(event, traj.t, traj.qd[:, j]) for j in range(robot.dof)]
        assert np.linalg.norm(stop.qd[0] - qd_event) < 1e-2  # (near the end: the next knot)
        np.testing.assert_array_equal(stop.qd[-1], 0.0)
        # Never leaves the path: every sample is q(s) for an s ahead, going forward.
        np.testing.assert_allclose(stop.q, tilt.path(stop.s), atol=1e-12)
        assert np.all(np.diff(stop.s) >= -1e-12) and stop.s[-1] <= tilt.path.x[-1] + 1e-12
        assert s - 1e-12 <= stop.s[0] <= s + 1e-3
        # Within the limits at every sample, and it really brakes (faster than the motion
        # would come to rest by itself, except near the end).
        assert np.all(np.abs(stop.qd) <= robot.velocity_limits * (1 + 1e-9))
        assert np.all(np.abs(stop.qdd) <= robot.acceleration_limits * (1 + 1e-9))
        if event < traj.duration - 1.0:
            assert stop.duration < traj.duration - event - 0.5


def test_the_scale_model_is_checked() -> None:
    with pytest.raises(ConfigError, match="gain"):
        FlowModel(gain=0.0)
    with pytest.raises(ConfigError, match="latency"):
        FlowModel(latency=-0.1)
    with pytest.raises(ConfigError, match="Cup") as info:
        FlowModel(cup="rice")  # type: ignore[arg-type]
    assert info.value.key == "cup"
    model = FlowModel(gain=50.0)  # the endless cup: a fixed spill angle
    assert model.rate(np.array([0.0, model.spill_angle]))[1] == 0.0
    assert model.rate(np.array([model.spill_angle + 1.0]))[0] == pytest.approx(50.0)
    with pytest.raises(ConfigError) as info:
        Cup(fill=1000.0)  # more than the cup holds
    assert info.value.key == "fill"
    with pytest.raises(ConfigError) as info:
        Cup(repose=-0.1)
    assert info.value.key == "repose"


def test_the_cup_empties_over_its_lip() -> None:
    cup = Cup(radius=0.03, depth=0.1, fill=200.0, density=1.0, repose=0.0)
    # Upright it holds its fill; on its side (90 deg, no repose) nothing.
    assert cup.held(0.0) == pytest.approx(200.0)
    assert cup.held(math.pi / 2) == pytest.approx(0.0, abs=1e-6)
    # Half full (the plane through the rim's lowest point and the bottom's far edge:
    # tan = depth / (2 radius)) it holds half the cylinder: pi r^2 h / 2 [g].
    half = math.atan(0.1 / 0.06)
    assert float(cup.held(half)) == pytest.approx(math.pi * 0.03 ** 2 * 0.1 / 2 * 1e6, rel=2e-3)
    tilts = np.linspace(0.0, math.pi, 200)
    assert np.all(np.diff(cup.held(tilts)) <= 1e-9)
    # The spill angle rises as the cup empties.
    assert cup.spill_angle(150.0) < cup.spill_angle(100.0) < cup.spill_angle(10.0)
    # Held at a fixed tilt the flow dies out once the cup keeps what that tilt keeps.
    t = np.linspace(0.0, 20.0, 10001)
    theta = np.full(t.size, math.radians(70.0))
    poured = 200.0 - float(cup.held(math.radians(70.0)))
    out = cup.pour(t, theta, np.array([50.0, 2000.0]))
    assert np.all(np.diff(out, axis=1) >= 0.0) and np.all(out <= poured + 1e-9)
    assert out[1, -1] == pytest.approx(poured, abs=1.0)
    # Faster with a larger gain.
    assert out[1, 200] > out[0, 200] > 0.0


def test_closed_loop_pours_within_two_grams(cell: Cell) -> None:
    q0 = cell.pose("above_bowl")
    T0 = cell.robot.frame_pose(q0)
    pivot = T0.translation + LIP
    R1 = pin.exp3(np.array([-1.0, 0.0, 0.0]) * math.radians(115)) @ T0.rotation
    slow = plan_tilt(cell, q0, R1, pivot, options=PourOptions(max_angular_speed=math.radians(5)))
    traj = slow.trajectory
    stop = stop_and_return(cell, slow, T0.rotation, pivot,
                           options=PourOptions(max_angular_speed=math.radians(30)))

    def tilt_of_t(x: float) -> float:
        return float(np.interp(x, traj.t, slow.tilt))

    stops = plan_stops(stop, tilt_of_t, traj.duration, Cup(), samples=8)
    finals, stepwise, direct = [], [], []
    for gain, latency, seed in ((550.0, 0.05, 1), (1900.0, 0.28, 2), (1000.0, 0.15, 3)):
        model = FlowModel(gain=gain, latency=latency, seed=seed, cup=Cup())
        run = simulate_pour(tilt_of_t, traj.duration, stop, model, stops=stops)
        assert run.stop_time is not None and run.stop_time < traj.duration
        assert run.compute_time < 0.5  # generous: the figure is benchmarks/pour.py's
        # The cup came back upright and the mass curve only grows.
        assert run.tilt[-1] < math.radians(0.5)
        assert np.all(np.diff(run.mass) >= -1e-9)
        # The controller found the flow's gain from the readings (not given to it).
        assert 0.7 < run.gain_estimate / gain < 1.4
        finals.append(run.final_mass)
        stepwise.append(simulate_stepwise(model).final_mass)
        direct.append(simulate_stepwise(model, steps=1, angle=math.pi / 2).final_mass)
    assert all(abs(m - 100.0) <= 2.0 for m in finals), finals
    # The brief's ways in the same simulation (the flow model's fill, repose and gain
    # were fitted to the brief's figures: ~103 g with 20 steps, 110-120 g with one move
    # to 90 deg): both overshoot (benchmarks/pour.py prints 24 runs of each).
    assert all(102.0 < m < 116.0 for m in stepwise), stepwise
    assert all(106.0 < m <= 115.0 + 1e-6 for m in direct), direct
