"""Property: the sphere layer never answers other than coal.

For random joint states of each bundled robot in its cell (anywhere in the limits, or
close to one of the cell's poses, where the robot is near the cell's objects), with and
without the held object and the margin enforced, and for states around each drawn one: a
state the layer calls free is free for coal, one it calls colliding collides for coal,
and the checker's answer (the layer, then coal for the states it leaves unsure) is coal's
answer alone. (Outer spheres shrunk by 10 % make it fail on the Ned3 Pro.)
"""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safepath import Cell, CheckOptions, CollisionChecker
from safepath.collision import COLLIDES, FREE

from .strategies import CELLS, bounded, bundled_cell, in_limits, near


@cache
def _checkers(robot: str, held: bool, margin: bool
              ) -> tuple[CollisionChecker, CollisionChecker]:
    """The cell's checker with its sphere layer, and the same checker on coal alone."""
    fast = bundled_cell(robot).checker(held=held, options=CheckOptions(enforce_margin=margin))
    exact = bundled_cell(robot).checker(held=held, options=dataclasses.replace(fast.options,
                                                                        fast=False))
    return fast, exact


#: States checked around each drawn one, and their spread per joint [rad].
NEIGHBOURS, NEIGHBOURHOOD = 31, 0.03


def _states(cell: Cell) -> st.SearchStrategy[np.ndarray]:
    return st.one_of(in_limits(cell.robot), near(cell.robot, list(cell.poses.values()), 0.15))


@pytest.mark.parametrize("robot", list(CELLS))
def test_the_sphere_layer_answers_as_coal(robot: str) -> None:
    cell = bundled_cell(robot)
    held = st.booleans() if cell.scene.grasp is not None else st.just(False)

    @bounded(300)
    @given(q=_states(cell), seed=st.integers(0, 2**32 - 1), held=held, margin=st.booleans())
    def agrees(q: np.ndarray, seed: int, held: bool, margin: bool) -> None:
        fast, exact = _checkers(robot, held, margin)
        assert fast.layer is not None
        # The drawn state and states around it (a drawn state near contact has neighbours
        # on both sides of it).
        around = np.random.default_rng(seed).normal(0.0, NEIGHBOURHOOD, (NEIGHBOURS, q.size))
        Q = np.vstack([q, np.clip(q + around, cell.robot.lower, cell.robot.upper)])  # noqa: N806
        status = fast.layer.classify_many(Q)
        truth = np.array([exact.is_valid(x) for x in Q])
        for wrong, what in (((status == FREE) & ~truth, "free a state that collides"),
                            ((status == COLLIDES) & truth, "colliding a state that is free")):
            assert not wrong.any(), f"the layer calls {what} for coal: {Q[wrong][0].tolist()}"
        assert [fast.is_valid(x) for x in Q] == truth.tolist()

    agrees()
