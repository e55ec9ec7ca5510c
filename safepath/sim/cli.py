"""``safepath sim``: run a cell's twin closed loop and print its figures."""

from __future__ import annotations

import argparse
import os
from collections import Counter
from pathlib import Path
from typing import Any, Literal

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sim`` command."""
    p = sub.add_parser("sim", help="run a cell's controller closed loop on simulated robot "
                                   "dynamics (MuJoCo) and print its figures")
    p.add_argument("scene", help="scene folder (scenes/quality_check_cell, "
                                 "scenes/pouring_cell)")
    p.add_argument("--duration", type=float, default=300.0,
                   help="simulated time [s] (quality-check cell, obstacles)")
    p.add_argument("--seed", type=int, default=0, help="seed of the (first) run")
    p.add_argument("--runs", type=int, default=1,
                   help="runs per architecture (seeds from --seed); more than one runs as a "
                        "resumable sweep on a process pool into --out (default "
                        "out/sweeps/<cell>-seed<first>-runs<N>)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: CPUs)")
    p.add_argument("--arrival", type=float, default=10.0,
                   help="mean time between vials put on the belt [s]")
    p.add_argument("--bag", default=None,
                   help="write a ROS 2 bag (MCAP) of the (first architecture's) safepath "
                        "run to this folder; with --runs N, one bag per run: "
                        "BAG/seed_<seed> (the runs then print the table, not as a sweep)")
    p.add_argument("--belt-runs", action="store_true",
                   help="quality-check cell: also run safepath with the belt running while "
                        "the robot works (ControllerOptions(belt_runs_while_working=True))")
    p.add_argument("--target", default=None,
                   help="pouring cell: mass to pour [g] (default 100)")
    p.add_argument("--tolerance", default=None,
                   help="pouring cell: a final mass within target +- tolerance counts as "
                        "within tolerance [g] (default 3.5)")
    p.add_argument("--out", default=None,
                   help="the sweep's folder (default with --runs N > 1: "
                        "out/sweeps/<cell>-seed<first>-runs<N>): results.jsonl (each run as "
                        "it finishes; started again, only the missing seeds run), "
                        "report.html, report.json (docs/sweeps.md)")
    p.add_argument("--cluster", default=None,
                   help="run the sweep's seeds on Ray: 'auto' (the cluster of this machine, "
                        "else a local Ray runtime) or ray://HOST:PORT; needs "
                        "pip install 'safepath[cluster]'")
    p.add_argument("--obstacles", action="store_true",
                   help="run the monitor node's core with a moving body crossing the cell, "
                        "seen by a simulated laser scanner and depth camera")
    p.set_defaults(func=cmd_sim)


def _pct(values: Any, q: float) -> float:
    import numpy as np

    return float(np.percentile(values, q)) if len(values) else float("nan")


def cmd_sim(args: argparse.Namespace) -> int:
    """Run the cell's twin (quality check, pour, or obstacles) and print the figures."""
    from ..cell import load_cell
    from .pouring import pour_route_of

    cell = load_cell(args.scene)
    sweep = _check_args(args, cell)
    if args.obstacles:
        from .obstacles import cmd_obstacles

        return cmd_obstacles(args, cell)
    if pour_route_of(cell) is not None:
        if sweep:
            from .sweep_cli import cmd_sweep

            return cmd_sweep(args, cell, _pouring_params(args))
        return _cmd_pouring(args, cell)
    _check_quality_check_routes(cell)
    if sweep:
        from .sweep_cli import cmd_sweep

        return cmd_sweep(args, cell, None)
    return _cmd_quality_check(args, cell)


def _check_args(args: argparse.Namespace, cell: Any) -> bool:
    """Whether the command is a sweep: ``--out``, ``--cluster``, or ``--runs`` > 1 without
    ``--bag`` (bags need each run's recording, which a sweep does not keep) or
    ``--obstacles``.

    Raises:
        InputError: An existing ``--bag``, ``--runs`` < 1, an option of another twin, or
            ``--bag`` / ``--obstacles`` with a sweep.
    """
    from ..errors import InputError

    if args.bag and Path(args.bag).exists():
        raise InputError(f"{args.bag} exists already; choose a new bag path", key="--bag")
    if args.runs < 1:
        raise InputError(f"expected >= 1, got {args.runs}", key="--runs")
    _check_pour_only(args, cell)
    many = args.runs > 1 and not args.bag and not args.obstacles
    sweep = bool(args.out or args.cluster or many)
    if sweep and (args.bag or args.obstacles):
        flag = "--bag" if args.bag else "--obstacles"
        raise InputError(f"{flag} is not part of a sweep (--out, --cluster): run it without",
                         key=flag)
    return sweep


def _check_quality_check_routes(cell: Any) -> None:
    """Raises InputError when the cell lacks the quality-check routes."""
    from ..cells.quality_check.commands import ControllerOptions
    from ..errors import InputError

    missing = [r for r in ControllerOptions().routes if r not in cell.route_table()]
    if missing:
        raise InputError(f"cell '{cell.scene.name}' has no pour (a route starting with a "
                         f"tilt) and lacks the quality-check routes {missing}: the twin "
                         "runs neither controller on it", key="scene")


def _cmd_quality_check(args: argparse.Namespace, cell: Any) -> int:
    """Run the quality-check twin in both architectures and print the figures."""
    import numpy as np

    from ..cells.quality_check.commands import ControllerOptions
    from .quality_check import QualityCheckParams, run_quality_check
    from .sweep import run_many

    scene = str(cell.folder)
    runs: dict[str, list[Any]] = {}
    Arch = Literal["safepath", "sequential"]
    variants: list[tuple[str, Arch, bool]] = [("safepath", "safepath", False)]
    if getattr(args, "belt_runs", False):
        variants = [("safepath, belt stopped during cycles", "safepath", False),
                    ("safepath, belt running while the robot works", "safepath", True)]
    sequential: tuple[str, Arch, bool] = ("sequential", "sequential", False)
    for label, arch, belt in [*variants, sequential]:
        params = QualityCheckParams(duration=args.duration, architecture=arch,
                                    arrival_interval=args.arrival,
                                    controller=ControllerOptions(belt_runs_while_working=belt))
        record = bool(args.bag) and label == variants[0][0]
        if args.runs == 1:
            runs[label] = [run_quality_check(scene, args.seed, params, record=record)]
        else:
            runs[label] = run_many(scene, range(args.seed, args.seed + args.runs), params,
                                   workers=args.workers, record=record)
    load = os.getloadavg()
    first = runs[variants[0][0]][0]
    print(f"twin of {cell.scene.name}: {args.duration:g} s simulated x {args.runs} run(s) "
          f"per architecture, seed {args.seed}, a vial every {args.arrival:g} s on average; "
          f"physics {first.duration / max(first.wall_time, 1e-9):.0f}x real time "
          f"(load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, {os.cpu_count()} CPUs)")
    for name, rs in runs.items():
        _print_architecture(name, rs, np)
    if args.bag:
        _write_bags(args.bag, runs[variants[0][0]], f"{variants[0][0]} run")
    return 0


def _write_bags(folder: str, rs: list[Any], what: str) -> None:
    """The bag of each recorded run: ``folder`` itself for one run, ``folder/seed_<seed>``
    for several."""
    from .bag import write_run_bag

    if len(rs) == 1:
        write_run_bag(folder, rs[0].record)
        print(f"wrote a ROS 2 bag of the {what} to {folder}")
        return
    for r in rs:
        write_run_bag(Path(folder) / f"seed_{r.seed}", r.record)
    print(f"wrote {len(rs)} ROS 2 bags of the {what}s to {folder}/seed_<seed> "
          f"(seeds {rs[0].seed}..{rs[-1].seed})")


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
    unfinished = sum(r.in_progress for r in rs)
    print(f"  vials per minute   {vpm.mean():.2f} (runs {vpm.min():.2f}-{vpm.max():.2f}); "
          f"{sum(len(r.cycles) for r in rs)} cycles: {sum(r.packaging for r in rs)} "
          f"packaged, {sum(r.rejected for r in rs)} rejected"
          + (f" (+{unfinished} vial(s) whose cycle the run's end cut short)"
             if unfinished else "")
          + f"; {sum(r.vials_arrived for r in rs)} vials arrived, "
          f"{sum(r.unsafe_packaged for r in rs)} unsafe packaged")
    print(f"  cycle time [s]     min {_pct(cycles, 0):.2f}  median {_pct(cycles, 50):.2f}  "
          f"p90 {_pct(cycles, 90):.2f}  max {_pct(cycles, 100):.2f}")
    print(f"  idle               robot {100 * sum(r.robot_idle for r in rs) / total:.0f} %, "
          f"conveyor stopped {100 * sum(r.conveyor_idle for r in rs) / total:.0f} %")
    timeouts = sorted({r.verdict_timeout for r in rs})
    print("  verdicts           " + ", ".join(f"{k}: {v}" for k, v in sorted(reasons.items()))
          + f" (time-out {', '.join(f'{t:g}' for t in timeouts)} s)")
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
    if any(r.belt_runs for r in rs):
        print(f"  belt               moving with a vial at the sensor "
              f"{sum(r.belt_moving_at_sensor for r in rs):.2f} s; picks with no vial at the "
              f"sensor {sum(r.empty_picks for r in rs)}; {sum(r.waiting_motions for r in rs)} "
              f"motions with the next vial waiting at the sensor (in the clearance check)")
    warned = Counter(w for r in rs for w in r.warnings)
    if warned:
        print(f"  controller warned  {sum(warned.values())}x: " + "; ".join(
            f"{n}x {w}" for w, n in warned.most_common()))
    print(f"  computation        {wall:.1f} s for {sim:.0f} s simulated "
          f"({sim / max(wall, 1e-9):.0f}x real time with the clearance check)")


def _cmd_pouring(args: argparse.Namespace, cell: Any) -> int:
    """Run the pouring twin over seeds and print its figures."""
    import numpy as np

    from .pouring import run_pouring
    from .sweep import run_many

    params = _pouring_params(args)
    scene = str(cell.folder)
    if args.runs == 1:
        rs = [run_pouring(scene, args.seed, params, record=bool(args.bag))]
    else:
        rs = run_many(scene, range(args.seed, args.seed + args.runs), params,
                      workers=args.workers, record=bool(args.bag))
    load = os.getloadavg()
    print(f"twin of {cell.scene.name}: PourController closed loop, {args.runs} run(s) "
          f"(seeds {args.seed}..{args.seed + args.runs - 1}); robot {cell.robot.name}, "
          f"physics 1 kHz; scale every {params.period * 1000:g} ms, noise "
          f"{params.noise:g} g, latency drawn in {params.latency_range[0]:g}-"
          f"{params.latency_range[1]:g} s, fall time {params.fall_time:g} s, flow gain drawn "
          f"in {params.gain_range[0]:g}-{params.gain_range[1]:g} g/s/rad^1.5 (the "
          f"controller knows the latency, not the gain)")
    _print_pouring(rs, np)
    sim = sum(r.duration for r in rs)
    wall = sum(r.wall_time for r in rs)
    whole = sum(r.wall_time + r.clearance_time for r in rs)
    print(f"  computation        {wall:.1f} s for {sim:.0f} s simulated "
          f"({sim / max(wall, 1e-9):.1f}x real time; {sim / max(whole, 1e-9):.1f}x with "
          f"the clearance check), load "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs")
    if args.bag:
        _write_bags(args.bag, rs, "pouring run")
    return 0


def _check_pour_only(args: argparse.Namespace, cell: Any) -> None:
    """``--target`` and ``--tolerance`` are the pouring twin's: refused elsewhere.

    Raises:
        InputError: One is given to another twin, naming it.
    """
    from ..errors import InputError
    from .pouring import pour_route_of

    pouring = not args.obstacles and pour_route_of(cell) is not None
    for flag in ("target", "tolerance"):
        if getattr(args, flag, None) is not None and not pouring:
            raise InputError(f"only the pouring twin takes it (cell '{cell.scene.name}' "
                             f"{'runs --obstacles' if args.obstacles else 'has no pour'})",
                             key=f"--{flag}")


def _pouring_params(args: argparse.Namespace) -> Any:
    """The pouring twin's parameters from ``--target`` and ``--tolerance``.

    Raises:
        InputError: A value that is not a finite number > 0, naming the option.
    """
    from ..errors import InputError
    from .pouring import PouringParams

    given: dict[str, float] = {}
    for key in ("target", "tolerance"):
        text = getattr(args, key, None)
        if text is None:
            continue
        try:
            given[key] = float(text)
        except ValueError:
            raise InputError(f"expected a number [g], got {text!r}", key=f"--{key}") from None
    try:
        default = PouringParams()
        return PouringParams(target=given.get("target", default.target),
                             tolerance=given.get("tolerance", default.tolerance))
    except InputError as exc:
        raise InputError(f"expected a finite number > 0 [g], got {getattr(args, str(exc.key))!r}",
                         key=f"--{exc.key}") from exc


def _print_pouring(rs: list[Any], np: Any) -> None:
    masses = np.array([r.final_mass for r in rs])
    errors = masses - rs[0].target
    worst = rs[int(np.argmax(np.abs(errors)))]
    within = sum(r.within_tolerance for r in rs)
    names = rs[0].joint_names
    tracking = np.max([r.tracking for r in rs], axis=0)
    speed = np.max([r.speed_ratio for r in rs], axis=0)
    clear = min(rs, key=lambda r: r.clearance.clearance)
    allowance = max(r.tcp_deviation for r in rs)
    margin = rs[0].margin
    faults = [f for r in rs for f in r.faults]
    std = masses.std(ddof=1) if len(masses) > 1 else 0.0
    print(f"  final mass [g]     mean {masses.mean():.2f}  std {std:.2f}  min "
          f"{masses.min():.2f}  max {masses.max():.2f}; worst {worst.final_mass:.2f} "
          f"(seed {worst.seed}, gain {worst.gain:.1f}, latency {worst.latency:.3f} s); "
          f"within {rs[0].target:g} +- {rs[0].tolerance:g} g: {within} of {len(rs)}")
    done = sum(r.state == "done" for r in rs)
    stops = sum("stop" in r.goals for r in rs)
    print(f"  controller         {done} of {len(rs)} done, {stops} stopped on the scale, "
          f"{len(faults)} fault(s)" + (f": {faults[0]}" if faults else ""))
    print("  tracking [mrad]    " + "  ".join(f"{n} {1000 * e:.2f}"
                                              for n, e in zip(names, tracking, strict=True)))
    over = [n for n, s in zip(names, speed, strict=True) if s > 1.0]
    print("  speed / limit      " + "  ".join(f"{n} {s:.4f}"
                                              for n, s in zip(names, speed, strict=True))
          + (f"  (OVER the limit: {', '.join(over)})" if over else "  (within the limits)"))
    lim = min(r.limit_margin for r in rs)
    print(f"  position limits    smallest distance to a limit {lim:.3f} rad "
          f"({'within' if lim >= 0 else 'OVER'})")
    c = clear.clearance
    ok = c.clearance >= margin - allowance
    pair = " / ".join(c.pair) if c.pair else "-"
    print(f"  executed clearance {1000 * c.clearance:.1f} mm ({pair}, t = {c.time:.2f} s of "
          f"seed {clear.seed}; {sum(r.clearance.states for r in rs)} states, cup held from "
          f"the close to the open); margin {1000 * margin:.0f} mm, tracking allowance "
          f"{1000 * allowance:.2f} mm (TCP): {'kept' if ok else 'NOT KEPT'}; MuJoCo "
          f"contacts with the cell: {sum(r.contact_steps for r in rs)} steps")
