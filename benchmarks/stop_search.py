"""Randomized stops of verified motions: how many stops the monitor's search finds no
candidate within the limits for.

The motions: every route of the bundled cells (``scenes/quality_check_cell``,
``scenes/pouring_cell``), planned, and random via-point paths on the bundled robots timed
by ``safepath.timing.time_path``. On each, chains of replacements from random instants
(slowings, speed-ups, stops, 0.02-0.3 s apart) end in a stop, so stops come while the
motion keeps its verified timing, brakes or speeds up (``tests/stop_states.py``). Printed
per source: stops, those that fell back on ``forced_stop``, those of them that follow the
running motion before braking (a hold), those beyond a limit as executed
(``info["executed_ratios"]`` over 1.0) and the worst ratio, each beyond a limit with its
replay (``--only SOURCE:MOTION:CHAIN``); the machine's load. With ``--bags DIR``, each
chain whose stop fell back on ``forced_stop`` is written as a bag of its goals (stamped
1 s after the bag's start), for an independent check of its switches.

    .venv/bin/python benchmarks/stop_search.py [--seed 0] [--chains 100] [--paths 20]
        [--sources quality_check_cell,pouring_cell,ned3pro,...] [--late S] [--bags DIR]
        [--save]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from stop_states import (  # noqa: E402
    Stop,
    cell_motions,
    chain_rng,
    path_rng,
    random_chain,
    via_point_motion,
)

CELLS = ("quality_check_cell", "pouring_cell")
ROBOTS = ("ned3pro", "panda", "ur5", "gen3", "gen3_lite")


def motions(source: str, seed: int, paths: int, knot_period: float | None = None
            ):  # noqa: ANN201
    """The robot and the motions of ``source``: a cell's routes, or ``paths`` random
    via-point paths on a robot (knots ``knot_period`` [s] apart, default the timing's)."""
    if source in CELLS:
        return cell_motions(source, knot_period)
    from safepath.description.robot_folder import load_robot

    robot = load_robot(source)
    return robot, [via_point_motion(robot, path_rng(seed, source, p), knot_period)
                   for p in range(paths)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--chains", type=int, default=100, help="chains per motion")
    parser.add_argument("--paths", type=int, default=20, help="random paths per robot")
    parser.add_argument("--sources", default=",".join(CELLS + ROBOTS))
    parser.add_argument("--only", default=None, help="SOURCE:MOTION:CHAIN, one chain")
    parser.add_argument("--bags", default=None, help="write forced stops' chains here")
    parser.add_argument("--late", type=float, default=None,
                        help="chains start in the motions' last LATE seconds")
    parser.add_argument("--knot-period", type=float, default=None,
                        help="time the motions with knots this far apart [s] "
                             "(TimingOptions.knot_period; default the timing's)")
    parser.add_argument("--save", action="store_true",
                        help="write benchmarks/results/stop_search.json")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    if args.only:
        source, motion, chain = args.only.split(":")
        robot, trajs = motions(source, args.seed, int(motion) + 1, args.knot_period)
        stops, _ = random_chain(trajs[int(motion)], robot,
                                chain_rng(args.seed, source, int(motion), int(chain)),
                                late=args.late)
        for stop in stops:
            print(stop)
        return
    print(f"stop_search: seed {args.seed}, {args.chains} chains per motion"
          f"{'' if args.late is None else f' in its last {args.late:g} s'}, {args.paths} "
          f"random paths per robot"
          f"{'' if args.knot_period is None else f', knots {args.knot_period:g} s apart'}; "
          f"load {load_before:.2f} on {os.cpu_count()} cores")
    header = (f"{'source':<20} {'motions':>7} {'stops':>6} {'forced':>6} {'held':>5} "
              f"{'over':>5} {'worst':>10} {'s':>6}")
    print(f"{header}\n{'-' * len(header)}")
    figures = {}
    for source in args.sources.split(","):
        figures[source] = _run(source, args)
    total = sum(f["over"] for f in figures.values())
    tried = sum(f["stops"] for f in figures.values())
    worst = max(f["worst"] for f in figures.values())
    print(f"beyond a limit: {total} of {tried} stops, worst ratio {worst:.7f}; "
          f"load {os.getloadavg()[0]:.2f}")
    if args.save:
        from _results import save

        save("stop_search", {"seed": args.seed, "chains": args.chains, "paths": args.paths,
                             "late": args.late, "knot_period": args.knot_period,
                             "sources": figures, "stops": tried, "over_limit": total,
                             "worst_ratio": worst}, load_before=load_before)


def _run(source: str, args: argparse.Namespace) -> dict[str, object]:
    """The chains on ``source``'s motions; prints its line and each stop beyond a limit."""
    started = time.perf_counter()
    robot, trajs = motions(source, args.seed, args.paths, args.knot_period)
    stops: list[tuple[str, Stop]] = []
    for m, traj in enumerate(trajs):
        for c in range(args.chains):
            replay = f"{source}:{m}:{c}"
            sent, follower = random_chain(traj, robot, chain_rng(args.seed, source, m, c),
                                          late=args.late)
            stops += [(replay, s) for s in sent]
            if args.bags and any(s.forced for s in sent):
                _bag(Path(args.bags) / replay.replace(":", "_"), follower.goals)
    over = [(r, s) for r, s in stops if s.worst > 1.0]
    forced = [s for _, s in stops if s.forced]
    held = sum(s.hold > 0 for s in forced)
    worst = max((s.worst for _, s in stops), default=0.0)
    print(f"{source:<20} {len(trajs):7d} {len(stops):6d} {len(forced):6d} {held:5d} "
          f"{len(over):5d} {worst:10.7f} {time.perf_counter() - started:6.1f}")
    for replay, s in over:
        print(f"  over: --only {replay}  ratios {np.round(s.ratios, 4).tolist()} at "
              f"{s.start:.3f} s after {[(round(t, 3), round(k, 2)) for t, k in s.events]}")
    return {"motions": len(trajs), "stops": len(stops), "forced": len(forced), "held": held,
            "over": len(over), "worst": worst, "over_replays": [r for r, _ in over]}


def _bag(path: Path, goals: list) -> None:  # noqa: ANN001
    """A bag of a chain's goals, each stamped at its start plus 1 s."""
    from safepath.monitor import MonitorOptions
    from safepath.monitor.ros import MonitorRecorder

    recorder = MonitorRecorder(MonitorOptions(), goals[0][1].joint_names)
    for start, traj in goals:
        recorder.goal(1.0 + start, traj, 1.0 + start)
    recorder.write(path)


if __name__ == "__main__":
    main()
