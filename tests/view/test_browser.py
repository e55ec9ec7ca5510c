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

from safepath.view import ReviewSession, ViewOptions

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
        self._id = 0
        self.call("Emulation.setDeviceMetricsOverride", width=WIDTH, height=HEIGHT,
                  deviceScaleFactor=1, mobile=False)

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        """Send one DevTools command and return its result."""
        self._id += 1
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=30))
            if msg.get("id") == self._id:
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
