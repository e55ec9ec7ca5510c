"""The review page in a real headless Chromium, driven over the DevTools protocol.

Skipped when ``/usr/bin/chromium`` is absent (install: ``apt-get install -y chromium``).
Checks from the browser side that the robot is drawn (the page changes where the
robot is when the server hides it) and that pressing the page's Play button moves it
(the server's timeline advances, and the robot's region of the page changes).
"""

from __future__ import annotations

import base64
import io
import json
import shutil
import subprocess
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from safepath import Cell, load_cell
from safepath.view import ReviewSession, ViewOptions

from .conftest import log_lines, saves_landed

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"
WIDTH, HEIGHT = 1280, 800
# The 3D view's middle, away from the control panel (right) and notifications (top left).
REGION = (slice(140, 780), slice(330, 930))

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason="headless browser test needs /usr/bin/chromium "
           "(apt-get install -y chromium)")

Image = pytest.importorskip("PIL.Image")
ws_sync = pytest.importorskip("websockets.sync.client")


class Browser:
    """A headless Chromium page driven over the DevTools protocol."""

    def __init__(self, user_dir: Path) -> None:
        self.proc = subprocess.Popen(
            [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={user_dir}",
             "--remote-debugging-port=0", f"--window-size={WIDTH},{HEIGHT}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = user_dir / "DevToolsActivePort"
        wait_for(lambda: port_file.exists() and len(port_file.read_text().split()) >= 2,
                 20.0, "Chromium did not open its DevTools port")
        port = int(port_file.read_text().split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
            pages = [t for t in json.load(r) if t["type"] == "page"]
        self.ws = ws_sync.connect(pages[0]["webSocketDebuggerUrl"], max_size=None,
                                  open_timeout=10)
        self.call_id = 0
        self.call("Emulation.setDeviceMetricsOverride", width=WIDTH, height=HEIGHT,
                  deviceScaleFactor=1, mobile=False)

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        """Send one DevTools command and return its result."""
        self.call_id += 1
        self.ws.send(json.dumps({"id": self.call_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=30))
            if msg.get("id") == self.call_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return dict(msg.get("result", {}))

    def js(self, expression: str) -> Any:
        """Evaluate JavaScript in the page; its value."""
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        return result.get("result", {}).get("value")

    def screenshot(self) -> np.ndarray:
        """The page as an RGB array, shape (HEIGHT, WIDTH, 3)."""
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))

    def click_button(self, label: str) -> bool:
        """Click the page's button whose text is ``label``."""
        return bool(self.js(
            "(() => { const b = [...document.querySelectorAll('button')]"
            f".find(b => b.textContent.trim() === {json.dumps(label)});"
            " if (!b) return false; b.click(); return true; })()"))

    def close(self) -> None:
        """Quit the browser."""
        try:
            self.ws.close()
        finally:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def wait_for(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``predicate`` every 50 ms until true; fail with ``what`` after ``timeout`` [s]."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.05)
    pytest.fail(what)


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    """How many pixels of the robot's region differ between two screenshots."""
    diff = np.abs(a[REGION].astype(int) - b[REGION].astype(int)).max(axis=2)
    return int(np.count_nonzero(diff > 24))


def drawn_pixels(img: np.ndarray) -> int:
    """How many pixels of the region are not the white background."""
    return int(np.count_nonzero(img[REGION].min(axis=2) < 235))


@pytest.fixture()
def browser(tmp_path: Path) -> Iterator[Browser]:
    """A headless Chromium, closed after the test."""
    b = Browser(tmp_path / "chromium-profile")
    try:
        yield b
    finally:
        b.close()
        shutil.rmtree(tmp_path / "chromium-profile", ignore_errors=True)


def test_page_draws_the_robot_and_play_moves_it(browser: Browser, plans_dir: Path,
                                                cell_dir: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    t0 = time.perf_counter()
    session = ReviewSession(cell_dir, plans=plans_dir,
                            options=ViewOptions(port=0)).start()
    try:
        server_ready = time.perf_counter() - t0
        browser.call("Page.enable")
        browser.call("Page.navigate", url=session.url)
        wait_for(lambda: bool(session.server.get_clients()), 20.0,
                 "the page never connected to the server")
        connected = time.perf_counter() - t0
        # First frame: the scene covers a good part of the 3D view.
        first = np.zeros((HEIGHT, WIDTH, 3), np.uint8)

        def scene_drawn() -> bool:
            nonlocal first
            first = browser.screenshot()
            return drawn_pixels(first) > 0.05 * first[REGION].shape[0] * first[REGION].shape[1]

        wait_for(scene_drawn, 30.0, "the page never drew the scene")
        first_frame = time.perf_counter() - t0
        figure = (f"review session: server start-up {server_ready:.2f} s, page connected "
                  f"{connected:.2f} s, start-up to first frame in the browser "
                  f"{first_frame:.2f} s (headless Chromium, software WebGL)")
        with capsys.disabled():
            print(f"\n{figure}")
        ARTIFACTS.mkdir(exist_ok=True)
        (ARTIFACTS / "view_startup.txt").write_text(figure + "\n")
        # Close the "software WebGL" notice so that it does not hide anything.
        browser.js("document.querySelectorAll('.mantine-Notification-closeButton')"
                   ".forEach(b => b.click())")
        time.sleep(1.0)
        shown = browser.screenshot()

        # The robot is drawn: hiding it (server side) changes its region of the page.
        with session.server.atomic():
            session.robot_nodes.set_visible(False)
        time.sleep(1.0)
        hidden = browser.screenshot()
        with session.server.atomic():
            session.robot_nodes.set_visible(True)
        time.sleep(1.0)
        assert changed_pixels(shown, hidden) > 2000, "the robot is not drawn"

        # Press Play in the page: the server's timeline runs and the robot moves.
        assert browser.click_button("Play"), "no Play button in the page"
        wait_for(lambda: session.playing and session.time > 1.5, 10.0,
                 "pressing Play did not start the timeline")
        assert browser.click_button("Pause")
        wait_for(lambda: not session.playing, 5.0, "pressing Pause did not stop playback")
        time.sleep(1.0)
        moved = browser.screenshot()
        assert changed_pixels(shown, moved) > 1000, "the robot did not move on the page"
        Image.fromarray(moved).save(ARTIFACTS / "review_session.png")
    finally:
        session.stop()


def type_into(browser: Browser, before_button: str, text: str) -> bool:
    """Type ``text`` into the text field just above the button ``before_button`` (as a
    user does: React sees an input event)."""
    return bool(browser.js(
        "(() => { const els = [...document.querySelectorAll("
        "'input:not([type=checkbox]):not([type=hidden]), button')];"
        f" const k = els.findIndex(e => e.tagName === 'BUTTON' && e.textContent.trim() === "
        f"{json.dumps(before_button)}); let i = k - 1;"
        " while (i >= 0 && els[i].tagName !== 'INPUT') i--; if (i < 0) return false;"
        " const set = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, 'value').set;"
        f" set.call(els[i], {json.dumps(text)});"
        " els[i].dispatchEvent(new Event('input', {bubbles: true})); return true; })()"))


def button_disabled(browser: Browser, label: str) -> bool | None:
    """Whether the page's button ``label`` is disabled (None: no such button)."""
    value = browser.js(
        "(() => { const b = [...document.querySelectorAll('button')]"
        f".find(b => b.textContent.trim() === {json.dumps(label)});"
        " return b ? b.disabled : null; })()")
    return None if value is None else bool(value)


def page_text(browser: Browser) -> str:
    """The page's visible text."""
    return str(browser.js("document.body.innerText") or "")


def save_and_confirm(browser: Browser) -> None:
    """Press Save poses, then Confirm save once the page shows what would be saved."""
    assert browser.click_button("Save poses")
    wait_for(lambda: button_disabled(browser, "Confirm save") is False, 15.0,
             f"no confirmation after Save poses: {page_text(browser)[-400:]}")
    assert browser.click_button("Confirm save")


def test_two_pages_need_the_token_and_lose_no_edit(tmp_path: Path, cell_copy: Path,
                                                   plans_dir: Path) -> None:
    from safepath import load_poses
    from safepath.view.access import AccessDenied

    token = "review-token-42"
    session = ReviewSession(cell_copy, plans=plans_dir,
                            options=ViewOptions(port=0, token=token, backend="process")).start()
    browsers: list[Browser] = []
    try:
        pages = []
        for name in ("a", "b"):  # one browser each: a background tab would not render
            browser = Browser(tmp_path / f"chromium-{name}")
            browsers.append(browser)
            browser.call("Page.navigate", url=session.url)
            wait_for(lambda: len(session.clients) == len(browsers), 30.0,
                     "a page never connected")
            wait_for(lambda b=browser: button_disabled(b, "Save poses") is not None, 30.0,
                     "the page never showed its edit folder")
            pages.append(max(session.clients.values(), key=lambda p: p.client_id))
        (a, b), (pa, pb) = browsers, pages
        assert pa.address != pb.address and pa.address.startswith("127.0.0.1:")
        poses_file = cell_copy / "poses.yaml"
        original = poses_file.read_bytes()

        # Read-only without the token: watching works, editing and saving do not.
        assert button_disabled(a, "Save poses") and button_disabled(b, "Save poses")
        assert "read-only" in page_text(a)
        assert a.click_button("Play")
        wait_for(lambda: session.playing, 10.0, "a read-only page could not play")
        session.pause()
        q0 = pa.edit_pose("high1").q.copy()  # looking at a pose is allowed
        assert pa.editor.pose == "high1" and not pa.editor.gizmo.visible
        with pytest.raises(AccessDenied, match="read-only"):
            pa.set_joint(0, float(q0[0]) + 0.05)
        with pytest.raises(AccessDenied, match="read-only"):
            pa.save()
        assert poses_file.read_bytes() == original and log_lines(cell_copy) == []

        # A wrong token is refused; the right one unlocks this page only.
        assert type_into(a, "Unlock editing", "not-the-token")
        wait_for(lambda: pa.widgets.token.value == "not-the-token", 10.0, "typing failed")
        assert a.click_button("Unlock editing")
        wait_for(lambda: any("wrong token" in m for m in pa.messages), 10.0,
                 "a wrong token was not refused")
        assert not pa.may_edit
        wait_for(lambda: "wrong token" in page_text(a), 10.0, "the page did not say so")
        assert type_into(a, "Unlock editing", token)
        wait_for(lambda: pa.widgets.token.value == token, 10.0, "typing failed")
        assert a.click_button("Unlock editing")
        wait_for(lambda: pa.may_edit, 10.0, "the right token did not unlock the page")
        # Now it can drag the TCP of high1: the page shows the gizmo once the unlock's
        # callback has updated it (right after granting the edit, on the server's thread).
        wait_for(lambda: pa.editor.gizmo.visible, 10.0, "no gizmo after the unlock")
        wait_for(lambda: button_disabled(a, "Save poses") is False, 10.0,
                 "Save stayed disabled after the unlock")
        assert not pb.may_edit and button_disabled(b, "Save poses")
        assert type_into(b, "Unlock editing", token) and b.click_button("Unlock editing")
        wait_for(lambda: pb.may_edit, 10.0, "page b was not unlocked")

        # Different poses edited on two pages: both saves land, each logged.
        with session.locked():
            qa = pa.set_joint(0, float(q0[0]) + 0.05).q
            pb.edit_pose("safe")
            qb = pb.set_joint(5, float(pb.edits.q("safe")[5]) + 0.05).q
        save_and_confirm(a)
        wait_for(lambda: saves_landed(cell_copy) == 1, 15.0, "page a's save did not land")
        # Page b sees the new poses: its base moved on, and the page says who saved.
        wait_for(lambda: np.array_equal(pb.edits.base.poses["high1"], qa), 10.0,
                 "page b's poses did not move on")
        wait_for(lambda: f"saved by {pa.address}" in page_text(b), 10.0,
                 "page b was not told about page a's save")
        save_and_confirm(b)
        wait_for(lambda: saves_landed(cell_copy) == 2, 15.0, "page b's save did not land")
        saved = load_poses(poses_file, session.cell.robot)
        assert np.array_equal(saved["high1"], qa) and np.array_equal(saved["safe"], qb)
        first, second = log_lines(cell_copy)
        assert (first["client"], list(first["changes"])) == (pa.address, ["high1"])
        assert (second["client"], list(second["changes"])) == (pb.address, ["safe"])
        assert first["check"]["high1"]["valid"] and first["sha256_after"] == \
            second["sha256_before"]
        assert (cell_copy / "poses.yaml~").exists()

        # The same pose on two pages: the second save is refused, never overwrites.
        with session.locked():
            pa.edit_pose("low1")
            q_low = pa.edits.q("low1")
            qa_low = pa.set_joint(0, float(q_low[0]) + 0.02).q
            pb.edit_pose("low1")
            qb_low = pb.set_joint(0, float(q_low[0]) - 0.02).q
        save_and_confirm(a)
        wait_for(lambda: saves_landed(cell_copy) == 3, 15.0, "page a's save did not land")
        wait_for(lambda: "low1" in pb.edits.conflicts, 10.0, "no conflict on page b")
        wait_for(lambda: "conflict" in page_text(b), 10.0, "page b shows no conflict")
        assert b.click_button("Save poses")
        wait_for(lambda: any("low1 changed in another save" in m for m in pb.messages), 10.0,
                 "page b's save of a pose saved meanwhile was not refused")
        assert len(log_lines(cell_copy)) == 3
        assert np.array_equal(load_poses(poses_file, session.cell.robot)["low1"], qa_low)
        # Page b keeps its edit on purpose, pose by pose: now it saves.
        wait_for(lambda: button_disabled(b, "Keep my edit") is False, 10.0,
                 "no way to keep the edit")
        assert b.click_button("Keep my edit")
        wait_for(lambda: "low1" not in pb.edits.conflicts, 10.0, "keep mine did nothing")
        save_and_confirm(b)
        wait_for(lambda: saves_landed(cell_copy) == 4, 15.0, "the kept edit was not saved")
        assert np.array_equal(load_poses(poses_file, session.cell.robot)["low1"], qb_low)
        # Every page shows the saved poses: the shared pose frame moved to it.
        target = session.cell.robot.frame_pose(qb_low).translation
        wait_for(lambda: np.allclose(session.pose_frames.frames["low1"].position, target),
                 10.0, "the shared frame of low1 did not move")
        # ... and the routes were re-planned with them (or marked stale meanwhile).
        assert session.wait_for_plans(timeout=120.0)
        wait_for(lambda: not session.plans.running and not session.plans.stale(), 120.0,
                 f"routes not re-planned after the saves: {session.messages[-3:]}")
    finally:
        for browser in browsers:
            browser.close()
        session.stop()


def test_page_draws_a_cell_built_in_python(browser: Browser) -> None:
    """A UR5 cell built in Python (no folder, no poses file) is served like a folder's:
    the page draws its robot, whose links are meshes (example-robot-data's convex hulls):
    hiding it changes the page."""
    yaml_cell = load_cell(Path(__file__).resolve().parents[2] / "examples" / "cells"
                          / "ur5_cell")
    cell = Cell(yaml_cell.robot, yaml_cell.scene, yaml_cell.poses,
                routes=yaml_cell.route_table())
    assert cell.folder is None and cell.poses_path is None
    session = ReviewSession(cell, options=ViewOptions(port=0, plan_on_start=False)).start()
    try:
        browser.call("Page.enable")
        browser.call("Page.navigate", url=session.url)
        wait_for(lambda: bool(session.server.get_clients()), 20.0,
                 "the page never connected to the server")
        wait_for(lambda: drawn_pixels(browser.screenshot()) > 20000, 30.0,
                 "the page never drew the scene")
        browser.js("document.querySelectorAll('.mantine-Notification-closeButton')"
                   ".forEach(b => b.click())")
        time.sleep(1.0)
        shown = browser.screenshot()
        with session.server.atomic():
            session.robot_nodes.set_visible(False)
        time.sleep(1.0)
        hidden = browser.screenshot()
        assert changed_pixels(shown, hidden) > 2000, "the robot is not drawn"
    finally:
        session.stop()


POURING = Path(__file__).resolve().parents[2] / "scenes" / "pouring_cell"


def test_the_fingers_whole_travel_hulls_are_drawn(browser: Browser) -> None:
    """The Gen3 Lite's fingers are covered over their whole travel by coal convex hulls
    (``locked_joints: travel``); the page draws each as a mesh of the hull's points."""
    import coal

    from safepath.view.scene_nodes import coal_mesh

    session = ReviewSession(POURING, options=ViewOptions(port=0)).start()
    try:
        robot = session.cell.robot
        hulls = {f"/robot/collision/{i:02d}_{g.name}": g.geometry
                 for i, g in enumerate(robot.collision_model.geometryObjects)
                 if isinstance(g.geometry, coal.ConvexBase)}
        assert len(hulls) == 4  # two links per finger
        browser.call("Page.enable")
        browser.call("Page.navigate", url=session.url)
        wait_for(lambda: bool(browser.js("typeof window.__viserSceneTree === 'object'")),
                 30.0, "the page never loaded viser's scene")

        def drawn(name: str) -> list[int] | None:
            return browser.js(  # type: ignore[no-any-return]
                "(() => { const e = window.__viserSceneTree.getState()"
                f"[{json.dumps(name)}]; if (!e || e.message.type !== 'MeshMessage') "
                "return null; const p = e.message.props; "
                "return [p.vertices.length / 3, p.faces.length / 3]; })()")

        for name, hull in hulls.items():
            wait_for(lambda n=name: drawn(n) is not None, 30.0, f"{name} is not in the page")
            vertices, faces = coal_mesh(hull)  # type: ignore[misc]
            assert drawn(name) == [hull.num_points, len(faces)]
            assert len(vertices) == hull.num_points and hull.num_points > 8
        # The three.js scene holds a mesh of each hull's vertex count.
        counts = browser.js(
            "(() => { const out = []; window.__viserMutable.scene.traverse(o => { if (o.isMesh"
            " && o.geometry && o.geometry.attributes.position) "
            "out.push(o.geometry.attributes.position.count); }); return out; })()")
        for hull in hulls.values():
            assert hull.num_points in counts
    finally:
        session.stop()


def click(browser: Browser, label: str) -> None:
    """Click the button ``label`` with the mouse, as a user does: the focus moves to it
    first (a box being typed in loses it), then the click."""
    xy = browser.js(
        "(() => { const b = [...document.querySelectorAll('button')]"
        f".find(b => b.textContent.trim() === {json.dumps(label)});"
        " if (!b) return null; b.scrollIntoView({block: 'center'});"
        " const r = b.getBoundingClientRect(); return [r.x + r.width / 2, r.y + r.height / 2];"
        " })()")
    assert xy is not None, f"no button {label!r} in the page"
    for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
        browser.call("Input.dispatchMouseEvent", type=kind, x=xy[0], y=xy[1], button="left",
                     clickCount=1)


# viser labels an input with <label for=uuid> (its text broken by <wbr> tags).
_BOX = ("(text => { const l = [...document.querySelectorAll('label')]"
        ".find(l => l.textContent.trim() === text);"
        " return l ? document.getElementById(l.htmlFor) : null; })")


def box(browser: Browser, label: str) -> dict[str, Any] | None:
    """The number box labelled ``label``: its text and whether it is disabled."""
    return browser.js(  # type: ignore[no-any-return]
        f"(() => {{ const e = {_BOX}({json.dumps(label)});"
        " return e ? {value: e.value, disabled: e.disabled} : null; })()")


def type_in_box(browser: Browser, label: str, text: str) -> None:
    """Type ``text`` over the content of the number box ``label`` (keyboard input)."""
    assert browser.js(
        f"(() => {{ const e = {_BOX}({json.dumps(label)}); if (!e) return false;"
        " e.scrollIntoView({block: 'center'}); e.focus(); e.select(); return true; })()")
    browser.call("Input.insertText", text=text)


def test_joint_boxes_refuse_out_of_limit_values_keep_precision_and_follow_rights(
        browser: Browser, cell_copy: Path) -> None:
    """Issue 30, in the page: a read-only page's joint boxes are disabled and its prompt
    says where the token comes from; a value typed outside the limits is neither clamped
    nor saved (the refusal starts "not saved:"), even when the click that takes the
    focus is "Save poses"; a typed 1.4318 is saved as 1.4318, after the page showed it;
    a value typed with more than the box's 7 decimals is rounded to them (issue 35: it
    was cut), and a value the server sets is shown rounded."""
    token = "review-token-42"
    session = ReviewSession(cell_copy, options=ViewOptions(
        port=0, token=token, plan_on_start=False, replan_on_save=False)).start()
    poses_file = cell_copy / "poses.yaml"
    original = poses_file.read_bytes()
    try:
        browser.call("Page.navigate", url=session.url)
        wait_for(lambda: len(session.clients) == 1, 30.0, "the page never connected")
        wait_for(lambda: button_disabled(browser, "Save poses") is not None, 30.0,
                 "the page never showed its edit folder")
        (page,) = session.clients.values()
        with session.locked():
            page.edit_pose("low1")
        q0 = page.edits.q("low1")
        wait_for(lambda: (box(browser, "joint_1 [rad]") or {}).get("value") == "1.4017786",
                 10.0, "the joint boxes do not show low1 at 7 decimals")

        # Read-only: every joint box is disabled, and the prompt says where the token
        # comes from (it was given, not printed on the console).
        assert all(box(browser, f"joint_{j} [rad]")["disabled"] for j in range(1, 7))
        text = page_text(browser)
        assert "the token this session was started with" in text
        assert "printed on the server console" not in text
        assert type_into(browser, "Unlock editing", token)
        wait_for(lambda: page.widgets.token.value == token, 10.0, "typing failed")
        click(browser, "Unlock editing")
        wait_for(lambda: not box(browser, "joint_2 [rad]")["disabled"], 10.0,
                 "the joint boxes stayed disabled after the unlock")

        # 7 decimals, rounded, never cut (issue 35): 0.123456789 typed is 0.1234568, and
        # a value the server sets (0.23456789) shows as 0.2345679.
        type_in_box(browser, "joint_2 [rad]", "0.123456789")
        wait_for(lambda: page.edits.q("low1")[1] == 0.1234568, 10.0,
                 f"typed 0.123456789, the server has {page.edits.q('low1')[1]!r}")
        with session.locked():
            page.set_joint(1, 0.23456789)
        wait_for(lambda: box(browser, "joint_2 [rad]")["value"] == "0.2345679", 10.0,
                 f"the box shows {box(browser, 'joint_2 [rad]')}")
        assert page.edits.q("low1")[1] == 0.23456789  # shown rounded, held in full

        # Outside the limits: shown as typed, refused at Save, never clamped to 0.44.
        type_in_box(browser, "joint_2 [rad]", "5")
        wait_for(lambda: page.edits.q("low1")[1] == 5.0, 10.0, "the typed 5 did not arrive")
        wait_for(lambda: "outside limits" in page_text(browser), 10.0,
                 "the page does not say the pose is outside the limits")
        click(browser, "Save poses")  # takes the focus from the box
        wait_for(lambda: any(m.startswith("not saved: pose low1") for m in page.messages),
                 10.0, f"the save was not refused: {page.messages}")
        refusal = next(m for m in page.messages if m.startswith("not saved: pose low1"))
        assert "joint_2 = 5.00000 rad is outside its limits" in refusal
        wait_for(lambda: "not saved: pose low1" in page_text(browser), 10.0,
                 "the page does not show the refusal")
        time.sleep(0.5)  # a clamp on blur would have arrived by now
        assert page.edits.q("low1")[1] == 5.0 and box(browser, "joint_2 [rad]")["value"] == "5"
        assert poses_file.read_bytes() == original and log_lines(cell_copy) == []
        assert button_disabled(browser, "Confirm save") is None  # nothing to confirm

        # Full precision: 1.4318 typed is shown before saving, then saved, as typed.
        click(browser, "Reset pose")
        wait_for(lambda: np.array_equal(page.edits.q("low1"), q0), 10.0, "reset failed")
        type_in_box(browser, "joint_1 [rad]", "1.4318")
        wait_for(lambda: page.edits.q("low1")[0] == 1.4318, 10.0,
                 f"typed 1.4318, the server has {page.edits.q('low1')[0]!r}")
        click(browser, "Save poses")
        wait_for(lambda: "joint_1 = 1.4318 (was 1.401779)" in page_text(browser), 10.0,
                 "the page does not show what would be saved")
        assert poses_file.read_bytes() == original  # not before the confirmation
        click(browser, "Confirm save")
        wait_for(lambda: saves_landed(cell_copy) == 1, 15.0, "the confirmed save did not land")
        (entry,) = log_lines(cell_copy)
        assert entry["changes"]["low1"]["to"][0] == 1.4318 and entry["check"]["low1"]["valid"]
        from safepath import load_poses
        assert load_poses(poses_file, session.cell.robot)["low1"][0] == 1.4318
    finally:
        session.stop()
