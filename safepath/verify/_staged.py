"""Verifiers of one world state that differ only in their allowed contacts, checked as
one (:class:`StagedVerifier`): a route's piece whose steps allow different contacts."""

from __future__ import annotations

import copy
import itertools
from collections.abc import Sequence

import numpy as np

from ..errors import VerificationError
from .verifier import FclVerifier, VerifyResult

__all__ = ["StagedVerifier"]


class StagedVerifier:
    """Verifiers of one world state that differ only in their allowed contacts, as one
    check of a trajectory whose consecutive stretches each follow one of them.

    A route's piece often crosses steps that allow different contacts (a finger may
    touch the vial in one, must keep its margin in the next). Checked as one, the piece
    is cut into one grid (the same samples as its stretches' grids together: the grid
    cuts every knot interval on its own), each pair is walked once along the stretches
    where its rules hold (a pair whose rules are the same in two consecutive stages is
    walked across their boundary, its bound carried over), and the knot two stages
    share is judged under both, as when each stage is verified on its own.

    Args:
        stages: Verifiers made with :meth:`FclVerifier.with_allowed` from one another
            (the same robot, bodies, environment, resolution and margins).

    Raises:
        ValueError: Stages that are not of one world state and resolution.
    """

    def __init__(self, stages: Sequence[FclVerifier]) -> None:
        first = stages[0]
        for v in stages[1:]:
            if (v._movers is not first._movers or v._env is not first._env
                    or v.resolution != first.resolution
                    or v.enforce_margin != first.enforce_margin
                    or v._margin != first._margin):
                raise ValueError("staged verifiers must be of one world state, resolution "
                                 "and margin (made with FclVerifier.with_allowed)")
        # Every pair (with what it must keep) of any stage, in the order first seen, and
        # the stages each belongs to.
        rows = np.concatenate([v._table for v in stages])
        _, first_at, union_of = np.unique(_row_keys(rows), return_index=True,
                                          return_inverse=True)
        order = np.argsort(first_at)
        position = np.empty_like(order)
        position[order] = np.arange(len(order))
        if len(stages) == 1:
            self._joined = first
        else:
            self._joined = copy.copy(first)
            self._joined._use_pairs(rows[first_at[order]])
            self._joined._layer = self._joined._conservative_layer(first._layer)
        stage_of = np.repeat(np.arange(len(stages)), [len(v._table) for v in stages])
        member = np.zeros((len(order), len(stages)), dtype=np.bool_)
        member[position[union_of.reshape(-1)], stage_of] = True
        # Each pair's runs of consecutive stages it belongs to, pair by pair: the pair,
        # its first stage and its last.
        padded = np.zeros((len(order), len(stages) + 2), dtype=np.int8)
        padded[:, 1:-1] = member
        edges = np.diff(padded, axis=1)
        self._todo, self._from = (a.astype(np.int64) for a in np.nonzero(edges == 1))
        self._to = np.nonzero(edges == -1)[1].astype(np.int64) - 1
        self.verifiers = tuple(stages)
        self._last: tuple[tuple[object, ...], VerifyResult | VerificationError] | None = None

    def verify(self, t: np.ndarray, q: np.ndarray, starts: Sequence[int], *,
               steps: Sequence[str] | None = None, known: float = float("inf")
               ) -> VerifyResult:
        """Check a timed trajectory, stage ``k`` from knot ``starts[k]`` to knot
        ``starts[k + 1]`` (both included; the last stage to the last knot), as
        :meth:`FclVerifier.verify` checks each stretch with its stage's verifier.

        Raises:
            VerificationError: As :meth:`FclVerifier.verify`; the first failing sample
                in time.
            ValueError: ``starts`` not one per stage, from knot 0, not descending.
        """
        q = np.asarray(q, dtype=float)
        knots = [*map(int, starts), len(q) - 1]
        if (len(knots) != len(self.verifiers) + 1 or knots[0] != 0
                or any(b < a for a, b in itertools.pairwise(knots))):
            raise ValueError(f"stage starts {list(starts)}: one per stage "
                             f"({len(self.verifiers)}), from knot 0, not descending, before "
                             f"knot {len(q)}")
        t = np.asarray(t, dtype=float)
        # The same check asked again (a planner retrying a blend that times to the same
        # piece) has the same outcome: the check is deterministic in its inputs.
        key = (t.tobytes(), q.tobytes(), q.shape, tuple(knots),
               None if steps is None else tuple(steps), float(known))
        if self._last is not None and self._last[0] == key:
            if isinstance(self._last[1], VerificationError):
                raise self._last[1]
            return self._last[1]
        try:
            result = self._check(t, q, knots, steps, known)
        except VerificationError as exc:
            self._last = (key, exc)
            raise
        self._last = (key, result)
        return result

    def _check(self, t: np.ndarray, q: np.ndarray, knots: list[int],
               steps: Sequence[str] | None, known: float) -> VerifyResult:
        """:meth:`verify` of stages starting at knots ``knots`` (and the last knot)."""
        joined = self._joined
        grid = joined.grid(q)
        # The sample at each knot (the last of its interval), and each stage's stretch.
        at = np.searchsorted(grid.knot_of, knots, side="right") - 1
        first, stop = at[:-1][self._from], at[1:][self._to] + 1
        return joined._check(t, q, grid, self._todo, (first, stop), steps, known)


def _row_keys(rows: np.ndarray) -> np.ndarray:
    """One integer per pair row (mover, mover or environment object, is environment,
    allowed depth), equal for equal rows only."""
    i, j, env = (rows[:, c].astype(np.int64) for c in range(3))
    _, depth = np.unique(rows[:, 3], return_inverse=True)
    bodies = int(max(i.max(initial=0), j.max(initial=0))) + 1
    return ((i * bodies + j) * 2 + env) * (int(depth.max(initial=0)) + 1) + depth.reshape(-1)
