"""Start-up of the browser review session (server side), on the bundled cell.

Prints, as the median of a few runs:
- ``start()`` with plans read from files (``safepath view --plans``): the page can be
  opened and shows the routes when it returns;
- ``start()`` without plans, and the time until the routes planned in the background
  are shown (``safepath view``);
- a save of an edited pose (``ReviewSession.save_poses``: content-hash check, atomic
  write with backup, re-read, a line in ``poses.log``, every editor moved on), on a copy
  of the cell.

The start-up to first frame *in a browser* is printed by tests/view/test_browser.py
(headless Chromium, software WebGL). Run: ``.venv/bin/python benchmarks/view_startup.py``.
"""

from __future__ import annotations

import argparse
import os
import shutil
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
    saves = save_times(10 * args.runs)
    print(f"save of an edited pose, median of {len(saves)}: "
          f"{statistics.median(saves) * 1000:.1f} ms (max {max(saves) * 1000:.1f} ms); "
          f"load {os.getloadavg()[0]:.1f}")


def save_times(count: int) -> list[float]:
    """Durations of ``count`` saves of an edited pose [s], on a copy of the cell."""
    with tempfile.TemporaryDirectory() as tmp:
        cell = Path(tmp) / "cell"
        cell.mkdir()
        for item in CELL.glob("*.yaml"):
            shutil.copy(item, cell / item.name)
        session = ReviewSession(cell, options=ViewOptions(port=0, plan_on_start=False,
                                                          replan_on_save=False)).start()
        try:
            q = session.edit_pose("high1").q.copy()
            out = []
            for i in range(count):
                q[0] += 0.001 if i % 2 else -0.001
                session.set_joints(q)
                t0 = time.perf_counter()
                session.save_poses()
                out.append(time.perf_counter() - t0)
            return out
        finally:
            session.stop()


if __name__ == "__main__":
    main()
