"""The pours as routes of the pouring cell: ``tilt`` and ``circle`` steps in routes.yaml,
planned, timed, verified and written by ``plan_cell`` / ``safepath plan`` like any route.

Figures are measured here from the released samples (forward kinematics of the timed
joint positions), not taken from what the planner reports; the planner's own figures
(``info["pours"]``) are checked against them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yaml

from safepath import Cell, ConfigError, PlanningError, load_cell, load_trajectory
from safepath.cell import load_routes
from safepath.cell.pour_steps import Circle, Tilt
from safepath.cell.routes import Route, Step, Target
from safepath.cli import main
from safepath.model.trajectory import Trajectory
from safepath.planning import WorldState, plan_cell, plan_route

REPO_ROOT = Path(__file__).resolve().parents[2]
POURING = REPO_ROOT / "scenes" / "pouring_cell"
PIVOT_TCP = np.array([0.035, 0.04, 0.0])  # the lip in the TCP frame, as routes.yaml has it


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_cell(POURING)


@pytest.fixture(scope="module")
def planned(cell: Cell) -> dict[str, Trajectory]:
    return plan_cell(cell)


def _tilts(cell: Cell, q: np.ndarray) -> np.ndarray:
    assert cell.scene.grasp is not None
    axis = cell.scene.grasp.T_tcp_object[:3, 2]
    return np.array([math.acos(np.clip((cell.robot.frame_pose(qk).rotation @ axis)[2], -1, 1))
                     for qk in q])


def _limits_kept(cell: Cell, traj: Trajectory) -> None:
    robot = cell.robot
    assert np.all(traj.q >= robot.lower - 1e-9) and np.all(traj.q <= robot.upper + 1e-9)
    assert np.all(np.abs(traj.qd) <= robot.velocity_limits * (1 + 1e-9))
    assert np.all(np.abs(traj.qdd) <= robot.acceleration_limits * (1 + 1e-9))


def _angular_speeds(cell: Cell, traj: Trajectory, rows: np.ndarray) -> np.ndarray:
    R = [cell.robot.frame_pose(q).rotation for q in traj.q[rows]]
    dt = np.diff(traj.t[rows])
    return np.array([np.linalg.norm(pin.log3(a.T @ b)) / d
                     for a, b, d in zip(R[:-1], R[1:], dt, strict=True)])


def test_the_slow_pour_is_a_route_step(cell: Cell, planned: dict[str, Trajectory]) -> None:
    traj = planned["slow_pour"]
    _limits_kept(cell, traj)
    assert traj.steps[0].startswith("0 tilt") and traj.steps[1].startswith("1 tilt")
    # It starts where pick_cup left the cup, and ends there upright again.
    assert np.allclose(traj.q[0], planned["pick_cup"].q[-1], atol=1e-9)
    tilt = _tilts(cell, traj.q)
    assert tilt[0] < math.radians(0.5) and tilt[-1] < math.radians(0.5)
    first = np.flatnonzero(traj.step_index == 0)
    assert abs(math.degrees(tilt[first[-1]]) - 115.0) < 1.0
    # One continuous motion to 115 deg: it never stops on the way.
    speed = np.linalg.norm(traj.qd[first], axis=1)
    assert np.all(speed[5:-5] > 1e-4)
    # About the lip: the pivot (a point of the cup) stays put, within 1 mm.
    T0 = cell.robot.frame_pose(traj.q[0])
    pivot = T0.act(PIVOT_TCP)
    drift = [np.linalg.norm(cell.robot.frame_pose(q).act(PIVOT_TCP) - pivot) for q in traj.q]
    assert max(drift) < 1e-3
    # The cup's angular speed, by finite differences of the released orientations.
    assert _angular_speeds(cell, traj, first).max() <= 0.0873 * 1.001
    back = np.flatnonzero(traj.step_index == 1)
    assert _angular_speeds(cell, traj, back).max() <= 0.5236 * 1.001
    # The planner's own figures agree with these.
    figures = traj.info["pours"][traj.steps[0]]
    assert figures["angular_speed_bound"] == pytest.approx(0.0873)
    assert figures["max_angular_speed"] <= 0.0873 * (1 + 1e-6)
    assert math.degrees(figures["final_tilt"]) == pytest.approx(math.degrees(tilt[first[-1]]),
                                                                abs=1e-6)


def test_the_barista_pour_is_a_route_step(cell: Cell, planned: dict[str, Trajectory]
                                          ) -> None:
    traj = planned["barista_pour"]
    _limits_kept(cell, traj)
    assert [s.split()[1] for s in traj.steps] == ["tilt", "circle", "tilt"]
    tilt = _tilts(cell, traj.q)
    on_circle = np.flatnonzero(traj.step_index == 1)
    assert on_circle.size > 100
    p = np.array([cell.robot.tcp_position(q) for q in traj.q[on_circle]])
    # The circle: 3 cm about the point 3 cm towards the bowl's axis (world -y) from where
    # the tilt (93 deg about world -x, about the lip) puts the TCP, at that height.
    T0 = cell.robot.frame_pose(traj.q[0])
    pivot = T0.act(PIVOT_TCP)
    R1 = pin.exp3(np.array([-1.6232, 0.0, 0.0])) @ T0.rotation
    start = pivot + R1 @ T0.rotation.T @ (T0.translation - pivot)
    center = start + np.array([0.0, -0.03, 0.0])
    off = np.hypot(np.hypot(p[:, 0] - center[0], p[:, 1] - center[1]) - 0.03,
                   p[:, 2] - center[2])
    assert off.max() <= 1e-3
    assert np.abs(np.degrees(tilt[on_circle]) - 93.0).max() <= 1.0
    # It really goes round (the TCP's angle about the centre covers a full turn).
    phi = np.unwrap(np.arctan2(p[:, 1] - center[1], p[:, 0] - center[0]))
    assert phi[-1] - phi[0] > 2 * math.pi * 0.95
    # The TCP speed limit, by finite differences.
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(traj.t[on_circle])
    assert v.max() <= 0.05 * 1.001
    # Tilt and circle are one motion: no stop between them (then a stop, and back).
    rows = np.flatnonzero(traj.step_index <= 1)
    assert np.all(np.linalg.norm(traj.qd[rows], axis=1)[5:-5] > 1e-5)
    figures = traj.info["pours"][traj.steps[1]]
    assert figures["circle_error"] == pytest.approx(off.max(), abs=1e-6)
    assert figures["tilt_error"] <= math.radians(1.0)
    assert figures["max_tcp_speed"] <= 0.05 and figures["tcp_speed_bound"] == 0.05
    assert tilt[-1] < math.radians(0.5)
    # The pour lands in the bowl: the lip (carried by the cup) stays above the bowl and
    # within its 70 mm radius of its axis on every sample of the three steps.
    bowl = cell.scene.objects["bowl"].T_world_object[:3, 3]
    lip = np.array([cell.robot.frame_pose(q).act(PIVOT_TCP) for q in traj.q])
    from_axis = np.hypot(lip[:, 0] - bowl[0], lip[:, 1] - bowl[1])
    assert from_axis.max() <= 0.036 and lip[:, 2].min() > bowl[2] + 0.03
    assert figures["landing"]["into"] == "bowl"
    # The whole rim of the cup's opening (radius 35 mm, 50 mm above its centre), tipped
    # past its 45 deg spill angle all along the circle, stays inside the bowl's 70 mm
    # radius less its 3 mm wall; the figure is that room less the check's allowances
    # (the rim followed at 360 points, its motion between samples): under 0.5 mm.
    reach = _rim_reach(cell, traj.q[on_circle], bowl)
    assert reach.max() < 0.067
    margin = figures["landing"]["margin"]
    assert 0.067 - reach.max() - 5e-4 < margin <= 0.067 - reach.max()
    assert figures["landing"]["spill_angle"] == pytest.approx(0.7854)


def _rim_reach(cell: Cell, q: np.ndarray, bowl: np.ndarray) -> np.ndarray:
    """Per state, the largest distance of the cup's rim (3600 points) from the bowl's
    axis [m]."""
    cup = cell.scene.objects["cup"]
    radius, length = cup.shape.size
    phi = np.linspace(0.0, 2 * math.pi, 3600, endpoint=False)
    rim = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, length / 2),
                    np.ones_like(phi)])
    grasp = cell.scene.grasp.T_tcp_object
    out = []
    for qk in q:
        p = cell.robot.frame_pose(qk).homogeneous @ grasp @ rim
        out.append(np.hypot(p[0] - bowl[0], p[1] - bowl[1]).max())
    return np.array(out)


def test_a_pour_landing_outside_its_receptacle_is_refused(cell: Cell) -> None:
    """The barista circle as it was (centre 3 cm towards the robot) carried the lip out
    to 76 mm from the bowl's axis, and the rest of the cup's opening further: refused,
    naming the step, the distance and the limit (70 mm less the 3 mm wall)."""
    from safepath.errors import PourLandingError

    tilt = Tilt((0.035, 0.04, 0.0), axis=(-1, 0, 0), angle=1.6232)
    route = Route("barista_wide", "above_bowl", (
        Step("tilt", None, pour=tilt, max_angular_speed=0.3491, into="bowl"),
        Step("circle", None, pour=Circle((-0.03, 0.0)), tcp_speed=0.05, into="bowl")))
    with pytest.raises(PourLandingError, match="outside 'bowl'") as info:
        plan_route(cell, route, world=WorldState(held="cup"))
    err = info.value
    assert err.step == "1 circle r30mm" and err.receptacle == "bowl"
    assert err.limit == pytest.approx(0.067) and err.distance > 0.076
    assert err.overshoot == pytest.approx(err.distance - err.limit)
    bowl = cell.scene.objects["bowl"].T_world_object[:3, 3]
    from_axis = np.hypot(*(err.lip[:2] - bowl[:2]))  # the rim point, measured here
    assert from_axis <= err.distance < from_axis + 1e-3  # plus the check's allowances
    assert f"{err.distance * 1000:.1f} mm" in str(err) and "67.0 mm" in str(err)
    # into names a scene object, on pour steps only.
    with pytest.raises(ConfigError, match="into"):
        Step("move", Target("home"), into="bowl")


def test_a_tilt_with_nothing_held_is_refused(cell: Cell) -> None:
    route = Route("empty", "above_bowl", (
        Step("tilt", None, pour=Tilt((0.035, 0.04, 0.0), axis=(-1, 0, 0), angle=1.0),
             max_angular_speed=0.3),))
    with pytest.raises(PlanningError, match="holds nothing") as info:
        plan_route(cell, route)
    assert info.value.step == "0 tilt 57.3deg"
    # Held, it tips the cup past its 45 deg spill angle and pours into nothing: refused.
    from safepath.errors import PourLandingError

    with pytest.raises(PourLandingError, match="pours into nothing") as spilt:
        plan_route(cell, route, world=WorldState(held="cup"))
    assert spilt.value.step == "0 tilt 57.3deg" and spilt.value.receptacle is None
    # Below its spill angle, the same tilt plans, from Python as from routes.yaml.
    low = Route("low", "above_bowl", (
        Step("tilt", None, pour=Tilt((0.035, 0.04, 0.0), axis=(-1, 0, 0), angle=0.7),
             max_angular_speed=0.3),))
    traj = plan_route(cell, low, world=WorldState(held="cup"))
    assert abs(math.degrees(_tilts(cell, traj.q[-1:])[0]) - 40.1) < 1.0


def test_plan_writes_the_pours_like_any_route(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    from safepath.ros import read_bag

    out, bag = tmp_path / "out", tmp_path / "cycle"
    assert main(["plan", str(POURING), "--out", str(out), "--bag", str(bag)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["pick_cup", "place_cup", "slow_pour", "barista_pour"]
    for name in summary:
        traj = load_trajectory(out / f"{name}.json")
        assert traj.route == name and traj.duration > 0
    barista = load_trajectory(out / "barista_pour.json")
    assert "pours" in barista.info  # the figures travel with the trajectory
    # The printed figures: carried tilt against max_tilt; the pours' errors and speeds.
    pick = next(line for line in printed.splitlines() if line.startswith("pick_cup: carried"))
    tilt = float(pick.split("tilt <= ")[1].split(" deg")[0])
    assert 0.0 <= tilt <= 5.0 and "max_tilt 5.00 deg" in pick
    assert tilt == pytest.approx(math.degrees(summary["pick_cup"]["carried_tilt"]["max"]),
                                 abs=1e-3)
    circle = next(line for line in printed.splitlines() if " circle " in line)
    off_mm = float(circle.split("TCP off the circle <= ")[1].split(" mm")[0])
    assert 0.0 <= off_mm <= 1.0
    assert "tilt error <=" in circle and "(limit 0.050)" in circle
    assert "cup angular speed <=" in next(line for line in printed.splitlines()
                                         if line.startswith("slow_pour: 0 tilt"))
    # The bag is one cycle of the cell (routes.yaml's `cycle`): pick, the two pours, put
    # the cup back; the gripper opens at the start, closes on the cup, opens at the end.
    contents = read_bag(bag)
    routes = [json.loads(m.msg.data)["route"] for m in contents.on("/safepath/route")]
    assert routes == ["pick_cup", "slow_pour", "barista_pour", "place_cup"]
    assert [json.loads(m.msg.data)["action"] for m in contents.on("/safepath/gripper")] == [
        "open", "close", "open"]
    states = contents.on("/joint_states")
    home = load_cell(POURING).pose("home")
    assert np.allclose(states[0].msg.position[:6], home, atol=1e-9)
    assert np.allclose(states[-1].msg.position[:6], home, atol=1e-6)
    # One message per motion between gripper events: pick 2, the pours 1 each, place 2.
    goals = contents.on("/safepath/trajectory")
    assert len(goals) == 6
    last = goals[2].msg.points[-1].time_from_start
    assert last.sec + last.nanosec * 1e-9 == pytest.approx(
        load_trajectory(out / "slow_pour.json").duration, abs=1e-3)


def test_a_cycle_that_does_not_hold_together_is_refused(tmp_path: Path) -> None:
    """A cycle naming an unknown route, or putting the cup down before the pours (the
    pours then start holding a cup that is on the table), names the file and key."""
    from safepath.cell.routes import load_cycle

    text = (POURING / "routes.yaml").read_text()
    good = "cycle: [pick_cup, slow_pour, barista_pour, place_cup]"
    assert good in text
    cell = load_cell(POURING)
    routes = cell.route_table()
    for cycle, key, words in (
            ("[pick_cup, place_cup, slow_pour, barista_pour]", "cycle[2]",
             "'slow_pour' starts holding the object"),
            ("[pick_cup, slow_pour, barista_pour]", "cycle[0]",
             "'barista_pour' before it in the cycle ends holding"),
            ("[pick_cup, slow_pur]", "cycle[1]", "did you mean 'slow_pour'")):
        path = tmp_path / "routes.yaml"
        path.write_text(text.replace(good, f"cycle: {cycle}"))
        with pytest.raises(ConfigError, match=words) as info:
            load_cycle(path, routes)
        assert info.value.key == key and info.value.path == path
    assert cell.cycle() == ["pick_cup", "slow_pour", "barista_pour", "place_cup"]


def _write(tmp_path: Path, steps: list[Any]) -> Path:
    path = tmp_path / "routes.yaml"
    path.write_text(yaml.safe_dump({"routes": {"pour": {"start": "above_bowl",
                                                        "steps": steps}}}))
    return path


TILT = {"axis": [-1, 0, 0], "angle": 1.0, "pivot": [0.035, 0.04, 0.0]}


@pytest.mark.parametrize(("steps", "key", "words"), [
    ([{"tilt": {**TILT, "pivto": [0, 0, 0]}, "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.pivto", "did you mean 'pivot'"),
    ([{"tilt": TILT, "max_angular_sped": 0.1}],
     "routes.pour.steps[0].max_angular_sped", "did you mean 'max_angular_speed'"),
    ([{"tilt": TILT}], "routes.pour.steps[0].max_angular_speed", "angular speed bound"),
    ([{"tilt": TILT, "max_angular_speed": -0.1}],
     "routes.pour.steps[0].max_angular_speed", "> 0"),
    ([{"tilt": {"orientation": [0.5, 0.5, 0.5, 0.9], "pivot": [0.035, 0.04, 0]},
       "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.orientation", "not a unit quaternion"),
    ([{"tilt": {"orientation": [0.5, 0.5, float("nan"), 0.5], "pivot": [0.035, 0.04, 0]},
       "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.orientation[2]", "not finite"),
    ([{"tilt": {**TILT, "orientation": [0.5, 0.5, 0.5, 0.5]}, "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.orientation", "not both"),
    ([{"tilt": {**TILT, "axis": [0, 0, 0]}, "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.axis", "zero"),
    ([{"tilt": {**TILT, "angle": 4.0}, "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.angle", "pi"),
    ([{"tilt": {"axis": [1, 0, 0], "angle": 1.0}, "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.pivot", "missing"),
    ([{"tilt": {**TILT, "pivot": [0, 0, 0.0002]}, "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt.pivot", "1 mm"),
    ([{"tilt": TILT, "max_angular_speed": 0.1, "max_tilt": 0.1}],
     "routes.pour.steps[0].max_tilt", "unknown key"),
    ([{"tilt": TILT, "max_angular_speed": 0.1, "into": "bowll"}],
     "routes.pour.steps[0].into", "did you mean 'bowl'"),
    ([{"tilt": "upright", "max_angular_speed": 0.1}],
     "routes.pour.steps[0].tilt", "expected a mapping"),
    ([{"circle": {"center": [-0.03, 0]}, "tcp_speed": 0.05}],
     "routes.pour.steps[0].circle", "follows a tilt"),
    ([{"tilt": TILT, "max_angular_speed": 0.1},
      {"circle": {"center": [-0.03, 0, 0]}, "tcp_speed": 0.05}],
     "routes.pour.steps[1].circle.center", "expected 2 values"),
    ([{"tilt": TILT, "max_angular_speed": 0.1},
      {"circle": {"center": [-0.03, 0], "turns": 0}, "tcp_speed": 0.05}],
     "routes.pour.steps[1].circle.turns", "non-zero"),
    ([{"tilt": TILT, "max_angular_speed": 0.1}, {"circle": {"center": [-0.03, 0]}}],
     "routes.pour.steps[1].tcp_speed", "TCP speed limit"),
    ([{"tilt": TILT, "max_angular_speed": 0.1, "tcp_speed": 0.1}],
     "routes.pour.steps[0].tcp_speed", "unknown key"),
])
def test_bad_pour_steps_name_file_and_key(tmp_path: Path, cell: Cell, steps: list[Any],
                                          key: str, words: str) -> None:
    path = _write(tmp_path, steps)
    with pytest.raises(ConfigError) as info:
        load_routes(path, poses=list(cell.poses), objects=list(cell.scene.objects))
    assert info.value.path == path
    assert info.value.key == key
    assert words in info.value.reason


def test_pour_step_constructors_check_their_values() -> None:
    with pytest.raises(ConfigError) as info:
        Tilt((0.0, 0.0, 0.0), axis=(1.0, 0.0, 0.0), angle=1.0)
    assert info.value.key == "pivot"
    with pytest.raises(ConfigError, match="not a unit quaternion") as info:
        Tilt((0.03, 0.0, 0.0), orientation=(0.5, 0.5, 0.5, 0.9))
    assert info.value.key == "orientation"
    with pytest.raises(ConfigError) as info:
        Circle((float("nan"), 0.0))
    assert info.value.key == "center"
    tilt = Tilt((0.03, 0.0, 0.0), axis=(0.0, 0.0, 2.0), angle=math.pi / 2)
    with pytest.raises(ConfigError) as info:
        Step("tilt", None, pour=tilt)  # no angular speed bound
    assert info.value.key == "max_angular_speed"
    with pytest.raises(ConfigError) as info:
        Step("tilt", Target("above_bowl"), pour=tilt, max_angular_speed=0.1)
    assert info.value.key == "target"
    with pytest.raises(ConfigError) as info:
        Step("move", Target("above_bowl"), max_angular_speed=0.1)
    assert info.value.key == "max_angular_speed"
    with pytest.raises(ConfigError) as info:
        Step("circle", None, pour=tilt, tcp_speed=0.05)
    assert info.value.key == "pour"
    circle = Step("circle", None, pour=Circle((-0.03, 0.0)), tcp_speed=0.05)
    with pytest.raises(ConfigError) as info:
        Route("r", "above_bowl", (circle,))
    assert info.value.key == "steps[0].circle"
    # The goal of a relative tilt: the turn about the world axis, from the start.
    assert np.allclose(tilt.goal(np.eye(3)), pin.exp3(np.array([0.0, 0.0, math.pi / 2])))


def test_check_validates_the_routes(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                    ) -> None:
    import shutil

    assert main(["check", str(POURING)]) == 0
    assert "routes.yaml: 4 routes, 18 steps valid" in capsys.readouterr().out
    folder = tmp_path / "cell"
    shutil.copytree(POURING, folder)
    text = (folder / "routes.yaml").read_text()
    (folder / "routes.yaml").write_text(text.replace("orientation: [0.5, 0.5, 0.5, 0.5], "
                                                     "pivot", "orientation: [0.5, 0.5, 0.5, "
                                                     "0.9], pivot", 1))
    assert main(["check", str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "routes.yaml" in err[0] and "routes.slow_pour.steps[1].tilt.orientation" in err[0]
