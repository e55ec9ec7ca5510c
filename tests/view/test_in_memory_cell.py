"""A cell built in Python in the review session: shown, planned and edited like a scene
folder's; saving needs a poses file, which the cell names (``Cell(..., poses_path=)``) or
the save is refused with a typed error and nothing is written."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from safepath import Cell, ConfigError, load_cell, load_poses
from safepath.view import ReviewSession, ViewOptions

CELLS = Path(__file__).resolve().parents[2] / "examples" / "cells"


def wait_for(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``predicate`` until true; fail with ``what`` after ``timeout`` [s]."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.05)
    pytest.fail(what)


def ur5_cell(poses_path: Path | None = None) -> Cell:
    """The example UR5 cell as a cell built in Python (no folder; a poses file only if
    given)."""
    yaml_cell = load_cell(CELLS / "ur5_cell")
    return Cell(yaml_cell.robot, yaml_cell.scene, yaml_cell.poses,
                routes=yaml_cell.route_table(), poses_path=poses_path)


@pytest.fixture()
def sessions() -> Iterator[list[ReviewSession]]:
    """Sessions to stop after the test."""
    started: list[ReviewSession] = []
    yield started
    for session in started:
        session.stop()


def test_a_cell_built_in_python_is_planned_and_shown(sessions: list[ReviewSession]) -> None:
    cell = ur5_cell()
    session = ReviewSession(cell, options=ViewOptions(port=0, replan_on_save=False)).start()
    sessions.append(session)
    wait_for(lambda: session.plans.ready.is_set(), 240.0, "planning never finished")
    assert sorted(session.route_names) == sorted(cell.route_table())
    session.select_route("over_the_wall")
    assert session.duration > 0.5
    assert session.cell is not cell  # the session works on a copy


def test_without_a_poses_file_a_save_is_refused_and_nothing_changes(
        sessions: list[ReviewSession], tmp_path: Path) -> None:
    cell = ur5_cell()
    before = {k: q.copy() for k, q in cell.poses.items()}
    session = ReviewSession(cell, options=ViewOptions(port=0, plan_on_start=False)).start()
    sessions.append(session)
    q = session.edit_pose("beside_wall").q.copy()
    q[0] -= 0.05
    assert session.set_joints(q).valid
    with pytest.raises(ConfigError) as info:
        session.save_poses()
    assert info.value.key == "poses_path" and "Cell(..., poses_path=" in str(info.value)
    assert all(np.array_equal(cell.poses[k], v) for k, v in before.items())
    assert np.array_equal(session.cell.poses["beside_wall"], before["beside_wall"])


def test_edits_are_saved_to_the_poses_path_the_cell_names(sessions: list[ReviewSession],
                                                          tmp_path: Path) -> None:
    path = tmp_path / "new" / "poses.yaml"
    path.parent.mkdir()
    cell = ur5_cell(poses_path=path)
    session = ReviewSession(cell, options=ViewOptions(port=0, plan_on_start=False,
                                                      replan_on_save=False)).start()
    sessions.append(session)
    q = session.edit_pose("beside_wall").q.copy()
    q[0] -= 0.05
    session.set_joints(q)
    assert session.save_poses() == path
    saved = load_poses(path, cell.robot)
    assert np.allclose(saved["beside_wall"], q)
    assert np.array_equal(saved["above_bin"], cell.poses["above_bin"])  # untouched ones too
    assert (path.parent / "poses.log").is_file()
    # A second session on that file with the cell's old poses is refused, not merged.
    with pytest.raises(ConfigError) as info:
        ReviewSession(ur5_cell(poses_path=path), options=ViewOptions(port=0))
    assert info.value.path == path and "beside_wall" in str(info.value)


@pytest.mark.parametrize("folder", ["scenes/quality_check_cell", "scenes/pouring_cell",
                                    "examples/cells/panda_cell"])
def test_the_first_view_frames_the_whole_cell(folder: str) -> None:
    """The first view looks at each cell, not at a fixed spot: the robot's TCP at every
    pose and every object's centre within its reach lie within 42 degrees of the view's
    axis."""
    import numpy as np

    from safepath import load_cell
    from safepath.view.scene_nodes import cell_framing

    cell = load_cell(Path(__file__).resolve().parents[2] / folder)
    eye, centre = (np.array(x) for x in cell_framing(cell))
    axis = (centre - eye) / np.linalg.norm(centre - eye)
    reach = max(np.linalg.norm(cell.robot.tcp_position(q)) for q in cell.poses.values())
    points = [o.T_world_object[:3, 3] for o in cell.scene.objects.values()
              if np.linalg.norm(o.T_world_object[:3, 3]) <= reach]
    points += [cell.robot.tcp_position(q) for q in cell.poses.values()]
    assert len(points) > len(cell.poses)
    for p in points:
        v = (p - eye) / np.linalg.norm(p - eye)
        assert np.degrees(np.arccos(np.clip(v @ axis, -1, 1))) <= 42.0, p
