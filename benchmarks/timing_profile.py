"""Where the compute of :func:`safepath.timing.time_path` goes, stage by stage.

On the via-point paths of ``timing_quality.py`` (same generator, ``--seed``), each robot's
paths are timed once to warm up, then once under :mod:`cProfile`; the cumulative time of
each stage of ``time_path`` is printed per path [ms], with the number of gridpoints and of
TOPP-RA runs per path. A stage called inside another (the quintic check inside a run) is
counted in both. The machine's load average is printed before and after.

Run: ``.venv/bin/python benchmarks/timing_profile.py [--paths 20] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from safepath.description.robot_folder import load_robot
from safepath.timing import TimingOptions, time_path
from safepath.timing.path_timing import CORNER_BLENDS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing_quality import ROBOTS, via_path  # noqa: E402

#: The stages reported: (label, module file ending, function name).
STAGES = (
    ("time_path", "path_timing.py", "time_path"),
    ("path limits", "_path_limits.py", "path_limits"),
    ("TOPP-RA run", "path_timing.py", "_time_once"),
    ("  TOPP-RA solve", "_topp.py", "solve"),
    ("  smoothing", "_smooth.py", "smooth"),
    ("  knots along", "_smooth.py", "along"),
    ("quintic check", "_release.py", "interval_ratios"),
    ("jerk window", "path_timing.py", "_jerk_window"),
    ("tighten (retry)", "path_timing.py", "_tighten"),
    ("release", "_release.py", "release"),
)


def stage_ms(stats: pstats.Stats, paths: int) -> dict[str, float]:
    """Cumulative milliseconds per path of each stage."""
    raw = stats.stats  # type: ignore[attr-defined]
    out = dict.fromkeys((label for label, _, _ in STAGES), 0.0)
    for (filename, _, name), (_, _, _, cumulative, _) in raw.items():
        for label, ending, function in STAGES:
            if name == function and filename.endswith(ending):
                out[label] += cumulative * 1e3 / paths
    return out


def profile_robot(name: str, paths: int, seed: int, blend: str) -> None:
    """Print one robot's stage breakdown."""
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    problems = [via_path(robot, rng, blend) for _ in range(paths)]  # type: ignore[arg-type]

    def run_all() -> list[int]:
        return [time_path(robot, p, s_way, scales=[1.0] * n, tcp_speeds=[None] * n).runs
                for p, s_way, n in problems]

    runs = run_all()
    profiler = cProfile.Profile()
    profiler.enable()
    run_all()
    profiler.disable()
    ms = stage_ms(pstats.Stats(profiler), paths)
    grid = [int(np.ceil(float(p.x[-1]) / TimingOptions().grid_step)) for p, _, _ in problems]
    print(f"\n{name}: {paths} paths, gridpoints (at least) median {statistics.median(grid):.0f}, "
          f"TOPP-RA runs per path mean {statistics.fmean(runs):.2f}")
    for label, value in ms.items():
        print(f"  {label:<18} {value:7.2f} ms/path")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--robots", nargs="*", default=sorted(
        p.name for p in ROBOTS.iterdir() if (p / "controller.yaml").is_file()))
    parser.add_argument("--blend", choices=CORNER_BLENDS, default=TimingOptions().corner_blend)
    args = parser.parse_args(argv)
    print(f"machine load before: {os.getloadavg()[0]:.2f} (cProfile adds overhead; "
          "timing_quality.py gives the plain compute time)")
    for name in args.robots:
        profile_robot(name, args.paths, args.seed, args.blend)
    print(f"\nmachine load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
