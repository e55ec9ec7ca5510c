"""Sweep throughput: seeds per second on the local pool against its workers, and Ray's
overhead against the pool on the same machine.

Runs the same sweep (``safepath.sweeps.run_sweep``: the quality-check twin, safepath
architecture, ``--duration`` simulated seconds, a vial every 2 s, seeds 0 .. ``--runs`` - 1)
into a fresh folder with each backend: 1 process (``workers=1``: this one) and a local
pool of 2, then Ray (a local runtime of 2 CPUs started here, its start and shutdown timed
apart; ``cluster="auto"`` finds it). This process plans the cell first, so the pool's
forked workers start planned; Ray's workers are new processes that import safepath and
plan once each (part of what Ray costs here). Prints seconds and seeds per second per
backend, the speed-up of two processes over one, Ray against the pool of 2, the
machine's load before and after, and checks that every backend wrote the same results.
``--save`` writes ``benchmarks/results/sweeps.json``.

    .venv/bin/python benchmarks/sweeps.py [--runs 16] [--duration 30] [--no-ray] [--save]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "scenes" / "quality_check_cell"


def _lines(folder: Path) -> dict[int, Any]:
    rows = (json.loads(line) for line in (folder / "results.jsonl").read_text().splitlines()[1:])
    return {row["seed"]: row["result"] for row in rows}


def _timed(task: Any, seeds: range, folder: Path, **backend: Any) -> float:
    """Wall time [s] of the whole sweep (results file, report included)."""
    from safepath.sweeps import SweepOptions, run_sweep

    t0 = time.perf_counter()
    run_sweep(task, seeds, folder, SweepOptions(progress=False, **backend))
    return time.perf_counter() - t0


def main() -> None:
    """Measure and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=16, help="seeds per backend")
    parser.add_argument("--duration", type=float, default=30.0, help="simulated [s] per run")
    parser.add_argument("--no-ray", action="store_true", help="the local pool only")
    parser.add_argument("--save", action="store_true", help="write results/sweeps.json")
    args = parser.parse_args()

    from safepath.sim.quality_check import QualityCheckParams
    from safepath.sim.sweep_tasks import QualityCheckTask
    from safepath.sweeps.task import execute

    params = QualityCheckParams(duration=args.duration, arrival_interval=2.0)
    task = QualityCheckTask(str(CELL), (("safepath", params),), "-")
    execute(task, 10_000)  # plan the cell in this process (the pool's workers fork from it)
    seeds = range(args.runs)
    load_before = os.getloadavg()
    rows: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(prefix="sweeps-bench-") as tmp:
        for workers in (1, 2):
            wall = _timed(task, seeds, Path(tmp) / f"pool{workers}", workers=workers)
            rows["this process" if workers == 1 else f"local pool, {workers} processes"] = {
                "wall_s": wall, "per_s": args.runs / wall}
        same = True
        if not args.no_ray:
            import ray

            # Started here, timed apart: the sweep finds it running and leaves it be.
            t0 = time.perf_counter()
            ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
            start = time.perf_counter() - t0
            wall = _timed(task, seeds, Path(tmp) / "ray", workers=2, cluster="auto")
            t0 = time.perf_counter()
            ray.shutdown()
            stop = time.perf_counter() - t0
            rows["Ray, local runtime of 2 CPUs"] = {"wall_s": wall, "per_s": args.runs / wall,
                                                    "start_s": start, "shutdown_s": stop}
            same = _lines(Path(tmp) / "ray") == _lines(Path(tmp) / "pool2")
        same = same and _lines(Path(tmp) / "pool1") == _lines(Path(tmp) / "pool2")
    load_after = os.getloadavg()
    print(f"sweep of {args.runs} quality-check twin runs ({args.duration:g} s simulated "
          f"each, safepath architecture, a vial every 2 s), {os.cpu_count()} CPUs, load "
          f"{load_before[0]:.2f} before, {load_after[0]:.2f} after")
    for name, row in rows.items():
        extra = f" (+ start {row['start_s']:.1f} s, shutdown {row['shutdown_s']:.1f} s)" \
            if "start_s" in row else ""
        print(f"  {name:32s} {row['wall_s']:6.2f} s  {row['per_s']:5.2f} runs/s{extra}")
    one, two = (rows[k]["per_s"] for k in list(rows)[:2])
    print(f"  speed-up of 2 processes over 1: {two / one:.2f}x")
    if "Ray, local runtime of 2 CPUs" in rows:
        ray = rows["Ray, local runtime of 2 CPUs"]
        pool = rows["local pool, 2 processes"]
        print(f"  Ray against the pool of 2: {ray['wall_s'] - pool['wall_s']:+.2f} s over "
              f"{args.runs} runs ({(ray['wall_s'] - pool['wall_s']) / args.runs * 1000:+.0f} "
              f"ms per run), {ray['per_s'] / pool['per_s']:.2f}x the pool's rate; its start "
              f"{ray['start_s']:.1f} s apart")
    print(f"  the same results on every backend: {'yes' if same else 'NO'}")
    if args.save:
        from _results import save

        save("sweeps", {"runs": args.runs, "duration_s": args.duration, "backends": rows,
                        "same_results": same}, load_before=load_before[0])


if __name__ == "__main__":
    main()
