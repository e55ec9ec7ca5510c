"""A state's clearance, closest pair and margin shortfalls from its pairs' distances.

The distances come per pair of coal's list (:mod:`safepath.collision._nearest` measures
those that matter); the names of a pair are a robot link (or the held object) and a
scene object, whose distance is the smallest over their shapes' pairs. The closest pair
alone answers a state farther from everything than the largest margin (no pair can fall
short of its margin); every pair of names is read only near contact.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .reports import Pair

__all__ = ["PairMargins"]


class PairMargins:
    """The distance pairs of a checker and the margin of each pair of names.

    Args:
        pairs: Index of each distance pair in coal's pair list.
        names: Names of every pair of coal's list (by index).
        margins: Margin of every pair of coal's list [m] (by index).
    """

    def __init__(self, pairs: Sequence[int], names: Sequence[Pair],
                 margins: Sequence[float]) -> None:
        self.pairs = list(pairs)
        self.names = [names[k] for k in self.pairs]
        #: Margin of each pair of names [m]: the largest of its shapes' pairs.
        self.margin_of: dict[Pair, float] = {}
        for k, name in zip(self.pairs, self.names, strict=True):
            self.margin_of[name] = max(self.margin_of.get(name, 0.0), float(margins[k]))
        self.largest = max(self.margin_of.values(), default=0.0)
        self._name_of = dict(zip(self.pairs, self.names, strict=True))
        # The pairs grouped by names, the names in the order their pairs first come.
        self._order = list(self.margin_of)
        index = {name: i for i, name in enumerate(self._order)}
        group = [index[name] for name in self.names]
        by_name = sorted(range(len(self.pairs)), key=group.__getitem__)  # stable
        self._rows = np.asarray(self.pairs, dtype=np.int64)[by_name]
        self._starts = np.flatnonzero(np.diff(np.array(group)[by_name], prepend=-1))

    def named(self, every: Sequence[float]) -> list[tuple[Pair, float]]:
        """Distance [m] of every pair of names (the smallest over their shapes), in the
        order the pairs first come, from each pair's distance (by index in coal's list)."""
        if not self.pairs:
            return []
        smallest = np.minimum.reduceat(np.asarray(every, dtype=float)[self._rows],
                                       self._starts)
        return list(zip(self._order, smallest.tolist(), strict=True))

    def report(self, every: Sequence[float], closest: int
               ) -> tuple[float, Pair | None, tuple[tuple[Pair, float, float], ...]]:
        """Clearance [m], closest pair and margin shortfalls (pair, distance, margin;
        smallest distance first) from each pair's distance [m] (by index in coal's list)
        and the index of the closest pair (the first of equals)."""
        if closest not in self._name_of:
            return float("inf"), None, ()
        clearance = float(every[closest])
        if clearance >= self.largest:
            return clearance, self._name_of[closest], ()
        return self._near(self.named(every))

    def _near(self, named: list[tuple[Pair, float]]
              ) -> tuple[float, Pair | None, tuple[tuple[Pair, float, float], ...]]:
        """Clearance, closest pair and shortfalls of a state nearer than some margin."""
        clearance, pair, short = float("inf"), None, []
        for p, d in named:
            if d < clearance:
                clearance, pair = d, p
            if d < self.margin_of[p]:
                short.append((p, d, self.margin_of[p]))
        short.sort(key=lambda item: item[1])
        return clearance, pair, tuple(short)
