"""The sweep's report in a real headless Chromium: every distribution is drawn (its SVG
laid out at full size, one bar per non-empty bin, the bars' colour on screen), the page
loads nothing from elsewhere. Skipped without ``/usr/bin/chromium``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from view.test_browser import CHROMIUM, Browser, wait_for  # the review page's driver

from safepath.sweeps import SweepOptions, run_sweep

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="needs /usr/bin/chromium")

#: The bars' fill, #3b6ea8.
BAR = np.array([59, 110, 168])

_PLOTS = """[...document.querySelectorAll('svg.plot')].map(s => {
  const r = s.getBoundingClientRect();
  const bars = [...s.querySelectorAll('rect.bar')];
  return [s.dataset.key, r.width, r.height, bars.length,
          bars.filter(b => b.getBBox().height > 0).length];
})"""


def test_the_reports_plots_render_in_a_headless_browser(task: Any, tmp_path: Path) -> None:
    outcome = run_sweep(task, range(3), tmp_path / "sweep",
                        SweepOptions(workers=1, progress=False, title="quick"))
    page = tmp_path / "sweep" / "report.html"
    html = page.read_text()
    # Self-contained: nothing to fetch, no script.
    assert not any(ref in html for ref in ("src=", "href=", "url(", "<script", "http"))
    dists = outcome.report["distributions"]
    drawn = [d for d in dists if d["count"]]
    assert drawn, "no distribution with a finite value to draw"
    browser = Browser(tmp_path / "profile")
    try:
        browser.call("Page.navigate", url=page.as_uri())
        wait_for(lambda: browser.js("document.title") == "quick"
                 and browser.js("document.readyState") == "complete", 20.0,
                 "the report did not load")
        plots = browser.js(_PLOTS)
        assert [p[0] for p in plots] == [d["key"] for d in dists]
        for (key, width, height, bars, tall), d in zip(plots, dists, strict=True):
            counts = d["histogram"]["counts"]
            assert (width, height) == (560, 220), key
            assert bars == len(counts) and tall == sum(c > 0 for c in counts), key
        # On screen: the first drawn plot, scrolled into view, shows its bars' colour.
        index = [d["key"] for d in dists].index(drawn[0]["key"])
        box = browser.js(f"(() => {{ const s = document.querySelectorAll('svg.plot')[{index}];"
                         " s.scrollIntoView(); const r = s.getBoundingClientRect();"
                         " return [r.left, r.top, r.right, r.bottom]; })()")
        shot = browser.screenshot()
        left, top, right, bottom = (int(round(v)) for v in box)
        region = shot[max(top, 0):bottom, max(left, 0):right].astype(int)
        coloured = np.count_nonzero(np.abs(region - BAR).max(axis=2) < 8)
        assert coloured > 200, coloured
    finally:
        browser.close()
