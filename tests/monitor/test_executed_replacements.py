"""A simulated monitor run with random slows, stops, resumes and kills: every replacement
goal, as a controller executes it (its points joined by a quintic per joint, sampled at
1 kHz by the tests' own implementation), stays within the speed, acceleration and jerk
limits, and lies on the verified motion."""

from __future__ import annotations

import numpy as np
from quintic_join import quintic_peaks
from random_decisions import decisions, goal_points

from safepath import Cell

from .conftest import Phase1, make_monitor

RUNS = 16


def test_random_decisions_replacements_within_limits_as_executed(cell: Cell, phase1: Phase1
                                                                 ) -> None:
    robot = cell.robot
    limits = (robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)
    rng = np.random.default_rng(5)
    kinds: dict[str, int] = {}
    worst = np.zeros(3)
    for run in range(RUNS):
        traj, held = phase1.motions[run % 2]
        monitor = make_monitor(cell, hold_time=0.1)
        monitor.follow(traj, start=0.0, held=held)
        kill_at = rng.uniform(0.0, traj.duration) if run % 3 == 0 else None
        for _, decision in decisions(monitor, traj.duration, rng, kill_at=kill_at):
            rep = decision.replacement
            if rep is None:
                continue
            kinds[decision.kind] = kinds.get(decision.kind, 0) + 1
            # On the verified motion, knot by knot.
            q, _, _ = traj.sample(np.asarray(rep.info["path_tau"]))
            assert np.array_equal(q, rep.q)
            # As the goal carries it (rounded times included) and as a controller runs it.
            ts, P, V, A = goal_points(rep, robot.controller)  # noqa: N806
            if ts.size > 1:
                peaks = quintic_peaks(ts, P, V, A)
                ratios = [float(np.max(p / lim)) for p, lim in zip(peaks, limits, strict=True)]
                worst = np.maximum(worst, ratios)
    assert np.all(worst <= 1.0 + 1e-9), worst
    # Every kind of replacement happened (not a vacuous run).
    assert {"slow", "stop", "resume"} <= set(kinds), kinds
