"""Randomized timing suite: seeded random via-point paths on every bundled robot, 0 overruns
as executed.

The problems and the check are ``tests/timing_suite.py``'s (the test suite runs a
bounded subset): polylines of 2-4 route steps with their own speed scales and TCP speed
limits, blended at their via points, timed by :func:`safepath.timing.time_path`; the
controller's quintic join of the released knots checked against each interval's step
limits at 0 tolerance (``safepath.model.execution.interval_ratios``). Printed per robot: paths,
overruns (must be 0), the largest ratio seen, the TOPP-RA runs per path and the share
re-timed, and the wall time; the machine's load before and after.

With ``--out DIR`` the suite is a resumable sweep (``safepath.sweeps``, docs/sweeps.md) of
``tests/timing_suite.TimingSuiteTask``: seed ``s`` times one path per robot, the results
go to ``DIR/results.jsonl`` as they finish (started again, only the missing seeds run),
on the local pool (``--workers``) or Ray (``--cluster auto``); printed per robot: the
overruns with the Wilson 95 % interval on their rate and the seed of each, which
``--paths 1 --seed S --out DIR2`` replays alone.

Run: ``.venv/bin/python benchmarks/timing_suite.py [--paths 1000] [--seed 0]``, or
``.venv/bin/python benchmarks/timing_suite.py --paths 20000 --out out/timing [--cluster auto]``
(100,000 paths on the five bundled arms; about 70 minutes on one core here). ``--save``
writes the figures to ``benchmarks/results/timing_suite.json`` (run again on the same
``--out`` to save a finished sweep: no seed runs twice).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the suite
from timing_suite import TimingSuiteTask, robot_names, run_suite  # noqa: E402


def _load() -> str:
    return f"{os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else "n/a"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the suite and print the report; returns 1 if any path overran a limit."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=1000, help="random paths per robot")
    parser.add_argument("--seed", type=int, default=0, help="seed of the problems")
    parser.add_argument("--robots", default="", help="comma-separated (default: all)")
    parser.add_argument("--out", default=None,
                        help="run as a resumable sweep into this folder (one path per robot "
                             "per seed)")
    parser.add_argument("--workers", type=int, default=None,
                        help="sweep: local processes (default: the CPUs)")
    parser.add_argument("--cluster", default=None, help="sweep: 'auto' or ray://HOST:PORT")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/timing_suite.json and "
                             "rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args(argv)
    names = args.robots.split(",") if args.robots else robot_names()
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    if args.out:
        return _sweep(args, names, load_before)
    print(f"timing_suite: python {platform.python_version()} on {platform.machine()}, "
          f"{os.cpu_count()} cores, load average {_load()}; {args.paths} random via-point "
          f"paths per robot, seed {args.seed}")
    header = (f"{'robot':<10} {'paths':>6} {'overruns':>8} {'worst ratio':>11} "
              f"{'TOPP-RA runs':>12} {'re-timed':>8} {'s':>7}")
    print(header)
    print("-" * len(header))
    overruns = 0
    robots = {}
    for name in names:
        t0 = time.perf_counter()
        outcomes = run_suite(name, args.paths, args.seed)
        seconds = time.perf_counter() - t0
        robots[name] = _figures([o.worst for o in outcomes], [o.runs for o in outcomes])
        over = robots[name]["overruns"]
        overruns += over
        print(f"{name:<10} {len(outcomes):6d} {over:8d} {robots[name]['worst']:11.6f} "
              f"{robots[name]['runs']:12.2f} {robots[name]['retimed']:8.0%} {seconds:7.1f}")
    print("(overruns: paths whose quintic join exceeds a velocity, acceleration or jerk "
          "limit of their steps; worst ratio: the largest seen, <= 1 required)")
    print(f"overruns in all: {overruns}; load average at the end {_load()}")
    if args.save:
        _save(robots, f"seed {args.seed}, {args.paths} paths per robot", load_before)
    return 1 if overruns else 0


def _figures(worst: Sequence[float], runs: Sequence[float]) -> dict[str, float | int]:
    """One robot's figures: its paths, overruns, largest ratio, TOPP-RA runs per path and
    the share timed more than once."""
    w, r = np.asarray(worst, dtype=float), np.asarray(runs, dtype=float)
    return {"paths": int(w.size), "overruns": int(np.sum(~(w <= 1.0))),
            "worst": float(np.max(w)), "runs": float(np.mean(r)),
            "retimed": float(np.mean(r > 1))}


def _save(robots: dict[str, dict[str, float | int]], problems: str,
          load_before: float | None) -> None:
    """Write ``benchmarks/results/timing_suite.json`` (and FIGURES.md); ``problems`` says
    which."""
    from _results import save

    figures = {"problems": problems, "robots": robots}
    print(f"saved {save('timing_suite', figures, load_before=load_before)}")


def _sweep(args: argparse.Namespace, names: list[str], load_before: float | None) -> int:
    """The suite as a sweep into ``--out``: the report's lines, then the overruns per robot
    with the Wilson interval on their rate and their seeds."""
    from safepath.sweeps import SweepOptions, run_sweep, wilson_interval
    from safepath.sweeps.report import report_lines

    replay = (f".venv/bin/python benchmarks/timing_suite.py --paths 1 --seed {{seed}} "
              f"--robots {','.join(names)} --out out/timing-seed-{{seed}}")
    task = TimingSuiteTask(tuple(names), replay)
    if args.cluster:
        # A Ray worker's path starts with this script's folder, where "timing_suite" is
        # this script: the suite's module travels by value instead.
        import ray.cloudpickle
        import timing_suite

        ray.cloudpickle.register_pickle_by_value(timing_suite)
    print(f"timing_suite sweep: {args.paths} seeds from {args.seed}, one path per robot "
          f"each, into {args.out}; load average {_load()}", flush=True)
    outcome = run_sweep(task, range(args.seed, args.seed + args.paths), args.out,
                        SweepOptions(workers=args.workers, cluster=args.cluster,
                                     progress=True, title="timing suite"))
    for line in report_lines(outcome.report):
        print(line)
    overruns = 0
    for name in names:
        seeds = [s for s, r in outcome.results.items()
                 if not r.checks.get(f"{name}.no_overrun", False)]
        low, high = wilson_interval(len(seeds), len(outcome.results))
        overruns += len(seeds)
        print(f"{name}: overruns {len(seeds)} / {len(outcome.results)}, "
              f"{100 * len(seeds) / len(outcome.results):.4f} % [{100 * low:.4f}, "
              f"{100 * high:.4f}] 95 % CI; seeds: {seeds[:20] if seeds else 'none'}"
              + (" ..." if len(seeds) > 20 else ""))
    print(f"overruns in all: {overruns}; ran {len(outcome.ran)} of {args.paths} seeds on "
          f"{outcome.backend}; load average at the end {_load()}")
    if args.save:
        results = outcome.results.values()
        _save({name: _figures([float(r.figures[f"{name}.worst_ratio"]) for r in results],
                              [float(r.figures[f"{name}.toppra_runs"]) for r in results])
               for name in names},
              f"seeds {args.seed}-{args.seed + args.paths - 1}, one path per robot each",
              load_before)
    return 1 if overruns else 0


if __name__ == "__main__":
    raise SystemExit(main())
