"""Replacement goals from random decisions, checked as the controller executes them.

Runs seeded random sequences of observations (an obstacle near the camera for a random
while, at a random distance), kill presses at random instants and sensor silences on the
bundled quality-check cell's two phase-1 motions; every replacement goal is taken by an
independent controller model (the goals' points as the message carries them, joined by a
quintic written here) at its ``replacement_start``. Prints: switches, the largest step at a
switch (position, velocity, acceleration), the largest speed / acceleration / jerk ratio
of the executed replacements, stops deferred (none may be), stops braking gentler than
assessed, and decision times of decisions that send a goal and of those that do not
(median, p99) with the machine's load.

    .venv/bin/python benchmarks/switches.py --runs 200 [--seed 0] [--save]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the independent quintic the tests use

from quintic_join import quintic_peaks, quintic_state  # noqa: E402
from random_decisions import decisions, goal_points  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--save", action="store_true",
                        help="write benchmarks/results/switches.json")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]

    from safepath import Trajectory, load_cell, plan_cell
    from safepath.errors import ExecutedLimitError
    from safepath.monitor import Monitor, MonitorOptions
    from safepath.ros import split_at_gripper_events

    cell = load_cell(ROOT / "scenes" / "quality_check_cell")
    robot = cell.robot
    routes = cell.route_table()
    traj = plan_cell(cell, routes={"phase1": routes["phase1"]})["phase1"]
    parts = [m for m in split_at_gripper_events(traj) if isinstance(m, Trajectory)]
    motions = [(parts[0], "vial"), (parts[1], None)]
    camera = np.eye(4)
    camera[:3, 3] = [1.2, 0.3, 0.4]
    limits = (robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)

    rng = np.random.default_rng(args.seed)
    switches, step, worst = 0, 0.0, np.zeros(3)
    kinds: dict[str, int] = {}
    stats: dict[str, int] = {}
    with_goal, without = [], []
    refused: list[str] = []
    started = time.perf_counter()
    for run in range(args.runs):
        m, held = motions[run % 2]
        mon = Monitor(cell, MonitorOptions(sensors={"cam": camera}, stale_after=0.06,
                                           hold_time=0.1))
        mon.follow(m, start=0.0, held=held)
        running = (0.0, *goal_points(m, robot.controller))
        kill_at = rng.uniform(0, m.duration) if rng.uniform() < 0.3 else None
        silent_from = rng.uniform(0, m.duration) if rng.uniform() < 0.2 else None
        for t, d in decisions(mon, m.duration, rng, kill_at=kill_at, silent_from=silent_from,
                              jitter=0.005):
            rep = d.replacement
            (with_goal if rep is not None else without).append(d.elapsed)
            if rep is None:
                continue
            kinds[d.kind] = kinds.get(d.kind, 0) + 1
            try:
                tn, P, V, A = goal_points(rep, robot.controller)  # noqa: N806
            except ExecutedLimitError as exc:  # the goal builder refuses it: counted
                refused.append(f"run {run} t={t:.3f} {d.kind}: {exc}")
                tn, P, V, A = (np.asarray(rep.t), rep.q, rep.qd, rep.qdd)  # noqa: N806
            stamp, *old = running
            p, v, a = quintic_state(old[0] + stamp, *old[1:], at=d.replacement_start)
            step = max(step, *(float(np.max(np.abs(x - y)))
                               for x, y in ((P[0], p), (V[0], v), (A[0], a))))
            if tn.size > 1:
                worst = np.maximum(worst, [float(np.max(pk / lim))
                                           for pk, lim in zip(quintic_peaks(tn, P, V, A), limits,
                                                              strict=True)])
            running = (d.replacement_start, tn, P, V, A)
            switches += 1
        for k, v in mon.stats.items():
            stats[k] = stats.get(k, 0) + v
    _report(args, time.perf_counter() - started, load_before, switches, kinds, step, worst,
            stats, with_goal, without, refused)


def _report(args, wall, load_before, switches, kinds, step, worst, stats,  # noqa: ANN001, PLR0913
            with_goal, without, refused) -> None:  # noqa: ANN001
    """Print the figures (and save them with ``--save``)."""
    load_after = os.getloadavg()[0]
    wg, wo = np.array(with_goal) * 1e3, np.array(without) * 1e3
    print(f"{args.runs} runs (seed {args.seed}), {switches} switches {kinds}, {wall:.1f} s; "
          f"load {load_before:.2f} -> {load_after:.2f} on {os.cpu_count()} cores")
    print(f"largest step at a switch: {step:.2e} (rad, rad/s, rad/s^2); executed ratios "
          f"speed {worst[0]:.4f}, acceleration {worst[1]:.4f}, jerk {worst[2]:.4f}")
    print(f"stops deferred: {stats.get('deferred', 0)}; braking gentler than assessed: "
          f"{stats.get('gentle_stops', 0)}; beyond the limits: {stats.get('stops_over_limit', 0)}"
          f" (goals the goal builder refuses: {len(refused)})")
    for line in refused[:5]:
        print("  refused:", line)
    def spread(ms: np.ndarray) -> str:  # a few runs may send no goal at all
        if not ms.size:
            return "none"
        return f"median {np.median(ms):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms ({ms.size})"

    print(f"decision time with a goal: {spread(wg)}; without: {spread(wo)}")
    if args.save:
        from _results import save

        save("switches", {
            "runs": args.runs, "seed": args.seed, "switches": switches, "kinds": kinds,
            "largest_switch_step": step, "executed_ratios": worst.tolist(),
            "stops_deferred": stats.get("deferred", 0),
            "gentle_stops": stats.get("gentle_stops", 0),
            "stops_over_limit": stats.get("stops_over_limit", 0),
            "goals_refused": len(refused),
            "goal_decision_ms": {"median": float(np.median(wg)),
                                 "p99": float(np.percentile(wg, 99))},
            "other_decision_ms": {"median": float(np.median(wo)),
                                  "p99": float(np.percentile(wo, 99))},
            "aim_goal_decision_ms": {"median": 5.0, "p99": 10.0}}, load_before=load_before)




if __name__ == "__main__":
    main()
