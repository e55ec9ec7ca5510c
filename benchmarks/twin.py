"""Speed of the cells' twins: simulated time per computation time, and the pour's masses.

Runs the twin (``safepath.sim.run_quality_check``, safepath architecture) for
``--duration`` simulated seconds, ``--runs`` times (seeds 0, 1, ...), in this process,
and prints the ratio simulated / real time of the simulation (physics at 1 kHz, the
trajectory controller, the cell and its state machine) and of the whole run (with the
executed-clearance check), with the machine's load (``os.getloadavg()``) before and
after. The target of issue 27: at least 10x faster than real time. Then the pouring
cell's twin (``safepath.sim.run_pouring``: pick, tilt stopped on the simulated scale,
return, place; seeds 0 .. ``--pour-runs`` - 1, in this process): the final masses against
the 100 g target and the simulated / real time. Writes ``benchmarks/results/twin.json``.

    .venv/bin/python benchmarks/twin.py [--duration 300] [--runs 3] [--pour-runs 4]
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
POURING = ROOT / "scenes" / "pouring_cell"


def main() -> None:
    """Run the twin and print its speed against real time."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0, help="simulated [s]")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--pour-runs", type=int, default=4, help="runs of the pouring twin")
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
    pouring = _pouring(args.pour_runs) if args.pour_runs > 0 else None
    if not args.no_write:
        out = ROOT / "benchmarks" / "results" / "twin.json"
        out.write_text(json.dumps({
            "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
            "machine": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "load_before": load_before, "load_after": load_after,
            "runs": rows, "pouring": pouring}, indent=2) + "\n")
        print(f"wrote {out.relative_to(ROOT)}")


def _pouring(runs: int) -> dict[str, object]:
    """The pouring twin over seeds 0 .. runs - 1: masses, speed, load."""
    import numpy as np

    from safepath.sim import PouringParams, run_pouring

    params = PouringParams()
    t0 = time.perf_counter()
    run_pouring(str(POURING), 0, PouringParams(max_time=0.5))  # plan, build: once
    setup = time.perf_counter() - t0
    load_before = os.getloadavg()
    rows = []
    for seed in range(runs):
        r = run_pouring(str(POURING), seed, params)
        rows.append({"seed": seed, "gain": r.gain, "latency_s": r.latency,
                     "final_mass_g": r.final_mass, "state": r.state,
                     "simulated_s": r.duration, "simulation_s": r.wall_time,
                     "clearance_s": r.clearance_time,
                     "ratio_simulation": r.duration / r.wall_time,
                     "executed_clearance_m": r.clearance.clearance,
                     "tcp_deviation_m": r.tcp_deviation,
                     "max_speed_ratio": float(r.speed_ratio.max()),
                     "max_tracking_rad": float(r.tracking.max())})
    load_after = os.getloadavg()
    masses = np.array([r["final_mass_g"] for r in rows])
    ratios = sorted(float(r["ratio_simulation"]) for r in rows)  # type: ignore[arg-type]
    within = int(np.sum(np.abs(masses - params.target) <= params.tolerance))
    print(f"\npouring twin: {runs} run(s), pick + tilt + stop + return + place (planning, "
          f"model and calibration once per process: {setup:.2f} s)")
    for r in rows:
        print(f"  seed {r['seed']}: gain {r['gain']:.1f}, latency {r['latency_s']:.3f} s -> "
              f"{r['final_mass_g']:.2f} g ({r['state']}); {r['simulated_s']:.1f} s simulated "
              f"in {r['simulation_s']:.2f} s ({r['ratio_simulation']:.1f}x real time), "
              f"clearance check {r['clearance_s']:.2f} s")
    std = float(masses.std(ddof=1)) if masses.size > 1 else 0.0
    print(f"final masses: mean {masses.mean():.2f} g, std {std:.2f}, worst "
          f"{masses[np.argmax(np.abs(masses - params.target))]:.2f}, within "
          f"{params.target:g} +- {params.tolerance:g} g: {within} of {runs}; simulated / real "
          f"time median {ratios[len(ratios) // 2]:.1f}x; load average before "
          f"{load_before[0]:.2f}, after {load_after[0]:.2f} on {os.cpu_count()} CPUs")
    return {"target_g": params.target, "tolerance_g": params.tolerance,
            "load_before": load_before, "load_after": load_after, "runs": rows}


if __name__ == "__main__":
    main()
