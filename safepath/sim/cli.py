"""``safepath sim``: run a cell's twin closed loop and print its figures."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sim`` command."""
    p = sub.add_parser("sim", help="run a cell's controller closed loop on simulated robot "
                                   "dynamics (MuJoCo) and print its figures")
    p.add_argument("scene", help="scene folder (scenes/quality_check_cell)")
    p.add_argument("--duration", type=float, default=300.0, help="simulated time [s]")
    p.add_argument("--seed", type=int, default=0, help="seed of the (first) run")
    p.add_argument("--runs", type=int, default=1, help="runs per architecture (seeds from "
                                                       "--seed), on a process pool")
    p.add_argument("--workers", type=int, default=None, help="processes (default: CPUs)")
    p.add_argument("--arrival", type=float, default=10.0,
                   help="mean time between vials put on the belt [s]")
    p.add_argument("--bag", default=None, help="write a ROS 2 bag (MCAP) of the first "
                                               "safepath run to this folder")
    p.set_defaults(func=cmd_sim)


def _pct(values: Any, q: float) -> float:
    import numpy as np

    return float(np.percentile(values, q)) if len(values) else float("nan")


def cmd_sim(args: argparse.Namespace) -> int:
    """Run the quality-check twin in both architectures and print the figures."""
    import numpy as np

    from ..cell import load_cell
    from ..errors import InputError
    from .bag import write_run_bag
    from .quality_check import QualityCheckParams, run_quality_check
    from .sweep import run_many

    cell = load_cell(args.scene)
    if cell.scene.name != "quality_check_cell":
        raise InputError(f"the twin runs the quality-check cell only so far, not "
                         f"'{cell.scene.name}'", key="scene")
    if args.bag and Path(args.bag).exists():
        raise InputError(f"{args.bag} exists already; choose a new bag path", key="--bag")
    if args.runs < 1:
        raise InputError(f"expected >= 1, got {args.runs}", key="--runs")
    scene = str(cell.folder)
    runs: dict[str, list[Any]] = {}
    for arch in ("safepath", "sequential"):
        params = QualityCheckParams(duration=args.duration, architecture=arch,
                                    arrival_interval=args.arrival)
        if args.runs == 1:
            runs[arch] = [run_quality_check(scene, args.seed, params,
                                            record=bool(args.bag) and arch == "safepath")]
        else:
            runs[arch] = run_many(scene, range(args.seed, args.seed + args.runs), params,
                                  workers=args.workers)
    load = os.getloadavg()
    first = runs["safepath"][0]
    print(f"twin of {cell.scene.name}: {args.duration:g} s simulated x {args.runs} run(s) "
          f"per architecture, seed {args.seed}, a vial every {args.arrival:g} s on average; "
          f"physics {first.duration / max(first.wall_time, 1e-9):.0f}x real time "
          f"(load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, {os.cpu_count()} CPUs)")
    for arch, rs in runs.items():
        _print_architecture(arch, rs, np)
    if args.bag:
        write_run_bag(args.bag, first.record)
        print(f"wrote a ROS 2 bag of the first safepath run to {args.bag}")
    return 0


def _print_architecture(arch: str, rs: list[Any], np: Any) -> None:
    vpm = np.array([r.vials_per_minute for r in rs])
    cycles = np.concatenate([r.cycle_times for r in rs]) if rs else np.zeros(0)
    total = sum(r.duration for r in rs)
    names = rs[0].joint_names
    tracking = np.max([r.tracking for r in rs], axis=0)
    speed = np.max([r.speed_ratio for r in rs], axis=0)
    worst = min(rs, key=lambda r: r.clearance.clearance)
    allowance = max(r.tcp_deviation for r in rs)
    margin = rs[0].margin
    clear = worst.clearance
    reasons: dict[str, int] = {}
    for r in rs:
        for k, v in r.reasons.items():
            reasons[k] = reasons.get(k, 0) + v
    sim = sum(r.duration for r in rs)
    wall = sum(r.wall_time + r.clearance_time for r in rs)
    print(f"\n[{arch}]")
    print(f"  vials per minute   {vpm.mean():.2f} (runs {vpm.min():.2f}-{vpm.max():.2f}); "
          f"{sum(len(r.cycles) for r in rs)} cycles, {sum(r.vials_arrived for r in rs)} "
          f"vials arrived, {sum(r.packaging for r in rs)} packaged, "
          f"{sum(r.rejected for r in rs)} rejected, "
          f"{sum(r.unsafe_packaged for r in rs)} unsafe packaged")
    print(f"  cycle time [s]     min {_pct(cycles, 0):.2f}  median {_pct(cycles, 50):.2f}  "
          f"p90 {_pct(cycles, 90):.2f}  max {_pct(cycles, 100):.2f}")
    print(f"  idle               robot {100 * sum(r.robot_idle for r in rs) / total:.0f} %, "
          f"conveyor stopped {100 * sum(r.conveyor_idle for r in rs) / total:.0f} %")
    print("  verdicts           " + ", ".join(f"{k}: {v}" for k, v in sorted(reasons.items())))
    print("  tracking [mrad]    " + "  ".join(f"{n} {1000 * e:.2f}"
                                              for n, e in zip(names, tracking, strict=True)))
    print("  speed / limit      " + "  ".join(f"{n} {s:.3f}"
                                              for n, s in zip(names, speed, strict=True))
          + ("  (over a limit)" if speed.max() > 1.0 else "  (within the limits)"))
    ok = clear.clearance >= margin - allowance
    pair = " / ".join(clear.pair) if clear.pair else "-"
    print(f"  executed clearance {1000 * clear.clearance:.1f} mm ({pair}, t = {clear.time:.2f} s"
          f" of seed {worst.seed}; {sum(r.clearance.states for r in rs)} states); margin "
          f"{1000 * margin:.0f} mm, tracking allowance {1000 * allowance:.1f} mm (TCP): "
          f"{'kept' if ok else 'NOT KEPT'}; MuJoCo contacts with the cell: "
          f"{sum(r.contact_steps for r in rs)} steps")
    faults = [f for r in rs for f in r.faults]
    if faults:
        print(f"  faults             {len(faults)}: {faults[0]}")
    print(f"  computation        {wall:.1f} s for {sim:.0f} s simulated "
          f"({sim / max(wall, 1e-9):.0f}x real time with the clearance check)")
