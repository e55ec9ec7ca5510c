"""Who may edit in a review session, and how saves keep every edit: the edit token and
its rate limit, the console lines of ``safepath view --host``, saves refused when
``poses.yaml`` changed behind the session (the difference named), reload and merge,
and the save log. Real viser servers on free ports; the two-page flow in a real
browser is in test_browser.py."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from safepath import InputError, SafepathError, load_poses
from safepath.cell.poses import dump_poses
from safepath.errors import PoseError
from safepath.view import ReviewSession, ViewOptions
from safepath.view.access import Access, AccessDenied
from safepath.view.store import PosesChanged

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
def session(cell_copy: Path, plans_dir: Path) -> Iterator[ReviewSession]:
    """A session of a writable copy of the cell (no re-plan after saves)."""
    s = ReviewSession(cell_copy, plans=plans_dir,
                      options=ViewOptions(port=0, replan_on_save=False)).start()
    yield s
    s.stop()


def test_the_token_is_needed_beyond_loopback_or_when_given(cell_dir: Path) -> None:
    assert ReviewSession(cell_dir).token is None
    exposed = ReviewSession(cell_dir, options=ViewOptions(host="0.0.0.0"))
    assert exposed.token is not None and len(exposed.token) >= 12
    assert exposed.access.required and not exposed.access.may_edit(0)
    assert ReviewSession(cell_dir, options=ViewOptions(host="0.0.0.0")).token != exposed.token
    given = ReviewSession(cell_dir, options=ViewOptions(token="lab-token-1"))
    assert given.token == "lab-token-1" and not given.access.may_edit(0)
    anonymous = ReviewSession(cell_dir, options=ViewOptions(host="0.0.0.0",
                                                            allow_anonymous_edit=True))
    assert anonymous.token is None and anonymous.access.may_edit(0)
    with pytest.raises(InputError, match="at least 8"):
        ViewOptions(token="short")
    with pytest.raises(InputError, match="exclude each other"):
        ViewOptions(token="lab-token-1", allow_anonymous_edit=True)


def test_wrong_tokens_are_refused_and_rate_limited() -> None:
    now = [0.0]
    access = Access("right-token", attempts=3, host_attempts=5, window=60.0,
                    clock=lambda: now[0])
    for left in (2, 1, 0):
        with pytest.raises(AccessDenied, match=f"wrong token \\({left} more"):
            access.unlock(1, "guess", host="10.0.0.5", address="10.0.0.5:4000")
    # The right token from that page is not even checked until the window passed.
    with pytest.raises(AccessDenied, match="too many wrong tokens from this page") as info:
        access.unlock(1, "right-token", host="10.0.0.5", address="10.0.0.5:4000")
    assert info.value.retry_after == pytest.approx(60.0) and not access.may_edit(1)
    # Another page of the same host still may try; the host's ceiling counts them all.
    for left in (1, 0):
        with pytest.raises(AccessDenied, match=f"wrong token \\({left} more"):
            access.unlock(3, "guess", host="10.0.0.5", address="10.0.0.5:4001")
    with pytest.raises(AccessDenied, match="too many wrong tokens from 10.0.0.5 \\(all its"):
        access.unlock(4, "right-token", host="10.0.0.5", address="10.0.0.5:4002")
    # Another host is not affected; the page it unlocks is the only one unlocked.
    access.unlock(2, "right-token", host="10.0.0.6", address="10.0.0.6:4000")
    assert access.may_edit(2) and not access.may_edit(1)
    with pytest.raises(AccessDenied, match="read-only"):
        access.check(1, "10.0.0.5:4000")
    now[0] = 60.5
    access.unlock(1, "right-token", host="10.0.0.5", address="10.0.0.5:4002")
    assert access.may_edit(1)
    access.forget(1)
    assert not access.may_edit(1)


@pytest.fixture()
def raw_pages() -> Iterator[Callable[[ReviewSession], Any]]:
    """Open pages on a session as viser's client does (a websocket, then its first camera
    message), without a browser; each is the session's ClientEditor for it."""
    import msgspec
    import viser
    from websockets.sync.client import connect

    sockets = []

    def new_page(session: ReviewSession) -> Any:
        known = set(session.clients)
        sock = connect(f"ws://127.0.0.1:{session.port}", max_size=None,
                       subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
                       open_timeout=10)
        sockets.append(sock)
        sock.send(msgspec.msgpack.encode({
            "type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
            "position": [1.0, 1.0, 1.0], "fov": 1.0, "near": 0.01, "far": 100.0,
            "image_height": 600, "image_width": 800, "look_at": [0.0, 0.0, 0.0],
            "up_direction": [0.0, 0.0, 1.0]}))
        wait_for(lambda: set(session.clients) - known, 10.0, "the page never connected")
        (new,) = set(session.clients) - known
        return session.clients[new]

    yield new_page
    for sock in sockets:
        sock.close()


def test_a_page_guessing_tokens_locks_out_itself_not_its_host(
        cell_copy: Path, raw_pages: Callable[[ReviewSession], Any]) -> None:
    """Pages from one host: the one that guesses is locked out, the others still
    unlock; past the host's ceiling, a new page of that host is refused too."""
    token = "review-token-42"
    session = ReviewSession(cell_copy, options=ViewOptions(
        port=0, token=token, token_attempts=3, token_host_attempts=5, plan_on_start=False,
        replan_on_save=False)).start()
    try:
        guesser, other = raw_pages(session), raw_pages(session)
        assert guesser.host == other.host == "127.0.0.1"
        assert "the token this session was started with" in guesser.widgets.access_note.content
        for _ in range(3):
            with pytest.raises(AccessDenied, match="wrong token"), session.locked():
                guesser.unlock("not-the-token")
        with pytest.raises(AccessDenied, match="from this page"), session.locked():
            guesser.unlock(token)
        with session.locked():
            other.unlock(token)  # the host is not locked out by one page
        assert other.may_edit and not guesser.may_edit
        third = raw_pages(session)
        for _ in range(2):  # the host's 4th and 5th wrong tokens
            with pytest.raises(AccessDenied, match="wrong token"), session.locked():
                third.unlock("not-the-token")
        fourth = raw_pages(session)  # a reload is a new page: the host's ceiling holds
        with pytest.raises(AccessDenied, match="from 127.0.0.1 \\(all its pages\\)"), \
                session.locked():
            fourth.unlock(token)
        assert not fourth.may_edit
    finally:
        session.stop()


def test_a_page_saves_only_what_it_showed(cell_copy: Path,
                                          raw_pages: Callable[[ReviewSession], Any]) -> None:
    """Save poses shows every value that would change; Confirm save writes exactly
    those, and is refused once anything changed after they were shown."""
    session = ReviewSession(cell_copy, options=ViewOptions(
        port=0, plan_on_start=False, replan_on_save=False)).start()
    try:
        page, other = raw_pages(session), raw_pages(session)
        with session.locked():
            page.edit_pose("low1")
            page.set_joint(0, 1.4318)
            shown = page.save()
        assert "**low1**: joint_1 = 1.4318 (was 1.401779) rad" in shown.summary
        assert page.widgets.to_save.content == shown.summary and page.widgets.confirm.visible
        assert not (cell_copy / "poses.log").exists()  # nothing written yet
        with session.locked():  # an edit arriving after the values were shown
            page.set_joint(0, 1.4319)
        assert page.pending is None and not page.widgets.confirm.visible
        with pytest.raises(SafepathError, match="not saved: press Save poses first"), \
                session.locked():
            page.confirm_save()
        with session.locked():
            page.save()
            other.edit_pose("safe")
            q = other.set_joint(5, float(other.edits.q("safe")[5]) + 0.01).q
            other.save()
            other.confirm_save()  # another page's save moves the base on
        assert page.pending is None
        with pytest.raises(SafepathError, match="press Save poses first"), session.locked():
            page.confirm_save()
        with session.locked():  # the edit buffer changed by a path that shows nothing
            page.save()
            q_low = page.edits.q("low1")
            q_low[1] += 0.01
            page.edits.set("low1", q_low)
        with pytest.raises(SafepathError, match="changed after Save poses showed them"), \
                session.locked():
            page.confirm_save()
        with session.locked():
            page.edits.set("low1", q_low - np.array([0, 0.01, 0, 0, 0, 0]))
            page.save()
            page.confirm_save()
        saved = load_poses(cell_copy / "poses.yaml", session.cell.robot)
        assert saved["low1"][0] == 1.4319 and np.array_equal(saved["safe"], q)
    finally:
        session.stop()


def test_a_joint_value_that_is_not_a_number_is_refused(
        cell_copy: Path, raw_pages: Callable[[ReviewSession], Any]) -> None:
    """A page's joint value must be a number: a numeric string (or a boolean) is refused
    naming the joint, and nothing is edited or saved."""
    session = ReviewSession(cell_copy, options=ViewOptions(
        port=0, plan_on_start=False, replan_on_save=False)).start()
    try:
        page = raw_pages(session)
        with session.locked():
            page.edit_pose("low1")
            before = page.edits.q("low1").copy()
            for bad in ("1.43", True, None, float("nan")):
                with pytest.raises(PoseError, match="'joint_1'"):
                    page.set_joint(0, bad)
            with pytest.raises(PoseError, match="joints"):
                page.set_joints(["1.43", 0, 0, 0, 0, 0])
            np.testing.assert_array_equal(page.edits.q("low1"), before)
            page.set_joint(0, 1.4318)  # a number is taken
        assert page.edits.q("low1")[0] == 1.4318
    finally:
        session.stop()


def test_an_external_edit_is_not_overwritten(session: ReviewSession, cell_copy: Path) -> None:
    poses_file = cell_copy / "poses.yaml"
    robot = session.cell.robot
    q = session.edit_pose("high1").q.copy()
    q[0] += 0.05
    session.set_joints(q)
    # Someone changes high2 in a text editor meanwhile.
    outside = load_poses(poses_file, robot)
    outside["high2"] = outside["high2"] + np.array([0.05, 0, 0, 0, 0, 0])
    poses_file.write_text(dump_poses(outside))
    edited_outside = poses_file.read_bytes()
    with pytest.raises(PosesChanged, match=r"changed since it was loaded \(high2 \(joint_1 "
                                           r"1\.5926 -> 1\.6426 rad\)\)") as info:
        session.save_poses()
    assert [c.pose for c in info.value.changes] == ["high2"]
    assert poses_file.read_bytes() == edited_outside
    assert (cell_copy / "poses.log").read_text() == ""  # a refused save is not logged
    # The page says so before anyone saves.
    wait_for(lambda: "changed on disk" in session.panel.notice.content, 5.0,
             "the change on disk was not noticed")
    assert "high2" in session.panel.notice.content
    # Reloading merges pose by pose: the edit of high1 stays, high2 comes from the file.
    session.reload_poses()
    notice = session.panel.notice.content
    assert "changed on disk" not in notice
    # The routes were planned with the old high2 (re-planning after saves is off here).
    assert "stale routes" in notice and "(high2)" in notice
    assert np.array_equal(session.edits.q("high1"), q)
    assert np.array_equal(session.edits.q("high2"), outside["high2"])
    session.save_poses()
    saved = load_poses(poses_file, robot)
    assert np.array_equal(saved["high1"], q) and np.array_equal(saved["high2"], outside["high2"])
    (entry,) = [json.loads(line) for line in (cell_copy / "poses.log").read_text().splitlines()]
    assert entry["client"] == "python" and list(entry["changes"]) == ["high1"]
    assert entry["changes"]["high1"]["to"] == [float(v) for v in q]
    assert entry["check"]["high1"]["valid"] and entry["insist"] is False


def test_an_external_edit_of_the_same_pose_is_a_conflict(session: ReviewSession,
                                                         cell_copy: Path) -> None:
    poses_file = cell_copy / "poses.yaml"
    robot = session.cell.robot
    q = session.edit_pose("safe").q.copy()
    q[0] += 0.03
    session.set_joints(q)
    outside = load_poses(poses_file, robot)
    outside["safe"] = outside["safe"] - np.array([0.03, 0, 0, 0, 0, 0])
    poses_file.write_text(dump_poses(outside))
    session.reload_poses()
    assert list(session.edits.conflicts) == ["safe"]
    with pytest.raises(PosesChanged, match="safe changed in another save") as info:
        session.save_poses()
    assert info.value.conflicts == ["safe"]
    assert np.array_equal(load_poses(poses_file, robot)["safe"], outside["safe"])
    # Taking the saved version drops the edit: nothing left to save.
    session.edits.take_saved("safe")
    assert np.array_equal(session.edits.q("safe"), outside["safe"])
    assert not session.edits.edits


def test_two_sessions_on_one_folder_do_not_overwrite_each_other(
        session: ReviewSession, cell_copy: Path, plans_dir: Path) -> None:
    other = ReviewSession(cell_copy, plans=plans_dir,
                          options=ViewOptions(port=0, replan_on_save=False)).start()
    try:
        q = session.edit_pose("grip").q.copy()
        q[5] += 0.02
        session.set_joints(q)
        session.save_poses()
        r = other.edit_pose("unsafe").q.copy()
        r[5] += 0.02
        other.set_joints(r)
        with pytest.raises(PosesChanged, match=r"grip \(joint_6"):
            other.save_poses()
        other.reload_poses()
        other.save_poses()
        saved = load_poses(cell_copy / "poses.yaml", session.cell.robot)
        assert np.array_equal(saved["grip"], q) and np.array_equal(saved["unsafe"], r)
        lines = (cell_copy / "poses.log").read_text().splitlines()
        assert [list(json.loads(line)["changes"]) for line in lines] == [["grip"], ["unsafe"]]
    finally:
        other.stop()


def _serve(args: list[str], env: dict[str, str] | None = None) -> str:
    """Run ``safepath view`` until it serves, interrupt it; its console output."""
    # Ctrl-C is honoured whatever the test run inherited: a run started in the background
    # by a shell ignores SIGINT, and so would the view (seen in a fresh-clone .ci/run
    # started with `&`: the view slept on through the interrupt). -X faulthandler: a stop
    # that hangs anyway is aborted below with every thread's stack shown.
    proc = subprocess.Popen([sys.executable, "-X", "faulthandler", "-c", VIEW_WITH_CTRL_C,
                             *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            cwd=REPO, env=env)
    try:
        assert proc.stdout is not None
        lines: list[str] = []
        end = time.monotonic() + 60
        while not any("safepath view:" in line for line in lines) and time.monotonic() < end:
            lines.append(proc.stdout.readline())
        assert any("safepath view:" in line for line in lines), "".join(lines)
        proc.send_signal(signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGABRT)
            stacks, _ = proc.communicate(timeout=30)
            raise AssertionError("safepath view did not stop within 60 s of Ctrl-C:\n"
                                 + "".join(lines) + stacks) from None
        assert proc.returncode == 0, "".join(lines) + out
        return "".join(lines) + out
    finally:
        if proc.poll() is None:
            proc.kill()


def test_the_command_warns_when_exposed(cell_dir: Path, plans_dir: Path) -> None:
    base = [str(cell_dir), "--plans", str(plans_dir), "--port", "0"]
    local = _serve(base)
    assert "warning" not in local.lower() and "token" not in local
    exposed = _serve([*base, "--host", "0.0.0.0"])
    (warning,) = [line for line in exposed.splitlines() if line.startswith("warning:")]
    assert "anyone who can reach it can watch" in warning and "SSH tunnel" in warning
    (token_line,) = [line for line in exposed.splitlines() if line.startswith("edit token")]
    assert len(token_line.split(": ", 1)[1]) >= 12
    anonymous = _serve([*base, "--host", "0.0.0.0", "--allow-anonymous-edit"])
    assert "WARNING: --allow-anonymous-edit: anyone who can reach" in anonymous
    assert "edit token" not in anonymous
