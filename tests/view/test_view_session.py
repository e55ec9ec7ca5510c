"""The review session, driven from Python: scene nodes, playback, scrubbing, pose
edits (live check, refusal to save a collision), saving, re-planning in the
background, bad input and ports. The server runs for real (on a free port); no
browser is needed here (see test_browser.py for the page)."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from safepath import (
    CollisionError,
    ConfigError,
    InputError,
    SafepathError,
    Trajectory,
    TrajectoryError,
    load_cell,
    load_poses,
)
from safepath.cli import main
from safepath.view import ReviewSession, ViewOptions
from safepath.view.analysis import RED, affected_routes
from safepath.view.scene_nodes import HIGHLIGHT

from .conftest import VIEW_WITH_CTRL_C

REPO = Path(__file__).resolve().parents[2]


def wait_for(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``predicate`` until true; fail with ``what`` after ``timeout`` [s]."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.02)
    pytest.fail(what)


@pytest.fixture()
def open_session() -> Iterator[Callable[..., ReviewSession]]:
    """Start sessions on free ports; every one is stopped after the test."""
    started: list[ReviewSession] = []

    def start(scene: Path, **kwargs: object) -> ReviewSession:
        options = kwargs.pop("options", ViewOptions(port=0, replan_on_save=False))
        session = ReviewSession(scene, options=options, **kwargs).start()  # type: ignore
        started.append(session)
        return session

    yield start
    for session in started:
        session.stop()


@pytest.fixture()
def session(open_session: Callable[..., ReviewSession], cell_dir: Path, plans_dir: Path
            ) -> ReviewSession:
    """A session of the bundled cell showing plans read from files."""
    return open_session(cell_dir, plans=plans_dir)


def lowered(session: ReviewSession, q: np.ndarray, dz: float) -> pin.SE3:
    """The TCP pose at ``q``, moved by ``dz`` [m] along world z."""
    T = session.cell.robot.frame_pose(q)
    T.translation = T.translation + np.array([0.0, 0.0, dz])
    return T


def test_the_scene_shows_robot_cell_poses_and_routes(session: ReviewSession) -> None:
    cell = session.cell
    assert session.url == f"http://127.0.0.1:{session.port}" and session.port > 0
    assert len(session.robot_nodes.nodes) == cell.robot.collision_model.ngeoms
    assert set(session.cell_nodes.nodes) == set(cell.scene.objects)
    assert set(session.pose_frames.frames) == set(cell.poses)
    assert session.route_names == ["phase1", "phase2_safe", "phase2_unsafe"]
    assert session.route == "phase1" and session.time == 0.0
    data = session.review_data
    assert data is not None
    # The path and the plots hold one value per sample.
    path = session.timeline.path
    assert path is not None and len(path.points) == data.times.size - 1
    assert session.panel.clearance_plot.data[1].shape == data.times.shape
    # The verified plan keeps its margins: no red sample, and the same minimum
    # clearance as the planner's verifier within a sample's worth.
    assert not np.any(data.level == RED)
    assert data.clearance.min() == pytest.approx(data.trajectory.info["min_clearance"],
                                                 abs=2e-3)
    # Vial: resting on the conveyor before the close, held from step 1 on.
    assert data.worlds[0].held is None and data.worlds[1].held == "vial"
    # The "visual" style shows the URDF's materials instead of per-link colours.
    collision = session.robot_nodes.nodes
    session.robot_nodes.set_style("visual")
    visual = session.robot_nodes.nodes
    assert visual is not collision and not any(n.root.visible for n in collision)
    assert {n.color for n in visual} == {(64, 64, 69), (235, 235, 235), (128, 128, 128)}


def test_a_state_in_collision_is_drawn_red(open_session: Callable[..., ReviewSession],
                                           cell_copy: Path, plans_dir: Path,
                                           trajectories: dict[str, Trajectory]) -> None:
    # An obstacle where the TCP passes at t = 2 s of phase1: the old plan now collides.
    cell = load_cell(cell_copy)
    x, y, z = cell.robot.tcp_position(trajectories["phase1"].sample([2.0])[0][0])
    scene = cell_copy / "scene.yaml"
    scene.write_text(scene.read_text().replace(
        "objects:\n", f"objects:\n  intruder:\n    shape: box\n    size: [0.03, 0.03, 0.03]\n"
                      f"    xyz: [{x}, {y}, {z}]\n", 1))
    session = open_session(cell_copy, plans=plans_dir)
    data = session.review_data
    assert data is not None and data.level[data.times.searchsorted(2.0)] == RED
    session.seek(2.0)
    assert session.shown is not None and not session.shown.valid
    assert any("intruder" in pair for pair in session.shown.collisions)
    # Exactly the geometry of the colliding pairs is red (links, the held vial, ...).
    nodes = [*session.robot_nodes.nodes, *session.cell_nodes.nodes.values()]
    red = {n.name for n in nodes if n.shown_color == HIGHLIGHT}
    assert red == {name for pair in session.shown.collisions for name in pair}
    assert "intruder" in red
    session.seek(0.0)
    assert session.shown.valid
    assert not any(n.shown_color == HIGHLIGHT for n in session.robot_nodes.nodes)


def test_play_advances_time_and_moves_the_robot(session: ReviewSession) -> None:
    gripper = session.robot_nodes.nodes[-1].root
    before = gripper.position.copy()
    session.play()
    wait_for(lambda: session.time > 0.8, 5.0, "playback did not advance")
    assert session.playing
    assert np.linalg.norm(gripper.position - before) > 0.01
    session.pause()
    paused = session.time
    time.sleep(0.2)
    assert session.time == paused and not session.playing
    assert session.panel.time.value == pytest.approx(paused, abs=0.01)


def test_playback_stops_at_the_end_unless_looping(session: ReviewSession) -> None:
    session.panel.loop.value = False
    session.set_speed(10.0)
    session.play()
    wait_for(lambda: not session.playing, 5.0, "playback did not stop at the end")
    assert session.time == pytest.approx(session.duration)


def test_scrub_shows_the_state_at_that_time(session: ReviewSession) -> None:
    data = session.review_data
    assert data is not None
    traj, robot = data.trajectory, session.cell.robot
    for t in (0.5, 2.0, session.duration):
        session.seek(t)
        q = traj.sample([t])[0][0]
        assert session.shown is not None and np.allclose(session.shown.q, q)
        # The drawn geometry sits where forward kinematics puts it.
        gmodel = robot.collision_model
        gdata = pin.GeometryData(gmodel)
        pdata = robot.model.createData()
        pin.forwardKinematics(robot.model, pdata, q)
        pin.updateGeometryPlacements(robot.model, pdata, gmodel, gdata)
        node = session.robot_nodes.nodes[-1]
        assert np.allclose(node.root.position, gdata.oMg[gmodel.ngeoms - 1].translation)
    # At the end of phase1 the vial was put down on the test plate.
    assert session.shown.held is None
    plate = session.cell.scene.objects["test_plate"]
    vial = session.cell_nodes.nodes["vial"].root.position
    top = plate.T_world_object[2, 3] + plate.shape.size[2] / 2
    assert vial[2] == pytest.approx(top + 0.045, abs=0.003)
    session.seek(2.0)
    assert session.shown.held == "vial"
    with pytest.raises(InputError, match="unknown route 'nope'"):
        session.select_route("nope")
    session.select_route("phase2_safe")
    assert session.route == "phase2_safe" and session.time == 0.0


def test_a_colliding_edit_is_flagged_and_not_saved(open_session: Callable[..., ReviewSession],
                                                   cell_copy: Path, plans_dir: Path) -> None:
    session = open_session(cell_copy, plans=plans_dir)
    poses_file = cell_copy / "poses.yaml"
    original = poses_file.read_bytes()
    status = session.edit_pose("low1")
    assert status.valid and session.mode == "edit"
    # Push the TCP 4 cm down: the held vial goes into the test plate.
    status = session.move_tcp(lowered(session, status.q, -0.04))
    assert not status.valid
    assert ("vial", "test_plate") in status.collisions
    assert session.shown is not None and not session.shown.valid
    assert session.cell_nodes.nodes["test_plate"].shown_color == HIGHLIGHT
    assert "COLLISION" in status.summary()
    with pytest.raises(CollisionError, match="low1"):
        session.save_poses()
    assert poses_file.read_bytes() == original
    assert not (cell_copy / "poses.yaml~").exists()
    # Ticking "I insist" saves it anyway, keeping the previous file.
    session.save_poses(insist=True)
    assert (cell_copy / "poses.yaml~").read_bytes() == original
    saved = load_poses(poses_file, session.cell.robot)
    assert np.allclose(saved["low1"], status.q)


def test_saving_writes_poses_atomically_with_a_backup(
        open_session: Callable[..., ReviewSession], cell_copy: Path, plans_dir: Path) -> None:
    session = open_session(cell_copy, plans=plans_dir)
    original = (cell_copy / "poses.yaml").read_bytes()
    q = session.edit_pose("high1").q.copy()
    q[0] += 0.05
    status = session.set_joints(q)
    assert status.valid
    path = session.save_poses()
    assert path == cell_copy / "poses.yaml"
    assert (cell_copy / "poses.yaml~").read_bytes() == original
    reloaded = load_cell(cell_copy)
    assert np.array_equal(reloaded.poses["high1"], q)
    assert np.array_equal(reloaded.poses["grip"], session.cell.poses["grip"])
    assert sorted(p.name for p in cell_copy.iterdir()) == [
        "poses.log", "poses.yaml", "poses.yaml~", "routes.yaml", "scene.yaml"]  # no temp file


def test_startup_planning_runs_in_the_background(open_session: Callable[..., ReviewSession],
                                                 cell_copy: Path) -> None:
    session = open_session(cell_copy, options=ViewOptions(port=0, backend="process"))
    # The page is usable at once: a pose can be checked while the cell is planned.
    assert session.route is None and session.messages[-1].startswith("planning")
    assert session.edit_pose("grip").valid
    assert session.wait_for_plans(timeout=60.0), session.messages
    assert session.route_names == ["phase1", "phase2_safe", "phase2_unsafe"]
    assert session.mode == "edit", "the arriving plans must not end the pose edit"
    # Re-plan after an edit of "unsafe": only the route that uses it (and the route
    # it follows), while playback goes on.
    assert affected_routes(session.routes, ["unsafe"]) == ["phase2_unsafe"]
    status = session.edit_pose("unsafe")
    status = session.move_tcp(lowered(session, status.q, +0.01))
    assert status.valid
    session.play()
    job = session.replan()
    assert session.messages[-1] == "planning phase2_unsafe..."
    t0 = session.time
    time.sleep(0.3)
    assert session.time > t0 + 0.1, "playback froze while planning"
    assert session.wait_for_plans(timeout=60.0) and job.exception() is None
    assert set(job.result()) == {"phase1", "phase2_unsafe"}
    new = session.timeline.reviews["phase2_unsafe"].trajectory
    assert np.min(np.max(np.abs(new.q - status.q), axis=1)) < 1e-9


def test_a_plan_for_another_robot_is_refused(cell_dir: Path, trajectories: dict[str, Trajectory],
                                             tmp_path: Path) -> None:
    data = trajectories["phase1"].to_dict()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "phase1.json").write_text(json.dumps({**data, "robot": "ur5"}))
    with pytest.raises(TrajectoryError, match="plan for robot 'ur5'"):
        ReviewSession(cell_dir, plans=tmp_path / "other")
    renamed = {**data, "joint_names": [f"j{i}" for i in range(6)]}
    (tmp_path / "renamed.json").write_text(json.dumps(renamed))
    with pytest.raises(TrajectoryError, match="joint_names"):
        ReviewSession(cell_dir, plans=tmp_path / "renamed.json")


def test_bad_input_is_one_line_and_exit_2(cell_dir: Path, tmp_path: Path,
                                         trajectories: dict[str, Trajectory],
                                         capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError):
        ReviewSession(tmp_path / "no_such_cell")
    with pytest.raises(TrajectoryError, match="not found"):
        ReviewSession(cell_dir, plans=tmp_path / "no_plans")
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**trajectories["phase1"].to_dict(), "robot": "panda"}))
    for argv in (["view", str(tmp_path / "no_such_cell")],
                 ["view", str(cell_dir), "--plans", str(other)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("safepath view: error:") and err.count("\n") == 1


def test_a_taken_port_is_reported_or_refused(open_session: Callable[..., ReviewSession],
                                             cell_dir: Path, plans_dir: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        session = open_session(cell_dir, plans=plans_dir, options=ViewOptions(port=port))
        assert session.port_changed and session.port != port
        assert session.url.endswith(f":{session.port}")
        with pytest.raises(InputError, match=f"port {port} on 127.0.0.1 is in use"):
            ReviewSession(cell_dir, plans=plans_dir,
                          options=ViewOptions(port=port, strict_port=True)).start()
        assert main(["view", str(cell_dir), "--plans", str(plans_dir), "--port", str(port),
                     "--strict-port"]) == 2
        assert "is in use" in capsys.readouterr().err
    with pytest.raises(InputError, match="cannot listen"):
        ReviewSession(cell_dir, plans=plans_dir,
                      options=ViewOptions(host="192.0.2.1", port=0)).start()


def test_gui_callbacks_show_errors_instead_of_raising(session: ReviewSession) -> None:
    event = SimpleNamespace(client=object(), target=SimpleNamespace(value="x"))

    def bad_input(_: object) -> None:
        raise SafepathError("that went wrong")

    def bug(_: object) -> None:
        raise ZeroDivisionError("boom")

    session.guarded(bad_input)(event)
    assert "that went wrong" in session.panel.status.content
    session.guarded(bug)(event)
    assert session.messages[-1] == "internal error: ZeroDivisionError: boom"
    # A pose edit without a selected pose is a message too, not a traceback.
    session.guarded(lambda e: session.editor.set_joint(0, 0.1))(event)
    assert session.messages[-1] == "pick a pose to edit first"


def test_the_command_serves_until_interrupted(cell_dir: Path, plans_dir: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", VIEW_WITH_CTRL_C, str(cell_dir), "--plans",
         str(plans_dir), "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, cwd=REPO)
    try:
        assert proc.stdout is not None
        line = ""
        end = time.monotonic() + 60
        while "safepath view:" not in line and time.monotonic() < end:
            line = proc.stdout.readline()
        assert "quality_check_cell (plans from" in line and "http://127.0.0.1:" in line
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0 and "stopped" in out
        assert "Traceback" not in err
    finally:
        if proc.poll() is None:
            proc.kill()


def test_planning_errors_keep_their_type_across_the_worker(cell_dir: Path) -> None:
    from safepath import PoseError
    from safepath.view.backend import ProcessPlanBackend

    backend = ProcessPlanBackend(cell_dir)
    try:
        poses = load_cell(cell_dir).poses
        with pytest.raises(InputError, match="unknown route 'nope'") as info:
            backend.plan(poses, ["nope"]).result(timeout=120)
        assert type(info.value) is InputError and info.value.key == "route"
        bad = {**poses, "safe": np.full(6, 9.0)}
        with pytest.raises(PoseError, match="poses.safe") as pose_info:
            backend.plan(bad, ["phase2_safe"]).result(timeout=120)
        assert pose_info.value.path == cell_dir / "poses.yaml"
    finally:
        backend.close()
