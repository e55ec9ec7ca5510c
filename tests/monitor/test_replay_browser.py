"""The monitor replay in a real headless Chromium: the zone and the points are drawn, and
the page's Play button runs the replay. Skipped without ``/usr/bin/chromium``."""

from __future__ import annotations

import base64
import io
import json
import shutil
import subprocess
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from safepath import Cell
from safepath.monitor.ros import read_monitor_bag
from safepath.view.monitor_replay import MonitorReplay

from .test_replay import bag  # noqa: F401  (the recorded run, a fixture)

CHROMIUM = Path("/usr/bin/chromium")
pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="needs /usr/bin/chromium")
Image = pytest.importorskip("PIL.Image")
ws_sync = pytest.importorskip("websockets.sync.client")


def _wait(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.05)
    pytest.fail(what)


class _Page:
    """Just enough of the DevTools protocol: navigate, evaluate, screenshot."""

    def __init__(self, profile: Path) -> None:
        self.proc = subprocess.Popen(
            [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
             f"--user-data-dir={profile}", "--remote-debugging-port=0",
             "--window-size=1280,800", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = profile / "DevToolsActivePort"
        _wait(lambda: port_file.exists() and len(port_file.read_text().split()) >= 2, 20.0,
              "Chromium did not start")
        port = int(port_file.read_text().split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
            page = next(t for t in json.load(r) if t["type"] == "page")
        self.ws = ws_sync.connect(page["webSocketDebuggerUrl"], max_size=None)
        self.call_id = 0

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        self.call_id += 1
        self.ws.send(json.dumps({"id": self.call_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=30))
            if msg.get("id") == self.call_id:
                return dict(msg.get("result", {}))

    def shot(self) -> np.ndarray:
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))[100:780, 0:900]

    def click(self, label: str) -> bool:
        result = self.call("Runtime.evaluate", returnByValue=True, expression=(
            "(() => { const b = [...document.querySelectorAll('button')]"
            f".find(b => b.textContent.trim() === {json.dumps(label)});"
            " if (!b) return false; b.click(); return true; })()"))
        return bool(result.get("result", {}).get("value"))

    def close(self) -> None:
        self.ws.close()
        self.proc.terminate()
        self.proc.wait(timeout=10)


def test_replay_page_draws_the_zone_and_plays(cell: Cell, bag: Path, tmp_path: Path  # noqa: F811
                                              ) -> None:
    import viser

    run = read_monitor_bag(bag)
    server = viser.ViserServer(host="127.0.0.1", port=0)
    page = _Page(tmp_path / "profile")
    try:
        replay = MonitorReplay(server, cell, run)
        stop = next(d for d in run.decisions if d["kind"] == "stop" and d["closest"])
        replay.show(stop["time"])
        page.call("Page.navigate", url=f"http://127.0.0.1:{server.get_port()}")
        _wait(lambda: bool(server.get_clients()), 20.0, "the page never connected")
        time.sleep(4.0)  # first frames (software WebGL)
        shown = page.shot()
        replay.zone.visible = False
        replay.points.visible = False
        time.sleep(1.5)
        hidden = page.shot()
        diff = np.abs(shown.astype(int) - hidden.astype(int)).max(axis=2) > 24
        assert diff.sum() > 2000, "the protective zone and the points are not drawn"
        replay.slider.value = 0.0
        assert page.click("Play"), "no Play button"
        _wait(lambda: float(replay.slider.value) > 0.5, 10.0, "Play did not run the replay")
        assert page.click("Pause")
        _wait(lambda: not replay.playing, 5.0, "Pause did not stop the replay")
    finally:
        replay.pause()
        page.close()
        server.stop()
        shutil.rmtree(tmp_path / "profile", ignore_errors=True)
