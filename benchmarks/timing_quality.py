"""Jerk-limited timing on every robot: compute per path, motion time against references.

For each robot folder under ``robots/`` (loaded by name), on fresh seeded problems
(``--seed``):

* **paths through 1-3 via points**: random polylines inside 80 % of the joint ranges
  (one turn for a continuous joint), blended at their via points as the planner's first
  attempt blends them (radius ``min(0.6, 0.4 x either segment)`` [rad], cut as
  ``--blend`` says), through
  :func:`safepath.timing.spline_path` and :func:`safepath.timing.time_path`. Reported: the
  compute time of ``time_path`` (one warm-up call, then the fastest of ``--runs``), and
  the motion time over the jerk-free time-optimal timing of the same spline (the ``toppra`` library,
  ``ParametrizeConstAccel``, velocity and acceleration limits, on a 0.002 rad grid: a
  reference only, it ignores jerk and its knots may exceed the acceleration limits);
* **straight rest-to-rest moves**: the motion time over the analytic jerk-limited
  S-curve along the segment (the limits projected on it);

and, for every timed path, whether the controller's quintic join of the released knots
stays within the velocity, acceleration and jerk limits (the count of paths over a
limit must be 0), and how many TOPP-RA runs each via-point path took (more than one: its
first run's knots needed more than a small time stretch and it was re-timed). The
machine's load average is printed before and after.

Run: ``.venv/bin/python benchmarks/timing_quality.py [--paths 40] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from safepath.description.robot_folder import load_robot
from safepath.model.execution import executed_peaks
from safepath.model.robot import Robot
from safepath.timing import PathSpline, TimedPiece, TimingOptions, spline_path, time_path
from safepath.timing.path_timing import CORNER_BLENDS, CornerBlend

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the references
from s_curve import s_curve_time  # noqa: E402
from timing_suite import sampling_box  # noqa: E402
from toppra_path import ToppraPath  # noqa: E402

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
#: Grid step of the jerk-free reference [rad].
REFERENCE_GRID = 0.002
#: Aims (issue 39): compute per path through via points [s], motion time over the
#: jerk-free optimum (median, p95), straight moves over the S-curve (median).
AIM_MS, AIM_MEDIAN, AIM_P95, AIM_STRAIGHT = 1.0, 1.05, 1.10, 1.01


def via_path(robot: Robot, rng: np.random.Generator, blend: CornerBlend
             ) -> tuple[PathSpline, np.ndarray, int]:
    """A random path through 1-3 via points, blended as the planner first tries."""
    segments = int(rng.integers(2, 5))
    lo, hi = sampling_box(robot)
    points = [lo + rng.random(robot.dof) * (hi - lo) for _ in range(segments + 1)]
    lengths = [float(np.linalg.norm(b - a)) for a, b in zip(points[:-1], points[1:],
                                                           strict=True)]
    corners = [(k, min(0.6, 0.4 * lengths[k - 1], 0.4 * lengths[k]))
               for k in range(1, segments)]
    path, s_way, _ = spline_path(points, 0.06, corners=corners, blend=blend)
    return path, s_way, segments


def jerk_free_duration(robot: Robot, path: PathSpline) -> float:
    """The jerk-free time-optimal duration of ``path`` by the ``toppra`` library [s]."""
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    breaks = path.x
    grid = np.linspace(0.0, float(breaks[-1]),
                       max(200, int(np.ceil(breaks[-1] / REFERENCE_GRID)) + 1))
    instance = algo.TOPPRA(
        [constraint.JointVelocityConstraint(robot.velocity_limits),
         constraint.JointAccelerationConstraint(
             robot.acceleration_limits,
             discretization_scheme=constraint.DiscretizationType.Interpolation)],
        ToppraPath(path, robot.dof), gridpoints=grid,
        parametrizer="ParametrizeConstAccel")
    return float(instance.compute_trajectory(0.0, 0.0).duration)


def timed(robot: Robot, path: PathSpline, s_way: np.ndarray, segments: int, runs: int
          ) -> tuple[TimedPiece, float]:
    """The timed piece and the fastest of ``runs`` compute times [s] (after a warm-up)."""
    def once() -> TimedPiece:
        return time_path(robot, path, s_way, scales=[1.0] * segments,
                         tcp_speeds=[None] * segments)

    piece = once()
    best = float("inf")
    for _ in range(runs):
        t0 = time.perf_counter()
        once()
        best = min(best, time.perf_counter() - t0)
    return piece, best


def within(robot: Robot, piece: TimedPiece) -> bool:
    """Whether the quintic join of the piece's knots keeps every limit (ratio <= 1)."""
    peaks = executed_peaks(piece.t, piece.q, piece.qd, piece.qdd)
    return max(peaks.ratios(robot.velocity_limits, robot.acceleration_limits,
                            robot.jerk_limits)) <= 1.0


def measure(robot: Robot, paths: int, seed: int, runs: int, blend: CornerBlend
            ) -> dict[str, float]:
    """The figures of one robot."""
    rng = np.random.default_rng(seed)
    ms, ratios, straight, straight_ms = [], [], [], []
    over = 0
    topp_runs = []
    for _ in range(paths):
        path, s_way, segments = via_path(robot, rng, blend)
        piece, seconds = timed(robot, path, s_way, segments, runs)
        topp_runs.append(piece.runs)
        ms.append(seconds * 1e3)
        ratios.append(float(piece.t[-1]) / jerk_free_duration(robot, path))
        over += not within(robot, piece)
    for _ in range(paths):
        lo, hi = sampling_box(robot)
        a, b = (lo + rng.random(robot.dof) * (hi - lo) for _ in range(2))
        path, s_way, _ = spline_path([a, b], 0.06)
        piece, seconds = timed(robot, path, s_way, 1, runs)
        straight_ms.append(seconds * 1e3)
        straight.append(float(piece.t[-1]) / s_curve_time(
            b - a, robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits))
        over += not within(robot, piece)
    r = np.asarray(ratios)
    return {"ms": statistics.median(ms), "ms_p95": float(np.percentile(ms, 95)),
            "median": float(np.median(r)), "p95": float(np.percentile(r, 95)),
            "max": float(r.max()), "straight": float(np.median(straight)),
            "straight_max": float(np.max(straight)), "straight_ms": statistics.median(straight_ms),
            "over": over, "runs_mean": float(np.mean(topp_runs)),
            "retimed": float(np.mean(np.asarray(topp_runs) > 1))}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print the report; returns the exit status (0)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=40, help="problems of each kind per robot")
    parser.add_argument("--seed", type=int, default=0, help="seed of the problems")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per path (best kept)")
    parser.add_argument("--robots", default="", help="comma-separated (default: all)")
    parser.add_argument("--blend", choices=CORNER_BLENDS, default=TimingOptions().corner_blend,
                        help="how via points are cut (TimingOptions.corner_blend)")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/timing_quality.json "
                             "and rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    names = args.robots.split(",") if args.robots else sorted(
        p.name for p in ROBOTS.iterdir() if (p / "controller.yaml").is_file())
    load = f", load average {os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else ""
    print(f"timing_quality: python {platform.python_version()} on {platform.machine()}, "
          f"{os.cpu_count()} cores{load}; {args.paths} via-point paths and {args.paths} "
          f"straight moves per robot, seed {args.seed}, corner blend {args.blend!r}")
    header = (f"{'robot':<10} {'ms median':>9} {'ms p95':>7}   {'/jerk-free median':>17} "
              f"{'p95':>6} {'max':>6}   {'straight/S-curve median':>23} {'max':>6} {'ms':>5}   "
              f"{'over a limit':>12}   {'TOPP-RA runs':>12} {'re-timed':>8}")
    print(header)
    print("-" * len(header))
    figures = {}
    for name in names:
        f = figures[name] = measure(load_robot(name), args.paths, args.seed, args.runs,
                                    args.blend)
        print(f"{name:<10} {f['ms']:9.2f} {f['ms_p95']:7.2f}   {f['median']:17.3f} "
              f"{f['p95']:6.3f} {f['max']:6.3f}   {f['straight']:23.4f} "
              f"{f['straight_max']:6.4f} {f['straight_ms']:5.2f}   {f['over']:12d}   "
              f"{f['runs_mean']:12.2f} {f['retimed']:8.0%}")
    print("(ms: time_path per path, median of the fastest of the runs; /jerk-free: motion time "
          "over toppra's jerk-free optimum of the same spline; over a limit: paths whose "
          "quintic join exceeds a limit; TOPP-RA runs: mean per via-point path (TimedPiece.runs), "
          "re-timed: share of them timed more than once)")
    worst = {k: max(f[k] for f in figures.values()) for k in ("ms", "median", "p95",
                                                              "straight")}
    for key, aim, what in (("ms", AIM_MS, "median compute per via-point path [ms]"),
                           ("median", AIM_MEDIAN, "median motion time / jerk-free"),
                           ("p95", AIM_P95, "p95 motion time / jerk-free"),
                           ("straight", AIM_STRAIGHT, "median straight move / S-curve")):
        print(f"aim: {what} <= {aim} on every robot: worst {worst[key]:.3f}, "
              f"{'met' if worst[key] <= aim else 'NOT met'}")
    if hasattr(os, "getloadavg"):
        print(f"load average at the end {os.getloadavg()[0]:.2f}")
    if args.save:
        from _results import save

        save("timing_quality", {"paths": args.paths, "seed": args.seed, "runs": args.runs,
                                "blend": args.blend,
                                "aims": {"ms": AIM_MS, "median": AIM_MEDIAN, "p95": AIM_P95,
                                         "straight": AIM_STRAIGHT},
                                "robots": figures}, load_before=load_before)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
