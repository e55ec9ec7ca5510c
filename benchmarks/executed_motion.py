"""Motion as a controller executes it: speed, acceleration and jerk ratios, motion time
against the jerk-free optimum, and the timing's compute time, with peers in the same run.

Problem sets, drawn afresh from ``--seed`` (and the bundled cells' own paths):

* ``cell``: every path :func:`safepath.timing.time_path` times while planning the
  bundled quality-check cell (Ned3 Pro) and pouring cell (Gen3 Lite), captured as they
  are timed (step speeds and TCP speed limits included);
* ``random``: ``--random`` polylines per robot (Ned3 Pro, Gen3 Lite, Panda, UR5) of 2-5
  waypoints within the joint limits, blends of 0-0.3 rad at the via points, full speed.

For each path:

* **safepath**: ``time_path`` (jerk-limited); its knots joined as ros2_control's
  joint_trajectory_controller joins a goal's points (a quintic per joint) and checked at
  every instant (:func:`safepath.model.execution.executed_peaks`);
* **jerk-free optimum**: TOPP-RA (safepath's kernel) on the same grid and limits without
  the jerk bound: the shortest motion without jerk limits (a lower bound);
* **toppra** (the library; random set, constant limits): ``TOPPRA([velocity,
  acceleration (interpolation)], ParametrizeConstAccel)``, sampled every 4 ms with
  position, velocity and acceleration, joined the same way;
* **safepath before** (``--before COMMIT``, default the last commit before jerk-limited
  timing; needs git, and compiles that version's kernels on first use, ~1 min): its
  ``time_path`` on the same random paths, joined the same way.

Printed: the worst and median executed ratios (v, a, j) of each, motion time over the
jerk-free optimum (median, p95, max) and compute time per path (median) against the
version before. Written to ``benchmarks/results/executed_motion.json``. The machine's load
is printed with the figures.

Run: ``.venv/bin/python benchmarks/executed_motion.py [--random 50] [--seed 0]
[--before be61fb6 | --before none]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

import safepath
from safepath.model.execution import executed_peaks
from safepath.planning import _chunks
from safepath.planning import pour as _pour
from safepath.timing import TimingOptions, _path_limits, _topp, spline_path, time_path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the references

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ("ned3pro", "gen3_lite", "panda", "ur5")
RESULTS = ROOT / "benchmarks" / "results" / "executed_motion.json"


def _ratios(robot: safepath.Robot, t: np.ndarray, q: np.ndarray, qd: np.ndarray,
            qdd: np.ndarray) -> tuple[float, float, float]:
    peaks = executed_peaks(t, q, qd, qdd)
    return peaks.ratios(robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)


def _optimum(robot: safepath.Robot, call: dict[str, Any]) -> float:
    """Duration of the jerk-free time-optimal motion (TOPP-RA, same grid and limits)."""
    options = call["options"]
    limits = _path_limits.path_limits(robot, call["path"], call["s_way"], call["scales"],
                                      call["tcp_speeds"], speed_scale=options.speed_scale,
                                      grid_step=options.grid_step, jerk_scale=1e30)
    x = _topp.solve(limits.grid, limits.at_grid.xmax, *limits.rows)
    return float("nan") if x is None else _topp.parametrize(limits.grid, x).duration


def _cell_calls() -> list[dict[str, Any]]:
    """The time_path calls of planning the two bundled cells."""
    calls: list[dict[str, Any]] = []

    def capture(robot, path, s_way, *, scales, tcp_speeds, options=None,  # noqa: ANN001, ANN202
                step=None):
        options = options or TimingOptions()
        calls.append(dict(robot=robot, path=path, s_way=s_way, scales=list(scales),
                          tcp_speeds=list(tcp_speeds), options=options, set="cell"))
        return time_path(robot, path, s_way, scales=scales, tcp_speeds=tcp_speeds,
                         options=options, step=step)

    with mock.patch.object(_chunks, "time_path", capture), \
            mock.patch.object(_pour, "time_path", capture):
        for name in ("quality_check_cell", "pouring_cell"):
            safepath.plan_cell(safepath.load_cell(ROOT / "scenes" / name),
                               safepath.PlanOptions())
    return calls


def _random_calls(robots: dict[str, safepath.Robot], n: int, seed: int
                  ) -> list[dict[str, Any]]:
    rng = np.random.default_rng(seed)
    calls = []
    for name, robot in robots.items():
        mid = (robot.lower + robot.upper) / 2
        half = np.minimum((robot.upper - robot.lower) / 2, np.pi) * 0.6
        for _ in range(n):
            pts = [mid + half * rng.uniform(-1, 1, robot.dof)
                   for _ in range(int(rng.integers(2, 6)))]
            corners = [(k, float(rng.choice([0.0, 0.1, 0.3]))) for k in range(1, len(pts) - 1)]
            path, s_way, _ = spline_path(pts, 0.06, corners=corners)
            calls.append(dict(robot=robot, path=path, s_way=s_way, scales=[1.0] * (len(pts) - 1),
                              tcp_speeds=[None] * (len(pts) - 1), options=TimingOptions(),
                              set="random", name=name, waypoints=np.array(pts),
                              corners=corners))
    return calls


def _ours(call: dict[str, Any]) -> dict[str, Any]:
    robot = call["robot"]
    t0 = time.perf_counter()
    piece = time_path(robot, call["path"], call["s_way"], scales=call["scales"],
                      tcp_speeds=call["tcp_speeds"], options=call["options"])
    elapsed = time.perf_counter() - t0
    return dict(duration=float(piece.t[-1]), compute=elapsed,
                ratios=_ratios(robot, piece.t, piece.q, piece.qd, piece.qdd))


def _toppra(call: dict[str, Any]) -> dict[str, Any] | None:
    """The toppra library on the same spline, constant limits, knots every 4 ms."""
    try:
        import logging

        import toppra.algorithm as algo
        import toppra.constraint as constraint
        from toppra_path import ToppraPath
    except ImportError:
        return None
    logging.getLogger("toppra").setLevel(logging.WARNING)
    robot, path = call["robot"], call["path"]
    breaks = path.x
    ta_path = ToppraPath(path, robot.dof)
    vlim = np.vstack([-robot.velocity_limits, robot.velocity_limits]).T
    alim = np.vstack([-robot.acceleration_limits, robot.acceleration_limits]).T
    cons = [constraint.JointVelocityConstraint(vlim),
            constraint.JointAccelerationConstraint(
                alim, discretization_scheme=constraint.DiscretizationType.Interpolation)]
    grid = _path_limits.gridpoints(breaks, call["s_way"], 0.005)
    t0 = time.perf_counter()
    traj = algo.TOPPRA(cons, ta_path, gridpoints=grid,
                       parametrizer="ParametrizeConstAccel").compute_trajectory()
    elapsed = time.perf_counter() - t0
    if traj is None:
        return None
    t = np.append(np.arange(0.0, traj.duration, 0.004), traj.duration)
    q, qd, qdd = traj(t), traj(t, 1), traj(t, 2)
    qd[0] = qd[-1] = 0.0
    return dict(duration=float(traj.duration), compute=elapsed,
                ratios=_ratios(robot, t, q, qd, qdd))


_BEFORE = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    import safepath
    from safepath.planning.timing import TimingOptions, spline_path, time_path
    data = np.load(sys.argv[1], allow_pickle=True)
    robots = {}
    out = []
    for name, pts, corners in zip(data["names"], data["waypoints"], data["corners"]):
        robot = robots.setdefault(str(name), safepath.load_robot(str(name)))
        path, s_way, _ = spline_path(list(pts), 0.06, corners=[tuple(c) for c in corners])
        n = len(pts) - 1
        time_path(robot, path, s_way, scales=[1.0] * n, tcp_speeds=[None] * n)  # warm
        t0 = time.perf_counter()
        piece = time_path(robot, path, s_way, scales=[1.0] * n, tcp_speeds=[None] * n)
        out.append(dict(compute=time.perf_counter() - t0, t=piece.t.tolist(),
                        q=piece.q.tolist(), qd=piece.qd.tolist(), qdd=piece.qdd.tolist()))
    json.dump(out, open(sys.argv[2], "w"))
""")


def _before(commit: str, calls: list[dict[str, Any]]) -> list[dict[str, Any]] | None:
    """The version at ``commit`` timing the random paths, in its own process."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "before"
        made = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f",
                               str(tree), commit], capture_output=True, text=True)
        if made.returncode != 0:
            print(f"  (safepath before: no worktree of {commit}: {made.stderr.strip()})")
            return None
        try:
            inputs, outputs = Path(tmp) / "in.npz", Path(tmp) / "out.json"
            np.savez(inputs, names=np.array([c["name"] for c in calls]),
                     waypoints=np.array([c["waypoints"] for c in calls], dtype=object),
                     corners=np.array([c["corners"] for c in calls], dtype=object))
            env = {**os.environ, "PYTHONPATH": str(tree)}
            run = subprocess.run([sys.executable, "-c", _BEFORE, str(inputs), str(outputs)],
                                 env=env, capture_output=True, text=True, cwd=tmp)
            if run.returncode != 0:
                print(f"  (safepath before failed: {run.stderr.strip().splitlines()[-1:]})")
                return None
            raw = json.loads(outputs.read_text())
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(tree)], capture_output=True)
    out = []
    for call, r in zip(calls, raw, strict=True):
        arrays = [np.asarray(r[k]) for k in ("t", "q", "qd", "qdd")]
        out.append(dict(duration=float(arrays[0][-1]), compute=r["compute"],
                        ratios=_ratios(call["robot"], *arrays)))
    return out


def _summary(rows: list[dict[str, Any]], optimum: list[float]) -> dict[str, Any]:
    ratios = np.array([r["ratios"] for r in rows])
    over = np.array([r["duration"] / o for r, o in zip(rows, optimum, strict=True)
                     if np.isfinite(o) and o > 0])
    return {"paths": len(rows),
            "worst_ratios_v_a_j": ratios.max(axis=0).round(4).tolist(),
            "median_ratios_v_a_j": np.median(ratios, axis=0).round(4).tolist(),
            "over_limit_paths": int(np.sum(ratios.max(axis=1) > 1.0 + 1e-9)),
            "time_over_optimum": {"median": round(float(np.median(over)), 4),
                                  "p95": round(float(np.percentile(over, 95)), 4),
                                  "max": round(float(over.max()), 4)},
            "compute_ms_median": round(1e3 * statistics.median(r["compute"] for r in rows), 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random", type=int, default=50, help="random paths per robot")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--before", default="be61fb6",
                    help="commit of safepath before jerk-limited timing ('none': skip)")
    args = ap.parse_args()
    robots = {name: safepath.load_robot(name) for name in ROBOTS}
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.2f} / {os.getloadavg()[1]:.2f}")
    cell = _cell_calls()
    rand = _random_calls(robots, args.random, args.seed)
    for call in (cell + rand)[:3]:  # warm the kernels
        _ours(call)
    report: dict[str, Any] = {"seed": args.seed, "random_per_robot": args.random,
                              "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                              "load": os.getloadavg()[:2]}
    for label, calls in (("cell", cell), ("random", rand)):
        optimum = [_optimum(c["robot"], c) for c in calls]
        ours = [_ours(c) for c in calls]
        report[f"{label}/safepath"] = _summary(ours, optimum)
        if label == "random":
            for name in ROBOTS:
                idx = [i for i, c in enumerate(calls) if c["name"] == name]
                report[f"random/{name}/safepath"] = _summary([ours[i] for i in idx],
                                                             [optimum[i] for i in idx])
            peers = [_toppra(c) for c in calls]
            if all(p is not None for p in peers):
                report["random/toppra"] = _summary(peers, optimum)  # type: ignore[arg-type]
            if args.before != "none":
                before = _before(args.before, calls)
                if before is not None:
                    report["random/safepath_before"] = _summary(before, optimum)
                    report["compute_vs_before"] = round(
                        report["random/safepath"]["compute_ms_median"]
                        / report["random/safepath_before"]["compute_ms_median"], 3)
    print(f"{'set/timing':32} {'paths':>5} {'worst v / a / j (executed)':>28} "
          f"{'over':>4} {'time/optimum med / p95 / max':>30} {'ms':>7}")
    for key, s in report.items():
        if not isinstance(s, dict) or "paths" not in s:
            continue
        w, t = s["worst_ratios_v_a_j"], s["time_over_optimum"]
        print(f"{key:32} {s['paths']:5d} {w[0]:8.4f} {w[1]:8.4f} {w[2]:9.4f} "
              f"{s['over_limit_paths']:5d} {t['median']:10.3f} {t['p95']:8.3f} {t['max']:8.3f}"
              f" {s['compute_ms_median']:8.2f}")
    if "compute_vs_before" in report:
        print(f"timing compute, median per random path: {report['compute_vs_before']:.2f}x "
              f"the version before ({args.before})")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(report, indent=1) + "\n")
    import figures  # benchmarks/figures.py, beside this script: the table the README links

    print(f"written to {RESULTS.relative_to(ROOT)} and {figures.write()}")


if __name__ == "__main__":
    main()
