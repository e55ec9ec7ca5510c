#!/usr/bin/env python3
"""Every OMPL planner safepath names, on three arms, with its default options.

The problem is the "post in the way" detour of ``tests/planning/test_planners.py`` (one
per robot: start and goal 0.8 rad either side of a post on the first joint, the direct
segment blocked). Each planner plans it with seeds 0 .. N-1 and ``PlannerOptions``'s
defaults except the time budget, and the script prints per planner and robot:

* **solved**: seeds that gave a path within the budget;
* **first path**: time to the first path [ms], median and max (restarts included);
* **trees**: trees grown before the first path, median and max (a tree that finds no
  path within its iteration budget is replaced: ``safepath.planning._ompl``);
* **call**: the whole ``plan_joint_path`` call [ms] (the optimizing planners RRTstar,
  InformedRRTstar, AORRTC and SORRTstar improve their path for the whole budget), and
  the CPU time of the call [ms] (on a shared machine the wall time grows with the load).

Prints the load average at the start and the end: the figures move with it.

Usage::

    .venv/bin/python benchmarks/planners_any_arm.py --seeds 16 --time-limit 1.0
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import time
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

import numpy as np

from safepath import PlannerOptions, PlannerTimeout
from safepath.planning import PLANNERS, plan_joint_path

ROOT = Path(__file__).resolve().parents[1]


def problems() -> ModuleType:
    """The test module that builds the detour problems (one definition of them)."""
    spec = importlib.util.spec_from_file_location(
        "planner_problems", ROOT / "tests" / "planning" / "test_planners.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(name: str, planner: str, seeds: int, time_limit: float, detour: ModuleType
        ) -> str:
    """One row of the table."""
    checker, q_start, q_goal = detour.detour_problem(name)
    solved, first, trees, wall, cpu = 0, [], [], [], []
    for seed in range(seeds):
        times: dict[str, float] = {}
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            plan_joint_path(checker, q_start, q_goal, times=times, options=PlannerOptions(
                planner=planner, time_limit=time_limit, seed=seed))
            solved += 1
            first.append(times["first_path"])
            trees.append(times["attempts"])
        except PlannerTimeout:
            pass
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)

    def ms(values: list[float]) -> str:
        if not values:
            return f"{'-':>8}{'-':>8}"
        return f"{1000 * np.median(values):>8.1f}{1000 * np.max(values):>8.1f}"

    tree_text = f"{np.median(trees):>6.0f}{np.max(trees):>6.0f}" if trees else \
        f"{'-':>6}{'-':>6}"
    return (f"{name:<9}{planner:<17}{solved:>4}/{seeds:<4}{ms(first)}{tree_text}"
            f"{ms(wall)}{1000 * np.median(cpu):>8.1f}")


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the arguments, plan and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=8, help="seeds per planner and robot")
    parser.add_argument("--time-limit", type=float, default=1.0,
                        help="PlannerOptions.time_limit [s]")
    parser.add_argument("--robots", default="ned3pro,ur5,panda", help="comma-separated")
    parser.add_argument("--planners", default=",".join(PLANNERS), help="comma-separated")
    args = parser.parse_args(argv)
    detour = problems()
    print(f"{args.seeds} seeds, time_limit {args.time_limit:g} s, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f} at start")
    print(f"{'robot':<9}{'planner':<17}{'solved':>9}{'first path [ms]':>16}{'trees':>12}"
          f"{'call [ms]':>16}{'cpu':>8}")
    print(f"{'':<35}{'median':>8}{'max':>8}{'median':>6}{'max':>6}{'median':>8}{'max':>8}"
          f"{'median':>8}")
    for name in args.robots.split(","):
        for planner in args.planners.split(","):
            print(run(name, planner, args.seeds, args.time_limit, detour), flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
