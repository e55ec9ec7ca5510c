"""The randomized timing suite, a bounded subset (``benchmarks/timing_suite.py`` runs as
many as asked): random via-point paths with steps of different speed scales and TCP
speed limits on every bundled robot, none over a limit as executed (0 tolerance)."""

from __future__ import annotations

import pytest
from timing_suite import robot_names, run_suite

#: Problems per robot (four robots: a few hundred in all).
PATHS = 60


@pytest.mark.parametrize("name", robot_names())
def test_random_paths_keep_every_limit_as_executed(name: str) -> None:
    outcomes = run_suite(name, PATHS, seed=2026)
    assert len(outcomes) == PATHS
    worst = max(o.worst for o in outcomes)
    assert worst <= 1.0, f"{name}: a quintic join at {worst!r} of a limit"
    # The motions use their limits: the suite would pass vacuously on crawling ones.
    assert sorted(o.worst for o in outcomes)[PATHS // 2] > 0.9
