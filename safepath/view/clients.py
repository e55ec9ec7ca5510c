"""One browser page of a review session: its own edit folder, edits, robot and rights.

Every page that connects gets a :class:`ClientEditor`: an "Edit poses" folder only it
sees, its own :class:`~safepath.view.edits.PoseEdits`, and, while it edits a pose, its
own robot (client-scoped nodes that shadow the shared robot for that page alone, so
the other pages keep watching the playback). Whether it may change anything is asked
of the session's :class:`~safepath.view.access.Access` on every action, server side:
a disabled button is a courtesy, not the check.

A page saves in two steps: "Save poses" checks the edits and shows every value that
would change, at full precision; "Confirm save" writes exactly those values, and is
refused if anything changed in between (an edit that reached the server late, another
page's save). The reviewer has seen every value written: viser's page sends its updates
through one 50 ms throttle that keeps only the latest message, so a value typed just
before a click can be dropped, and the confirmation is where that shows.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import viser

from ..cell import Cell
from ..errors import PoseError, SafepathError
from ..files._io import as_float, as_vector
from .access import Access
from .editor import PoseEditor
from .edits import PoseEdits, PoseStatus
from .panel import NO_POSE, build_edit_panel, typed_joint
from .scene_nodes import PoseFrames
from .stage import Stage

__all__ = ["ClientEditor", "PendingSave", "client_address", "guard"]

log = logging.getLogger(__name__)


def client_address(server: viser.ViserServer, client: viser.ClientHandle) -> tuple[str, str]:
    """``(host, "host:port")`` of a page's websocket peer.

    viser has no public accessor for it; its websocket server keeps the live
    connections by client id. Behind a reverse proxy this is the proxy's address.
    """
    connections = getattr(getattr(server, "_websock_server", None), "_live_connections", {})
    peer = getattr(connections.get(client.client_id), "remote_address", None)
    if not peer:
        return "unknown", f"unknown (client {client.client_id})"
    host, port = str(peer[0]), int(peer[1])
    return host, (f"[{host}]:{port}" if ":" in host else f"{host}:{port}")


def guard(fn: Callable[[Any], object], report: Callable[[str], None]) -> Callable[[Any], None]:
    """A GUI callback that reports failures (one line) instead of raising."""
    @functools.wraps(fn)
    def callback(event: Any) -> None:
        if getattr(event, "client", None) is None:
            return  # the server changed the value itself
        try:
            fn(event)
        except SafepathError as exc:
            report(str(exc))
        except Exception as exc:
            log.debug("GUI callback %s failed", getattr(fn, "__name__", fn), exc_info=True)
            report(f"internal error: {type(exc).__name__}: {exc}")
    return callback


@dataclass(frozen=True)
class PendingSave:
    """A save shown to a page, waiting for "Confirm save".

    Attributes:
        base: Digest of the poses file version the edits were made on.
        poses: Every pose the save would write [rad].
        insist: Whether a pose in collision would be saved on purpose.
        summary: What the page shows: every value that would change, at full precision.
    """

    base: str
    poses: dict[str, np.ndarray] = field(repr=False)
    insist: bool
    summary: str

    def matches(self, base: str, poses: dict[str, np.ndarray]) -> bool:
        """Whether a save of ``poses`` over version ``base`` writes exactly what was
        shown."""
        return (base == self.base and poses.keys() == self.poses.keys()
                and all(np.array_equal(poses[k], self.poses[k]) for k in poses))


def describe_save(saved: dict[str, np.ndarray], poses: dict[str, np.ndarray],
                  joint_names: tuple[str, ...] | list[str], *, insist: bool) -> str:
    """Markdown: each value a save of ``poses`` over ``saved`` would change, written as
    it would be saved (the shortest text of the double) [rad]."""
    lines = []
    for name, q in poses.items():
        before = saved.get(name)
        moved = [j for j in range(len(q)) if before is None or q[j] != before[j]]
        parts = [f"{joint_names[j]} = {float(q[j])!r}"
                 + ("" if before is None else f" (was {float(before[j]):.7g})")
                 for j in moved]
        if parts:
            lines.append(f"- **{name}**: {', '.join(parts)} rad")
    what = "\n".join(lines) or "- no value changes"
    on_purpose = "\n\nsaved **in collision on purpose** (I insist)" if insist else ""
    return (f"**Would save** (check the values, then press Confirm save):\n\n{what}"
            f"{on_purpose}")


class ClientEditor:
    """One page's editing (see the module docstring). The session calls every method
    under its lock; the page's callbacks take ``lock`` themselves.

    Args:
        client: The page.
        address: Its ``host:port``.
        host: Its host (the token rate limit counts per host).
        cell: The cell.
        edits: This page's edit buffer.
        access: The session's edit rights.
        lock: The session's lock.
        save: Writes an edit buffer for a client: ``save(edits, address, insist)``.
        replan: Re-plans with given poses.
        reload: Reads the poses file again for every page.
    """

    def __init__(self, client: viser.ClientHandle, *, address: str, host: str, cell: Cell,
                 edits: PoseEdits, access: Access, lock: Any,
                 save: Callable[[PoseEdits, str, bool], Path],
                 replan: Callable[[dict[str, Any]], Future[Any]],
                 reload: Callable[[str], None]) -> None:
        self.client = client
        self.address = address
        self.host = host
        self.cell = cell
        self.edits = edits
        self.access = access
        self.messages: list[str] = []
        self._lock = lock
        self._save, self._replan, self._reload = save, replan, reload
        self._stage: Stage | None = None
        self._pending: PendingSave | None = None
        self.widgets = build_edit_panel(client.gui, cell.robot, list(edits.base.poses),
                                        token=access.required)
        gizmo = client.scene.add_transform_controls("/edit/tcp", scale=0.12,
                                                    depth_test=False, visible=False)
        self.frames = PoseFrames(client, cell.robot, {})
        self.editor = PoseEditor(cell, edits, stage=self._own_stage, frames=self.frames,
                                 widgets=self.widgets, gizmo=gizmo)
        self._wire(gizmo)
        self.update_access()

    @property
    def client_id(self) -> int:
        """viser's id of the page."""
        return int(self.client.client_id)

    @property
    def may_edit(self) -> bool:
        """Whether this page may edit and save."""
        return self.access.may_edit(self.client_id)

    # -- actions (each checks the page's rights) --------------------------------------------
    def unlock(self, token: str) -> None:
        """Unlock editing with the session's token.

        Raises:
            AccessDenied: Wrong token, or too many wrong ones from this host.
        """
        try:
            self.access.unlock(self.client_id, token, host=self.host, address=self.address)
        finally:
            if self.widgets.token is not None:
                self.widgets.token.value = ""
            self.update_access()
        self.say(f"editing unlocked for this page ({self.address})")

    def edit_pose(self, name: str) -> PoseStatus:
        """Show pose ``name`` on this page (watching needs no rights)."""
        status = self.editor.edit_pose(name)
        self.update_access()
        return status

    def set_joint(self, j: int, value: Any) -> PoseStatus:
        """Edit joint ``j`` of the selected pose.

        Raises:
            PoseError: ``value`` is not a finite number (a string is refused, not read).
        """
        self._check("edit poses")
        value = as_float(value, path=None, key=self.cell.robot.joint_names[j],
                         error=PoseError)
        self._drop_pending()
        return self.editor.set_joint(j, value)

    def set_joints(self, q: Any) -> PoseStatus:
        """Edit the selected pose to ``q`` [rad].

        Raises:
            PoseError: ``q`` is not a list of finite numbers (strings are refused).
        """
        self._check("edit poses")
        if not isinstance(q, np.ndarray) or q.dtype.kind not in "fi":
            q = np.asarray(as_vector(list(q) if isinstance(q, np.ndarray) else q, None,
                                     path=None, key="joints", error=PoseError))
        self._drop_pending()
        return self.editor.set_joints(q)

    def drag_tcp(self, wxyz: Any, position: Any) -> PoseStatus:
        """Edit the selected pose from a TCP gizmo drag."""
        self._check("edit poses")
        self._drop_pending()
        return self.editor.drag_tcp(wxyz, position)

    def reset_pose(self) -> PoseStatus:
        """Drop the edit of the selected pose."""
        self._check("edit poses")
        self._drop_pending()
        return self.editor.reset_pose()

    def take_saved(self) -> PoseStatus:
        """Conflict on the selected pose: drop this page's edit."""
        self._check("resolve conflicts")
        self._drop_pending()
        status = self.edits.take_saved(self.editor.selected())
        self.refresh()
        return status

    def keep_mine(self) -> PoseStatus:
        """Conflict on the selected pose: keep this page's edit over the saved version."""
        self._check("resolve conflicts")
        self._drop_pending()
        status = self.edits.keep_mine(self.editor.selected())
        self.refresh()
        return status

    def save(self, *, insist: bool = False) -> PendingSave:
        """Check this page's edits and show what a save would write; nothing is written
        until :meth:`confirm_save`.

        Raises:
            AccessDenied: The page is read-only.
            SafepathError: Nothing is edited.
            PosesChanged: An edit is in conflict.
            OutsideLimits: An edited pose is outside the joint limits.
            CollisionError: An edited pose collides and ``insist`` is false.
        """
        self._check("save poses")
        self._drop_pending()
        poses, _ = self.edits.to_save(insist=insist)
        summary = describe_save(self.edits.base.poses, poses, self.cell.robot.joint_names,
                                insist=insist)
        self._pending = PendingSave(self.edits.base.digest, poses, insist, summary)
        self.widgets.to_save.content = summary
        self.update_access()
        return self._pending

    def confirm_save(self) -> Path:
        """Write what :meth:`save` showed (see :meth:`ReviewSession.save_edits`).

        Raises:
            AccessDenied: The page is read-only.
            SafepathError: No save was shown, or the poses changed since it was shown
                (nothing is written: press Save poses again).
        """
        self._check("save poses")
        pending = self._pending
        self._drop_pending()
        if pending is None:
            raise SafepathError("not saved: press Save poses first, to see what would be "
                                "saved")
        poses, _ = self.edits.to_save(insist=pending.insist)
        if not pending.matches(self.edits.base.digest, poses):
            raise SafepathError("not saved: the poses changed after Save poses showed them "
                                "(a late edit, or another save); check them and press Save "
                                "poses again")
        return self._save(self.edits, self.address, pending.insist)

    def replan(self) -> Future[Any]:
        """Re-plan the routes with this page's poses (edits applied)."""
        self._check("re-plan")
        return self._replan(self.edits.poses())

    def reload(self) -> None:
        """Read the poses file again (every page moves onto it)."""
        self._check("reload poses.yaml")
        self._drop_pending()
        self._reload(self.address)

    def review(self) -> None:
        """Stop editing: this page shows the shared playback again."""
        self.editor.leave()
        if self._stage is not None:
            self._stage.remove()
            self._stage = None
        self.update_access()

    # -- display ----------------------------------------------------------------------------
    @property
    def pending(self) -> PendingSave | None:
        """The save shown and waiting for its confirmation, if any."""
        return self._pending

    def refresh(self) -> None:
        """Show the current edits and conflicts (after a save, a reload, a rebase); a
        save waiting for its confirmation is dropped (the poses it showed moved on)."""
        self._drop_pending()
        for name in [n for n in self.frames.frames if n not in self.edits.edits]:
            self.frames.remove(name)
        for name in self.edits.edits:
            self.frames.set(name, self.edits.edits[name])
        self.editor.refresh()
        self.update_access()

    def update_access(self) -> None:
        """Enable the widgets this page may use and say why the others are off."""
        may_edit = self.may_edit
        pose = self.editor.pose
        self.widgets.enable(may_edit=may_edit, editing=pose is not None,
                            conflict=pose is not None and pose in self.edits.conflicts,
                            pending=self._pending is not None)
        # A read-only page looks at a pose without the gizmo it could not drag.
        self.editor.set_gizmo_visible(may_edit and bool(self.widgets.gizmo_enabled.value))
        lines = []
        if not may_edit:
            lines.append(f"**read-only**: enter the edit token ({self.access.where}) to "
                         "edit and save poses")
        elif self.access.required:
            lines.append(f"editing unlocked for this page ({self.address})")
        if self.edits.conflicts:
            names = self.cell.robot.joint_names
            lines.append("**conflict**: changed in another save while you edited: " + "; ".join(
                c.describe(names) for c in self.edits.conflicts.values()) +
                " (pick the pose, then take the saved version or keep yours)")
        self.widgets.access_note.content = "\n\n".join(lines)

    def say(self, text: str, *, error: bool = False) -> None:
        """Tell this page (a notification; errors in red)."""
        self.messages.append(text)
        if error:
            log.warning("%s: %s", self.address, text)
        self.client.add_notification("safepath", text, color="red" if error else "blue",
                                     auto_close_seconds=10.0)

    def close(self) -> None:
        """The page went away."""
        self.access.forget(self.client_id)

    # -- internals --------------------------------------------------------------------------
    def _check(self, what: str) -> None:
        self.access.check(self.client_id, self.address, what)

    def _drop_pending(self) -> None:
        """Forget a save shown for confirmation (the edits it showed change)."""
        if self._pending is not None:
            self._pending = None
            self.widgets.to_save.content = ""
            self.widgets.confirm.visible = False

    def _own_stage(self) -> Stage:
        if self._stage is None:
            self._stage = Stage(self.client, self.cell)
        return self._stage

    def _wire(self, gizmo: Any) -> None:
        w = self.widgets

        def on(handle: Any, fn: Callable[[Any], object], *, button: bool = False) -> None:
            def locked(event: Any) -> None:
                with self._lock:
                    try:
                        fn(event)
                    except SafepathError:
                        self.refresh()  # put a refused joint box or gizmo back
                        raise
            callback = guard(locked, lambda text: self.say(text, error=True))
            (handle.on_click if button else handle.on_update)(callback)

        if w.unlock is not None:
            on(w.unlock, lambda e: self.unlock(str(w.token.value)), button=True)
        on(w.pose, lambda e: self.review() if e.target.value == NO_POSE
           else self.edit_pose(e.target.value))
        for j, joint_box in enumerate(w.joints):
            on(joint_box, functools.partial(
                lambda j, e: self.set_joint(j, typed_joint(e.target.value)), j))
        on(w.gizmo_enabled, lambda e: self.update_access())
        on(w.reset, lambda e: self.reset_pose(), button=True)
        on(w.take_saved, lambda e: self.take_saved(), button=True)
        on(w.keep_mine, lambda e: self.keep_mine(), button=True)
        on(w.replan, lambda e: self.replan(), button=True)
        on(w.save, lambda e: self.save(insist=bool(w.insist.value)), button=True)
        on(w.confirm, lambda e: self.confirm_save(), button=True)
        on(w.reload, lambda e: self.reload(), button=True)
        on(gizmo, lambda e: self.drag_tcp(e.target.wxyz, e.target.position))
