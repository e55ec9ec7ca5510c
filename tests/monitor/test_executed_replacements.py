"""A simulated monitor run with random slows, stops, resumes and kills: every replacement
goal, as a controller executes it (its points joined by a quintic per joint, sampled at
1 kHz by the tests' own implementation), stays within the speed, acceleration and jerk
limits, and lies on the verified motion."""

from __future__ import annotations

import numpy as np
from quintic_join import quintic_peaks

from safepath import Cell
from safepath.monitor import Scan
from safepath.ros import joint_trajectory

from .conftest import Phase1, make_monitor

RUNS = 16


def _scan(stamp: float, near: float | None) -> Scan:
    ranges = np.full(360, np.inf)
    if near is not None:
        ranges[170:190] = near
    return Scan(stamp, "cam", ranges, -np.pi, 2 * np.pi / 360, 0.05, 8.0)


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
        near_from = rng.uniform(0.0, traj.duration)
        near_to = near_from + rng.uniform(0.05, 1.0)
        distance = rng.uniform(0.3, 1.2)
        t = 0.0
        while t < traj.duration + 1.0:
            t += 1 / 30
            if kill_at is not None and kill_at <= t:
                decision, kill_at = monitor.kill(t), None
            else:
                decision = monitor.observe(
                    _scan(t, distance if near_from <= t <= near_to else None), t)
            rep = decision.replacement
            if rep is None:
                continue
            kinds[decision.kind] = kinds.get(decision.kind, 0) + 1
            # On the verified motion, knot by knot.
            q, _, _ = traj.sample(np.asarray(rep.info["path_tau"]))
            assert np.array_equal(q, rep.q)
            # As the goal carries it (rounded times included) and as a controller runs it.
            msg = joint_trajectory(rep, controller=robot.controller, backend="rosbags")
            ts = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                           for p in msg.points])
            P, V, A = (np.array([list(getattr(p, f)) for p in msg.points])  # noqa: N806
                       for f in ("positions", "velocities", "accelerations"))
            if ts.size > 1:
                peaks = quintic_peaks(ts, P, V, A)
                ratios = [float(np.max(p / lim)) for p, lim in zip(peaks, limits, strict=True)]
                worst = np.maximum(worst, ratios)
    assert np.all(worst <= 1.0 + 1e-9), worst
    # Every kind of replacement happened (not a vacuous run).
    assert {"slow", "stop", "resume"} <= set(kinds), kinds
