"""The poses file of a review session: read with its content hash, saved only over the
version the editors loaded, every save recorded in an append-only log.

A save is refused (:class:`PosesChanged`, naming the poses that differ) when
``poses.yaml`` no longer has the content the session loaded: someone edited it in a
text editor, or another session saved. Saves of sessions on the same folder are
serialised by an exclusive ``flock`` on the log file, so two sessions cannot both pass
the check and overwrite each other. A text editor takes no lock: a write landing in the
instant between the check and the rename is not detected (the log and the backup
``poses.yaml~`` keep what was replaced).

The log, ``poses.log`` beside ``poses.yaml``, gets one JSON object per line and save:
``time`` (UTC, ISO 8601), ``client`` (address of the page, or ``python``), ``file``,
``sha256_before`` / ``sha256_after`` (of the file's bytes), ``changes`` (pose name ->
``{"from": [...], "to": [...]}`` in [rad], null for a pose added or removed) and
``check`` (pose name -> the live check at save time: ``valid``, ``margin_ok``,
``clearance_mm``, ``collisions``), and ``insist`` (saved in collision on purpose).

The log is written ahead: a save writes the new file's text to a temporary file beside
it (``.poses.yaml.<random>.tmp``, flushed to disk), then appends its log line (flushed to
disk), and only then renames the temporary file over ``poses.yaml``. So a process killed
at any instant leaves one of: the file unchanged and no line (a leftover temporary file,
removed at the next start or save); the line written and the file not yet replaced (the
next start or save finishes the rename from the temporary file, whose hash the line
names); or both done. The file never changes without its line, so one that follows the
log sees a save's line an instant before the file changes: the save has landed once the
file's hash is the line's ``sha256_after`` (the session tells its pages only then). If
the rename fails (a full disk, a permission), a line ``{"time", "client", "file",
"undone": <time of the save's line>, "reason"}`` withdraws the save's line.

No write follows a link (see :mod:`safepath.files._io`): ``poses.yaml``, its backup
``poses.yaml~`` and ``poses.log`` must be regular files, or the save (and the start that
would finish a killed save) is refused naming the file; a leftover temporary file that is
not a regular file is removed, never read.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import os
import stat
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from ..cell import Cell
from ..cell.poses import load_poses, save_poses
from ..errors import ConfigError, PoseError, SafepathError
from ..files._io import keep_backup, leftover_temporaries, open_no_follow, read_bytes

__all__ = ["PoseChange", "PosesChanged", "PosesSnapshot", "PosesStore", "differences"]

log = logging.getLogger(__name__)

#: Name of the save log beside the poses file.
LOG_NAME = "poses.log"
#: How much of the log's end is read to find its last line [bytes].
_TAIL = 1 << 20


@dataclass(frozen=True)
class PosesSnapshot:
    """One version of the poses file.

    Attributes:
        digest: SHA-256 of the file's bytes (empty when there is no file).
        poses: Its poses [rad], in file order (do not mutate).
    """

    digest: str
    poses: dict[str, np.ndarray] = field(repr=False)


@dataclass(frozen=True)
class PoseChange:
    """How one pose differs between two versions.

    Attributes:
        pose: Pose name.
        before: Joint vector in the first version [rad] (None: not there).
        after: Joint vector in the second version [rad] (None: not there).
    """

    pose: str
    before: np.ndarray | None = field(repr=False)
    after: np.ndarray | None = field(repr=False)

    def describe(self, joint_names: list[str] | tuple[str, ...]) -> str:
        """One phrase: which joints moved and by how much."""
        if self.before is None:
            return f"{self.pose} added"
        if self.after is None:
            return f"{self.pose} removed"
        delta = self.after - self.before
        moved = [j for j in np.argsort(-np.abs(delta)) if abs(delta[j]) > 0][:2]
        parts = [f"{joint_names[j]} {self.before[j]:.4f} -> {self.after[j]:.4f} rad"
                 for j in moved]
        return f"{self.pose} ({', '.join(parts)})"

    def to_json(self) -> dict[str, Any]:
        """``{"from": [...], "to": [...]}`` [rad] (None for a missing side)."""
        def values(q: np.ndarray | None) -> list[float] | None:
            return None if q is None else [float(v) for v in q]
        return {"from": values(self.before), "to": values(self.after)}


def differences(before: Mapping[str, np.ndarray], after: Mapping[str, np.ndarray]
                ) -> list[PoseChange]:
    """The poses that differ between two versions (order: ``before``'s, then new ones)."""
    out = []
    for name in [*before, *(n for n in after if n not in before)]:
        a, b = before.get(name), after.get(name)
        if a is None or b is None or not np.array_equal(a, b):
            out.append(PoseChange(name, a, b))
    return out


class PosesChanged(SafepathError):
    """A save was refused so that no edit is lost: the file changed since it was loaded,
    or a pose edited here was saved meanwhile by someone else.

    Attributes:
        path: The poses file.
        changes: What differs between the version loaded and the one found.
        conflicts: Poses edited here that were also changed there.
    """

    def __init__(self, reason: str, *, path: Path, changes: list[PoseChange],
                 conflicts: list[str]) -> None:
        self.path = path
        self.changes = changes
        self.conflicts = conflicts
        self.reason = reason
        super().__init__(reason)


class PosesStore:
    """Reads and saves one cell's poses file (see the module docstring).

    A cell built in Python may have no poses file: its poses are then the only version,
    and a save is refused with a ``ConfigError``. One whose ``poses_path`` does not
    exist yet starts from its own poses, and the first save creates the file.

    Args:
        cell: The cell; its ``poses`` are left to the caller.

    Raises:
        ConfigError: The cell was built in Python with a ``poses_path`` that exists and
            holds other poses than the cell's (names the file and the poses).
    """

    def __init__(self, cell: Cell) -> None:
        self.robot = cell.robot
        #: The poses file, or None: the cell was built in Python without one.
        self.path: Path | None = cell.poses_path
        self.log_path = None if self.path is None else self.path.with_name(LOG_NAME)
        if self.path is not None and self.log_path is not None \
                and leftover_temporaries(self.path):
            with self._open_log() as log_file:
                fcntl.flock(log_file, fcntl.LOCK_EX)
                self._recover(log_file)
        # The cell's own poses are the version in force while there is no file.
        self._initial = {k: np.array(q) for k, q in cell.poses.items()} \
            if self.path is None or not self.path.exists() else None
        if cell.folder is None and self._initial is None:
            changes = differences(cell.poses, self.read().poses)
            if changes:
                what = "; ".join(c.describe(self.robot.joint_names) for c in changes)
                raise ConfigError(f"the file holds other poses than the cell's ({what}): "
                                  "build the cell from it (safepath.load_poses) or give a "
                                  "new poses_path", path=self.path, key="poses_path")

    def read(self) -> PosesSnapshot:
        """The file as it is now, with its hash (the cell's own poses, hash ``""``, while
        it has no file).

        Raises:
            PoseError: The file is malformed (names file and key).
        """
        if self.path is None:
            return PosesSnapshot("", dict(self._initial or {}))
        for _ in range(5):
            raw = self._bytes()
            if raw is not None:
                poses = load_poses(self.path, self.robot)
            else:
                poses = dict(self._initial) if self._initial is not None else {}
            if self._bytes() == raw:  # not rewritten while it was parsed
                return PosesSnapshot(_digest(raw), poses)
        raise PoseError("the file keeps changing while it is read", path=self.path)

    def save(self, base: PosesSnapshot, poses: Mapping[str, np.ndarray], *, client: str,
             checks: Mapping[str, dict[str, Any]], insist: bool = False) -> PosesSnapshot:
        """Write ``poses`` if the file is still ``base``; log the save.

        Args:
            base: The version the poses were edited from.
            poses: Every pose to write [rad].
            client: Who saves (page address, or ``python``).
            checks: The live check of every changed pose (see the module docstring).
            insist: Whether a pose in collision is saved on purpose.

        Returns:
            The new version.

        Raises:
            ConfigError: The cell has no poses file (built in Python without
                ``poses_path``): nothing is written.
            PosesChanged: The file is not ``base`` any more (nothing is written).
            PoseError: A pose is malformed or outside the limits (nothing is written).
        """
        if self.path is None or self.log_path is None:
            raise ConfigError("not saved: the cell was built in Python without a poses "
                              "file; build it with Cell(..., poses_path=PATH) to save its "
                              "poses to PATH", key="poses_path")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self._open_log() as log_file:
            fcntl.flock(log_file, fcntl.LOCK_EX)
            self._recover(log_file)
            current = self.read()
            if current.digest != base.digest:
                changes = differences(base.poses, current.poses)
                names = self.robot.joint_names
                what = "; ".join(c.describe(names) for c in changes) or "formatting only"
                raise PosesChanged(f"not saved: {self.path.name} changed since it was loaded "
                                   f"({what}); reload it to merge pose by pose",
                                   path=self.path, changes=changes, conflicts=[])
            entry = {
                "time": _now(), "client": client, "file": self.path.name,
                "sha256_before": base.digest, "sha256_after": "",
                "changes": {c.pose: c.to_json() for c in differences(
                    base.poses, {k: np.asarray(q, dtype=float) for k, q in poses.items()})},
                "check": dict(checks), "insist": insist,
            }

            def write_ahead(tmp: Path) -> None:
                entry["sha256_after"] = _digest(tmp.read_bytes())
                _fsync_folder(tmp.parent)  # the temporary file's name is on disk too
                append_log_entry(log_file, entry)

            try:
                save_poses(self.path, poses, self.robot, backup=True,
                           before_replace=write_ahead)
            except SafepathError as exc:
                if entry["sha256_after"]:  # logged, then the rename failed
                    append_log_entry(log_file, {"time": _now(), "client": client,
                                                "file": self.path.name,
                                                "undone": entry["time"], "reason": str(exc)})
                raise
            _fsync_folder(self.path.parent)
            new = self.read()
        log.info("%s saved by %s", self.path, client)
        return new

    def _open_log(self) -> Any:
        """The save log, opened to read and append (created if missing), never through a
        link.

        Raises:
            PoseError: ``poses.log`` is a symbolic link or not a regular file.
        """
        assert self.log_path is not None
        fd = open_no_follow(self.log_path, os.O_RDWR | os.O_APPEND | os.O_CREAT,
                            error=PoseError)
        return os.fdopen(fd, "a+", encoding="utf-8")

    def _recover(self, log_file: Any) -> None:
        """Finish a save killed between its log line and its rename; remove the temporary
        files of saves killed before their line, and a torn last line. (Under the log's
        lock, ``log_file``: no save of this file is under way.)

        Raises:
            PoseError: A killed save cannot be finished: ``poses.yaml`` or its backup
                name is a link or not a regular file (nothing is changed).
        """
        assert self.path is not None and self.log_path is not None
        leftovers = leftover_temporaries(self.path)
        if not leftovers:
            return
        last = _last_entry(log_file)
        on_disk = _digest(self._bytes())
        for tmp in leftovers:
            try:
                regular = stat.S_ISREG(os.lstat(tmp).st_mode)
            except FileNotFoundError:
                continue
            logged = (regular and last is not None and on_disk == last.get("sha256_before")
                      and on_disk != last.get("sha256_after")
                      and _digest(read_bytes(tmp, error=PoseError))
                      == last.get("sha256_after"))
            if logged:
                assert last is not None
                keep_backup(self.path, error=PoseError)
                os.replace(tmp, self.path)
                _fsync_folder(self.path.parent)
                on_disk = str(last["sha256_after"])
                log.warning("%s: finished the save logged at %s by %s (the saving process "
                            "stopped before replacing the file)", self.path,
                            last.get("time"), last.get("client"))
            elif not regular:  # no writer of ours left it: removed, never read
                tmp.unlink(missing_ok=True)
                log.warning("%s: removed %s, which is not a regular file (a save's "
                            "temporary file is)", self.path, tmp.name)
            else:
                tmp.unlink(missing_ok=True)
                log.info("%s: removed %s, left by a save that stopped before its log line",
                         self.path, tmp.name)

    def _bytes(self) -> bytes | None:
        """The poses file's bytes, None if there is none (read as every file is read:
        :func:`safepath.files._io.read_bytes`)."""
        if self.path is None or not os.path.lexists(self.path):
            return None
        return read_bytes(self.path, error=PoseError)


def _digest(raw: bytes | None) -> str:
    return "" if raw is None else hashlib.sha256(raw).hexdigest()


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def append_log_entry(log_file: Any, entry: dict[str, Any]) -> None:
    """Append ``entry`` as one JSON line to the open poses log ``log_file``
    (``poses.log``), on disk before this returns: every save is logged so, before the
    poses file is replaced."""
    log_file.write(json.dumps(entry) + "\n")
    log_file.flush()
    os.fsync(log_file.fileno())


def _fsync_folder(folder: Path) -> None:
    """Put a folder's entries (a new or renamed file's name) on disk."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def unfinished_save(path: str | Path) -> dict[str, Any] | None:
    """The log entry of a save of ``path`` that stopped between its log line and its
    rename (a temporary file beside ``path`` holds the logged new poses; ``path`` still
    holds the ones before), or None. Reads only: the review session finishes such a
    save when it opens the cell (:class:`PosesStore`)."""
    path = Path(path)
    log_path = path.with_name(LOG_NAME)
    leftovers = leftover_temporaries(path)
    if not leftovers or not os.path.lexists(log_path) or not os.path.lexists(path):
        return None
    try:
        raw = read_bytes(log_path, error=PoseError)
        on_disk = _digest(read_bytes(path, error=PoseError))
    except PoseError:
        return None
    lines = [line for line in raw.splitlines() if line.strip()]
    try:
        last = json.loads(lines[-1]) if raw.endswith(b"\n") and lines else None
    except ValueError:
        return None
    if not isinstance(last, dict) or on_disk != last.get("sha256_before") \
            or on_disk == last.get("sha256_after"):
        return None
    for tmp in leftovers:
        try:
            if stat.S_ISREG(os.lstat(tmp).st_mode) and \
                    _digest(read_bytes(tmp, error=PoseError)) == last.get("sha256_after"):
                return last
        except (OSError, PoseError):
            continue
    return None


def _last_entry(log_file: Any) -> dict[str, Any] | None:
    """The last whole line of the open log ``log_file``, parsed; a torn last line (a kill
    while it was written, before its save renamed anything) is cut off first."""
    log_file.flush()
    fd = log_file.fileno()
    size = os.fstat(fd).st_size
    start = max(0, size - _TAIL)
    tail = os.pread(fd, size - start, start)
    if tail and not tail.endswith(b"\n"):
        keep = tail.rfind(b"\n") + 1
        os.ftruncate(fd, start + keep)
        tail = tail[:keep]
    lines = tail.splitlines()
    if not lines:
        return None
    try:
        entry = json.loads(lines[-1])
    except ValueError:
        return None
    return entry if isinstance(entry, dict) else None
