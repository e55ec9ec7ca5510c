"""The monitor's core: odd readings, silence, kill switch, re-timing within the limits."""

from __future__ import annotations

import numpy as np
import pytest
from quintic_join import quintic_peaks as _quintic_peaks

from safepath import Cell
from safepath.collision.spheres import surface_points
from safepath.errors import ConfigError, InputError
from safepath.monitor import Cloud, MonitorOptions, ObservationError, Obstacles, Scan
from safepath.monitor.sweep import PathSweep, RobotSpheres

from .conftest import CAMERA, Phase1, make_monitor


def _scan(stamp: float, ranges: np.ndarray) -> Scan:
    n = ranges.size
    return Scan(stamp, "cam", ranges, -np.pi, 2 * np.pi / n, 0.05, 8.0)


def _world_to_cam(points: np.ndarray) -> np.ndarray:
    return (points - CAMERA[:3, 3]) @ CAMERA[:3, :3]


def test_all_inf_scan_continues_and_nan_is_counted(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    d = m.observe(_scan(0.0, np.full(360, np.inf)), 0.01)
    assert d.kind == "continue" and d.scale == 1.0 and d.replacement is None
    assert d.counts.no_return == 360 and d.counts.used == 0
    assert d.separation_now == np.inf
    ranges = np.full(360, np.inf)
    ranges[:40] = np.nan
    d = m.observe(_scan(0.03, ranges), 0.04)
    assert d.kind == "continue" and d.counts.nan == 40 and d.counts.used == 0
    # An empty scan and an empty cloud are valid observations that see nothing.
    empty = Scan(0.05, "cam", np.zeros(0), -np.pi, 0.01, 0.05, 8.0)
    assert m.observe(empty, 0.05).kind == "continue"
    d = m.observe(Cloud(0.06, "cam", np.zeros((0, 3))), 0.06)
    assert d.kind == "continue" and d.counts.used == 0 and d.separation_now == np.inf


def _protective_distance(cell: Cell, phase1: Phase1, at: float) -> float:
    """The motion's protective distance at full speed at time ``at`` [m]: what the
    monitor tests a reading far from the robot (a point 3 m out) against."""
    m = make_monitor(cell)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    d = m.observe(Cloud(at, "cam", _world_to_cam(np.array([[3.0, 0.3, 0.4]]))), at)
    assert d.kind == "continue" and d.separation_kept > d.protective_distance > 0.0
    return d.protective_distance


def test_close_reading_stops_and_neg_inf_counts_as_too_close(cell: Cell, phase1: Phase1
                                                             ) -> None:
    # The camera moved out along +x so that the point 0.05 m in front of it (range_min)
    # lies about 0.1 m beyond the motion's own protective distance: far, the robot
    # continues (the separation grows by at most the shift).
    traj, held = phase1.motions[0]
    probe = make_monitor(cell)
    probe.follow(traj, start=0.0, held=held)
    point = CAMERA[:3, 3] + CAMERA[:3, 0] * 0.05
    sep = probe.observe(Cloud(0.5, "cam", _world_to_cam(point[None, :])), 0.5).separation_kept
    camera = CAMERA.copy()
    camera[0, 3] += max(0.0, _protective_distance(cell, phase1, 0.5) + 0.1 - sep)
    m = make_monitor(cell, sensors={"cam": camera})
    m.follow(traj, start=0.0, held=held)
    m.observe(_scan(0.0, np.full(360, np.inf)), 0.0)
    ranges = np.full(360, np.inf)
    ranges[180] = -np.inf  # beam along +x of the camera: something at range_min
    d = m.observe(_scan(0.5, ranges), 0.5)
    assert d.counts.too_close == 1 and d.counts.used == 1
    assert d.separation_kept >= d.protective_distance + 0.05
    assert d.kind == "continue"
    # The same reading taken right beside the arm: it stops, along its path.
    q_now = traj.sample([0.55])[0][0]
    tcp = cell.robot.tcp_position(q_now)
    near = Cloud(0.55, "cam", (tcp[None, :] + [0.12, 0.0, 0.0] - camera[:3, 3]) @ camera[:3, :3])
    d = m.observe(near, 0.55)
    assert d.kind == "stop" and d.scale == 0.0
    assert d.separation_now < d.protective_distance
    stop = d.replacement
    # Taken at the command latency after the decision, on the motion's next knot (the
    # controller's state there is the path's own).
    assert stop is not None and d.replacement_start is not None
    assert 0.57 - 1e-9 <= d.replacement_start <= 0.57 + traj.t[1] - traj.t[0] + 1e-9
    assert np.isclose(np.min(np.abs(traj.t - d.replacement_start)), 0.0, atol=1e-9)
    assert np.all(stop.qd[-1] == 0.0)
    _assert_on_path_within_limits(cell, traj, stop)


def test_sensor_silence_stops(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    assert m.observe(_scan(0.0, np.full(360, np.inf)), 0.0).kind == "continue"
    assert m.tick(0.05).kind == "continue"
    d = m.tick(0.07)  # 70 ms of silence > stale_after (60 ms)
    assert d.kind == "stop" and "silence" in d.reason and d.replacement is not None
    # A stale observation does not count as the sensor speaking.
    d = m.observe(_scan(0.0, np.full(360, np.inf)), 0.2)
    assert d.kind == "stop" and m.stats["stale"] == 1


def test_malformed_message_keeps_the_last_decision(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    first = m.observe(_scan(0.0, np.full(360, np.inf)), 0.0)
    with pytest.raises(ObservationError, match="range_max"):
        m.observe(Scan(0.01, "cam", np.ones(360), -np.pi, 0.01, 1.0, 0.5), 0.01)
    with pytest.raises(ObservationError, match="unknown frame 'lidar'"):
        m.observe(Cloud(0.02, "lidar", np.zeros((1, 3))), 0.02)
    with pytest.raises(ObservationError, match="future"):
        m.observe(Cloud(1.0, "cam", np.zeros((1, 3))), 0.02)
    with pytest.raises(ObservationError, match="shape"):
        Cloud(0.02, "cam", np.zeros((4, 2)))
    assert m.last is first and m.stats["malformed"] == 2
    # Out of order: ignored, counted, decided on what it had.
    m.observe(_scan(0.03, np.full(360, np.inf)), 0.03)
    m.observe(_scan(0.02, np.zeros(360)), 0.035)
    assert m.stats["out_of_order"] == 1 and m.last.kind == "continue"


def test_kill_switch_latches_until_reset(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell, hold_time=0.1)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    m.observe(_scan(0.0, np.full(360, np.inf)), 0.0)
    d = m.kill(0.8)
    assert d.kind == "stop" and d.latched and d.replacement is not None
    _assert_on_path_within_limits(cell, traj, d.replacement)
    t = 0.8
    for _ in range(10):  # clear for longer than the hold time: still latched
        t += 0.03
        d = m.observe(_scan(t, np.full(360, np.inf)), t)
        assert d.kind == "stop" and d.latched and d.replacement is None
    m.reset()
    kinds = []
    for _ in range(8):
        t += 0.03
        kinds.append(m.observe(_scan(t, np.full(360, np.inf)), t).kind)
    assert kinds[0] == "stop" and "resume" in kinds
    resume = m.last if m.last.kind == "resume" else None
    assert not m.last.latched and (resume is None or resume.replacement is not None)


def test_user_obstacles_box_and_sphere(cell: Cell, phase1: Phase1) -> None:
    traj, held = phase1.motions[0]
    protective = _protective_distance(cell, phase1, 0.0)
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 0.2]
    m = make_monitor(cell, sensors={})
    m.follow(traj, start=0.0, held=held)
    # Along +x the box's separation from the robot grows as fast as the box moves (the
    # robot's nearest point is behind it): a box 3 m out shows where to put one a given
    # separation away.
    beyond = m.observe(Obstacles(0.0, boxes=((T, [0.1, 0.1, 0.1]),)), 0.0).separation_kept
    # A box 0.1 m beyond the motion's protective distance (a sphere behind it): continue.
    T[0, 3] -= beyond - (protective + 0.1)
    m = make_monitor(cell, sensors={})
    m.follow(traj, start=0.0, held=held)
    d = m.observe(Obstacles(0.0, spheres=[[T[0, 3] + 0.3, 0.0, 0.2, 0.05]],
                            boxes=((T, [0.1, 0.1, 0.1]),)), 0.0)
    assert d.kind == "continue" and d.counts.used > 1
    assert np.isclose(d.separation_now, protective + 0.1, atol=1e-3)
    assert d.separation_kept >= d.protective_distance
    # The same box at half the protective distance: no speed keeps it, stop.
    T[0, 3] -= 0.5 * protective + 0.1
    d = m.observe(Obstacles(0.01, boxes=((T, [0.1, 0.1, 0.1]),)), 0.01)
    assert d.kind == "stop" and d.separation_kept < d.protective_distance
    with pytest.raises(ObservationError, match="boxes"):
        Obstacles(0.0, boxes=((T, [0.1, -1.0, 0.1]),))


def test_scene_points_are_filtered(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    # Points on the table top and the conveyor: the static scene, ignored.
    rng = np.random.default_rng(1)
    table = np.column_stack([rng.uniform(0.0, 0.8, 200), rng.uniform(-0.2, 0.8, 200),
                             np.zeros(200)])
    d = m.observe(Cloud(0.0, "cam", _world_to_cam(table)), 0.0)
    assert d.counts.scene == 200 and d.counts.used == 0 and d.kind == "continue"


def test_options_are_validated() -> None:
    with pytest.raises(ConfigError, match="approach_speed"):
        MonitorOptions(approach_speed=0.0)
    with pytest.raises(ConfigError, match="sensors.cam"):
        MonitorOptions(sensors={"cam": np.zeros((4, 4))})
    with pytest.raises(ConfigError, match="workspace"):
        MonitorOptions(workspace=(0, 0, 0, -1, 1, 1))


def test_follow_refuses_events_inside(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell)
    with pytest.raises(InputError, match="gripper event"):
        m.follow(phase1.trajectory, start=0.0)


def test_spheres_enclose_the_links_and_bound_the_separation(cell: Cell, phase1: Phase1
                                                            ) -> None:
    """Sample points on every moving link's surface at sampled path states: each lies
    inside a placed sphere, so sphere distances are lower bounds."""
    traj, held = phase1.motions[0]
    spheres = RobotSpheres.build(cell.robot, cell.scene, held, cell=0.04)
    sweep = PathSweep.build(cell.robot, spheres, traj.t, traj.q, spacing=0.01)
    assert sweep.spacing <= 0.0101
    rng = np.random.default_rng(0)
    import pinocchio as pin

    data = cell.robot.model.createData()
    geoms = [g for g in cell.robot.collision_model.geometryObjects if g.parentJoint != 0]
    for s in rng.choice(sweep.tau.size, 6, replace=False):
        q = traj.q[sweep.knot[s]]
        pin.forwardKinematics(cell.robot.model, data, q)
        C, R = sweep.centers[s], spheres.radii
        for g in geoms:
            local = surface_points(g.geometry, 200, rng)
            M = data.oMi[g.parentJoint].homogeneous @ g.placement.homogeneous
            world = local @ M[:3, :3].T + M[:3, 3]
            inside = np.linalg.norm(world[:, None, :] - C[None], axis=2) <= R[None] + 1e-9
            assert inside.any(axis=1).all(), g.name


def _assert_on_path_within_limits(cell: Cell, traj, rep) -> None:  # noqa: ANN001
    """Every knot of a replacement is a state of the verified motion, and the motion a
    controller executes from them (their quintic join at 1 kHz) is within the speed,
    acceleration and jerk limits."""
    robot = cell.robot
    # Positions: the verified motion's at the knots' path parameters, bit for bit.
    q, _, _ = traj.sample(np.asarray(rep.info["path_tau"]))
    assert np.array_equal(q, rep.q)
    assert np.all(np.diff(rep.info["path_tau"]) >= 0)  # along the path, never back
    peaks = _quintic_peaks(rep.t, rep.q, rep.qd, rep.qdd)
    for peak, limit in zip(peaks, (robot.velocity_limits, robot.acceleration_limits,
                                   robot.jerk_limits), strict=True):
        assert np.max(peak / limit) <= 1.0 + 1e-9


def test_silence_does_not_count_toward_a_replan(cell: Cell, phase1: Phase1) -> None:
    m = make_monitor(cell, replan_after=1.0)
    traj, held = phase1.motions[0]
    m.follow(traj, start=0.0, held=held)
    m.observe(_scan(0.0, np.full(360, np.inf)), 0.0)
    for k in range(1, 60):  # 2 s of silence: stopped
        assert m.tick(k / 30).kind in ("continue", "stop")
    assert m.last.kind == "stop" and "silence" in m.last.reason
    q_now = traj.sample([0.1])[0][0]
    near = _world_to_cam(cell.robot.tcp_position(q_now)[None, :] + [0.12, 0.0, 0.0])
    kinds = [m.observe(Cloud(2.0 + k / 30, "cam", near), 2.0 + k / 30).kind for k in range(45)]
    assert "replan" not in kinds[:29] and kinds.count("replan") == 1
    assert m.last.kind == "stop"


def test_self_filter_ignores_the_arm_itself(cell: Cell, phase1: Phase1) -> None:
    """A camera that sees the arm: without the self filter the monitor stops for the arm,
    with it the arm's own points are ignored and counted, and a point beside it is not."""
    import pinocchio as pin

    traj, held = phase1.motions[0]
    rng = np.random.default_rng(5)
    t = 1.6
    q = traj.sample([t])[0][0]
    data = cell.robot.model.createData()
    pin.forwardKinematics(cell.robot.model, data, q)
    pts = []
    for g in cell.robot.collision_model.geometryObjects:
        if g.parentJoint == 0:
            continue
        M = data.oMi[g.parentJoint].homogeneous @ g.placement.homogeneous
        pts.append(surface_points(g.geometry, 40, rng) @ M[:3, :3].T + M[:3, 3])
    arm = np.vstack(pts)
    decisions = {}
    for self_filter in (None, 0.0):
        m = make_monitor(cell, self_filter=self_filter)
        m.follow(traj, start=0.0, held=held)
        decisions[self_filter] = m.observe(Cloud(t, "cam", _world_to_cam(arm)), t)
    assert decisions[None].kind == "stop"
    d = decisions[0.0]
    assert d.kind == "continue" and d.counts.robot == len(arm)
    m = make_monitor(cell, self_filter=0.0)
    m.follow(traj, start=0.0, held=held)
    tcp = cell.robot.tcp_position(q)
    outward = np.array([tcp[0], tcp[1], 0.0]) / np.linalg.norm(tcp[:2])
    beside = np.vstack([arm, tcp + 0.12 * outward])  # 12 cm out from the gripper
    d = m.observe(Cloud(t, "cam", _world_to_cam(beside)), t)
    assert d.counts.robot == len(arm) and d.kind == "stop"


_FIRST_STOP = """
import sys
import numpy as np
import safepath
from safepath.monitor import Cloud, Monitor, MonitorOptions
from safepath.ros import split_at_gripper_events
cell = safepath.load_cell({scene!r})
routes = safepath.load_routes(cell.folder / "routes.yaml", poses=list(cell.poses),
                              objects=list(cell.scene.objects))
traj = safepath.plan_cell(cell, safepath.PlanOptions(), routes={{"phase1": routes["phase1"]}})
motion = [m for m in split_at_gripper_events(traj["phase1"])
          if isinstance(m, safepath.Trajectory)][0]
m = Monitor(cell, MonitorOptions(sensors={{"cam": np.eye(4)}}, stale_after=0.06))
m.follow(motion, start=0.0, held="vial")
assert m.observe(Cloud(0.0, "cam", np.array([[3.0, 0.3, 0.4]])), 0.0).kind == "continue"
before = set(sys.modules)
tcp = cell.robot.tcp_position(motion.sample([0.03])[0][0])
d = m.observe(Cloud(0.03, "cam", tcp[None, :] + [[0.12, 0.0, 0.0]]), 0.03)
print(d.kind, sorted(set(sys.modules) - before))
"""


def test_a_first_stop_loads_no_module(cell: Cell) -> None:
    """The first stop of a process decides and hands out its stop without importing
    anything: the body that blocks the robot, which a stop records before it leaves
    (for the re-plan's rest rule), is found by a compiled search loaded with the monitor.
    (It imported scipy's k-d tree and graph modules there, about 0.36 s.)"""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _FIRST_STOP.format(scene=str(cell.folder))],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    assert out.strip().splitlines()[-1] == "stop []", out
