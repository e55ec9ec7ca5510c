"""Live obstacles: a body crossing the cell in MuJoCo, seen by ray-cast LaserScan and
PointCloud2 messages, MonitorNodeCore closed loop, and a kill just before a motion ends."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from safepath.errors import InputError
from safepath.monitor import Monitor, MonitorOptions
from safepath.monitor.node import MonitorNodeCore, NodeParameters
from safepath.sim.obstacles import (
    MovingBody,
    ObstacleRun,
    ObstacleTwin,
    SensorRig,
    cmd_obstacles,
    run_obstacles,
)


def test_the_monitor_slows_for_the_body_and_a_kill_stays_latched_through_a_motion_end(
        cell_dir: Path) -> None:
    run = run_obstacles(str(cell_dir), 0, duration=4.0, kill_before_end_of=0)
    # The sensors published, the node core decided on them: the body made it slow down.
    assert run.scans > 50 and run.clouds > 40
    assert "slow" in run.decisions
    # The true distance arm - body was measured (MuJoCo's geometry), the body outside the arm.
    assert 0.0 < run.closest <= run.closest_moving < 1.0
    # Killed 5 ms before the first motion's end; that motion (braked) ended after it, and
    # nothing followed: no gripper action, no next motion, the arm stays where it stopped.
    assert run.kill_time is not None and run.motion_end_after_kill
    assert run.after_kill == ()
    assert run.moved_after_kill < 1e-3


def test_the_crossing_is_seeded() -> None:
    a = MovingBody.crossing(np.random.default_rng([3, 5]))
    b = MovingBody.crossing(np.random.default_rng([3, 5]))
    assert a == b
    # It passes the base axis at the drawn distance: 0.22-0.40 m.
    t = np.linspace(a.enter, a.leave, 2001)
    d = min(float(np.hypot(*a.at(x)[:2])) for x in t)
    assert 0.22 - 1e-3 <= d <= 0.40 + 1e-3


def _far_body() -> MovingBody:
    """A body that stands where no sensor sees it: the monitor never slows."""
    return MovingBody(0.1, 0.8, 0.0, (5.0, 5.0), (0.0, 0.0), 0.0, 0.0)


def _stop_and_leave(cell_dir: Path) -> ObstacleTwin:
    """9 s of phase 1 while a cylinder walks fast past the base (0.3 m from its axis) and
    on out of the sensors' range; re-plans are off (not the point here): the arm stops,
    rests mid-path while the body passes, and resumes by the hold-time rule once it has
    gone."""
    rig = SensorRig()
    body = MovingBody(0.1, 0.8, 0.0, (-2.5, 0.3), (1.5, 0.0), 0.0, 6.0)
    core = MonitorNodeCore(NodeParameters(
        scene=str(cell_dir), route="phase1",
        options=MonitorOptions(sensors=rig.sensors(), replan_after=60.0)))
    core.configure()
    loop = ObstacleTwin(core, body=body, rig=rig)
    loop.run(9.0)
    return loop


def test_a_body_that_stops_the_arm_mid_motion_and_leaves_lets_the_route_go_on(
        cell_dir: Path) -> None:
    loop = _stop_and_leave(cell_dir)
    first, second = loop.core.motions[0][0], loop.core.motions[1][0]
    goals = {g.goal_id: g for g in loop.arm_goals}
    done = {r.goal_id: r for r in loop.twin.arm.results if r.success}
    # The stop's goal succeeded with the arm at rest mid-path, far from the motion's end.
    stops = [g for g in loop.arm_goals if g.reason == "stop" and g.goal_id in done]
    assert stops, "the body never stopped the arm"
    rest_time = done[stops[0].goal_id].time
    rest = loop.positions[np.searchsorted(loop.times, rest_time)]
    assert np.abs(rest - first.q[-1]).max() > 0.1
    assert rest_time < 0.5 + first.duration  # before the motion, unstopped, would end
    # Nothing followed that stop but a resume (the hold-time rule, once the body had
    # gone); the gripper opened only when a goal not a stop had reached the path's end.
    assert [a.action for a in loop.gripper_actions] == ["close", "open"]
    opened = loop.gripper_actions[1]
    assert opened.time > rest_time and opened.object == "vial"
    assert [g.reason for g in loop.arm_goals if rest_time < g.time < opened.time][:1] \
        == ["resume"]
    reached = [g for g in loop.arm_goals if g.time < opened.time][-1]
    assert reached.reason != "stop" and reached.goal_id in done
    assert done[reached.goal_id].time <= opened.time
    # The vial was let go where the route puts it down: at the end of the first motion.
    assert all(a.at_pose for a in loop.gripper_actions)
    assert opened.error is not None and np.abs(opened.error).max() < 1e-2
    # The second motion started from there, after the gripper.
    nexts = [g for g in goals.values() if g.reason == "next motion"]
    assert len(nexts) == 2 and nexts[1].time > opened.time
    np.testing.assert_allclose(second.q[0], first.q[-1], atol=1e-9)
    assert loop.replans == []
    run = loop.report()
    assert run.ok, run.failures
    assert run.gripper_offset < 1e-2
    assert 0.0 < run.closest <= run.closest_moving


def test_the_commanded_motion_of_an_obstacle_run_stays_within_the_limits(
        cell_dir: Path) -> None:
    # Replacements (slow, stop) switch the controller's goal while it runs: every switch
    # continues the commanded motion, and the motion stays within the limits.
    run = run_obstacles(str(cell_dir), 0, duration=3.0)
    assert "slow" in run.decisions
    for peak in (run.commanded_speed, run.commanded_acceleration, run.commanded_jerk):
        assert 0.0 < peak.ratio <= 1.0 + 1e-6, peak
    assert run.ok, run.failures


def test_a_kill_with_no_lead_is_pressed_at_the_motions_end_and_holds(cell_dir: Path) -> None:
    from safepath.model.execution import executed_peaks

    core = MonitorNodeCore(NodeParameters(scene=str(cell_dir), route="phase1"))
    core.configure()
    # phase 1: the gripper closes (0.5 s), then the first motion runs unchanged (nothing
    # near): it ends at 0.5 s + its duration.
    motion = core.motions[0][0]
    end = 0.5 + motion.duration
    run = run_obstacles(str(cell_dir), 0, duration=end + 1.5, kill_before_end_of=0,
                        kill_lead=0.0, body=_far_body())
    assert "slow" not in run.decisions and run.kill_time is not None
    assert end - 1e-9 <= run.kill_time <= end + 0.001 + 1e-9  # at the end, to a physics step
    # The controller's result of that instant reached the node after the kill: the
    # gripper stays shut, the arm where it is.
    assert run.motion_end_after_kill
    assert run.after_kill == () and run.moved_after_kill < 1e-3
    assert run.ok, run.failures
    # What the controller commanded is the verified motion: its peaks, as executed.
    robot = core.monitor.cell.robot  # type: ignore[union-attr]
    exact = executed_peaks(motion.t, motion.q, motion.qd, motion.qdd,
                           interpolation=robot.controller.interpolation)
    for peak, top, limit in ((run.commanded_speed, exact.velocity, robot.velocity_limits),
                             (run.commanded_acceleration, exact.acceleration,
                              robot.acceleration_limits),
                             (run.commanded_jerk, exact.jerk, robot.jerk_limits)):
        ratio = top / limit
        assert ratio.max() * (1 - 1e-2) <= peak.ratio <= ratio.max() * (1 + 1e-9)
        assert peak.joint == robot.joint_names[int(np.argmax(ratio))]
        assert 0.5 <= peak.time <= end
    with pytest.raises(InputError, match="kill_lead"):
        run_obstacles(str(cell_dir), 0, duration=1.0, kill_before_end_of=0,
                      kill_lead=-0.001, body=_far_body())


def test_the_report_names_a_vial_dropped_mid_path(cell_dir: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    # The rule this issue replaced: any success of the newest goal moved the route on.
    # Then the stop's success at rest mid-path opens the gripper there: the run fails.
    monkeypatch.setattr(Monitor, "at_end", lambda self, time: True)
    run = _stop_and_leave(cell_dir).report()
    assert not run.ok and run.gripper_offset > 0.1
    drops = [f for f in run.failures if "drops 'vial'" in f]
    assert len(drops) == 1 and drops[0].startswith("gripper open at ")


def test_the_obstacle_command_exits_non_zero_naming_a_failed_run(
        cell_dir: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from safepath import load_cell
    from safepath.sim import obstacles

    real = obstacles.run_obstacles
    failure = "gripper open at 1.000 s 0.500 rad from its pose: drops 'vial'"

    def second_fails(*args: object, **kwargs: object) -> ObstacleRun:
        run = real(*args, **kwargs)  # type: ignore[arg-type]
        return dataclasses.replace(run, failures=(failure,)) if run.seed == 1 else run

    monkeypatch.setattr(obstacles, "run_obstacles", second_fails)
    code = cmd_obstacles(argparse.Namespace(duration=2.0, runs=3, seed=0),
                         load_cell(cell_dir))
    lines = capsys.readouterr().out.strip().splitlines()
    header = [c.strip() for c in lines[1].strip("|").split("|")]
    rows = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines
            if ln.startswith("| ") and ln[2].isdigit()]
    assert [r[0] for r in rows] == ["0", "1", "2"]
    # The figures are printed: the commanded motion's ratios, within the limits.
    column = header.index("commanded speed / accel / jerk vs limit")
    for row in rows:
        ratios = [float(x) for x in row[column].split(" / ")]
        assert len(ratios) == 3 and 0.0 < max(ratios) <= 1.0 + 1e-6
    assert [r[-1] for r in rows] == ["ok", "FAILED", "ok"]
    assert code == 1 and lines[-1] == f"obstacle twin FAILED: seed 1: {failure}"
