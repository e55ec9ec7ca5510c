"""Issue 35, what a user's files cannot do: a named pipe, a device or an oversized file is
refused before it is read (no hang, no unbounded memory); a write or a backup never goes
through a link planted at its name; a misspelt top-level key is named with a
did-you-mean, never printed with the file's content. Real FIFOs, real symbolic links."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from safepath import ConfigError, PoseError, Robot, load_cell, load_poses, save_poses
from safepath.files._io import MAX_FILE_BYTES

ENTRY = Path(sys.executable).with_name("safepath")
GRIP = [-0.0168, -0.0208, -0.8436, -0.0459, -0.6519, -0.0245]
HIGH1 = [-0.0154, -0.0056, 0.0734, 0.0016, -1.5969, -0.0168]


def check(folder: Path) -> subprocess.CompletedProcess[str]:
    """``safepath check FOLDER`` as a user runs it, killed after 60 s (a hang fails)."""
    cmd = [str(ENTRY)] if ENTRY.exists() else [sys.executable, "-m", "safepath.cli"]
    return subprocess.run([*cmd, "check", str(folder)], capture_output=True, text=True,
                          timeout=60, check=False)


def _fifo(path: Path) -> None:
    os.mkfifo(path)


def _dev_zero(path: Path) -> None:
    path.symlink_to("/dev/zero")


def _oversized(path: Path) -> None:
    with open(path, "wb") as handle:  # sparse: no disk used
        handle.truncate(MAX_FILE_BYTES + 1)


def _folder(path: Path) -> None:
    path.mkdir()


UNREADABLE = {"a named pipe": (_fifo, "is a named pipe"),
              "/dev/zero": (_dev_zero, "is a character device"),
              "a sparse file over the limit": (_oversized, "file too large .* at most 16 MiB"),
              "a folder": (_folder, "is a folder")}


@pytest.mark.parametrize("kind", list(UNREADABLE))
def test_a_poses_file_that_is_no_regular_file_is_refused(cell_copy: Path, robot: Robot,
                                                         kind: str) -> None:
    make, match = UNREADABLE[kind]
    path = cell_copy / "poses.yaml"
    path.unlink()
    make(path)
    with pytest.raises(PoseError, match=match) as info:
        load_poses(path, robot)
    assert info.value.path == path


@pytest.mark.parametrize("name", ["scene.yaml", "routes.yaml"])
def test_a_scene_or_routes_file_that_is_a_pipe_is_refused(cell_copy: Path, name: str) -> None:
    path = cell_copy / name
    path.unlink()
    os.mkfifo(path)
    with pytest.raises(ConfigError, match="is a named pipe") as info:
        load_cell(cell_copy).route_table()  # routes.yaml is read when needed
    assert info.value.path == path


@pytest.mark.parametrize("kind", ["a named pipe", "/dev/zero", "a sparse file over the limit"])
def test_check_refuses_them_in_one_line(cell_copy: Path, kind: str) -> None:
    make, match = UNREADABLE[kind]
    path = cell_copy / "poses.yaml"
    path.unlink()
    make(path)
    result = check(cell_copy)
    assert result.returncode != 0
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr[:2000]
    assert str(path) in lines[0]
    assert re.search(match, lines[0]), lines[0]


def test_a_misspelt_top_level_key_is_named_not_printed(cell_copy: Path, robot: Robot) -> None:
    path = cell_copy / "poses.yaml"
    path.write_text("posess:\n" + "".join(f"  p{i}: {GRIP}\n" for i in range(2000)))
    with pytest.raises(PoseError) as info:
        load_poses(path, robot)
    assert info.value.key == "posess"
    assert "did you mean 'poses'?" in info.value.reason
    assert "p1" not in str(info.value) and len(str(info.value)) < 200
    result = check(cell_copy)
    assert result.returncode != 0
    assert result.stderr.count("\n") == 1 and len(result.stderr) < 300, result.stderr[:500]
    assert "did you mean 'poses'?" in result.stderr


def test_a_long_value_is_cut_short_in_the_message(tmp_path: Path, robot: Robot) -> None:
    path = tmp_path / "poses.yaml"
    path.write_text("poses:\n  grip: " + str(list(range(30000))) + "\n")
    with pytest.raises(PoseError, match="grip") as info:
        load_poses(path, robot)
    assert len(str(info.value)) < 250


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim.txt"
    victim.write_text("not yours to overwrite\n")
    return victim


def test_a_backup_name_planted_as_a_link_is_refused(tmp_path: Path, robot: Robot) -> None:
    victim = _victim(tmp_path)
    path = tmp_path / "poses.yaml"
    save_poses(path, {"grip": GRIP}, robot)
    old = path.read_bytes()
    (tmp_path / "poses.yaml~").unlink(missing_ok=True)
    (tmp_path / "poses.yaml~").symlink_to(victim)
    with pytest.raises(PoseError, match="is a symbolic link") as info:
        save_poses(path, {"grip": GRIP, "high1": HIGH1}, robot)
    assert info.value.path == tmp_path / "poses.yaml~"
    assert victim.read_text() == "not yours to overwrite\n"
    assert path.read_bytes() == old
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_a_link_planted_after_the_check_is_replaced_not_followed(
        tmp_path: Path, robot: Robot, monkeypatch: pytest.MonkeyPatch) -> None:
    """The race: the link appears between the check and the copy. The backup is a new
    file renamed over the name, so the link itself is replaced."""
    victim = _victim(tmp_path)
    path = tmp_path / "poses.yaml"
    save_poses(path, {"grip": GRIP}, robot, backup=False)
    old = path.read_bytes()
    (tmp_path / "poses.yaml~").symlink_to(victim)
    monkeypatch.setattr("safepath.files._io.check_replaceable", lambda *a, **k: None)
    save_poses(path, {"grip": GRIP, "high1": HIGH1}, robot)
    assert victim.read_text() == "not yours to overwrite\n"
    backup = tmp_path / "poses.yaml~"
    assert not backup.is_symlink() and backup.read_bytes() == old
    assert list(load_poses(path, robot)) == ["grip", "high1"]


@pytest.mark.parametrize("kind", ["a link to a file", "a named pipe"])
def test_a_target_that_is_no_regular_file_is_not_replaced(tmp_path: Path, robot: Robot,
                                                           kind: str) -> None:
    victim = _victim(tmp_path)
    path = tmp_path / "poses.yaml"
    if kind == "a named pipe":
        os.mkfifo(path)
    else:
        save_poses(victim, {"grip": GRIP}, robot, backup=False)
        path.symlink_to(victim)
    before = victim.read_bytes()
    with pytest.raises(PoseError, match="not replaced") as info:
        save_poses(path, {"grip": HIGH1}, robot, backup=False)
    assert info.value.path == path
    assert victim.read_bytes() == before
    assert path.is_symlink() == (kind != "a named pipe")
    if kind != "a named pipe":
        np.testing.assert_array_equal(load_poses(path, robot)["grip"], GRIP)  # read through
