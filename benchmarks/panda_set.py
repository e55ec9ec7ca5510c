"""safepath alone on the Panda problem set of the peer benchmark, wall and CPU time.

The peer benchmark (``benchmarks/peers/run.py``) compares planners in one run; this
script is its safepath half without the peers, for following safepath's own figures on a
shared machine: for every problem of ``benchmarks/peers/panda_problems.json`` (24 start /
goal pairs around a pillar, Franka Panda from example-robot-data), it plans, smooths,
times and verifies with :func:`safepath.plan_route` and the default options, and prints,
median and 95th percentile over the problems and seeds:

* path search (IK for lines, OMPL: ``info["planning_time"] - info["shortcut_time"]``),
  shortcutting (``info["shortcut_time"]``), and the whole call (wall time);
* the CPU time of this process for the whole call (``time.process_time``): on a busy
  machine the wall time grows with the load, the CPU time much less.

Each problem is planned with seeds ``seed + 100 * k`` for k < ``--seeds`` (no result is
reused: every call plans from scratch; the checkers are built once per world, as in a
long-lived process), after one untimed warm-up plan.

Run: ``.venv/bin/python benchmarks/panda_set.py [--seeds 1] [--limit N]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import safepath
from safepath import PlannerOptions, PlanOptions

PEERS = Path(__file__).resolve().parent / "peers"


def _problems_module() -> object:
    spec = importlib.util.spec_from_file_location("peer_problems", PEERS / "problems.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _row(label: str, values: list[float]) -> str:
    ms = np.asarray(values) * 1e3
    return (f"{label:<34} {statistics.median(ms):>8.1f} {np.percentile(ms, 95):>8.1f} "
            f"{ms.min():>8.1f} {ms.max():>8.1f}")


def main(argv: list[str] | None = None) -> int:
    """Plan the set and print the table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="seeds per problem")
    parser.add_argument("--seed", type=int, default=0, help="added to each problem's seed")
    parser.add_argument("--limit", type=int, default=None, help="first N problems only")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/panda_set.json and "
                             "rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args(argv)
    problems = json.loads((PEERS / "panda_problems.json").read_text())
    if args.limit is not None:
        problems = {**problems, "problems": problems["problems"][: args.limit]}
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with tempfile.TemporaryDirectory() as tmp:
        folder = _problems_module().write_panda_cell(problems, Path(tmp) / "panda")  # type: ignore[attr-defined]
        cell = safepath.load_cell(folder)
        routes = safepath.load_routes(cell.folder, poses=list(cell.poses),
                                      objects=list(cell.scene.objects))
        first = problems["problems"][0]
        safepath.plan_route(cell, routes[first["id"]], PlanOptions())  # warm-up, untimed
        search, smooth, wall, cpu = [], [], [], []
        for k in range(args.seeds):
            for p in problems["problems"]:
                seed = int(p["seed"]) + args.seed + 100 * k
                options = PlanOptions(planner=PlannerOptions(seed=seed))
                t0, c0 = time.perf_counter(), time.process_time()
                traj = safepath.plan_route(cell, routes[p["id"]], options)
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
                search.append(traj.info["planning_time"] - traj.info["shortcut_time"])
                smooth.append(traj.info["shortcut_time"])
    print(f"panda_set: {len(wall)} plans ({len(problems['problems'])} problems x "
          f"{args.seeds} seeds), python {sys.version.split()[0]}, {os.cpu_count()} cores, "
          f"load average {load:.1f} (before), "
          f"{os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan'):.1f} (after)")
    print(f"{'[ms]':<34} {'median':>8} {'p95':>8} {'min':>8} {'max':>8}")
    print("-" * 70)
    print(_row("path search (IK, OMPL)", search))
    print(_row("shortcutting", smooth))
    print(_row("plan + smooth + timing + verify", wall))
    print(_row("the same, CPU time", cpu))
    if args.save:
        from _results import save

        save("panda_set", {"plans": len(wall), "seeds": args.seeds, **{
            f"{name}_ms": {"median": statistics.median(v) * 1000,
                           "p95": float(np.percentile(v, 95)) * 1000}
            for name, v in (("search", search), ("smooth", smooth), ("chain", wall),
                            ("cpu", cpu))}}, load_before=load)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
