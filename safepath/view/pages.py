"""The pages of a review session and the saved poses they share: pages come and go,
a save or a reload reaches every page, and the shared notice says when the routes are
stale or ``poses.yaml`` changed behind the session's back.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import numpy as np
import viser

from ..cell import Cell
from ..errors import SafepathError
from .access import Access
from .clients import ClientEditor, client_address
from .editor import PoseEditor
from .edits import PoseEdits
from .plans import Plans
from .scene_nodes import PoseFrames
from .sync import SharedPoses

__all__ = ["Pages"]

log = logging.getLogger(__name__)


class Pages:
    """Every page's editor, saves and reloads, and the shared notice.

    Args:
        cell: The cell (its ``poses`` are the saved poses).
        poses: The saved poses and every editor's edits.
        access: Who may edit.
        lock: The session's lock.
        frames: The shared taught-pose frames.
        local: The editor of the Python API (shown on the shared stage).
        plans: The routes shown.
        notice: The shared notice (a markdown handle).
        say: Tells every page a line (``error=``, ``notify=``).
        replan: Re-plans with given poses.
        replan_on_save: Re-plan the routes a save makes stale.
    """

    def __init__(self, cell: Cell, poses: SharedPoses, access: Access, lock: Any, *,
                 frames: PoseFrames, local: PoseEditor, plans: Plans, notice: Any,
                 say: Callable[..., None],
                 replan: Callable[[Mapping[str, np.ndarray]], Future[Any]],
                 replan_on_save: bool) -> None:
        self.cell = cell
        self.poses = poses
        self.access = access
        self.clients: dict[int, ClientEditor] = {}
        self._lock = lock
        self._frames, self._local, self._plans, self._notice = frames, local, plans, notice
        self._say, self._replan, self._replan_on_save = say, replan, replan_on_save
        self._replan_pending = False
        self._closed = False

    def connected(self, server: viser.ViserServer, client: viser.ClientHandle) -> None:
        """A page connected: give it its edit folder and edits."""
        host, address = client_address(server, client)
        with self._lock:
            page = ClientEditor(client, address=address, host=host, cell=self.cell,
                                edits=self.poses.new_editor(), access=self.access,
                                lock=self._lock, save=self.save, replan=self._replan,
                                reload=self.reload)
            self.clients[page.client_id] = page
        log.info("page connected from %s (%s)", address,
                 "may edit" if page.may_edit else "read-only")

    def disconnected(self, client: viser.ClientHandle) -> None:
        """A page went away: its edits and its unlock go with it."""
        with self._lock:
            page = self.clients.pop(int(client.client_id), None)
            if page is not None:
                page.close()
                self.poses.drop_editor(page.edits)

    def save(self, edits: PoseEdits, client: str, insist: bool = False) -> Path:
        """Save one editor's edits (see :meth:`ReviewSession.save_edits`)."""
        with self._lock:
            path, changes = self.poses.save(edits, client=client, insist=insist)
            names = self.cell.robot.joint_names
            what = "; ".join(c.describe(names) for c in changes) or "no pose changed"
            self._changed(f"{path.name} saved by {client}: {what}", [c.pose for c in changes])
            return path

    def reload(self, client: str) -> None:
        """Read the poses file again (see :meth:`ReviewSession.reload_poses`)."""
        with self._lock:
            changes = self.poses.reload()
            names = self.cell.robot.joint_names
            what = "; ".join(c.describe(names) for c in changes) or "no pose changed"
            self._changed(f"{self.cell.poses_file().name} reloaded by {client}: {what}",
                          [c.pose for c in changes])

    def plans_changed(self) -> None:
        """Re-plan with the saved poses when a save asked for it and planning is free;
        update the notice."""
        with self._lock:
            if self._replan_pending and not self._closed and not self._plans.running:
                self._replan_pending = False
                if self._plans.stale() and self._plans.timeline.reviews:
                    try:
                        self._replan(self.cell.poses)
                    except SafepathError as exc:
                        log.info("no re-plan after the save: %s", exc)
        self.update_notice()

    def update_notice(self) -> None:
        """The shared notice: stale routes, a poses file changed behind the session."""
        with self._lock:
            if self._closed:
                return
            lines = []
            stale = self._plans.stale() if self._plans.timeline.reviews else []
            if stale:
                doing = "re-planning..." if self._plans.running else "re-plan to update them"
                lines.append(f"**stale routes**: planned with poses that differ from "
                             f"{self.cell.poses_file().name} ({', '.join(stale)}); {doing}")
            on_disk = self.poses.on_disk
            if on_disk is not None:
                names = self.cell.robot.joint_names
                what = ("; ".join(c.describe(names) for c in on_disk)
                        or "unreadable, or formatting only")
                lines.append(f"**{self.cell.poses_file().name} changed on disk** ({what}): "
                             "saving is refused until a page reloads it")
            self._notice.content = "\n\n".join(lines)

    def close(self) -> None:
        """The session stops."""
        self._closed = True

    def _changed(self, text: str, changed: list[str]) -> None:
        """Show a new saved version on every page (holds the lock)."""
        for name in changed:
            if name in self.cell.poses:
                self._frames.set(name, self.cell.poses[name])
        self._local.refresh()
        for page in self.clients.values():
            page.refresh()
            if page.edits.conflicts:
                page.say("conflict: " + ", ".join(page.edits.conflicts) + " changed in "
                         "another save while you edited; take the saved version or keep "
                         "yours", error=True)
        self._say(text, notify=True)
        if changed and self._replan_on_save:
            self._replan_pending = True
        self.plans_changed()
