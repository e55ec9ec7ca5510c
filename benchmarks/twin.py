"""Speed of the quality-check cell's twin: simulated time per computation time.

Runs the twin (``safepath.sim.run_quality_check``, safepath architecture) for
``--duration`` simulated seconds, ``--runs`` times (seeds 0, 1, ...), in this process,
and prints the ratio simulated / real time of the simulation (physics at 1 kHz, the
trajectory controller, the cell and its state machine) and of the whole run (with the
executed-clearance check), with the machine's load (``os.getloadavg()``) before and
after. The target of issue 27: at least 10x faster than real time. Writes
``benchmarks/results/twin.json``.

    .venv/bin/python benchmarks/twin.py [--duration 300] [--runs 3]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "scenes" / "quality_check_cell"


def main() -> None:
    """Run the twin and print its speed against real time."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0, help="simulated [s]")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--no-write", action="store_true", help="do not write results")
    args = parser.parse_args()

    from safepath.sim import QualityCheckParams, run_quality_check

    params = QualityCheckParams(duration=args.duration)
    t0 = time.perf_counter()
    run_quality_check(str(CELL), 0, QualityCheckParams(duration=1.0))  # plan, build: once
    setup = time.perf_counter() - t0
    load_before = os.getloadavg()
    rows = []
    for seed in range(args.runs):
        run = run_quality_check(str(CELL), seed, params)
        rows.append({"seed": seed, "simulated_s": run.duration, "simulation_s": run.wall_time,
                     "clearance_s": run.clearance_time,
                     "ratio_simulation": run.duration / run.wall_time,
                     "ratio_with_clearance": run.duration / (run.wall_time
                                                             + run.clearance_time),
                     "vials_per_minute": run.vials_per_minute})
    load_after = os.getloadavg()
    ratios = sorted(r["ratio_simulation"] for r in rows)
    whole = sorted(r["ratio_with_clearance"] for r in rows)
    print(f"quality-check twin: {args.runs} run(s) of {args.duration:g} s simulated "
          f"(planning and model, once per process: {setup:.2f} s)")
    for r in rows:
        print(f"  seed {r['seed']}: simulation {r['simulation_s']:.2f} s "
              f"({r['ratio_simulation']:.0f}x real time), clearance check "
              f"{r['clearance_s']:.2f} s ({r['ratio_with_clearance']:.0f}x with it), "
              f"{r['vials_per_minute']:.2f} vials/min")
    print(f"simulated / real time: median {ratios[len(ratios) // 2]:.0f}x "
          f"(min {ratios[0]:.0f}x); with the clearance check median "
          f"{whole[len(whole) // 2]:.0f}x (target >= 10x)")
    print(f"load average before {load_before[0]:.2f} {load_before[1]:.2f} "
          f"{load_before[2]:.2f}, after {load_after[0]:.2f} {load_after[1]:.2f} "
          f"{load_after[2]:.2f} on {os.cpu_count()} CPUs")
    if not args.no_write:
        out = ROOT / "benchmarks" / "results" / "twin.json"
        out.write_text(json.dumps({
            "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
            "machine": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "load_before": load_before, "load_after": load_after,
            "runs": rows}, indent=2) + "\n")
        print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
