#!/usr/bin/env python3
"""What a cancelled or timed-out request costs the runtime planner.

A request that is cancelled or times out while it plans stops its worker process (a
plan in native code cannot be interrupted otherwise). Measured on the bundled cell,
with the warm spare (the default) and without it (``spare=False``: the next request
waits for a new worker to load):

* **timeout overshoot**: how long after its deadline a ``timeout=`` request fails
  with ``PlannerTimeout`` [ms] (requests that plan, with timeouts of 5 to 300 ms);
* **cached after a cancel**: a request the cache holds, asked right after a running
  request was cancelled [ms];
* **new plan after a cancel**: a route with a new seed, asked right after a cancel
  (the spare, if any, loaded), against the same kind of request with nothing
  cancelled before [ms].

Prints the machine's load average: the figures move with it (two cores shared).

Usage::

    .venv/bin/python benchmarks/runtime_recovery.py --runs 5
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from concurrent.futures import CancelledError
from pathlib import Path

import numpy as np

from safepath import PlannerTimeout
from safepath.runtime import RuntimePlanner

DEFAULT_SCENE = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"
LONG = 120.0


def elapsed(fn: object) -> float:
    """Wall time of ``fn()`` [s]."""
    t0 = time.perf_counter()
    fn()  # type: ignore[operator]
    return time.perf_counter() - t0


def wait_idle(planner: RuntimePlanner, spare: bool) -> None:
    """Until no request runs, every worker is loaded and (with ``spare``) a spare too."""
    deadline = time.monotonic() + LONG
    while time.monotonic() < deadline:
        stats = planner.stats()
        if stats.busy == 0 and None not in stats.pids and (stats.spares or not spare):
            return
        time.sleep(0.01)
    raise RuntimeError("the planner did not settle")


def cancel_running(planner: RuntimePlanner, seed: int) -> None:
    """Start a plan of the cell and cancel it once a worker plans it."""
    future = planner.plan_cell(seed=seed)
    while planner.stats().busy == 0:
        time.sleep(0.001)
    future.cancel()
    try:
        future.result(timeout=LONG)
    except CancelledError:
        pass


def measure(scene: Path, runs: int, spare: bool, seed0: int) -> dict[str, list[float]]:
    """The three figures [s] over ``runs`` repetitions."""
    out: dict[str, list[float]] = {"overshoot": [], "cached": [], "after": [], "plain": []}
    with RuntimePlanner(scene, spare=spare) as planner:
        planner.ready().result(timeout=LONG)
        planner.plan_route("phase1").result(timeout=LONG)  # cached from now on
        seed = seed0
        for _ in range(runs):
            for limit in (0.005, 0.05, 0.3):
                wait_idle(planner, spare)
                seed += 1
                t0 = time.perf_counter()
                try:
                    planner.plan_cell(seed=seed, timeout=limit).result(timeout=LONG)
                except PlannerTimeout:
                    out["overshoot"].append(time.perf_counter() - t0 - limit)
            wait_idle(planner, spare)
            cancel_running(planner, seed := seed + 1)
            out["cached"].append(elapsed(lambda: planner.plan_route("phase1").result(LONG)))
            wait_idle(planner, spare)
            cancel_running(planner, seed := seed + 1)
            out["after"].append(elapsed(
                lambda s=seed: planner.plan_route("phase1", seed=s + 500).result(LONG)))
            wait_idle(planner, spare)
            out["plain"].append(elapsed(
                lambda s=seed: planner.plan_route("phase1", seed=s + 1000).result(LONG)))
    return out


def row(name: str, values: Sequence[float]) -> str:
    ms = np.asarray(values) * 1000.0
    return (f"{name:<34}{np.median(ms):>9.1f}{np.max(ms):>9.1f}{len(ms):>5}")


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the arguments, measure and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", type=Path, default=DEFAULT_SCENE, help="scene folder")
    parser.add_argument("--runs", type=int, default=5, help="repetitions of each figure")
    parser.add_argument("--no-compare", action="store_true",
                        help="measure with the spare only (not also without it)")
    args = parser.parse_args(argv)
    modes = [True] if args.no_compare else [True, False]
    print(f"scene: {args.scene.name}, {args.runs} runs, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f} at start")
    for spare in modes:
        figures = measure(args.scene, args.runs, spare, 1000 if spare else 2000)
        print(f"\n{'with' if spare else 'without'} the warm spare "
              f"(RuntimePlanner(spare={spare}))")
        print(f"{'':<34}{'median':>9}{'max':>9}{'n':>5}   [ms]")
        print(row("timeout overshoot", figures["overshoot"]))
        print(row("cached request after a cancel", figures["cached"]))
        print(row("new route plan after a cancel", figures["after"]))
        print(row("new route plan, nothing cancelled", figures["plain"]))
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
