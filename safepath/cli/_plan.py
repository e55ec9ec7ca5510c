"""``safepath plan``: plan every route of a cell, write the trajectories (and a ROS 2 bag),
print a table. A command of the command line, above planning and ROS (planning imports
neither)."""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``plan`` command."""
    p = sub.add_parser("plan", help="plan, time and verify every route of a cell")
    p.add_argument("scene", help="scene folder (e.g. scenes/quality_check_cell)")
    p.add_argument("--out", default=None, help="output folder (default: out/<scene name>)")
    p.add_argument("--seed", type=int, default=0, help="planner seed")
    p.add_argument("--planner", default="RRTConnect", help="OMPL planner name")
    p.add_argument("--time-limit", type=float, default=2.0, help="planning budget per move [s]")
    p.add_argument("--speed", type=float, default=1.0, help="global speed scale in (0, 1]")
    p.add_argument("--route", action="append", default=None, help="plan only this route")
    p.add_argument("--bag", default=None,
                   help="also write a ROS 2 bag (MCAP) of the cycle: the routes in the order "
                        "of routes.yaml's `cycle`, else every chain of routes (route, the "
                        "routes that follow it, ...) back to back")
    p.set_defaults(func=cmd_plan)


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan the cell's routes; write JSON and CSV per route and a summary.

    Nothing is written unless everything succeeds: the bag (if asked for) is built and
    checked before any file is written, every file is written atomically, and the files
    this command wrote are removed again if a later one cannot be written.
    """
    from ..cell import load_cell
    from ..cell.routes import after_chain
    from ..errors import ConfigError
    from ..files._io import check_names
    from ..planning import PlannerOptions, PlanOptions, plan_cell
    from ..timing import TimingOptions

    if args.bag and Path(args.bag).exists():
        raise ConfigError(f"{args.bag} exists already; choose a new bag path", key="--bag")
    cell = load_cell(args.scene)
    routes = cell.route_table()
    if args.route:
        check_names(args.route, routes, path=None, key="--route", what="route")
        keep: set[str] = set()
        for name in args.route:
            keep.update(after_chain(routes, name))  # and the routes whose end it starts from
        routes = {k: v for k, v in routes.items() if k in keep}
    options = PlanOptions(planner=PlannerOptions(planner=args.planner, time_limit=args.time_limit,
                                                 seed=args.seed),
                          timing=TimingOptions(speed_scale=args.speed), baseline=True)
    _note_jit_kernels()
    t0 = time.perf_counter()
    trajectories = plan_cell(cell, options, routes=routes)
    wall = time.perf_counter() - t0
    out = Path(args.out) if args.out else Path("out") / cell.scene.name
    summary = {name: _summary_row(traj) for name, traj in trajectories.items()}
    cycle = [trajectories[name] for name in _bag_order(cell, routes)] if args.bag else []
    with _collector_paused():
        bag = _write_outputs(out, trajectories, summary, Path(args.bag) if args.bag else None,
                             cycle, cell.robot)
    header = (f"{'route':<15} {'steps':>5} {'plan[ms]':>9} {'motion[s]':>10} "
              f"{'stop&go[s]':>11} {'ratio':>6} {'clearance[mm]':>14} {'bound[mm]':>10}  "
              f"closest pair")
    print(f"cell {cell.scene.name}: {len(trajectories)} routes planned, timed and verified "
          f"in {wall * 1000:.0f} ms (seed {args.seed}, {args.planner})")
    print(header)
    print("-" * len(header))
    for name, row in summary.items():
        pair = " / ".join(row["closest_pair"] or [])
        base = row["baseline_time"]
        base_text = f"{base:>11.3f}" if base else f"{'-':>11}"
        ratio = f"{row['motion_time'] / base:>6.2f}" if base else f"{'-':>6}"
        print(f"{name:<15} {row['steps']:>5} {row['planning_time'] * 1000:>9.0f} "
              f"{row['motion_time']:>10.3f} {base_text} {ratio} "
              f"{row['min_clearance'] * 1000:>14.1f} {row['clearance_bound'] * 1000:>10.1f}  "
              f"{pair}")
    for line in _figure_lines(summary):
        print(line)
    print(f"wrote {len(trajectories)} trajectories (JSON, CSV) and summary.json to {out}")
    if bag is not None:
        print(f"wrote a ROS 2 bag of the cycle ({' -> '.join(t.route for t in cycle)}) to {bag}")
    return 0


@contextlib.contextmanager
def _collector_paused() -> Iterator[None]:
    """Pause Python's cycle collector while the outputs are written (restored after).

    Writing a bag imports rosbags and the messages' classes and builds tens of thousands
    of messages, none in a reference cycle; each collection the allocations trigger walks
    every object of the planned cell too (a full one about 15 ms of a ``plan --bag``
    process). What they free, reference counting frees.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _note_jit_kernels() -> None:
    """Say on standard error, before planning, when the kernels were not compiled ahead
    of time for these sources (none built, or built from other sources: any edit of a
    kernel module, the monitor's included, needs a new build): numba then compiles or
    loads them during the first route, which waits for it (most of a second from
    numba's cache; minutes on a fresh or busy machine, with nothing else to show)."""
    import os
    import sys

    from .. import _aot

    if _aot.compiled() is None and os.environ.get(_aot.ENV_MODE, "1") != "0":
        print(f"safepath plan: note: {_aot.status()}; the first route waits for numba "
              "to compile or load the kernels (under a second from its cache, minutes "
              "on a fresh or busy machine): `safepath build-kernels` compiles them ahead "
              "of time", file=sys.stderr, flush=True)


def _summary_row(traj: Any) -> dict[str, Any]:
    return {
        "steps": len(traj.steps),
        "motion_time": traj.duration,
        "baseline_time": traj.info["baseline_duration"],
        "planning_time": traj.info["total_time"],
        "min_clearance": traj.info["min_clearance"],
        "clearance_bound": traj.info["clearance_bound"],
        "closest_pair": traj.info["closest_pair"],
        "step_durations": traj.step_durations(),
        **{k: traj.info[k] for k in ("carried_tilt", "pours") if k in traj.info},
    }


def _figure_lines(summary: dict[str, Any]) -> list[str]:
    """The held object's largest tilt on the steps that keep it upright, and the pours'
    figures, route by route (measured on the released samples)."""
    import math

    from ..planning._pour_chunk import describe

    lines = []
    for name, row in summary.items():
        carried = row.get("carried_tilt")
        if carried:
            lines.append(f"{name}: carried upright, tilt <= "
                         f"{math.degrees(carried['max']):.3f} deg (max_tilt "
                         f"{math.degrees(carried['bound']):.2f} deg)")
        lines += [f"{name}: {line}" for line in describe(row.get("pours") or {})]
    return lines


def _write_outputs(out: Path, trajectories: dict[str, Any], summary: dict[str, Any],
                   bag: Path | None, cycle: list[Any], robot: Any) -> Path | None:
    """Write the bag first (it validates every message before touching the disk and
    appears whole or not at all; the robot's controller addresses it, its locked joints
    are in ``/joint_states``), then the files; on failure, remove what was written."""
    from ..errors import InputError, SafepathError
    from ..files._io import atomic_write_text

    written: list[Path] = []
    out_existed = out.exists()
    try:
        if bag is not None:
            from ..ros.bag import write_bag

            written.append(write_bag(bag, cycle, controller=robot.controller,
                                     locked_joints=robot.locked_joints))
        for name, traj in trajectories.items():
            for path, write in ((out / f"{name}.json", traj.to_json),
                                (out / f"{name}.csv", traj.to_csv)):
                existed = path.exists()
                write(path)
                if not existed:
                    written.append(path)
        path = out / "summary.json"
        existed = path.exists()
        atomic_write_text(path, json.dumps(summary, indent=2) + "\n")
        if not existed:
            written.append(path)
    except (OSError, SafepathError) as exc:
        for path in reversed(written):
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        if not out_existed and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        if isinstance(exc, OSError):
            raise InputError(f"cannot write ({exc.strerror or exc})", path=out) from None
        raise
    return bag


def _bag_order(cell: Any, routes: dict) -> list[str]:
    """The routes of the bag: the cell's ``cycle`` (routes.yaml) when every route of it
    is planned, else every chain of the planned routes (:func:`cycle_order`)."""
    cycle = cell.cycle()
    if cycle is not None and all(name in routes for name in cycle):
        return cycle
    return cycle_order(routes)


def cycle_order(routes: dict) -> list[str]:
    """Every chain of routes from a first route to a last one, back to back: for the
    quality-check cell, phase1, phase2_safe, phase1, phase2_unsafe."""
    from ..cell.routes import after_chain

    followed = {r.after for r in routes.values() if r.after is not None}
    order: list[str] = []
    for name in routes:
        if name in followed:
            continue  # not a last route
        order += after_chain(routes, name)
    return order
