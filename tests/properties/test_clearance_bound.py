"""Property: the checker's branch-and-bound figures are coal's all-pairs figures, bit for bit.

A checker with a sphere layer asks coal only for the pairs whose certified lower bound
does not rule them out (:mod:`safepath.collision._nearest`); a checker without one asks
coal for every pair. For random states of each bundled robot in its cell (anywhere in
the limits, or near a taught pose, where the robot touches or nearly touches the cell),
held or not, margins enforced or not, and with each pose's allowed contacts, both give
the same report (colliding pairs, clearance, closest pair, margin shortfalls) and the
same clearance. A bound inflated by 5 mm makes them differ (the last test).
"""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safepath import Cell, CheckOptions, CollisionChecker
from safepath.collision import _nearest

from .strategies import CELLS, bounded, bundled_cell, in_limits, near

#: States checked around each drawn one, and their spread per joint [rad].
NEIGHBOURS, NEIGHBOURHOOD = 15, 0.03


def _contact_poses(cell: Cell) -> list[str | None]:
    """No pose (no allowed contact), and each pose with allowed contacts."""
    named = {p for c in cell.scene.allowed_contacts for p in c.at}
    return [None, *sorted(named)]


@cache
def _checkers(robot: str, held: bool, at: str | None, margin: bool
              ) -> tuple[CollisionChecker, CollisionChecker]:
    """The cell's checker with its sphere layer, and the same checker on coal alone."""
    cell = bundled_cell(robot)
    fast = cell.checker(held=held, at=at, options=CheckOptions(enforce_margin=margin))
    exact = cell.checker(held=held, at=at,
                         options=dataclasses.replace(fast.options, fast=False))
    return fast, exact


def _disagreements(fast: CollisionChecker, exact: CollisionChecker, Q: np.ndarray  # noqa: N803
                   ) -> list[tuple[list[float], str]]:
    """The states of ``Q`` where the two checkers' figures differ, and what differs."""
    out = []
    for q in Q:
        a, b = fast.check(q), exact.check(q)
        for what in ("collisions", "clearance", "closest_pair", "margin_violations"):
            if getattr(a, what) != getattr(b, what):
                out.append((q.tolist(), f"{what}: {getattr(a, what)} != {getattr(b, what)}"))
        if fast.clearance(q) != exact.clearance(q):
            out.append((q.tolist(), f"clearance(): {fast.clearance(q)} != {exact.clearance(q)}"))
    return out


def _around(cell: Cell, q: np.ndarray, seed: int) -> np.ndarray:
    """``q`` and states around it (a state near contact has neighbours on both sides)."""
    step = np.random.default_rng(seed).normal(0.0, NEIGHBOURHOOD, (NEIGHBOURS, q.size))
    return np.vstack([q, np.clip(q + step, cell.robot.lower, cell.robot.upper)])


@pytest.mark.parametrize("robot", list(CELLS))
def test_branch_and_bound_figures_are_the_all_pairs_figures(robot: str) -> None:
    cell = bundled_cell(robot)
    held = st.booleans() if cell.scene.grasp is not None else st.just(False)
    states = st.one_of(in_limits(cell.robot),
                       near(cell.robot, list(cell.poses.values()), 0.15))

    @bounded(150)
    @given(q=states, seed=st.integers(0, 2**32 - 1), held=held, margin=st.booleans(),
           at=st.sampled_from(_contact_poses(cell)))
    def agrees(q: np.ndarray, seed: int, held: bool, margin: bool, at: str | None) -> None:
        fast, exact = _checkers(robot, held, at, margin)
        assert fast.layer is not None and exact.layer is None
        wrong = _disagreements(fast, exact, _around(cell, q, seed))
        assert not wrong, f"{len(wrong)} disagreements, first: {wrong[0]}"

    agrees()


def test_an_inflated_bound_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    # The comparison above can fail: with every finite layer bound 5 mm too large,
    # pairs that are nearest are ruled out and the figures differ.
    real = _nearest.NearestPairs.bounds

    def inflated(self: _nearest.NearestPairs, Q: np.ndarray) -> np.ndarray:  # noqa: N803
        return real(self, Q) + 0.005

    cell = bundled_cell("ned3pro")
    fast, exact = (cell.checker(held=False), cell.checker(options=CheckOptions(fast=False)))
    rng = np.random.default_rng(3)
    Q = np.vstack([_around(cell, p, int(rng.integers(1 << 30)))  # noqa: N806
                   for p in cell.poses.values()])
    assert not _disagreements(fast, exact, Q)
    monkeypatch.setattr(_nearest.NearestPairs, "bounds", inflated)
    fast = cell.checker(held=False)
    wrong = _disagreements(fast, exact, Q)
    assert wrong, "an inflated bound went unnoticed"
