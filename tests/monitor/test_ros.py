"""ROS 2 wiring of the monitor: CDR round trips, bags, the node's parameters and lifecycle."""

from __future__ import annotations

import py_compile
from pathlib import Path

import numpy as np
import pytest
from quintic_join import quintic_state

from safepath import Cell
from safepath.errors import ConfigError
from safepath.monitor import Cloud, ObservationError, Scan
from safepath.monitor.node import (
    Gripper,
    MonitorNodeCore,
    Publish,
    SendGoal,
    load_node_parameters,
    parameters_from_mapping,
)
from safepath.monitor.ros import (
    GOAL_TOPIC,
    REPLACEMENT_TOPIC,
    MonitorRecorder,
    MonitorRun,
    cloud_message,
    read_monitor_bag,
    scan_message,
)
from safepath.monitor.simulation import MovingSphere, simulate
from safepath.ros.bag import read_bag
from safepath.ros.messages import deserialize, serialize, typestore

from .conftest import CAMERA, BoxOnRoute, NodeCoreFactory, Phase1, make_monitor

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "ros2"


def _round_trip(msg, typename: str):  # noqa: ANN001, ANN202
    return deserialize(serialize(msg, typename), typename)


def test_scan_cdr_round_trip_keeps_every_reading() -> None:
    ranges = np.array([1.0, np.inf, -np.inf, np.nan, 0.01, 9.0, 2.5])
    scan = Scan(12.25, "laser", ranges, -0.3, 0.1, 0.05, 8.0)
    back = Scan.from_ros(_round_trip(scan_message(scan), "sensor_msgs/msg/LaserScan"))
    assert back.stamp == pytest.approx(12.25) and back.frame_id == "laser"
    np.testing.assert_array_equal(back.ranges, ranges.astype(np.float32))
    P, counts = back.points()
    assert (counts.used, counts.no_return, counts.too_close, counts.nan, counts.invalid) == \
        (3, 2, 1, 1, 1)
    np.testing.assert_allclose(np.linalg.norm(P, axis=1), [1.0, 0.05, 2.5], rtol=1e-6)


def test_cloud_cdr_round_trip_and_big_endian_float64() -> None:
    rng = np.random.default_rng(3)
    P = rng.normal(size=(50, 3))
    P[7] = np.nan
    cloud = Cloud(3.5, "cam", P)
    back = Cloud.from_ros(_round_trip(cloud_message(cloud), "sensor_msgs/msg/PointCloud2"))
    np.testing.assert_allclose(back.points, P.astype(np.float32), equal_nan=True)
    assert back.valid_points()[1].nan == 1
    # A float64, big-endian cloud with padding (x, pad, y, z; 32-byte points, 2 rows).
    T = typestore().types
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=8, count=1)
              for n, o in (("x", 0), ("y", 16), ("z", 24))]
    Q = rng.normal(size=(4, 3))
    raw = np.zeros((4, 4), dtype=">f8")
    raw[:, 0], raw[:, 2], raw[:, 3] = Q[:, 0], Q[:, 1], Q[:, 2]
    header = scan_message(Scan(0.0, "cam", np.zeros(1), 0.0, 0.0, 0.0, 1.0)).header
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=header, height=2, width=2, fields=fields, is_bigendian=True, point_step=32,
        row_step=64, data=raw.view(np.uint8).ravel(), is_dense=True)
    np.testing.assert_array_equal(Cloud.from_ros(_round_trip(msg, "sensor_msgs/msg/PointCloud2")
                                                 ).points, Q)
    empty = Cloud.from_ros(_round_trip(cloud_message(Cloud(1.0, "cam", np.zeros((0, 3)))),
                                       "sensor_msgs/msg/PointCloud2"))
    assert empty.points.shape == (0, 3)
    bad = T["sensor_msgs/msg/PointCloud2"](
        header=header, height=2, width=2, fields=fields, is_bigendian=True, point_step=32,
        row_step=64, data=raw.view(np.uint8).ravel()[:-8], is_dense=True)
    with pytest.raises(ObservationError, match="bytes"):
        Cloud.from_ros(bad)
    no_z = T["sensor_msgs/msg/PointCloud2"](
        header=header, height=2, width=2, fields=fields[:2], is_bigendian=True,
        point_step=32, row_step=64, data=raw.view(np.uint8).ravel(), is_dense=True)
    with pytest.raises(ObservationError, match="no 'z' field"):
        Cloud.from_ros(no_z)


def test_malformed_laser_scan_message() -> None:
    msg = scan_message(Scan(1.0, "laser", np.ones(10), 0.0, 0.1, 0.05, 8.0))
    msg.angle_max = 3.0  # 10 beams by 0.1 rad cannot end at 3 rad
    with pytest.raises(ObservationError, match="angle_max"):
        Scan.from_ros(_round_trip(msg, "sensor_msgs/msg/LaserScan"))


def test_a_recorded_run_replays_from_its_bag(cell: Cell, phase1: Phase1, tmp_path: Path
                                             ) -> None:
    monitor = make_monitor(cell, hold_time=0.3)
    recorder = MonitorRecorder(monitor.options, cell.robot.joint_names, topics={"cam": "/points"})
    target = np.array([0.33, 0.30, 0.30])
    obstacle = MovingSphere.approach(target + [0.8, 0, 0], target, 1.6, 0.2, 0.7, leave_at=1.2)
    res = simulate(monitor, list(phase1.motions), obstacle, sensor="cam", sensor_pose=CAMERA,
                   until=2.5, recorder=recorder)
    path = recorder.write(tmp_path / "run")
    with pytest.raises(Exception, match="exists"):
        recorder.write(path)
    run = read_monitor_bag(path)
    assert [d["kind"] for d in run.decisions] == [d.kind for d in res.decisions]
    assert len(run.observations) == len(res.decisions)
    np.testing.assert_allclose(run.sensors["cam"], CAMERA)
    # The observed points lie on the obstacle where it truly was when captured.
    k = len(run.observations) // 2
    assert run.observation_times[k] - run.observation_stamps[k] == pytest.approx(0.01, abs=0.0041)
    centre = obstacle.at(run.observation_stamps[k])
    r = np.linalg.norm(run.observations[k] - centre, axis=1)
    np.testing.assert_allclose(r, obstacle.radius, atol=1e-5)
    assert run.joint_positions.shape[1] == 6 and len(run.truth) == len(run.joint_times)
    assert run.parameters["approach_speed"] == 1.6
    _goals_continue_and_are_what_ran(path, run)


def _goals_continue_and_are_what_ran(path: Path, run: MonitorRun) -> None:
    """The bag's goals (the motions sent whole and the replacements), each taken at its
    stamp and joined by an independent quintic, continue one another exactly and are
    the motion the recorded joint states followed."""
    contents = read_bag(path)
    goals = []
    for m in sorted(contents.on(GOAL_TOPIC) + contents.on(REPLACEMENT_TOPIC),
                    key=lambda m: m.timestamp):
        stamp = m.msg.header.stamp.sec + m.msg.header.stamp.nanosec * 1e-9
        pts = m.msg.points
        t = stamp + np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                              for p in pts])
        goals.append((stamp, t, *(np.array([getattr(p, k) for p in pts])
                                  for k in ("positions", "velocities", "accelerations"))))
    assert len(contents.on(GOAL_TOPIC)) >= 1 and len(goals) >= 3
    for prev, nxt in zip(goals, goals[1:], strict=False):
        state = quintic_state(*prev[1:], nxt[0])
        first = int(np.searchsorted(nxt[1], nxt[0] - 1e-6))
        for x, s in zip((nxt[2], nxt[3], nxt[4]), state, strict=True):
            np.testing.assert_allclose(x[first], s, atol=1e-6)
    stamps = np.array([g[0] for g in goals])
    for time, q in zip(run.joint_times, run.joint_positions, strict=True):
        g = goals[int(np.searchsorted(stamps, time + 1e-9, side="right")) - 1]
        np.testing.assert_allclose(q, quintic_state(*g[1:], time)[0], atol=1e-6)


def test_example_parameters_validate_and_errors_name_the_key(tmp_path: Path) -> None:
    params = load_node_parameters(EXAMPLES / "monitor_params.yaml")
    assert params.route == "phase1" and params.options.approach_speed == 1.6
    np.testing.assert_allclose(params.options.sensors["laser"][:3, 3], [0.9, 0.6, 0.25])
    with pytest.raises(ConfigError, match="approach_spede"):
        parameters_from_mapping({"scene": "x", "approach_spede": 1.0})
    with pytest.raises(ConfigError, match="stale_after"):
        parameters_from_mapping({"scene": "x", "stale_after": -1.0})
    with pytest.raises(ConfigError, match="scan_xyz"):
        parameters_from_mapping({"scene": "x", "scan_xyz": [0, 0]})
    bad = tmp_path / "p.yaml"
    bad.write_text("other_node:\n  ros__parameters: {}\n")
    with pytest.raises(ConfigError, match="safepath_monitor"):
        load_node_parameters(bad)


def test_node_core_lifecycle(cell_dir: Path, node_core: NodeCoreFactory) -> None:
    params = parameters_from_mapping({"scene": str(cell_dir), "route": "phase1",
                                      "scan_frame": "laser", "scan_xyz": [0.9, 0.6, 0.25],
                                      "stale_after": 0.15})
    core = MonitorNodeCore(params)
    scan = scan_message(Scan(0.0, "laser", np.full(360, np.inf), -np.pi, np.pi / 180, 0.05, 8))
    assert core.on_scan(scan, 0.0) == []  # unconfigured: ignored
    with pytest.raises(ConfigError, match="activate"):
        core.activate(0.0)
    core.configure()
    assert core.state == "inactive" and [h for _, h in core.motions] == ["vial", None]
    # phase 1 starts with "close vial": the gripper first, then the first motion.
    first = core.activate(10.0)
    assert isinstance(first[0], Gripper) and first[0].event.action == "close"
    # The motion is assessed before it is sent: with no scan yet (sensor silence) it
    # waits at its start; after a fresh scan it is sent.
    held = core.on_gripper_done(10.5)
    assert len(held) == 1 and isinstance(held[0], Publish)
    assert held[0].decision.kind == "stop" and "waits at its start" in held[0].decision.reason
    scan = scan_message(Scan(10.45, "laser", np.full(360, np.inf), -np.pi, np.pi / 180,
                             0.05, 8))
    core = node_core(params)
    core.activate(10.0)
    core.on_scan(_round_trip(scan, "sensor_msgs/msg/LaserScan"), 10.46)
    move = core.on_gripper_done(10.5)
    assert isinstance(move[0], SendGoal) and move[0].trajectory is core.motions[0][0]
    scan = scan_message(Scan(10.55, "laser", np.full(360, np.inf), -np.pi, np.pi / 180,
                             0.05, 8))
    out = core.on_scan(_round_trip(scan, "sensor_msgs/msg/LaserScan"), 10.56)
    assert len(out) == 1 and isinstance(out[0], Publish) and out[0].decision.kind == "continue"
    silent = core.on_tick(10.8)  # no scan for 0.25 s > 0.15 s
    # A stop's goal is the first command, then its decision.
    assert isinstance(silent[0], SendGoal) and silent[0].reason == "stop"
    assert isinstance(silent[1], Publish) and silent[1].decision.kind == "stop"
    stop = core.deactivate(10.81)
    assert core.state == "inactive" and isinstance(stop[-1], Publish)
    assert stop[-1].decision.latched
    assert core.on_tick(10.9) == [] and core.on_scan(scan, 10.9) == []
    assert core.activate(11.0) == []
    t = 11.0
    kinds = []
    for _ in range(40):
        t += 0.05
        scan = scan_message(Scan(t, "laser", np.full(360, np.inf), -np.pi, np.pi / 180, 0.05, 8))
        kinds += [c.decision.kind for c in core.on_scan(scan, t) if isinstance(c, Publish)]
    assert "resume" in kinds  # released, clear for the hold time: moves on


def test_example_monitor_node_compiles(tmp_path: Path) -> None:
    py_compile.compile(str(EXAMPLES / "monitor_node.py"), cfile=str(tmp_path / "n.pyc"),
                       doraise=True)


@pytest.mark.parametrize("found", [True, False])
def test_node_core_replans_around_an_obstacle_that_stays(cell_dir: Path, found: bool) -> None:
    from safepath.monitor.node import Replan
    from safepath.monitor.replan import replan

    box = BoxOnRoute(cell_dir)
    core = box.core
    request = None
    t = 0.0
    while request is None and t < 8.0:
        t = round(t + 1 / 30, 6)
        request = next((c for c in box.scan(t) if isinstance(c, Replan)), None)
    assert request is not None and request.held == "vial" and request.route == "phase1"
    if not found:  # the planner found no way: stopped, saying why
        assert core.on_replan_failed(request.request, "no way (test)", t) == []
        t = round(t + 1 / 30, 6)
        published = [c for c in box.scan(t) if not isinstance(c, Replan)]
        decision = published[0].decision  # type: ignore[attr-defined]
        assert decision.kind == "stop" and "no way (test)" in decision.reason
        return
    traj = replan(core.monitor.cell, request.route, request.request,  # type: ignore[union-attr]
                  held=request.held, margin=request.margin)
    out = core.on_replanned(request.request, traj, t)
    assert isinstance(out[0], SendGoal)
    np.testing.assert_allclose(out[0].trajectory.q[0], request.request.q, atol=1e-9)
