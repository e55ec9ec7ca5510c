"""A randomized timing suite: seeded random via-point paths on the bundled robots, timed by
``time_path`` and checked as a controller executes them, at 0 tolerance.

Shared by ``tests/planning/test_timing_suite.py`` (a bounded subset) and
``benchmarks/timing_suite.py`` (as many paths as asked; with ``--out``, a resumable sweep
of :class:`TimingSuiteTask`: one path per robot for each seed). Each problem is a polyline of
2-4 segments inside 80 % of the joint ranges (one turn for a continuous joint), each
segment its own route step: a speed scale in [0.2, 1] (or 1), a TCP speed limit in
[0.05, 0.5] m/s on some, via points blended as the planner's first attempt blends them
(``min(0.6, 0.4 x either segment)`` [rad]), cut the ``"gap"`` or the ``"g2"`` way,
timed with or without ``limits_ahead``. The check: the quintic join of the
released knots (``safepath.model.execution.interval_ratios``), each interval against the
limits of the slower step of its two knots, every ratio <= 1.0.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from safepath.description.robot_folder import load_robot
from safepath.model.execution import interval_ratios
from safepath.model.robot import Robot
from safepath.sweeps import ReplayBySeed, TaskResult
from safepath.timing import TimedPiece, TimingOptions, spline_path, time_path

ROBOTS_DIR = Path(__file__).resolve().parents[1] / "robots"


def robot_names() -> list[str]:
    """The bundled robots (folders under ``robots/`` with a controller)."""
    return sorted(p.name for p in ROBOTS_DIR.iterdir() if (p / "controller.yaml").is_file())


@dataclass(frozen=True)
class Outcome:
    """One timed problem.

    Attributes:
        worst: The largest speed, acceleration or jerk ratio of its executed motion.
        runs: TOPP-RA runs its timing took.
        duration: Its motion time [s].
    """

    worst: float
    runs: int
    duration: float


def sampling_box(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Where random joint positions are drawn [rad]: 80 % of each joint's range, and one
    turn (-pi, pi) for a continuous joint (its limits are infinite)."""
    bounded = np.isfinite(robot.lower) & np.isfinite(robot.upper)
    return (np.where(bounded, robot.lower * 0.8, -np.pi),
            np.where(bounded, robot.upper * 0.8, np.pi))


def timed_problem(robot: Robot, rng: np.random.Generator, knot_period: float | None = None
                  ) -> tuple[TimedPiece, np.ndarray]:
    """One random problem timed: the piece and each segment's speed scale (knots
    ``knot_period`` [s] apart, default the timing's)."""
    segments = int(rng.integers(2, 5))
    lo, hi = sampling_box(robot)
    points = [lo + rng.random(robot.dof) * (hi - lo) for _ in range(segments + 1)]
    lengths = [float(np.linalg.norm(b - a)) for a, b in zip(points[:-1], points[1:],
                                                           strict=True)]
    corners = [(k, min(0.6, 0.4 * lengths[k - 1], 0.4 * lengths[k]))
               for k in range(1, segments)]
    blend = "g2" if rng.random() < 0.5 else "gap"
    scales = np.where(rng.random(segments) < 0.5, rng.uniform(0.2, 1.0, segments), 1.0)
    tcp = [float(v) if rng.random() < 0.3 else None
           for v in rng.uniform(0.05, 0.5, segments)]
    path, s_way, _ = spline_path(points, 0.06, corners=corners, blend=blend)
    options = TimingOptions(corner_blend=blend, limits_ahead=bool(rng.random() < 0.5),
                            knot_period=TimingOptions.knot_period if knot_period is None
                            else knot_period)
    piece = time_path(robot, path, s_way, scales=scales.tolist(), tcp_speeds=tcp,
                      options=options)
    return piece, scales


def executed_worst(robot: Robot, piece: TimedPiece, scales: np.ndarray) -> float:
    """The largest limit ratio of the piece's quintic join, each interval against the
    slower step of its two knots."""
    knot_scale = scales[piece.segment]
    interval = np.minimum(knot_scale[:-1], knot_scale[1:])[:, None]
    ratios = interval_ratios(piece.t, piece.q, piece.qd, piece.qdd,
                             vmax=interval * robot.velocity_limits,
                             amax=interval * robot.acceleration_limits,
                             jmax=interval * robot.jerk_limits)
    return max(float(r.max()) for r in ratios)


def run_suite(name: str, paths: int, seed: int) -> list[Outcome]:
    """``paths`` random problems on the robot ``name``, from ``seed``."""
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(paths):
        piece, scales = timed_problem(robot, rng)
        out.append(Outcome(executed_worst(robot, piece, scales), piece.runs,
                           float(piece.t[-1])))
    return out


#: The robots this process loaded, by name (a plain dict, not ``functools.cache``: a
#: cache wrapper pickles by reference, which a Ray worker cannot resolve, see
#: ``benchmarks/timing_suite.py``).
_ROBOTS: dict[str, Robot] = {}


def suite_robot(name: str) -> Robot:
    """The robot ``name``, loaded once per process (a sweep worker keeps it for its seeds)."""
    if name not in _ROBOTS:
        _ROBOTS[name] = load_robot(name)
    return _ROBOTS[name]


def path_rng(seed: int, name: str) -> np.random.Generator:
    """The generator of seed ``seed``'s path on robot ``name``: the seed and the name
    alone (not the robot's place in a list), so a path replays with any ``--robots``."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


@dataclass(frozen=True)
class TimingSuiteTask(ReplayBySeed):
    """The suite as a sweep task (:mod:`safepath.sweeps`): for each seed, one random
    via-point path per robot, timed and checked as executed.

    Attributes:
        robots: The bundled robots' names.
        replay_command: The command of one seed, ``{seed}`` in place of the seed.
    """

    robots: tuple[str, ...]
    replay_command: str

    def __call__(self, seed: int) -> TaskResult:
        """Time seed ``seed``'s path on each robot: the largest executed ratio [-], the
        TOPP-RA runs and the motion time [s]; the check: no ratio over 1.0."""
        figures: dict[str, float | tuple[float, ...]] = {}
        checks: dict[str, bool] = {}
        for name in self.robots:
            robot = suite_robot(name)
            piece, scales = timed_problem(robot, path_rng(seed, name))
            worst = executed_worst(robot, piece, scales)
            figures |= {f"{name}.worst_ratio": worst, f"{name}.toppra_runs": float(piece.runs),
                        f"{name}.duration": float(piece.t[-1])}
            checks[f"{name}.no_overrun"] = worst <= 1.0
        return TaskResult(figures=figures, checks=checks)

    def identity(self) -> dict[str, Any]:
        """The suite and its robots."""
        return {"kind": "timing suite", "robots": list(self.robots)}

    def labels(self) -> dict[str, str]:
        """The report's words."""
        out: dict[str, str] = {}
        for name in self.robots:
            out[f"{name}.no_overrun"] = f"paths executed within every limit ({name})"
        for name in self.robots:
            out |= {f"{name}.worst_ratio": f"largest executed limit ratio ({name})",
                    f"{name}.toppra_runs": f"TOPP-RA runs per path ({name})",
                    f"{name}.duration": f"motion time [s] ({name})"}
        return out

