"""Collision-checking throughput of the Ned3 Pro in the bundled quality-check cell.

Measures, with the gripper empty and holding the vial, on one core with a fixed seed:

* single-state checks per second (``CollisionChecker.is_valid``) on uniformly random
  states inside the joint limits, and on valid states near the taught poses;
* full reports per second (``CollisionChecker.check``: collisions, clearance, margins);
* segment checks per second (``CollisionChecker.segment_is_valid``) on random pairs of
  valid states near the taught poses, and on the taught pose-to-pose segments, with the
  average number of states a full check of such a segment takes.

Run: ``.venv/bin/python benchmarks/collision_checks.py [--n 20000] [--seed 0] [--core 0]``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from safepath import Cell, CollisionChecker, load_cell

CELL_DIR = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"
#: Throughput aimed at for single-state checks [checks/s] (issue 10).
TARGET_STATE_CHECKS = 200_000
#: Throughput aimed at inside batched edge checks [2 mm grid states decided per second].
TARGET_EDGE_STATES = 1_000_000
#: Spread of the "near the taught poses" samples around each pose [rad].
NEAR_SIGMA = 0.1


@dataclass(frozen=True)
class Result:
    """One measured workload.

    Attributes:
        gripper: ``empty`` or the held object's name.
        workload: What was timed.
        count: Number of calls timed.
        seconds: Wall time of all calls [s].
        cpu_seconds: CPU time of this process over the calls [s] (on a shared, loaded
            machine the wall rate falls with the load; the CPU rate much less).
        note: Extra facts (share of valid answers, states per segment).
    """

    gripper: str
    workload: str
    count: int
    seconds: float
    cpu_seconds: float
    note: str = ""
    grid_rate: float = 0.0
    grid_cpu_rate: float = 0.0

    @property
    def rate(self) -> float:
        """Calls per second of wall time [1/s]."""
        return self.count / self.seconds if self.seconds > 0 else float("inf")

    @property
    def cpu_rate(self) -> float:
        """Calls per second of CPU time [1/s]."""
        return self.count / self.cpu_seconds if self.cpu_seconds > 0 else float("inf")


def pin_to_core(core: int | None) -> str:
    """Run on one core: pinned to ``core`` if given, else one thread wherever the OS puts it.

    safepath's checks are single-threaded either way; pinning only helps on a quiet
    machine (on a busy one it can tie the benchmark to the busiest core).
    """
    if core is None:
        where = "1 thread (unpinned)"
    elif hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {core})
        where = f"1 thread pinned to core {core}"
    else:
        where = "1 thread (pinning unsupported)"
    if hasattr(os, "getloadavg"):
        where += f", load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    return where


def timed(fn: Callable[[np.ndarray], object], states: Iterable[np.ndarray]
          ) -> tuple[float, float, list[object]]:
    """Call ``fn`` on every state; return the wall and CPU times [s] and the answers."""
    out = []
    start, cpu = time.perf_counter(), time.process_time()
    for q in states:
        out.append(fn(q))
    return time.perf_counter() - start, time.process_time() - cpu, out


def near_valid_states(cell: Cell, checker: CollisionChecker, n: int,
                      rng: np.random.Generator) -> np.ndarray:
    """``n`` valid states drawn around the taught poses (Gaussian, ``NEAR_SIGMA``)."""
    robot = cell.robot
    poses = np.array(list(cell.poses.values()))
    found: list[np.ndarray] = []
    while len(found) < n:
        batch = poses[rng.integers(len(poses), size=n)] + rng.normal(0.0, NEAR_SIGMA,
                                                                     size=(n, robot.dof))
        batch = np.clip(batch, robot.lower, robot.upper)
        found.extend(q for q in batch if checker.is_valid(q))
    return np.array(found[:n])


def bench_gripper(cell: Cell, held: bool, n: int, seed: int) -> list[Result]:
    """All workloads for one gripper state."""
    robot = cell.robot
    checker = cell.checker(held=held)
    label = cell.scene.grasp.object if held and cell.scene.grasp else "empty"
    rng = np.random.default_rng(seed)
    results = []

    random_states = rng.uniform(robot.lower, robot.upper, size=(n, robot.dof))
    near = near_valid_states(cell, checker, n, rng)
    checker.is_valid(random_states[0])  # warm up the broad phase
    for name, states in (("is_valid, random states in limits", random_states),
                         ("is_valid, valid states near taught poses", near)):
        seconds, cpu, answers = timed(checker.is_valid, states)
        results.append(Result(label, name, len(states), seconds, cpu,
                               f"{np.mean([bool(a) for a in answers]):.0%} valid"))

    n_full = max(1, n // 10)
    for name, states in (("check (full report), random states", random_states[:n_full]),
                         ("check (full report), near taught poses", near[:n_full])):
        seconds, cpu, _ = timed(checker.check, states)
        results.append(Result(label, name, len(states), seconds, cpu))

    n_seg = max(1, n // 100)
    pairs = [(near[2 * i], near[2 * i + 1]) for i in range(min(n_seg, len(near) // 2))]
    taught = [(cell.poses[a], cell.poses[b]) for a, b in itertools.permutations(cell.poses, 2)]
    for name, segments in (("segments, random valid pairs near poses", pairs),
                           ("segments, taught pose to taught pose", taught)):
        states_per = [checker.segment_states(q0, q1) + 1 for q0, q1 in segments]
        valid, times, cpus = [], [], []
        for q0, q1 in segments:
            start, cpu = time.perf_counter(), time.process_time()
            valid.append(checker.segment_is_valid(q0, q1))
            times.append(time.perf_counter() - start)
            cpus.append(time.process_time() - cpu)
        # A valid segment checks all its states; an invalid one stops at the first hit.
        full_states = sum(n for n, ok in zip(states_per, valid, strict=True) if ok)
        full_time = sum(t for t, ok in zip(times, valid, strict=True) if ok)
        full_cpu = sum(t for t, ok in zip(cpus, valid, strict=True) if ok)
        grid_rate = full_states / full_time if full_time > 0 else 0.0
        grid_cpu = full_states / full_cpu if full_cpu > 0 else 0.0
        per_state = (f", {grid_rate:,.0f} grid states/s ({grid_cpu:,.0f} per CPU s)"
                     if full_time > 0 else "")
        results.append(Result(label, name, len(segments), sum(times), sum(cpus),
                              f"{np.mean(valid):.0%} valid, "
                              f"{np.mean(states_per):.0f} states/segment{per_state}",
                              grid_rate, grid_cpu))
    return results


def report(results: Sequence[Result]) -> str:
    """The results as a table, with the single-state target verdict."""
    lines = [f"{'gripper':<8} {'workload':<42} {'count':>7} {'rate [1/s]':>12} "
             f"{'per CPU s':>10}  note",
             "-" * 92]
    for r in results:
        lines.append(f"{r.gripper:<8} {r.workload:<42} {r.count:>7} {r.rate:>12,.0f} "
                     f"{r.cpu_rate:>10,.0f}  {r.note}")
    single = [r for r in results if r.workload.startswith("is_valid")]
    worst = min(single, key=lambda r: r.rate)
    verdict = "met" if worst.rate >= TARGET_STATE_CHECKS else "NOT met"
    lines.append("")
    lines.append(f"target: >= {TARGET_STATE_CHECKS:,} state checks/s (is_valid): {verdict} "
                 f"(slowest: {worst.rate:,.0f}/s, {worst.gripper}, {worst.workload}; "
                 f"{worst.cpu_rate:,.0f} per CPU second)")
    edge = [r for r in results if r.workload.startswith("segments") and r.grid_rate]
    if edge:
        slow = min(edge, key=lambda r: r.grid_rate)
        ok = "met" if slow.grid_rate >= TARGET_EDGE_STATES else "NOT met"
        lines.append(f"target: >= {TARGET_EDGE_STATES:,} grid states/s inside edge checks: {ok} "
                     f"(slowest: {slow.grid_rate:,.0f}/s, {slow.gripper}, {slow.workload}, "
                     f"{slow.grid_cpu_rate:,.0f} per CPU second; a "
                     "grid state is decided by the sphere layer's clearance certificate or "
                     "checked by coal)")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print its table; returns the exit status (0)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20_000,
                        help="single-state checks per workload (full reports: n/10, "
                             "segments: n/100)")
    parser.add_argument("--seed", type=int, default=0, help="seed of all samples")
    parser.add_argument("--core", type=int, default=None, help="pin the process to this core")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/collision_checks.json and "
                             "rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args(argv)
    if args.n < 100:
        parser.error("--n must be at least 100")
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    where = pin_to_core(args.core)
    cell = load_cell(CELL_DIR)
    results = []
    for held in (False, True):
        results += bench_gripper(cell, held, args.n, args.seed)
    checker = cell.checker()
    print(f"safepath collision checks: {cell.robot.name} in {cell.scene.name}, "
          f"{len(checker.pairs)} pairs checked (empty gripper), resolution "
          f"{checker.options.resolution * 1000:.0f} mm")
    print(f"{where}; seed {args.seed}, n {args.n}")
    print(report(results))
    if args.save:
        from _results import save

        save("collision_checks", {
            "n": args.n, "seed": args.seed, "aim_state_checks": TARGET_STATE_CHECKS,
            "aim_grid_states": TARGET_EDGE_STATES,
            "workloads": [{"gripper": r.gripper, "workload": r.workload, "count": r.count,
                           "rate": r.rate, "cpu_rate": r.cpu_rate, "grid_rate": r.grid_rate}
                          for r in results]}, load_before=load_before)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
