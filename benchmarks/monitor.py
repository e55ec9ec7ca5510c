#!/usr/bin/env python3
"""Speed and separation monitoring: decision latency, and the closest approach in closed loop.

Latency: the Ned3 Pro follows motion 1 of the quality-check cell's phase 1 (vial held)
while a person-sized obstacle walks from 1.6 m to 0.3 m of the arm and back. Every
decision is one ``Monitor.observe`` call on a deserialized ROS 2 message (CDR bytes ->
``rosbags`` message -> decision, replacement trajectory included when the speed
changes), for

* a 360-beam ``sensor_msgs/LaserScan`` (legs of the person, the cell's walls 2.5 m out);
* a 5,000-point ``sensor_msgs/PointCloud2`` (the side of the person facing the camera).

One core: numba kernels are single-threaded and BLAS is limited to one thread here.
Aim (issue 13): median <= 5 ms, p99 <= 10 ms per decision.

Closed loop: :func:`safepath.monitor.simulation.simulate` with an obstacle approaching
the high1 -> high2 sweep at several speeds (camera cloud, 30 Hz, 10 ms latency); the
closest approach is measured by python-fcl on the robot's collision geometry against
the obstacle's true position at every 4 ms sample.

Usage::

    .venv/bin/python benchmarks/monitor.py
    .venv/bin/python benchmarks/monitor.py --decisions 100 --speeds 1.6 --bag out/monitor_run
    .venv/bin/python -m safepath.view.monitor_replay out/monitor_run   # http://127.0.0.1:8080
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from safepath import PlanOptions, Trajectory, load_cell, load_routes, plan_cell  # noqa: E402
from safepath.monitor import Monitor, MonitorOptions  # noqa: E402
from safepath.monitor.simulation import FclSeparation, MovingSphere, simulate  # noqa: E402
from safepath.ros import split_at_gripper_events  # noqa: E402
from safepath.ros.messages import deserialize, serialize, typestore  # noqa: E402

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"
CAMERA = np.eye(4)
CAMERA[:3, 3] = [1.2, 0.3, 0.4]
LIDAR = np.eye(4)
LIDAR[:3, 3] = [0.9, 0.6, 0.25]
TARGET = np.array([0.33, 0.30, 0.30])


def _header(ts: object, stamp: float, frame: str) -> object:
    sec = int(np.floor(stamp))
    time_ = ts.types["builtin_interfaces/msg/Time"](sec=sec,  # type: ignore[attr-defined]
                                                    nanosec=int(round((stamp - sec) * 1e9)))
    return ts.types["std_msgs/msg/Header"](stamp=time_, frame_id=frame)  # type: ignore[attr-defined]


def person_cloud(center: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points on the camera-facing side of a standing person (a capsule of radius
    0.18 m, 1.0 m tall about ``center``), in the camera frame [m]."""
    z = rng.uniform(-0.5, 0.5, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    P = np.column_stack([0.18 * np.cos(phi), 0.18 * np.sin(phi), z]) + center
    toward = CAMERA[:3, 3] - center
    back = (P - center) @ toward < 0
    P[back] = 2 * center - P[back]
    P[back, 2] = P[back, 2]
    return (P - CAMERA[:3, 3]) @ CAMERA[:3, :3]


def person_scan(center: np.ndarray) -> np.ndarray:
    """360 ranges: two legs (cylinders of radius 0.07 m) and walls 2.5 m out."""
    a = -np.pi + 2 * np.pi * np.arange(360) / 360
    d = np.column_stack([np.cos(a), np.sin(a)])
    r = np.full(360, 2.5)
    for off in ([0.0, -0.12], [0.0, 0.12]):
        c = (center[:2] + off) - LIDAR[:2, 3]
        b = d @ c
        disc = b * b - (c @ c - 0.07 ** 2)
        hit = (disc >= 0) & (b > 0)
        r[hit] = np.minimum(r[hit], b[hit] - np.sqrt(disc[hit]))
    return r


def cloud_msg(ts: object, stamp: float, points: np.ndarray) -> bytes:
    T = ts.types  # type: ignore[attr-defined]
    fields = [T["sensor_msgs/msg/PointField"](name=c, offset=4 * k, datatype=7, count=1)
              for k, c in enumerate("xyz")]
    data = np.ascontiguousarray(points, dtype="<f4").view(np.uint8).ravel()
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=_header(ts, stamp, "cam"), height=1, width=len(points), fields=fields,
        is_bigendian=False, point_step=12, row_step=12 * len(points), data=data,
        is_dense=True)
    return serialize(msg, "sensor_msgs/msg/PointCloud2")


def scan_msg(ts: object, stamp: float, ranges: np.ndarray) -> bytes:
    T = ts.types  # type: ignore[attr-defined]
    inc = 2 * np.pi / 360
    msg = T["sensor_msgs/msg/LaserScan"](
        header=_header(ts, stamp, "lidar"), angle_min=-np.pi, angle_max=-np.pi + 359 * inc,
        angle_increment=inc, time_increment=0.0, scan_time=0.1, range_min=0.05,
        range_max=8.0, ranges=np.asarray(ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32))
    return serialize(msg, "sensor_msgs/msg/LaserScan")


def latency(cell: object, motion: Trajectory, kind: str, decisions: int,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Wall time and CPU time of this thread of each ``observe`` (deserialize + decide)
    [s]."""
    ts = typestore()
    sensor = {"cam": CAMERA} if kind == "cloud" else {"lidar": LIDAR}
    opts = MonitorOptions(sensors=sensor, stale_after=0.06)
    monitor = Monitor(cell, opts)  # type: ignore[arg-type]
    period = 1 / 30
    typename = "sensor_msgs/msg/PointCloud2" if kind == "cloud" else "sensor_msgs/msg/LaserScan"
    out: list[float] = []
    cpu: list[float] = []
    now = 0.0
    # Warm-up (numba compiles or loads its cache): one decision of each kind.
    monitor.follow(motion, start=now, held="vial")
    for dist in (1.6, 0.3):
        center = TARGET + [dist, 0.0, 0.0]
        data = cloud_msg(ts, now, person_cloud(center, 5000, rng)) if kind == "cloud" \
            else scan_msg(ts, now, person_scan(center))
        monitor.observe(deserialize(data, typename), now)
        now += period
    now += 1.0
    while len(out) < decisions:
        monitor = Monitor(cell, opts)  # type: ignore[arg-type]
        monitor.follow(motion, start=now, held="vial")
        run_start = now
        while now - run_start < motion.duration + 1.0 and len(out) < decisions:
            phase = (now - run_start) / (motion.duration + 1.0)
            dist = 0.3 + 1.3 * abs(1 - 2 * phase)  # 1.6 m -> 0.3 m -> 1.6 m
            center = TARGET + [dist, 0.0, 0.0]
            center[2] = 0.5
            if kind == "cloud":
                data = cloud_msg(ts, now, person_cloud(center, 5000, rng))
            else:
                data = scan_msg(ts, now, person_scan(center))
            t0, c0 = time.perf_counter(), time.thread_time()
            msg = deserialize(data, typename)
            monitor.observe(msg, now)
            cpu.append(time.thread_time() - c0)
            out.append(time.perf_counter() - t0)
            now += period
        now += 1.0
    return np.array(out), np.array(cpu)


def closed_loop(cell: object, motions: list[tuple[Trajectory, str | None]], speed: float,
                bag: Path | None = None) -> tuple[float, str, np.ndarray]:
    """Closest true approach [m], the decision kinds in order, decision times [s]; the run
    is written to ``bag`` (MCAP) when given."""
    from safepath.monitor.ros import MonitorRecorder

    monitor = Monitor(cell, MonitorOptions(sensors={"cam": CAMERA}, stale_after=0.06,  # type: ignore[arg-type]
                                           hold_time=0.5))
    recorder = None if bag is None else MonitorRecorder(
        monitor.options, cell.robot.joint_names, topics={"cam": "/camera/points"})  # type: ignore[attr-defined]
    t_stop = 0.2 + 1.0 / speed
    obstacle = MovingSphere.approach(TARGET + [1.0, 0, 0], TARGET, speed, 0.2, t_stop,
                                     leave_at=t_stop + 1.0)
    res = simulate(monitor, motions, obstacle, sensor="cam", sensor_pose=CAMERA,
                   until=t_stop + 1.0 + 1.0 / speed + 6.0, recorder=recorder)
    if recorder is not None and bag is not None:
        recorder.write(bag)
    seps = {h: FclSeparation(cell, h) for h in set(res.held)}  # type: ignore[arg-type]
    d = np.array([seps[h](q, c, obstacle.radius)
                  for q, c, h in zip(res.q, res.obstacle, res.held, strict=True)])
    kinds: list[str] = []
    for dec in res.decisions:
        if not kinds or kinds[-1] != dec.kind:
            kinds.append(dec.kind)
    return float(d.min()), " > ".join(kinds), np.array([x.elapsed for x in res.decisions])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--decisions", type=int, default=600, help="decisions per sensor")
    parser.add_argument("--speeds", type=float, nargs="*", default=[0.25, 0.5, 1.0, 1.6],
                        help="obstacle speeds of the closed-loop runs [m/s]")
    parser.add_argument("--bag", type=Path, default=None,
                        help="write the first closed-loop run to this MCAP bag (replay: "
                             "python -m safepath.view.monitor_replay BAG)")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/monitor.json and "
                             "rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    saved: dict[str, dict[str, float]] = {}
    cell = load_cell(SCENE)
    routes = load_routes(SCENE / "routes.yaml", poses=list(cell.poses),
                         objects=list(cell.scene.objects))
    phase1 = plan_cell(cell, PlanOptions(), routes={"phase1": routes["phase1"]})["phase1"]
    parts = [m for m in split_at_gripper_events(phase1) if isinstance(m, Trajectory)]
    motions: list[tuple[Trajectory, str | None]] = [(parts[0], "vial"), (parts[1], None)]
    rng = np.random.default_rng(0)
    print(f"machine load (1 min): {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          "one core for the monitor (single-threaded kernels, BLAS 1 thread)")
    print("decision latency (deserialize + observe + decide, replacement included) [ms]; "
          "wall clock, and CPU time of the deciding thread (what one core spends)")
    for kind, label in (("scan", "LaserScan, 360 beams"), ("cloud", "PointCloud2, 5,000 points")):
        wall, cpu = latency(cell, parts[0], kind, args.decisions, rng)
        for name, x in (("wall", wall * 1e3), ("cpu ", cpu * 1e3)):
            verdict = "met" if np.median(x) <= 5 and np.percentile(x, 99) <= 10 else "NOT met"
            print(f"  {label:26s} {name} n={x.size:4d}  median {np.median(x):6.2f}  p99 "
                  f"{np.percentile(x, 99):6.2f}  max {x.max():6.2f}  (aim 5 / 10: {verdict})")
            saved[f"{kind}_{name.strip()}_ms"] = {"median": float(np.median(x)),
                                                 "p99": float(np.percentile(x, 99))}
    print("closed loop, phase 1 (camera 30 Hz, v_h 1.6 m/s, C 0.05 m): closest true approach")
    for k, speed in enumerate(args.speeds):
        closest, kinds, el = closed_loop(cell, motions, speed, args.bag if k == 0 else None)
        print(f"  obstacle at {speed:4.2f} m/s: closest {closest * 1e3:6.1f} mm "
              f"(min separation 50 mm)  decisions median {np.median(el) * 1e3:.2f} ms: {kinds}")
        saved.setdefault("closest_mm", {})[f"{speed:.2f}"] = closest * 1e3
    if args.save:
        from _results import save

        save("monitor", {"decisions": args.decisions, "aim_median_ms": 5.0, "aim_p99_ms": 10.0,
                         "min_separation_mm": 50.0, **saved}, load_before=load_before)


if __name__ == "__main__":
    main()
