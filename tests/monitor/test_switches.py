"""Replacement goals continue the motion that is running (issue 34): each one's first point
is the state (p, v, a) the controller commands when it takes the goal, joined as
ros2_control's joint_trajectory_controller joins a new goal, computed here by the tests'
own quintic; stops are sent at once (never deferred) and within the limits as executed."""

from __future__ import annotations

import numpy as np
import pytest
from quintic_join import quintic_peaks, quintic_state
from random_decisions import decisions, goal_points

from safepath import Cell
from safepath.model.execution import ControllerModel

from .conftest import Phase1, make_monitor


def test_the_monitor_follows_the_goal_it_sent_without_lag(cell: Cell, phase1: Phase1) -> None:
    traj, held = phase1.motions[0]
    monitor = make_monitor(cell)
    monitor.follow(traj, start=2.0, held=held)
    for t in (2.0, 2.1, 2.5, 3.7):
        tau, r = monitor.state_at(t)
        assert tau == pytest.approx(t - 2.0 + traj.t[0], abs=1e-9) and r == pytest.approx(1.0)


@pytest.mark.parametrize("seed", [3, 11])
def test_every_switch_continues_the_running_motion_within_the_limits(
        cell: Cell, phase1: Phase1, seed: int) -> None:
    robot = cell.robot
    limits = (robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)
    rng = np.random.default_rng(seed)
    kinds: dict[str, int] = {}
    worst_step, worst = 0.0, np.zeros(3)
    for run in range(30):
        traj, held = phase1.motions[run % 2]
        monitor = make_monitor(cell, hold_time=0.1)
        monitor.follow(traj, start=0.0, held=held)
        # (stamp, t, P, V, A) of the goal in force
        running = (0.0, *goal_points(traj, robot.controller))
        kill_at = rng.uniform(0.0, traj.duration) if run % 3 == 0 else None
        for t, decision in decisions(monitor, traj.duration, rng, kill_at=kill_at,
                                     jitter=0.005):
            assert "deferred" not in decision.reason
            assert "beyond the limits" not in decision.reason, decision.reason
            rep = decision.replacement
            if rep is None:
                continue
            kinds[decision.kind] = kinds.get(decision.kind, 0) + 1
            start = decision.replacement_start
            assert start is not None
            assert start >= t + monitor.options.command_latency - 1e-9
            # On the running goal's next point at or after the latency (its points are
            # the knot period apart, or a little more where the timing stretched them).
            spacing = float(np.max(np.diff(running[1]), initial=0.004))
            assert start <= t + monitor.options.command_latency + spacing + 1e-9
            t_new, P, V, A = goal_points(rep, robot.controller)  # noqa: N806
            stamp, *old = running
            p, v, a = quintic_state(old[0] + stamp, *old[1:], at=start)
            assert t_new[0] == 0.0
            worst_step = max(worst_step, *(float(np.max(np.abs(x - y)))
                                           for x, y in ((P[0], p), (V[0], v), (A[0], a))))
            if t_new.size > 1:
                peaks = quintic_peaks(t_new, P, V, A)
                worst = np.maximum(worst, [float(np.max(pk / lim))
                                           for pk, lim in zip(peaks, limits, strict=True)])
            running = (start, t_new, P, V, A)
    assert worst_step <= 1e-6, worst_step  # no jump at any switch
    assert np.all(worst <= 1.0 + 1e-9), worst
    assert {"slow", "stop", "resume"} <= set(kinds), kinds


def test_the_controller_model_joins_a_late_goal_from_its_state() -> None:
    """A goal whose first point lies after the switch is joined from the commanded state
    (not from rest); points in the past are dropped; a first point at the switch steps."""
    model = ControllerModel(np.zeros(1))
    t = np.linspace(0.0, 1.0, 11)
    q = (t ** 2)[:, None]
    model.take(t, q, (2 * t)[:, None], np.full((11, 1), 2.0), start=0.0)
    p, v, a = model.state(0.55)
    assert p[0] == pytest.approx(0.3025) and v[0] == pytest.approx(1.1) and a[0] == pytest.approx(2)
    # A goal stamped 0.4 whose points start at 0.1: taken at 0.55, its point at 0.5 is
    # dropped and its next (0.6) joined from the state at 0.55.
    sw = model.take(t[1:], q[1:] + 1.0, np.zeros((10, 1)), np.zeros((10, 1)), start=0.4,
                    time=0.55)
    assert sw.joined and sw.first == 1 and sw.continuous
    assert np.allclose(model.state(0.55)[1], 1.1)
    assert np.allclose(model.state(0.6)[0], 1.04)
    # A goal whose first point lies at the switch replaces the state at once: a step.
    sw = model.take(np.array([0.0, 0.1]), np.array([[5.0], [5.0]]), np.zeros((2, 1)),
                    np.zeros((2, 1)), start=0.7)
    assert not sw.joined and not sw.continuous and sw.position_step > 3.0
    assert model.state(2.0)[0][0] == 5.0 and model.state(2.0)[1][0] == 0.0
