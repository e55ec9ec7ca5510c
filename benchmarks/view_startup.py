"""Start-up of the browser review session (server side), on the bundled cell.

Prints, as the median of a few runs:
- ``start()`` with plans read from files (``safepath view --plans``): the page can be
  opened and shows the routes when it returns;
- ``start()`` without plans, and the time until the routes planned in the background
  are shown (``safepath view``).

The start-up to first frame *in a browser* is printed by tests/view/test_browser.py
(headless Chromium, software WebGL). Run: ``.venv/bin/python benchmarks/view_startup.py``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from safepath import load_cell, plan_cell
from safepath.view import ReviewSession, ViewOptions

CELL = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"


def main() -> None:
    """Measure and print the start-up figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        plans = Path(tmp)
        for name, traj in plan_cell(load_cell(CELL)).items():
            traj.to_json(plans / f"{name}.json")
        with_plans, bare, planned = [], [], []
        for _ in range(args.runs):
            session = ReviewSession(CELL, plans=plans, options=ViewOptions(port=0))
            t0 = time.perf_counter()
            session.start()
            with_plans.append(time.perf_counter() - t0)
            session.stop()

            session = ReviewSession(CELL, options=ViewOptions(port=0))
            t0 = time.perf_counter()
            session.start()
            bare.append(time.perf_counter() - t0)
            if not session.wait_for_plans(timeout=120.0):
                raise SystemExit(f"planning failed: {session.messages[-1]}")
            planned.append(time.perf_counter() - t0)
            session.stop()
    print(f"review session start-up, median of {args.runs} runs:")
    print(f"  with --plans (routes shown)        {statistics.median(with_plans):6.2f} s")
    print(f"  without plans (page usable)        {statistics.median(bare):6.2f} s")
    print(f"  without plans (routes planned)     {statistics.median(planned):6.2f} s")


if __name__ == "__main__":
    main()
