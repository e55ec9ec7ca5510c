"""The saved poses every editor of a session shares, and how saves reach all of them.

:class:`SharedPoses` holds the version of ``poses.yaml`` the session shows (its base)
and every editor's :class:`~safepath.view.edits.PoseEdits`. A save writes one editor's
edits through the :class:`~safepath.view.store.PosesStore` (refused if the file is not
that base any more), then moves every other editor onto the new version: their edits
of other poses carry over, their edits of a pose just saved become conflicts. A reload
does the same with the file as found. Between saves, :meth:`SharedPoses.watch` notices
when the file was changed behind the session's back (it is not adopted silently:
saving stays refused until someone reloads).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..cell import Cell
from ..collision import CollisionChecker
from ..errors import SafepathError
from .edits import PoseEdits
from .store import PoseChange, PosesSnapshot, PosesStore, differences

__all__ = ["SharedPoses"]

log = logging.getLogger(__name__)


class SharedPoses:
    """The session's saved poses and its editors (see the module docstring).

    Not thread-safe: the session calls it under its lock.

    Args:
        cell: The cell; its ``poses`` follow every version adopted.
        store: The poses file.
    """

    def __init__(self, cell: Cell, store: PosesStore) -> None:
        self.cell = cell
        self.store = store
        self.current = store.read()
        self.editors: list[PoseEdits] = []
        self.on_disk: list[PoseChange] | None = None
        self._checkers: dict[tuple[str, bool], CollisionChecker] = {}
        self._stat: tuple[int, int] | None = self._file_stat()
        self._seen = self.current.digest
        self._set_cell_poses(self.current)

    def new_editor(self) -> PoseEdits:
        """An edit buffer on the current version, kept up to date by saves and reloads."""
        edits = PoseEdits(self.cell, self.current, checkers=self._checkers)
        self.editors.append(edits)
        return edits

    def drop_editor(self, edits: PoseEdits) -> None:
        """Forget an editor (its page went away)."""
        if edits in self.editors:
            self.editors.remove(edits)

    def save(self, edits: PoseEdits, *, client: str, insist: bool = False
             ) -> tuple[Path, list[PoseChange]]:
        """Save one editor's edits; move every editor onto the new version.

        Returns:
            The poses file and what changed in it.

        Raises:
            SafepathError: Nothing edited.
            ConfigError: The cell has no poses file (built in Python without one).
            PosesChanged: A conflict in ``edits``, or the file is not the version the
                edits were made on (nothing is written).
            CollisionError: An edited pose collides and ``insist`` is false.
            PoseError: A pose outside the joint limits.
        """
        poses, checks = edits.to_save(insist=insist)
        new = self.store.save(edits.base, poses, client=client, checks=checks, insist=insist)
        edits.saved(new)
        assert self.store.path is not None  # the store saves only to a file
        return self.store.path, self._adopt(new)

    def reload(self) -> list[PoseChange]:
        """Read the file again and move every editor onto it; what changed.

        Raises:
            PoseError: The file is malformed (nothing changes).
        """
        return self._adopt(self.store.read())

    def watch(self) -> bool:
        """Check whether the file changed on disk without the session (cheap when it did
        not: a ``stat``); whether :attr:`on_disk` changed.

        :attr:`on_disk` is then None (the file is the session's version) or what differs
        on disk (empty when the file cannot be read, or differs in formatting only).
        """
        stat = self._file_stat()
        if stat == self._stat:
            return False
        self._stat = stat
        try:
            found: PosesSnapshot | None = self.store.read()
        except SafepathError as exc:  # a half-edited file: say so, keep the session's
            log.info("poses file unreadable: %s", exc)
            found = None
        digest = "unreadable" if found is None else found.digest
        if digest == self._seen:
            return False
        self._seen = digest
        if found is not None and found.digest == self.current.digest:
            self.on_disk = None
        else:
            self.on_disk = differences(self.current.poses, found.poses) if found else []
        return True

    def _adopt(self, new: PosesSnapshot) -> list[PoseChange]:
        changes = differences(self.current.poses, new.poses)
        self.current = new
        self._set_cell_poses(new)
        for edits in self.editors:
            edits.rebase(new)
        self.on_disk = None
        self._stat, self._seen = self._file_stat(), new.digest
        return changes

    def _set_cell_poses(self, snapshot: PosesSnapshot) -> None:
        self.cell.poses.clear()
        self.cell.poses.update({k: np.array(q) for k, q in snapshot.poses.items()})

    def _file_stat(self) -> tuple[int, int] | None:
        if self.store.path is None:
            return None
        try:
            st = self.store.path.stat()
        except FileNotFoundError:
            return None
        return st.st_mtime_ns, st.st_size
