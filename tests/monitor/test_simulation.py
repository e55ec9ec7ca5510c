"""Closed loop on the quality-check cell: an obstacle walks toward the robot in phase 1.

The robot's executed states are checked against the obstacle's *true* position at every
4 ms sample with python-fcl on the robot's own collision geometry (independent of the
monitor's spheres): never closer than the configured minimum separation.
"""

from __future__ import annotations

import numpy as np
import pytest
from quintic_join import quintic_peaks as _quintic_peaks

from safepath import Cell, PlanOptions, SafepathError, Trajectory, load_routes, plan_cell
from safepath.monitor.profile import KNOT_NS
from safepath.monitor.replan import replan
from safepath.monitor.simulation import FclSeparation, MovingSphere, SimResult, simulate
from safepath.ros import split_at_gripper_events
from safepath.timing import TimingOptions
from safepath.verify import FclVerifier

from .conftest import CAMERA, Phase1, make_monitor

#: Where the obstacle heads: beside the high1 -> high2 sweep, at its height [m].
TARGET = np.array([0.33, 0.30, 0.30])


def _true_separation(cell: Cell, res: SimResult, radius: float) -> np.ndarray:
    checkers = {h: FclSeparation(cell, h) for h in set(res.held)}
    return np.array([checkers[h](q, c, radius)
                     for q, c, h in zip(res.q, res.obstacle, res.held, strict=True)])


def _check_replacements(cell: Cell, res: SimResult) -> None:
    """Every replacement, as a controller executes it (its knots' quintic join at 1 kHz),
    is within the speed, acceleration and jerk limits."""
    robot = cell.robot
    for _, rep in res.replacements:
        if rep.t.size == 1:  # a hold where the motion already ended: one point, at rest
            assert not np.any(rep.qd) and not np.any(rep.qdd)
            continue
        peaks = _quintic_peaks(rep.t, rep.q, rep.qd, rep.qdd)
        for peak, limit in zip(peaks, (robot.velocity_limits, robot.acceleration_limits,
                                       robot.jerk_limits), strict=True):
            assert np.max(peak / limit) <= 1.0 + 1e-9


@pytest.mark.parametrize("speed", [0.25, 0.8, 1.6])
def test_approach_slows_stops_keeps_separation_and_resumes(cell: Cell, phase1: Phase1,
                                                           speed: float) -> None:
    monitor = make_monitor(cell, hold_time=0.5)
    travel = 1.0  # the obstacle walks 1 m toward the sweep, waits 1 s, walks back
    t_stop = 0.2 + travel / speed
    start = TARGET + [travel, 0.0, 0.0]
    obstacle = MovingSphere.approach(start, TARGET, speed, 0.2, t_stop, leave_at=t_stop + 1.0)
    res = simulate(monitor, list(phase1.motions), obstacle, sensor="cam", sensor_pose=CAMERA,
                   until=t_stop + 1.0 + travel / speed + 20.0)
    kinds = [d.kind for d in res.decisions]
    first_stop = kinds.index("stop")
    assert "continue" in kinds[:first_stop]
    if speed <= 0.8:
        assert "slow" in kinds[:first_stop]  # slowed before stopping
    before = res.decisions[first_stop - 1]
    assert before.separation_kept >= before.protective_distance
    sep = _true_separation(cell, res, obstacle.radius)
    assert sep.min() >= monitor.options.min_separation, (sep.min(), res.t[sep.argmin()])
    # It was at rest while the obstacle stood there, then resumed and finished.
    standing = int(np.searchsorted(res.t, t_stop + 0.5))
    assert np.abs(res.qd[standing]).max() == 0.0
    assert "resume" in kinds[first_stop:]
    last, _ = phase1.motions[-1]
    np.testing.assert_allclose(res.q[-1], last.q[-1], atol=1e-9)
    _check_replacements(cell, res)
    # Only the timing changed: every executed state lies on the verified path.
    path = np.vstack([m.q for m, _ in phase1.motions])
    gaps = [np.min(np.max(np.abs(path - q), axis=1)) for q in res.q[::25]]
    assert max(gaps) < 0.02


@pytest.mark.parametrize("knot_period", [0.006, 0.01])
def test_knots_further_apart_are_followed_as_finely(cell: Cell, knot_period: float) -> None:
    """A motion timed with knots further apart than 4 ms (``TimingOptions.knot_period``)
    is assessed and re-timed as finely: the profiles march over states of its join
    between its knots. Marched over its own knots, the bundled cell's phase 1 timed at
    6 ms was slowed, and at 10 ms stopped, at the first decision, the body 1 m away."""
    routes = load_routes(cell.folder / "routes.yaml", poses=list(cell.poses),
                         objects=list(cell.scene.objects))
    options = PlanOptions(timing=TimingOptions(knot_period=knot_period))
    traj = plan_cell(cell, options, routes={"phase1": routes["phase1"]})["phase1"]
    assert np.diff(traj.t).min() > 1.25 * KNOT_NS / 1e9
    parts = [m for m in split_at_gripper_events(traj) if isinstance(m, Trajectory)]
    motions = [(parts[0], "vial"), (parts[1], None)]
    monitor = make_monitor(cell, hold_time=0.5)
    speed, travel = 0.8, 1.0
    t_stop = 0.2 + travel / speed
    obstacle = MovingSphere.approach(TARGET + [travel, 0.0, 0.0], TARGET, speed, 0.2, t_stop,
                                     leave_at=t_stop + 1.0)
    res = simulate(monitor, motions, obstacle, sensor="cam", sensor_pose=CAMERA,
                   until=t_stop + 1.0 + travel / speed + 20.0)
    kinds = [d.kind for d in res.decisions]
    first_stop = kinds.index("stop")
    assert kinds[:2] == ["continue", "continue"], kinds[:5]
    assert _true_separation(cell, res, obstacle.radius).min() >= monitor.options.min_separation
    _check_replacements(cell, res)
    assert "resume" in kinds[first_stop:]
    np.testing.assert_allclose(res.q[-1], parts[-1].q[-1], atol=1e-9)


def test_scan_sees_the_obstacle_too(cell: Cell, phase1: Phase1) -> None:
    lidar = np.eye(4)
    lidar[:3, 3] = [0.9, 0.6, 0.30]  # a planar lidar at the obstacle's height
    monitor = make_monitor(cell, sensors={"lidar": lidar})
    obstacle = MovingSphere.approach(TARGET + [0.8, 0, 0], TARGET, 1.6, 0.2, 0.7,
                                     leave_at=1.5)
    res = simulate(monitor, list(phase1.motions), obstacle, sensor="lidar", sensor_pose=lidar,
                   kind="scan", until=5.0)
    kinds = [d.kind for d in res.decisions]
    assert "stop" in kinds and "resume" in kinds
    assert _true_separation(cell, res, obstacle.radius).min() >= 0.05
    assert max(d.counts.no_return for d in res.decisions) > 300


def test_obstacle_that_stays_is_planned_around(cell: Cell, phase1: Phase1) -> None:
    monitor = make_monitor(cell, replan_after=1.0, parked_speed=0.0)  # a box: it never moves
    obstacle = MovingSphere.approach(TARGET + [0.8, 0, 0], TARGET, 0.5, 0.2, 1.8)
    plans: list[Trajectory] = []

    def on_replan(decision, t):  # noqa: ANN001, ANN202
        request = decision.replan
        new = replan(cell, "phase1", request, held="vial", margin=0.03)
        plans.append(new)
        monitor.add_static_box(request.obstacle_center, request.obstacle_size)
        motions = [m for m in split_at_gripper_events(new) if isinstance(m, Trajectory)]
        return [(motions[0], "vial")] + [(m, None) for m in motions[1:]]

    res = simulate(monitor, list(phase1.motions), obstacle, sensor="cam", sensor_pose=CAMERA,
                   until=12.0, on_replan=on_replan)
    kinds = [d.kind for d in res.decisions]
    assert kinds.count("replan") == 1 and len(plans) == 1
    assert kinds.index("stop") < kinds.index("replan")
    sep = _true_separation(cell, res, obstacle.radius)
    assert sep.min() >= monitor.options.min_separation
    # The new route reaches phase 1's end pose, and was verified: re-check its first
    # motion here against the obstacle box, with the independent checker.
    np.testing.assert_allclose(res.q[-1], phase1.motions[-1][0].q[-1], atol=1e-6)
    new = plans[0]
    assert new.events and new.events[0].action == "open"
    request = next(d.replan for d in res.decisions if d.replan is not None)
    assert request is not None
    verifier_scene = _scene_with(cell, request.obstacle_center, request.obstacle_size)
    head = [m for m in split_at_gripper_events(new) if isinstance(m, Trajectory)][0]
    FclVerifier(cell.robot, verifier_scene, held="vial", margin=0.0,
                resting={"vial": None}).verify(head.t, head.q, head.qd)


def test_replan_refuses_an_unknown_step(cell: Cell, phase1: Phase1) -> None:
    from safepath.monitor import ReplanRequest

    request = ReplanRequest(0.0, phase1.motions[0][0].q[0], 0.0, "9 fly", np.ones(3),
                            np.full(3, 0.1))
    with pytest.raises(SafepathError, match="no step '9 fly'"):
        replan(cell, "phase1", request, held="vial", margin=0.03)


def _scene_with(cell: Cell, center: np.ndarray, size: np.ndarray):  # noqa: ANN202
    from dataclasses import replace

    from safepath.model.scene import SceneObject, Shape

    T = np.eye(4)
    T[:3, 3] = center
    box = SceneObject("obstacle", Shape("box", tuple(float(v) for v in size)), T)
    # The obstacle alone (and the vial, held): the scene's own contacts are the
    # planner's business, checked when it verified the route.
    return replace(cell.scene, objects={"vial": cell.scene.objects["vial"], "obstacle": box})


def test_a_replanned_route_is_found_again(cell: Cell) -> None:
    from safepath import load_routes
    from safepath.monitor.replan import start_pose, step_index

    route = load_routes(cell.folder / "routes.yaml", poses=list(cell.poses),
                        objects=list(cell.scene.objects))["phase1"]
    assert step_index(route, "3 move high2") == 3
    assert step_index(route, "0 move high2") == 3  # numbered from 0 in a re-planned route
    assert step_index(route, "0 line high2") == 6  # the last of the same text
    assert step_index(route, "0 move nowhere") is None
    assert start_pose(route, 1) == "grip" and start_pose(route, 4) == "high2"


def test_same_inputs_same_decisions_in_any_thread(cell: Cell, phase1: Phase1) -> None:
    import threading

    def run() -> SimResult:
        obstacle = MovingSphere.approach(TARGET + [0.8, 0, 0], TARGET, 1.6, 0.2, 0.7,
                                         leave_at=1.2)
        return simulate(make_monitor(cell, hold_time=0.3), list(phase1.motions), obstacle,
                        sensor="cam", sensor_pose=CAMERA, until=3.0, seed=7)

    first = run()
    box: list[SimResult] = []
    thread = threading.Thread(target=lambda: box.append(run()))
    thread.start()
    thread.join()
    second = box[0]
    assert [(d.kind, d.scale, d.separation_now) for d in first.decisions] == \
        [(d.kind, d.scale, d.separation_now) for d in second.decisions]
    assert len(first.replacements) == len(second.replacements) > 0
    for (t1, a), (t2, b) in zip(first.replacements, second.replacements, strict=True):
        assert t1 == t2 and a == b
    np.testing.assert_array_equal(first.q, second.q)
