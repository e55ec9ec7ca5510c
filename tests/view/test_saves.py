"""What a save of the review session keeps, and what its log guarantees after a kill:
the file's mode and group, its comments, key order and layout, the full precision of a
typed value; the log line is on disk before ``poses.yaml`` changes, and the next start
finishes or forgets a save that was killed half-way (no temporary file is left). Real
viser servers on free ports; the kills are real ``SIGKILL``s of a saving process."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from safepath import load_poses
from safepath.view import ReviewSession, ViewOptions

from .conftest import saves_landed

#: A session that neither plans at start nor after a save (the saves are the point).
OPTIONS = ViewOptions(port=0, plan_on_start=False, replan_on_save=False)


def log_lines(folder: Path) -> list[dict[str, Any]]:
    """The save log's entries."""
    path = folder / "poses.log"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() \
        else []


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob(".poses.yaml.*.tmp"))


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


@pytest.fixture()
def session(cell_copy: Path) -> Iterator[ReviewSession]:
    s = ReviewSession(cell_copy, options=OPTIONS).start()
    yield s
    s.stop()


def test_a_save_keeps_the_mode_comments_order_and_layout(cell_copy: Path) -> None:
    poses_file = cell_copy / "poses.yaml"
    lines = poses_file.read_text().splitlines()
    # A comment in the middle, and a pose appended flat by record_joint_pose.sh.
    lines.insert(3, "  # high1 was re-taught after the fixture moved")
    lines.append("recorded: [0.1, -0.2, 0.3, 0.0, -1.0, 0.0]  # by the recorder")
    original = "\n".join(lines) + "\n"
    poses_file.write_text(original)
    os.chmod(poses_file, 0o644)
    session = ReviewSession(cell_copy, options=OPTIONS).start()
    try:
        q = session.edit_pose("low1").q.copy()
        q[0] = 1.4318
        session.set_joints(q)
        session.save_poses()
        r = session.edit_pose("recorded").q.copy()
        r[2] = 0.25
        session.set_joints(r)
        session.save_poses()
    finally:
        session.stop()
    text = poses_file.read_text()
    # Only the two values typed changed; every other byte (comments, order, layout, the
    # text of the values that stayed) is the file's own. (An end-of-line comment keeps
    # its column: one space less before it, as the line grew by one character.)
    expected = original.replace("low1: [1.4017786420317657,", "low1: [1.4318,").replace(
        "recorded: [0.1, -0.2, 0.3, 0.0, -1.0, 0.0]  #",
        "recorded: [0.1, -0.2, 0.25, 0.0, -1.0, 0.0] #")
    assert text == expected
    assert text.startswith("# Taught joint poses")
    saved = load_poses(poses_file, session.cell.robot)
    assert saved["low1"][0] == 1.4318 and saved["recorded"][2] == 0.25
    # The file and its backup keep the mode they had: another user (the robot's
    # process) still reads them.
    assert mode(poses_file) == 0o644 and mode(cell_copy / "poses.yaml~") == 0o644
    assert leftovers(cell_copy) == []


def test_a_new_file_gets_the_umasks_mode(cell_copy: Path, tmp_path: Path) -> None:
    from safepath import Cell, load_cell

    folder_cell = load_cell(cell_copy)
    poses_file = tmp_path / "new" / "poses.yaml"
    poses_file.parent.mkdir()
    cell = Cell(folder_cell.robot, folder_cell.scene, folder_cell.poses,
                routes=folder_cell.route_table(), poses_path=poses_file)
    session = ReviewSession(cell, options=OPTIONS).start()
    old = os.umask(0o027)
    try:
        q = session.edit_pose("safe").q.copy()
        q[5] += 0.01
        session.set_joints(q)
        session.save_poses()
    finally:
        os.umask(old)
        session.stop()
    assert mode(poses_file) == 0o640  # what the umask gives, not mkstemp's 0600
    assert log_lines(poses_file.parent)[-1]["sha256_after"] == sha256(poses_file)


# A saving process that SIGKILLs itself at one instant of the save (``argv[2]``).
_KILLED_SAVE = """
import os, signal, sys
from pathlib import Path
from safepath.view import ReviewSession, ViewOptions

folder, when = Path(sys.argv[1]), sys.argv[2]
session = ReviewSession(folder, options=ViewOptions(port=0, plan_on_start=False,
                                                    replan_on_save=False)).start()
q = session.edit_pose("high1").q.copy()
q[0] += 0.05
session.set_joints(q)
target = folder / "poses.yaml"
real_replace, real_fsync = os.replace, os.fsync

def die():
    os.kill(os.getpid(), signal.SIGKILL)

def replace(src, dst, *args, **kwargs):
    if Path(dst) == target and when == "before the rename":
        die()
    real_replace(src, dst, *args, **kwargs)
    if Path(dst) == target and when == "after the rename":
        die()

def fsync(fd):
    real_fsync(fd)
    if when == "before the log line" and os.readlink(f"/proc/self/fd/{fd}").endswith(".tmp"):
        die()

os.replace, os.fsync = replace, fsync
session.save_poses()
"""


def _killed_save(folder: Path, when: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-c", _KILLED_SAVE, str(folder), when],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


@pytest.mark.parametrize("when", ["before the log line", "before the rename",
                                  "after the rename"])
def test_a_save_killed_at_any_instant_leaves_the_log_and_the_file_agreeing(
        cell_copy: Path, when: str, capsys: pytest.CaptureFixture[str]) -> None:
    poses_file = cell_copy / "poses.yaml"
    os.chmod(poses_file, 0o644)
    before = sha256(poses_file)
    child = _killed_save(cell_copy, when)
    _, err = child.communicate(timeout=120)
    assert child.returncode == -signal.SIGKILL, err.decode()[-2000:]
    lines = log_lines(cell_copy)
    # Whenever the file changed, its line is on disk (and names the new content).
    if sha256(poses_file) != before:
        assert lines and lines[-1]["sha256_after"] == sha256(poses_file)
    # 'safepath check' reads the file as it is, and says when a logged save is unfinished
    # (it changes nothing: the session below finishes it).
    from safepath.cli import main

    capsys.readouterr()
    assert main(["check", str(cell_copy)]) == 0
    warned = "did not finish" in capsys.readouterr().err
    assert warned == (when == "before the rename"), when
    # The next start finishes a logged save, forgets an unlogged one, and leaves no
    # temporary file behind.
    session = ReviewSession(cell_copy, options=OPTIONS).start()
    try:
        lines = log_lines(cell_copy)
        if when == "before the log line":
            assert lines == [] and sha256(poses_file) == before
        else:
            (entry,) = lines
            assert (entry["sha256_before"], entry["sha256_after"]) == \
                (before, sha256(poses_file))
            assert list(entry["changes"]) == ["high1"]
            q = entry["changes"]["high1"]["to"]
            assert np.array_equal(session.edits.q("high1"), q)  # the session shows it
            assert sha256(cell_copy / "poses.yaml~") == before
            assert mode(cell_copy / "poses.yaml~") == 0o644
        assert leftovers(cell_copy) == []
        assert mode(poses_file) == 0o644
        # The session saves on from there, and its line follows on.
        q = session.edit_pose("safe").q.copy()
        q[5] += 0.01
        session.set_joints(q)
        session.save_poses()
        assert log_lines(cell_copy)[-1]["sha256_after"] == sha256(poses_file)
    finally:
        session.stop()


def test_a_failed_rename_withdraws_its_log_line(session: ReviewSession, cell_copy: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    from safepath import PoseError

    poses_file = cell_copy / "poses.yaml"
    before = poses_file.read_bytes()
    q = session.edit_pose("grip").q.copy()
    q[5] += 0.01
    session.set_joints(q)

    def full_disk(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full_disk)
    with pytest.raises(PoseError, match="No space left"):
        session.save_poses()
    monkeypatch.undo()
    assert poses_file.read_bytes() == before and leftovers(cell_copy) == []
    saved, undone = log_lines(cell_copy)
    assert undone["undone"] == saved["time"] and "No space left" in undone["reason"]
    assert saves_landed(cell_copy) == 0


def test_a_save_has_landed_when_the_file_is_replaced_not_when_its_line_appears(
        session: ReviewSession, cell_copy: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two editors, two poses: the first save carries the other editor's edit over, and
    its save writes it. The log is written ahead, so for an instant the second save's
    line is on disk while ``poses.yaml`` is still the first save's version: a reader
    that counts lines and reads the file at once finds the edit "lost" (the browser
    test of two pages did, under load); nobody is told of the save before the file
    holds it, and :func:`saves_landed` waits for the file."""
    import safepath.view.store as store

    poses_file = cell_copy / "poses.yaml"
    robot = session.cell.robot
    other = session.poses.new_editor()  # a page's edit buffer
    q_high = session.edit_pose("high1").q.copy()
    q_high[0] += 0.05
    session.set_joints(q_high)
    q_safe = other.q("safe")
    q_safe[5] += 0.05
    other.set("safe", q_safe)
    session.save_poses()
    assert saves_landed(cell_copy) == 1
    assert np.array_equal(other.edits["safe"], q_safe)  # carried over the first save

    at_line: dict[str, Any] = {}
    append = store.append_log_entry

    def append_and_look(log_file: Any, entry: dict[str, Any]) -> None:
        append(log_file, entry)
        at_line.update(lines=len(log_lines(cell_copy)), landed=saves_landed(cell_copy),
                       safe=load_poses(poses_file, robot)["safe"],
                       told=[m for m in session.messages if "saved by 127.0.0.1:5" in m])

    monkeypatch.setattr(store, "append_log_entry", append_and_look)
    session.save_edits(other, "127.0.0.1:5")
    # At its line: logged, the file not replaced yet, nobody told.
    assert at_line["lines"] == 2 and at_line["landed"] == 1 and at_line["told"] == []
    assert not np.array_equal(at_line["safe"], q_safe)
    # Once the save returns: the file holds both edits, and every page is told.
    saved = load_poses(poses_file, robot)
    assert saves_landed(cell_copy) == 2
    assert np.array_equal(saved["safe"], q_safe) and np.array_equal(saved["high1"], q_high)
    assert any("saved by 127.0.0.1:5" in m for m in session.messages)
