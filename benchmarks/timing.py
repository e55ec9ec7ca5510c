"""Time per TOPP-RA run: safepath's numba kernel against the ``toppra`` library, same paths.

The paths are every :func:`safepath.timing.time_path` call of one warm plan of the
bundled cell (captured while planning), plus random polylines of the Ned3 Pro. On each
path, on the grid safepath gave toppra (0.015 rad steps), with the robot's limits
(constant along the path, so that toppra's own constraint classes apply), it measures
``--runs`` times and keeps the fastest:

* ``toppra``: ``TOPPRA([JointVelocityConstraint, JointAccelerationConstraint
  (interpolation)], ParametrizeConstAccel).compute_trajectory`` and the evaluation of the
  path parameter at the knots (``_eval_params``), what safepath ran before;
* ``ours``: the same steps with :mod:`safepath.timing._topp` (path derivatives on the
  grid, constraint rows, backward and forward pass, parametrisation, knots);

and prints the durations both find. Then, for the captured calls, the whole ``time_path``
(grid, limits, runs with local tightening, stretch, release check), and the split of one
warm ``plan_cell`` of the two routes of each outcome. With ``--compile``, it also measures
numba's first compile and its cached load, each in a fresh process.

The machine's load average is printed with the figures: timings on a shared machine vary.

Run: ``.venv/bin/python benchmarks/timing.py [--runs 5] [--random 8] [--compile]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

from safepath import Cell, PlanOptions, load_cell, load_routes, plan_cell
from safepath.model.robot import Robot
from safepath.planning import _chunks
from safepath.timing import PathSpline, TimingOptions, _topp, spline_path

ROOT = Path(__file__).resolve().parents[1]
CELL_DIR = ROOT / "scenes" / "quality_check_cell"
OUTCOMES = {"safe": ("phase1", "phase2_safe"), "unsafe": ("phase1", "phase2_unsafe")}
#: Grid step safepath used with toppra [rad] (time_path now cuts each spline piece into
#: steps of at most TimingOptions.grid_step, 0.005 rad).
OLD_GRID_STEP = 0.015


@dataclass(frozen=True)
class Case:
    """One path to time.

    Attributes:
        name: Where it comes from.
        path: The spline.
        length: Its length [rad].
        call: The captured ``time_path`` arguments, or None for a random path.
    """

    name: str
    path: PathSpline
    length: float
    call: tuple[tuple[Any, ...], dict[str, Any]] | None


def best_of(runs: int, fn: Callable[[], object]) -> float:
    """The fastest of ``runs`` calls [s]."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def captured_cases(cell: Cell) -> list[Case]:
    """The ``time_path`` calls of one plan of the bundled cell (all routes)."""
    routes = load_routes(cell.folder, poses=list(cell.poses), objects=list(cell.scene.objects))
    calls: list[tuple[tuple[Any, ...], dict[str, Any]]] = []
    original = _chunks.time_path

    def record(*args: Any, **kwargs: Any) -> object:
        calls.append((args, kwargs))
        return original(*args, **kwargs)

    with mock.patch.object(_chunks, "time_path", record):
        plan_cell(cell, PlanOptions(), routes=routes)
    return [Case(f"{kw.get('step') or 'plan'} #{n}", args[1], float(args[2][-1]), (args, kw))
            for n, (args, kw) in enumerate(calls)]


def random_cases(robot: Robot, count: int, seed: int) -> list[Case]:
    """Random polylines of 2 to 4 segments inside 80 % of the joint range."""
    rng = np.random.default_rng(seed)
    out = []
    for n in range(count):
        lo, hi = robot.lower * 0.8, robot.upper * 0.8
        waypoints = [lo + rng.random(robot.dof) * (hi - lo)
                     for _ in range(int(rng.integers(3, 6)))]
        path, s_way, _ = spline_path(waypoints, 0.06)
        out.append(Case(f"random #{n}", path, float(s_way[-1]), None))
    return out


def grid_of(length: float) -> np.ndarray:
    """The grid safepath gave toppra: evenly spaced, :data:`OLD_GRID_STEP` apart."""
    return np.linspace(0.0, length, max(20, int(np.ceil(length / OLD_GRID_STEP)) + 1))


def toppra_run(path: PathSpline, grid: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
               period: float) -> float:
    """One toppra run and its knots, as safepath timed before; returns the duration [s]."""
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    spline = path  # safepath's not-a-knot cubic spline
    S = spline.x  # type: ignore[attr-defined]
    tpath = ta.SplineInterpolator(S, path(S))
    instance = algo.TOPPRA(
        [constraint.JointVelocityConstraint(vmax),
         constraint.JointAccelerationConstraint(
             amax, discretization_scheme=constraint.DiscretizationType.Interpolation)],
        tpath, gridpoints=grid, parametrizer="ParametrizeConstAccel")
    traj = instance.compute_trajectory(0.0, 0.0)
    duration = float(traj.duration)
    traj._eval_params(np.linspace(0.0, duration, int(np.ceil(duration / period)) + 1))
    return duration


def our_run(path: PathSpline, grid: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
            period: float) -> float:
    """The same with safepath's kernel; returns the duration [s]."""
    dq, ddq = path(grid, 1), path(grid, 2)
    with np.errstate(divide="ignore"):
        xmax = np.min(vmax / np.abs(dq), axis=1) ** 2
    a, b, c = _topp.acceleration_rows(grid, dq, ddq, np.broadcast_to(amax, dq.shape))
    x = _topp.solve(grid, np.minimum(xmax, _topp.X_CAP), a, b, c)
    assert x is not None
    profile = _topp.parametrize(grid, x)
    _topp.evaluate(profile, np.linspace(0.0, profile.duration,
                                        int(np.ceil(profile.duration / period)) + 1))
    return profile.duration


def compare_runs(robot: Robot, cases: Sequence[Case], runs: int) -> None:
    """The per-run table."""
    period = TimingOptions().knot_period
    vmax, amax = robot.velocity_limits, robot.acceleration_limits
    print(f"{'path':<34} {'grid':>5} {'toppra':>9} {'ours':>8} {'x':>6}   "
          f"{'duration':>9} {'rel. diff':>9}")
    ratios = []
    for case in cases:
        grid = grid_of(case.length)
        reference = partial(toppra_run, case.path, grid, vmax, amax, period)
        ours = partial(our_run, case.path, grid, vmax, amax, period)
        d_ref, d_ours = reference(), ours()
        t_ref, t_ours = best_of(runs, reference), best_of(runs, ours)
        ratios.append(t_ref / t_ours)
        print(f"{case.name[:34]:<34} {grid.size:5d} {t_ref * 1e3:9.2f} {t_ours * 1e3:8.3f} "
              f"{t_ref / t_ours:6.0f}   {d_ours:9.4f} {d_ours / d_ref - 1:+9.1e}")
    print(f"(ms per run, fastest of {runs}; median speed-up "
          f"{statistics.median(ratios):.0f}x; durations: ours, and ours/toppra - 1)")


def time_path_calls(cases: Sequence[Case], runs: int) -> None:
    """The whole time_path of each captured call."""
    from safepath.timing import time_path

    total = 0.0
    for case in cases:
        assert case.call is not None
        args, kwargs = case.call
        total += best_of(runs, partial(time_path, *args, **kwargs))
    print(f"time_path, all {len(cases)} calls of one plan of the cell: {total * 1e3:.2f} ms "
          f"(sum of the fastest of {runs} per call)")


def plan_split(cell: Cell) -> None:
    """Wall time of one warm plan_cell per outcome, and the part spent in time_path."""
    routes = load_routes(cell.folder, poses=list(cell.poses), objects=list(cell.scene.objects))
    original = _chunks.time_path
    spent = {"time": 0.0, "calls": 0}

    def clocked(*args: Any, **kwargs: Any) -> object:
        t0 = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            spent["time"] += time.perf_counter() - t0
            spent["calls"] += 1

    runs = [0]
    original_solve = _topp.solve

    def counted(*args: Any, **kwargs: Any) -> object:
        runs[0] += 1
        return original_solve(*args, **kwargs)

    for names in OUTCOMES.values():
        subset = {name: routes[name] for name in names}
        plan_cell(cell, PlanOptions(), routes=subset)  # warm-up
        spent.update(time=0.0, calls=0)
        runs[0] = 0
        with mock.patch.object(_chunks, "time_path", clocked), \
                mock.patch.object(_topp, "solve", counted):
            t0 = time.perf_counter()
            plan_cell(cell, PlanOptions(), routes=subset)
            wall = time.perf_counter() - t0
        print(f"plan_cell {' + '.join(names):<26} wall {wall * 1e3:7.1f} ms, time_path "
              f"{spent['time'] * 1e3:6.2f} ms in {spent['calls']} calls, "
              f"{runs[0]} TOPP-RA runs")


COLD = textwrap.dedent("""
    import time
    t0 = time.perf_counter()
    import numba
    t1 = time.perf_counter()
    numba.njit(lambda x: x + 1.0)(1.0)  # numba's own start-up, shared by every kernel
    t2 = time.perf_counter()
    import numpy as np
    from safepath.timing import _topp
    t3 = time.perf_counter()
    grid = np.linspace(0.0, 1.0, 50)
    ones = np.ones((49, 2))
    _topp.solve(grid, np.ones(50), ones, ones, ones)
    t4 = time.perf_counter()
    print(f"{t1 - t0:.4f} {t2 - t1:.4f} {t4 - t3:.4f}")
""")


def compile_times() -> None:
    """numba's first compile of our kernels and their cached load, in fresh processes."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for label in ("first compile", "cached load", "cached load"):
            out = subprocess.run([sys.executable, "-c", COLD], cwd=ROOT, env=env, check=True,
                                 capture_output=True, text=True).stdout.split()
            ms_ = [float(v) * 1e3 for v in out]
            print(f"fresh process, {label:<13}: import numba {ms_[0]:5.0f} ms, numba start-up "
                  f"(a trivial kernel) {ms_[1]:5.0f} ms, TOPP-RA kernels ready {ms_[2]:6.1f} ms")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print the report; returns the exit status (0)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="timed runs per path (best kept)")
    parser.add_argument("--random", type=int, default=8, help="random paths")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random paths")
    parser.add_argument("--compile", action="store_true",
                        help="also time numba's compile and cached load (fresh processes)")
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be at least 1")

    import numba
    import toppra  # noqa: F401 - imported before the clock starts

    load = f", load average {os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else ""
    print(f"timing: python {platform.python_version()} on {platform.machine()}, "
          f"{os.cpu_count()} cores{load}, numba {numba.__version__}")
    cell = load_cell(CELL_DIR)
    cases = captured_cases(cell)
    print()
    compare_runs(cell.robot, [*cases, *random_cases(cell.robot, args.random, args.seed)],
                 args.runs)
    print()
    time_path_calls(cases, args.runs)
    plan_split(cell)
    if args.compile:
        print()
        compile_times()
    if hasattr(os, "getloadavg"):
        print(f"load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
