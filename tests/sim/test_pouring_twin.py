"""The pouring cell's twin: PourController closed loop on the simulated Gen3 Lite (MuJoCo)
and the simulated scale (the project's flow model on the tilt the simulated arm has)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safepath.errors import InputError
from safepath.ros import read_bag
from safepath.sim.bag import ARM_GOALS, JOINT_STATES, write_run_bag
from safepath.sim.pouring import PouringParams, run_pouring

#: The tilt alone (the cup held at the pour's start): the pick and place routes add
#: 35 s of simulated motion and nothing the controller decides on.
_TILT = PouringParams(pick_and_place=False)


@pytest.fixture(scope="module")
def pouring_dir(repo_root: Path) -> str:
    return str(repo_root / "scenes" / "pouring_cell")


def test_the_pour_ends_within_the_tolerance_without_an_executed_violation(
        pouring_dir: str, tmp_path: Path) -> None:
    run = run_pouring(pouring_dir, 3, _TILT, record=True)
    assert run.state == "done" and not run.faults, run.faults
    # Stopped on the scale: the stop joined the running tilt, then back upright.
    assert run.goals == ("pour", "stop", "return")
    assert run.report is not None and run.report.stopped
    assert run.within_tolerance, (run.final_mass, run.gain, run.latency)
    # The simulated arm: within its position limits, touching nothing, tracking closely,
    # and at least the cell's margin less the tracking allowance from the cell.
    assert run.limit_margin >= 0.0
    assert run.contact_steps == 0
    assert run.tracking.max() < 0.005
    assert run.clearance.states > 0
    assert run.clearance.clearance >= run.margin - run.tcp_deviation
    # The return upright is timed at 0.9965 of joint_6's speed limit; the servo overshoots
    # it by 0.35 % (measured 1.00007 of the limit): within 0.1 %, and reported as over.
    assert run.speed_ratio.max() <= 1.001
    # Its bag: the executed joint states and the three goals as sent.
    bag = read_bag(write_run_bag(tmp_path / "pour", run.record))
    assert len(bag.on(JOINT_STATES)) == len(run.record.time)
    assert len(bag.on(ARM_GOALS)) == 3


def test_a_kill_brakes_the_tilt_and_nothing_follows(pouring_dir: str) -> None:
    run = run_pouring(pouring_dir, 4, PouringParams(pick_and_place=False, kill_at=5.0))
    assert run.state == "fault" and run.faults == ("killed",)
    # The kill braked the tilt along its path (a stop goal), and no return followed.
    assert run.goals == ("pour", "stop")
    assert run.killed_at == pytest.approx(5.0, abs=0.01)
    assert run.moved_after_kill < 1e-3
    assert run.final_mass < run.target


def test_a_seed_gives_the_same_gain_and_bad_parameters_are_typed_errors(
        pouring_dir: str) -> None:
    with pytest.raises(InputError, match="seed"):
        run_pouring(pouring_dir, -1, _TILT)
    with pytest.raises(InputError, match="gain_range"):
        PouringParams(gain_range=(120.0, 40.0))
    with pytest.raises(InputError, match="kill_at"):
        PouringParams(kill_at=-1.0)
    with pytest.raises(InputError, match="pour_route"):
        run_pouring(pouring_dir, 0, PouringParams(pour_route="no_such_route",
                                                  pick_and_place=False))
    # A seed gives the same run: the same truth, readings and executed motion.
    short = PouringParams(pick_and_place=False, max_time=1.5)
    a = run_pouring(pouring_dir, 9, short, record=True)
    b = run_pouring(pouring_dir, 9, short, record=True)
    c = run_pouring(pouring_dir, 10, short)
    assert (a.gain, a.latency) == (b.gain, b.latency) != (c.gain, c.latency)
    assert np.array_equal(a.record.q, b.record.q) and np.array_equal(a.tracking, b.tracking)


def test_the_pour_ends_where_the_controller_predicts_not_short_of_it(pouring_dir: str) -> None:
    """Issue 35: every simulated pour ended under 100 g (mean 97.65). The stop braked from
    its first knot, at or before the decision, while the predictor counted the tilt
    running ``stop_lead`` longer, and its table of what the stop pours joined six events
    by chords: the prediction at the decision was 2-3 g above what landed. Now the stop
    holds the tilt's knots to where the predictor brakes, and the table is dense."""
    runs = [run_pouring(pouring_dir, seed, _TILT) for seed in range(6)]
    for run in runs:
        assert run.report is not None and run.report.stopped and run.report.predicted
        # What the controller predicted at its decision is what landed.
        assert abs(run.report.predicted - run.final_mass) < 1.0, (run.seed, run.gain)
        assert run.within_tolerance
    bias = float(np.mean([r.error for r in runs]))
    assert abs(bias) < 0.75, [round(r.final_mass, 2) for r in runs]


def test_the_stop_holds_the_tilt_until_it_brakes(pouring_dir: str) -> None:
    """The stop goal follows the tilt's own knots from the one at or before the decision
    to the first at or after ``decision + stop_lead`` (the goal reaches the trajectory
    controller before the arm deviates from the tilt), and only then brakes."""
    from safepath.cells.pouring.parts import PourStopper
    from safepath.sim.pouring import pour_plan

    plan = pour_plan(pouring_dir, None, False)
    stopper = PourStopper(plan.cell, plan.tilt, return_angular_speed=plan.return_speed)
    t = plan.tilt.trajectory.t
    decision = float(t[-1]) * 0.8 + 0.001  # between knots
    stop = stopper.stop(decision, decision + 0.05)
    path_tau = np.asarray(stop.info["path_tau"])
    k0 = int(np.searchsorted(t, stop.info["time_offset"]))
    held = path_tau[path_tau <= stop.info["brake_at"]]
    assert stop.info["time_offset"] <= decision <= stop.info["brake_at"] - 0.05
    np.testing.assert_array_equal(held, t[k0:k0 + held.size])
    np.testing.assert_array_equal(stop.q[:held.size], plan.tilt.trajectory.q[k0:k0 + held.size])
    assert stop.info["s_rest"] > float(np.interp(stop.info["brake_at"], t, plan.tilt.s))
