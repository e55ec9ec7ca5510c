"""Issue 35: links planted in a cell folder by someone who may create files there do not
make a review session's save, or its recovery at start, write another file. Real
symbolic links; the store of a real session (:class:`safepath.view.store.PosesStore`)."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

from safepath import PoseError, dump_poses, load_cell
from safepath.view.store import PosesStore

VICTIM_TEXT = "not yours to overwrite\n"


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim.txt"
    victim.write_text(VICTIM_TEXT)
    return victim


def _sha(raw: bytes) -> str:
    return hashlib.sha256(raw).hexdigest()


def _edited(store: PosesStore) -> dict[str, np.ndarray]:
    poses = dict(store.read().poses)
    poses["high1"] = poses["high1"].copy()
    poses["high1"][5] += 0.01
    return poses


def test_a_save_refuses_a_planted_backup_link(cell_copy: Path, tmp_path: Path) -> None:
    victim = _victim(tmp_path)
    (cell_copy / "poses.yaml~").symlink_to(victim)
    store = PosesStore(load_cell(cell_copy))
    base = store.read()
    before = (cell_copy / "poses.yaml").read_bytes()
    with pytest.raises(PoseError, match="is a symbolic link") as info:
        store.save(base, _edited(store), client="python", checks={})
    assert info.value.path == cell_copy / "poses.yaml~"
    assert victim.read_text() == VICTIM_TEXT
    assert (cell_copy / "poses.yaml").read_bytes() == before
    assert (cell_copy / "poses.log").read_text() == ""  # refused before its line
    assert not any(p.name.endswith(".tmp") for p in cell_copy.iterdir())
    # Once the link is gone, the same save lands and keeps a real backup.
    (cell_copy / "poses.yaml~").unlink()
    store.save(base, _edited(store), client="python", checks={})
    assert (cell_copy / "poses.yaml~").read_bytes() == before
    assert victim.read_text() == VICTIM_TEXT


def test_a_save_refuses_a_planted_log_link(cell_copy: Path, tmp_path: Path) -> None:
    victim = _victim(tmp_path)
    (cell_copy / "poses.log").symlink_to(victim)
    store = PosesStore(load_cell(cell_copy))
    before = (cell_copy / "poses.yaml").read_bytes()
    with pytest.raises(PoseError, match="is a symbolic link") as info:
        store.save(store.read(), _edited(store), client="python", checks={})
    assert info.value.path == cell_copy / "poses.log"
    assert victim.read_text() == VICTIM_TEXT  # neither appended to nor cut
    assert (cell_copy / "poses.yaml").read_bytes() == before


def _killed_after_its_line(folder: Path) -> bytes:
    """The state a save killed between its log line and its rename leaves: the new text
    in a temporary file, the line naming it. Returns the new text."""
    poses_file = folder / "poses.yaml"
    old = poses_file.read_bytes()
    new = (dump_poses({"grip": [0.0] * 6})).encode()
    (folder / ".poses.yaml.0badc0de.tmp").write_bytes(new)
    entry = {"time": "2025-01-01T00:00:00.000+00:00", "client": "python",
             "file": "poses.yaml", "sha256_before": _sha(old), "sha256_after": _sha(new),
             "changes": {}, "check": {}, "insist": False}
    (folder / "poses.log").write_text(json.dumps(entry) + "\n")
    return new


def test_the_recovery_at_start_does_not_follow_a_planted_link(cell_copy: Path,
                                                              tmp_path: Path) -> None:
    victim = _victim(tmp_path)
    old = (cell_copy / "poses.yaml").read_bytes()
    new = _killed_after_its_line(cell_copy)
    (cell_copy / "poses.yaml~").symlink_to(victim)
    cell = load_cell(cell_copy)
    with pytest.raises(PoseError, match="is a symbolic link") as info:
        PosesStore(cell)
    assert info.value.path == cell_copy / "poses.yaml~"
    assert victim.read_text() == VICTIM_TEXT
    assert (cell_copy / "poses.yaml").read_bytes() == old  # nothing half-done
    # Without the link the start finishes the logged save, with a real backup.
    (cell_copy / "poses.yaml~").unlink()
    PosesStore(cell)
    assert (cell_copy / "poses.yaml").read_bytes() == new
    assert (cell_copy / "poses.yaml~").read_bytes() == old
    assert victim.read_text() == VICTIM_TEXT


def test_a_planted_temporary_link_is_removed_unread(cell_copy: Path, tmp_path: Path) -> None:
    """A leftover temporary name that is a link (to a pipe: reading it would block) is
    removed, never read or renamed into place; its target is untouched."""
    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    victim = _victim(tmp_path)
    before = (cell_copy / "poses.yaml").read_bytes()
    _killed_after_its_line(cell_copy)  # a line: the leftovers' hashes would be compared
    (cell_copy / ".poses.yaml.0badc0de.tmp").unlink()
    (cell_copy / ".poses.yaml.0000beef.tmp").symlink_to(pipe)
    (cell_copy / ".poses.yaml.1111beef.tmp").symlink_to(victim)
    PosesStore(load_cell(cell_copy))
    assert not any(p.name.endswith(".tmp") for p in cell_copy.iterdir())
    assert (cell_copy / "poses.yaml").read_bytes() == before
    assert pipe.exists() and victim.read_text() == VICTIM_TEXT
