"""What the property tests draw from, and how many draws each makes.

Every property test is derandomized (its examples follow from the test's own code, so
``make test`` runs the same examples every time), keeps no example database, and has no
deadline (a slow machine slows a test down; it never fails it).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from pathlib import Path

import numpy as np
from hypothesis import settings
from hypothesis import strategies as st

from safepath import Cell, Robot, load_cell

REPO_ROOT = Path(__file__).resolve().parents[2]
#: Each bundled robot in a cell of its own.
CELLS = {
    "ned3pro": REPO_ROOT / "scenes" / "quality_check_cell",
    "gen3_lite": REPO_ROOT / "scenes" / "pouring_cell",
    "panda": REPO_ROOT / "examples" / "cells" / "panda_cell",
    "ur5": REPO_ROOT / "examples" / "cells" / "ur5_cell",
}


@cache
def bundled_cell(robot: str) -> Cell:
    """The cell of a bundled robot (a key of :data:`CELLS`), loaded once."""
    return load_cell(CELLS[robot])


def bounded(max_examples: int) -> settings:
    """The settings of a property test that draws ``max_examples`` examples at most."""
    return settings(derandomize=True, max_examples=max_examples, deadline=None,
                    database=None)


def in_limits(robot: Robot, margin: float = 0.0) -> st.SearchStrategy[np.ndarray]:
    """Joint states [rad] inside the robot's limits by at least ``margin`` [rad] (0: the
    limits themselves included)."""
    joints = [st.floats(float(lo) + margin, float(hi) - margin)
              for lo, hi in zip(robot.lower, robot.upper, strict=True)]
    return st.tuples(*joints).map(lambda q: np.array(q, dtype=float))


def near(robot: Robot, poses: Sequence[np.ndarray], reach: float
         ) -> st.SearchStrategy[np.ndarray]:
    """Joint states [rad] within ``reach`` [rad] of one of ``poses`` in every joint,
    clipped to the limits (close to what a cell's poses are close to)."""
    offsets = st.tuples(*[st.floats(-reach, reach)] * robot.dof)
    return st.tuples(st.sampled_from([np.asarray(p, dtype=float) for p in poses]),
                     offsets).map(lambda pair: np.clip(pair[0] + np.array(pair[1]),
                                                       robot.lower, robot.upper))
