"""A state's clearance and colliding pairs from coal, measuring only the pairs that matter.

coal's all-pairs calls measure every pair of a state; most are far from anything. With
the sphere layer's certified lower bound on each pair's distance
(:func:`safepath.collision._bounds.pair_bounds`), a state's figures need coal only for:

* clearance: branch and bound, nearest bound first: a pair whose bound exceeds the
  smallest distance coal has measured so far cannot be the nearest (nor tie with it);
* margin shortfalls: the pairs whose bound is below their margin;
* collisions: the pairs the layer cannot prove apart (bound ``-inf``).

The other pairs are given a stand-in distance (:data:`FAR`) larger than any real one,
so the figures read from the measured ones (:class:`._margins.PairMargins`) are exactly
the all-pairs figures, ties broken alike (the first pair of equals; tested against a
checker without a layer, which measures every pair). Each pair is measured by a fresh
coal solver: a state's figures do not depend on the states measured before it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ._margins import PairMargins
from .layer import SphereLayer
from .reports import Pair

__all__ = ["FAR", "NearestPairs", "bounds_kernel"]

#: The stand-in distance of a pair coal did not measure [m]: beyond any real one.
FAR = 1e300
#: What a layer bound is lowered by before it rules a pair out [m]: the bound holds for the
#: true distance, coal's figure may lie on either side of it by its GJK tolerance.
SLACK = 1e-5
#: coal's GJK tolerance for the distances measured (relative). Its default (1e-6) stops
#: early on curved shapes: a cylinder-box distance of 13.003666 mm (the pouring twin's
#: executed clearance) came out 13.003678 mm, 12 um too far, and 3,000 random primitive
#: pairs up to 1.3 um too far; with 1e-9, within 1.4 nm of a 1e-13 solve, 7 % slower.
GJK_TOLERANCE = 1e-9


def bounds_kernel(layer: SphereLayer | None, security: np.ndarray, margins: PairMargins
                  ) -> Callable[[np.ndarray, np.ndarray], None]:
    """The layer's bounds kernel (:func:`._bounds.pair_bounds`) for a checker whose pairs
    have coal's ``security`` margins [m] and distance pairs ``margins``: called with the
    states and the array to fill. Each bound is refined up to what proves its pair apart
    and, for a distance pair, beyond its margin (and :data:`SLACK`). Without a layer,
    every bound is ``-inf``: coal measures every pair."""
    from . import _bounds

    if layer is None:
        return lambda Q, out: out.fill(-np.inf)
    floor = np.maximum(np.asarray(security, dtype=float), 0.0) + layer.options.free_eps
    dist = np.zeros(len(floor), dtype=bool)
    dist[margins.pairs] = True
    for k, name in zip(margins.pairs, margins.names, strict=True):
        floor[k] = max(floor[k], margins.margin_of[name] + SLACK)
    F, I_ = layer.F, layer.I  # noqa: N806

    def kernel(Q: np.ndarray, out: np.ndarray) -> None:  # noqa: N803
        _bounds.pair_bounds(Q, F, I_, floor, dist, out)

    return kernel


class NearestPairs:
    """A checker's exact figures from the pairs its sphere layer cannot rule out.

    Args:
        model: The robot's kinematic model.
        geometry: coal's geometry model with every pair of the checker.
        gdata: coal's data of every pair (the checker's: its collision requests).
        margins: The checker's distance pairs and their margins.
        names: The names of every pair (by index).
        kernel: The layer's bounds (:func:`bounds_kernel`).
    """

    def __init__(self, model: pin.Model, geometry: pin.GeometryModel, gdata: pin.GeometryData,
                 margins: PairMargins, names: list[Pair], kernel: Any) -> None:
        self._model, self._data = model, model.createData()
        self._geometry, self._gdata = geometry, gdata
        self._margins = margins
        self._names = names
        self._kernel = kernel
        self._shapes = [g.geometry for g in geometry.geometryObjects]
        self._ends = [(p.first, p.second) for p in geometry.collisionPairs]
        self._request = coal.DistanceRequest()
        self._request.gjk_tolerance = GJK_TOLERANCE
        self._dist = np.asarray(margins.pairs, dtype=np.int64)
        #: Per distance pair, the margin of its names [m] (below it: always measured).
        self._margin = np.array([margins.margin_of[n] for n in margins.names], dtype=float)

    def bounds(self, Q: np.ndarray) -> np.ndarray:  # noqa: N803
        """The layer's lower bound on every pair's distance at each row of ``Q`` (states x
        pairs [m]; ``-inf``: none)."""
        out = np.empty((len(Q), len(self._names)))
        self._kernel(np.ascontiguousarray(Q, dtype=float), out)
        return out

    def _place(self, q: np.ndarray) -> None:
        pin.updateGeometryPlacements(self._model, self._data, self._geometry, self._gdata, q)

    def collisions(self, q: np.ndarray, bound: np.ndarray, *, placed: bool = False
                   ) -> list[Pair]:
        """Every colliding pair at ``q`` (limits ignored), in pair order, as coal's
        all-pairs call finds them: coal checks the pairs the layer's ``bound`` (this
        state's row of :meth:`bounds`) cannot prove apart."""
        if not placed:
            self._place(q)
        hits = [self._names[k] for k in np.flatnonzero(bound == -np.inf).tolist()
                if pin.computeCollision(self._geometry, self._gdata, k)]
        return list(dict.fromkeys(hits))

    def distances(self, q: np.ndarray, bound: np.ndarray, *, margins: bool
                  ) -> tuple[list[float], int]:
        """coal's distance [m] of each pair that may be nearest at ``q`` (with
        ``margins``: or short of its margin), :data:`FAR` for the others (by pair
        index), and the index of the nearest pair (the first of equals; -1: no
        distance pair)."""
        self._place(q)
        every = [FAR] * len(self._names)
        if not len(self._dist):
            return every, -1
        lower = bound[self._dist] - SLACK
        best, first = np.inf, -1
        if margins:
            for j in np.flatnonzero(lower < self._margin).tolist():
                best, first = self._measure(j, every, best, first)
        # The nearest bound first; only the pairs whose bound is within its distance are
        # sorted (most states leave none).
        nearest = int(np.argmin(lower))
        if every[self._dist[nearest]] == FAR:
            best, first = self._measure(nearest, every, best, first)
        rest = np.flatnonzero(lower <= best)
        for j in rest[np.argsort(lower[rest], kind="stable")].tolist():
            if lower[j] > best:
                break
            if every[self._dist[j]] == FAR:
                best, first = self._measure(j, every, best, first)
        return every, first

    def _measure(self, j: int, every: list[float], best: float, first: int
                 ) -> tuple[float, int]:
        """Measure distance pair ``j`` into ``every``; the nearest (distance, pair index)
        so far, the lower index first among equals."""
        k = int(self._dist[j])
        every[k] = d = self._distance(k)
        if d < best or (d == best and k < first):
            return d, k
        return best, first

    def _distance(self, k: int) -> float:
        """coal's distance [m] of pair ``k`` as placed, from a fresh solver: pinocchio's
        per-pair solvers keep state between calls (a penetration depth measured again
        after other states differs in its last bits), this is the state's alone."""
        a, b = self._ends[k]
        oMg = self._gdata.oMg  # noqa: N806
        return float(coal.distance(self._shapes[a], coal.Transform3s(oMg[a]), self._shapes[b],
                                   coal.Transform3s(oMg[b]), self._request,
                                   coal.DistanceResult()))

    def report(self, q: np.ndarray, free: bool
               ) -> tuple[tuple[Pair, ...], float, Pair | None,
                          tuple[tuple[Pair, float, float], ...]]:
        """Colliding pairs (none when ``free``: the layer proved the state free),
        clearance [m], closest pair and margin shortfalls at ``q``, as the all-pairs
        calls give them."""
        bound = self.bounds(q[None])[0]
        every, first = self.distances(q, bound, margins=True)
        collisions = () if free else tuple(self.collisions(q, bound, placed=True))
        return (collisions, *self._margins.report(every, first))

    def every_distance(self, q: np.ndarray) -> list[tuple[Pair, float]]:
        """Distance [m] of every pair of names at ``q`` (see :meth:`PairMargins.named`)."""
        every, _ = self.distances(q, np.full(len(self._names), -np.inf), margins=False)
        return self._margins.named(every)

    def clearance(self, q: np.ndarray) -> tuple[float, Pair | None]:
        """Smallest robot-environment distance at ``q`` [m], and its pair (as
        :meth:`PairMargins.distances` over every pair gives it)."""
        every, _ = self.distances(q, self.bounds(q[None])[0], margins=False)
        pair, best = min(self._margins.named(every), key=lambda item: item[1],
                         default=(None, np.inf))
        return float(best), pair
