"""Live obstacles: a body crossing the cell in MuJoCo, seen by ray-cast LaserScan and
PointCloud2 messages, MonitorNodeCore closed loop, and a kill just before a motion ends."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from safepath.sim.obstacles import MovingBody, run_obstacles


def test_the_monitor_slows_for_the_body_and_a_kill_stays_latched_through_a_motion_end(
        cell_dir: Path) -> None:
    run = run_obstacles(str(cell_dir), 0, duration=4.0, kill_before_end_of=0)
    # The sensors published, the node core decided on them: the body made it slow down.
    assert run.scans > 50 and run.clouds > 40
    assert "slow" in run.decisions
    # The true distance arm - body was measured (MuJoCo's geometry), the body outside the arm.
    assert 0.0 < run.closest <= run.closest_moving < 1.0
    # Killed 5 ms before the first motion's end; that motion (braked) ended after it, and
    # nothing followed: no gripper action, no next motion, the arm stays where it stopped.
    assert run.kill_time is not None and run.motion_end_after_kill
    assert run.after_kill == ()
    assert run.moved_after_kill < 1e-3


def test_the_crossing_is_seeded() -> None:
    a = MovingBody.crossing(np.random.default_rng([3, 5]))
    b = MovingBody.crossing(np.random.default_rng([3, 5]))
    assert a == b
    # It passes the base axis at the drawn distance: 0.22-0.40 m.
    t = np.linspace(a.enter, a.leave, 2001)
    d = min(float(np.hypot(*a.at(x)[:2])) for x in t)
    assert 0.22 - 1e-3 <= d <= 0.40 + 1e-3
