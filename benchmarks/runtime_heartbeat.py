#!/usr/bin/env python3
"""Does planning stall the caller? A 100 Hz heartbeat while the cell is planned.

Plans the whole cell N times (one seed per run) in two ways, alternately so that both
see the same machine load: through a :class:`safepath.runtime.RuntimePlanner` (worker
process), and in this process on a thread, as a ROS 2 callback or a viser handler
would. A heartbeat thread sleeps for the period and records the time between its
wake-ups; OMPL, Pinocchio, coal and TOPPRA hold the interpreter lock while they
compute, which lengthens the gaps in-process. A *control* heartbeat runs in a separate
process throughout: its gaps during each mode show what the machine's own load (other
processes, two cores) costs, which no planner design can remove. The two modes must
give identical trajectories.

Prints: worker start-up time; per mode, plan latency (median, p95) and heartbeat gaps
(max, p99) of this process and of the control process [ms]; the time of a request the
planner answers from its cache (kept in this process: unpickling only).

Usage::

    .venv/bin/python benchmarks/runtime_heartbeat.py --runs 5
    .venv/bin/python benchmarks/runtime_heartbeat.py --runs 5 --detour high1 high2

The bundled cell's moves are mostly direct (OMPL rarely runs); ``--detour`` puts a
pillar in the way of one move, in a temporary copy of the scene, so that OMPL plans.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np

from safepath import PlannerOptions, PlanOptions, Trajectory, load_cell, plan_cell
from safepath.runtime import RuntimePlanner

DEFAULT_SCENE = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"

Plans = dict[str, Trajectory]


def beat(period: float, stop: Callable[[], bool]) -> list[tuple[float, float]]:
    """Sleep ``period`` [s] until ``stop()``; (wake-up time, gap since the last) [s]."""
    out = []
    last = time.monotonic()  # system-wide clock: comparable between processes
    while not stop():
        time.sleep(period)
        now = time.monotonic()
        out.append((now, now - last))
        last = now
    return out


def control(conn: Connection, period: float) -> None:
    """Heartbeat of the control process, until the parent writes to ``conn``."""
    conn.send(beat(period, conn.poll))


@dataclass
class Mode:
    """One way of planning, and its figures."""

    name: str
    plan: Callable[[int], Plans]
    latencies: list[float] = field(default_factory=list)
    beats: list[tuple[float, float]] = field(default_factory=list)
    windows: list[tuple[float, float]] = field(default_factory=list)
    results: list[Plans] = field(default_factory=list)

    def measure(self, seed: int, period: float) -> None:
        """Plan once under a heartbeat thread of this process."""
        stop = threading.Event()
        beats: list[tuple[float, float]] = []
        thread = threading.Thread(target=lambda: beats.extend(beat(period, stop.is_set)))
        thread.start()
        t0 = time.monotonic()
        self.results.append(self.plan(seed))
        t1 = time.monotonic()
        stop.set()
        thread.join()
        self.latencies.append(t1 - t0)
        self.windows.append((t0, t1))
        self.beats.extend(beats)

    def inside(self, beats: list[tuple[float, float]]) -> list[float]:
        """Gaps [s] of ``beats`` that ended while this mode planned."""
        return [g for t, g in beats if any(a <= t <= b for a, b in self.windows)]


def with_pillar(scene: Path, pose_a: str, pose_b: str, folder: Path) -> Path:
    """A copy of ``scene`` in ``folder`` with a 5 x 5 x 6 cm pillar where the TCP passes
    halfway along the direct joint move between two taught poses: OMPL must detour."""
    cell = load_cell(scene)
    x, y, z = cell.robot.tcp_position(0.5 * (cell.pose(pose_a) + cell.pose(pose_b)))
    target = folder / scene.name
    shutil.copytree(scene, target)
    path = target / "scene.yaml"
    path.write_text(path.read_text().replace("objects:\n", (
        "objects:\n  pillar:\n    shape: box\n    size: [0.05, 0.05, 0.06]\n"
        f"    xyz: [{x:.4f}, {y:.4f}, {z:.4f}]\n"), 1))
    return target


def on_thread(cell_plan: Callable[[int], Plans]) -> Callable[[int], Plans]:
    """Run ``cell_plan`` on a new thread of this process, the caller waiting for it."""
    def plan(seed: int) -> Plans:
        out: list[Plans] = []
        thread = threading.Thread(target=lambda: out.append(cell_plan(seed)))
        thread.start()
        thread.join()
        return out[0]
    return plan


def same(a: Plans, b: Plans) -> bool:
    """Whether two planned cells hold bit-identical trajectories."""
    return list(a) == list(b) and all(
        np.array_equal(getattr(a[n], k), getattr(b[n], k))
        for n in a for k in ("t", "q", "qd", "qdd", "step_index"))


def ms(values: Sequence[float], q: float) -> float:
    """Percentile ``q`` of ``values`` [s], in [ms]."""
    return float(np.percentile(np.asarray(values), q)) * 1000.0


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the arguments, run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", type=Path, default=DEFAULT_SCENE, help="scene folder")
    parser.add_argument("--runs", type=int, default=5, help="plans of the cell per mode")
    parser.add_argument("--period", type=float, default=0.01, help="heartbeat period [s]")
    parser.add_argument("--workers", type=int, default=1, help="worker processes")
    parser.add_argument("--detour", nargs=2, metavar="POSE", default=None,
                        help="put a pillar halfway between two taught poses (OMPL plans)")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/runtime_heartbeat.json "
                             "and rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        scene: Path = args.scene
        if args.detour:
            scene = with_pillar(scene, args.detour[0], args.detour[1], Path(tmp))
        return benchmark(scene, args.runs, args.period, args.workers,
                         f"{args.scene.name}" + (" + pillar between " + " and ".join(args.detour)
                                                 if args.detour else ""), save=args.save)


def benchmark(scene: Path, runs: int, period: float, workers: int, title: str, *,
              save: bool = False) -> int:
    """Measure and print; 1 if the two modes disagree. ``save``: write the figures
    (``_results.save``)."""
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    warm_seed = 10_000
    cell = load_cell(scene)

    def local(seed: int) -> Plans:
        return plan_cell(cell, PlanOptions(planner=PlannerOptions(seed=seed)))

    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe()
    probe = ctx.Process(target=control, args=(child, period), daemon=True)
    probe.start()
    t0 = time.perf_counter()
    with RuntimePlanner(scene, workers=workers) as planner:
        planner.ready().result()
        startup = time.perf_counter() - t0
        # Warm both sides (lazy imports, first-use costs) out of the figures.
        planner.plan_cell(seed=warm_seed).result()
        local(warm_seed)
        worker = Mode("RuntimePlanner (worker)", lambda s: planner.plan_cell(seed=s).result())
        thread = Mode("in-process thread", on_thread(local))
        # Alternately: both modes see the same machine load. Seeds from 1: the worker
        # planned the cell with the default seed 0 while warming up (cached).
        for seed in range(1, runs + 1):
            worker.measure(seed, period)
            thread.measure(seed, period)
        # A request answered from the cache: the cost of going through the planner alone.
        round_trip = []
        for _ in range(20):
            t1 = time.perf_counter()
            planner.plan_cell(seed=warm_seed).result()
            round_trip.append(time.perf_counter() - t1)
    parent.send("stop")
    control_beats: list[tuple[float, float]] = parent.recv()
    probe.join()

    identical = all(same(a, b) for a, b in zip(worker.results, thread.results, strict=True))
    print(f"scene: {title}, {runs} plans of the cell per mode, heartbeat "
          f"period {period * 1000:.0f} ms, switch interval "
          f"{sys.getswitchinterval() * 1000:.0f} ms, {os.cpu_count()} CPUs")
    print(f"worker start-up (spawn, import, load, warm-up): {startup:.2f} s")
    print(f"{'':<25}{'plan latency':>17}{'heartbeat gap':>28}{'control gap':>28}")
    print(f"{'mode':<25}{'median':>9}{'p95':>8}"
          f"{'median':>10}{'p99':>9}{'max':>9}{'median':>10}{'p99':>9}{'max':>9}")

    def gap_columns(gaps: list[float]) -> str:
        return f"{ms(gaps, 50):>7.1f} ms{ms(gaps, 99):>6.1f} ms{max(gaps) * 1000:>6.1f} ms"

    for mode in (worker, thread):
        print(f"{mode.name:<25}{ms(mode.latencies, 50):>6.0f} ms{ms(mode.latencies, 95):>5.0f} ms"
              f"{gap_columns([g for _, g in mode.beats])}"
              f"{gap_columns(mode.inside(control_beats))}")
    print(f"a cached cell plan (3 trajectories, from the cache in this process): median"
          f" {ms(round_trip, 50):.1f} ms, max {max(round_trip) * 1000:.1f} ms")
    print(f"identical trajectories in both modes: {'yes' if identical else 'NO'}")
    if save:
        from _results import save as save_figures

        save_figures("runtime_heartbeat", {
            "scene": title, "runs": runs, "period_ms": period * 1000, "aim_gap_ms": 20.0,
            "identical": identical, "modes": {
                mode.name: {"heartbeat_gap_max_ms": max(g for _, g in mode.beats) * 1000,
                            "latency_median_ms": ms(mode.latencies, 50)}
                for mode in (worker, thread)}}, load_before=load_before)
    return 0 if identical else 1


if __name__ == "__main__":
    raise SystemExit(main())
