"""Re-plan latency on the warm runtime planner, and the monitor's decision time on clouds.

Re-plan: boxes parked on the bundled cell's transfer to the reject bin (phase2_unsafe,
step ``3 move unsafe...``), the robot at rest a fixed 30 % of the step before them (one of
the seven boxes reaches that rest state: its request fails, "start state is invalid",
and is counted, not timed); latency is from the request
(the monitor's ``replan`` decision) to the new trajectory in hand, whose first point is
the first point of the new goal. Clouds: a 30 Hz camera's clouds of 5,000 points beside
the lift of phase 1; the wall time of ``Monitor.observe`` per cloud.

Prints both with the machine's load (``os.getloadavg()``) and writes
``benchmarks/results/replan.json``.

    .venv/bin/python benchmarks/replan.py [--repeats 5] [--clouds 300]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

CELL = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"
OFFSETS = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.04), (0.0, 0.0, -0.04), (0.04, 0.0, 0.0),
           (-0.04, 0.0, 0.0), (0.0, 0.04, 0.0), (0.0, -0.04, 0.0)]


def _requests(cell, planned):  # noqa: ANN001, ANN202
    from safepath.monitor import ReplanRequest
    from safepath.monitor.replan import world_at

    traj = planned["phase2_unsafe"]
    step = "3 move unsafe+0.000,+0.000,+0.060"
    knots = np.flatnonzero(np.array([traj.steps[s] for s in traj.step_index]) == step)
    k_rest, k_box = int(knots[int(0.2 * knots.size)]), int(knots[knots.size // 2])
    world = world_at(cell, [planned["phase1"], traj], float(traj.t[k_rest]))
    out = []
    for offset in OFFSETS:
        center = cell.robot.tcp_position(traj.q[k_box]) + np.asarray(offset)
        out.append((ReplanRequest(float(traj.t[k_rest]), traj.q[k_rest].copy(),
                                  float(traj.t[k_rest]), step, center, np.full(3, 0.14)),
                    world))
    return out


def replan_latency(repeats: int) -> dict:
    from safepath import load_cell, plan_cell
    from safepath.runtime import RuntimePlanner

    cell = load_cell(CELL)
    planned = plan_cell(cell)
    latencies, failures = [], []
    with RuntimePlanner(CELL, spare=False) as planner:
        planner.ready().result()
        for seed in range(repeats):
            for request, world in _requests(cell, planned):
                t0 = time.perf_counter()
                future = planner.replan("phase2_unsafe", request, held=world.held, margin=0.03,
                                        world=world, seed=seed)
                try:
                    future.result()
                except Exception as exc:  # noqa: BLE001 - counted and printed
                    failures.append(str(exc)[:200])
                    continue
                latencies.append(time.perf_counter() - t0)
    lat = np.array(latencies) * 1000
    return {"requests": len(latencies) + len(failures), "found": len(latencies),
            "failures": failures,
            "latency_ms": {"median": float(np.median(lat)), "p90": float(np.percentile(lat, 90)),
                           "max": float(lat.max())} if lat.size else None}


def cloud_times(clouds: int, points: int) -> dict:
    from safepath import load_cell, plan_cell
    from safepath.model.trajectory import Trajectory
    from safepath.monitor import Cloud, Monitor, MonitorOptions
    from safepath.ros import split_at_gripper_events

    cell = load_cell(CELL)
    traj = plan_cell(cell, routes={"phase1": cell.route_table()["phase1"]})["phase1"]
    motion = [m for m in split_at_gripper_events(traj) if isinstance(m, Trajectory)][0]
    camera = np.eye(4)
    camera[:3, 3] = [1.2, 0.3, 0.4]
    monitor = Monitor(cell, MonitorOptions(sensors={"cam": camera}, stale_after=0.06))
    monitor.follow(motion, start=0.0, held="vial")
    rng = np.random.default_rng(0)
    wall, cpu = [], []
    for k in range(clouds):
        t = k / 30
        center = np.array([0.75, 0.0, 0.3])  # a person 0.5 m beside the lift
        pts = center + rng.normal(scale=0.12, size=(points, 3))
        cloud = Cloud(t, "cam", (pts - camera[:3, 3]) @ camera[:3, :3])
        w0, c0 = time.perf_counter(), time.process_time()
        monitor.observe(cloud, t + 0.01)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    w, c = np.array(wall[10:]) * 1000, np.array(cpu[10:]) * 1000
    return {"points": points, "clouds": len(w),
            "wall_ms": {"median": float(np.median(w)), "p99": float(np.percentile(w, 99))},
            "cpu_ms": {"median": float(np.median(c)), "p99": float(np.percentile(c, 99))}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--clouds", type=int, default=300)
    parser.add_argument("--points", type=int, default=5000)
    args = parser.parse_args()
    load_before = os.getloadavg()
    clouds = cloud_times(args.clouds, args.points)
    replan = replan_latency(args.repeats)
    result = {"when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "load_before": load_before, "load_after": os.getloadavg(),
              "cpus": os.cpu_count(), "replan": replan, "clouds": clouds}
    lat = replan["latency_ms"]
    print(f"load {load_before[0]:.2f} (1 min) on {os.cpu_count()} CPUs")
    print(f"re-plan: {replan['found']}/{replan['requests']} found; latency request -> "
          f"trajectory median {lat['median']:.0f} ms, p90 {lat['p90']:.0f} ms, "
          f"max {lat['max']:.0f} ms" if lat else "re-plan: none found")
    print(f"clouds of {clouds['points']} points: decision wall median "
          f"{clouds['wall_ms']['median']:.2f} ms, p99 {clouds['wall_ms']['p99']:.2f} ms; "
          f"CPU median {clouds['cpu_ms']['median']:.2f} ms, p99 {clouds['cpu_ms']['p99']:.2f} ms")
    out = Path(__file__).resolve().parent / "results" / "replan.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    import figures  # benchmarks/figures.py, beside this script: the table the README links

    print(f"written {out} and {figures.write()}")


if __name__ == "__main__":
    main()
