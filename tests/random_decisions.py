"""Seeded random monitor decisions, for the switch tests and ``benchmarks/switches.py``.

A run follows one motion while an obstacle stands in front of the camera for a random
while at a random distance; the caller may add a kill press and a sensor silence. The
decisions come at about 30 Hz (with a random jitter when asked).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from safepath.monitor import Decision, Monitor, Scan
from safepath.ros import joint_trajectory

__all__ = ["decisions", "goal_points", "scan"]


def scan(stamp: float, near: float | None) -> Scan:
    """A 360-ray scan of camera ``cam`` at ``stamp`` [s]: free, or an obstacle at
    ``near`` [m] straight ahead."""
    ranges = np.full(360, np.inf)
    if near is not None:
        ranges[170:190] = near
    return Scan(stamp, "cam", ranges, -np.pi, 2 * np.pi / 360, 0.05, 8.0)


def goal_points(traj: Any, controller: Any) -> tuple[np.ndarray, ...]:
    """A goal's points as its message carries them: times [s] (rounded to ns), positions,
    velocities and accelerations."""
    msg = joint_trajectory(traj, controller=controller, backend="rosbags")
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])
    return (t, *(np.array([list(getattr(p, f)) for p in msg.points])
                 for f in ("positions", "velocities", "accelerations")))


def decisions(monitor: Monitor, duration: float, rng: np.random.Generator, *,
              kill_at: float | None = None, silent_from: float | None = None,
              jitter: float = 0.0) -> Iterator[tuple[float, Decision]]:
    """The monitor's decisions over a motion of ``duration`` [s] plus 1 s, with the time
    [s] of each.

    Args:
        monitor: Following the motion from time 0.
        duration: The motion's duration [s].
        rng: Draws the obstacle's interval and distance, then the jitter.
        kill_at: When the kill switch is pressed [s], or None.
        silent_from: Start of a 0.3 s sensor silence [s], or None.
        jitter: Each step is 1/30 s plus a uniform draw in [-jitter, jitter] [s] (none
            drawn when 0).
    """
    near_from = rng.uniform(0.0, duration)
    near_to = near_from + rng.uniform(0.05, 1.0)
    distance = rng.uniform(0.3, 1.2)
    t = 0.0
    while t < duration + 1.0:
        t += (1 / 30 + rng.uniform(-jitter, jitter)) if jitter else 1 / 30
        if kill_at is not None and kill_at <= t:
            decision, kill_at = monitor.kill(t), None
        elif silent_from is not None and silent_from <= t < silent_from + 0.3:
            decision = monitor.tick(t)
        else:
            decision = monitor.observe(scan(t, distance if near_from <= t <= near_to else None),
                                       t)
        yield t, decision
