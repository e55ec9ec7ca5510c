"""The sphere layer's per-pair distance lower bounds: which pairs coal must measure.

A state's clearance is the smallest distance over its distance pairs, and its colliding
pairs are among the pairs the layer cannot prove apart. :func:`pair_bounds` gives, per
state and pair, a certified lower bound [m] on the pair's distance, or ``-inf`` where the
layer proves nothing (the bound is not beyond the pair's margin and ``free_eps``: the
same test by which :func:`safepath.collision._kernels.classify` proves a state free). The
checker then asks coal only for the pairs whose bound does not already rule them out
(branch and bound, see :mod:`safepath.collision._nearest`), so coal's exact figures are
reported and no collision goes unseen.

Bounds start from the bounding spheres (one distance each) and are refined (separating
axes, GJK, fine spheres: ``_pair_bound``) only up to what the caller can use: a pair's
``floor`` (its margin, below which coal measures it anyway), or, for a distance pair, an
upper bound on the state's clearance (a bounding sphere's far side: no point of a body
lies farther from its centre than its radius), beyond which the pair cannot be nearest.
"""

from __future__ import annotations

import math

from .._aot import njit
from ._kernels import _place_bounds
from ._pair_tests import _env_sdist3, _pair_bound
from ._placement import _fk
from ._records import (
    bound_centre,
    free_eps,
    mover_radius,
    n_pairs,
    pair,
    pair_margin,
    workspace,
)

__all__ = ["pair_bounds"]

_helper = njit(cache=True, nogil=True, _nrt=False)


@njit(cache=True, nogil=True)
def pair_bounds(Q, fb, ib, floor, dist, out):  # noqa: N803
    """Lower bounds [m] on every pair's distance at every row of ``Q`` (states inside the
    limits) into the rows of ``out`` (states x pairs): ``-inf`` where the layer proves
    nothing. ``floor`` (per pair [m]): refine a bound at least up to this; ``dist`` (per
    pair): a distance pair (refined up to the state's clearance bound too)."""
    Rw, pw, wf, wi = workspace(ib)
    for i in range(Q.shape[0]):
        _fk(Q[i], fb, ib, Rw, pw)
        _place_bounds(fb, ib, Rw, pw, wf, wi)
        upper = _coarse_bounds(fb, ib, wf, wi, dist, out[i])
        _refine(fb, ib, Rw, pw, wf, wi, floor, dist, upper, out[i])


@_helper
def _coarse_bounds(fb, ib, wf, wi, dist, row):
    """Each pair's bounding-sphere bound into ``row``; returns an upper bound [m] on the
    smallest distance of the distance pairs (1e300: none)."""
    upper = 1e300
    for k in range(n_pairs(ib)):
        a, b, is_env, _ = pair(ib, k)
        ax, ay, az = bound_centre(wf, wi, a)
        ra = mover_radius(fb, ib, a)
        if is_env == 1:
            d = _env_sdist3(fb, ib, b, ax, ay, az) - ra
            if dist[k] and d + 2.0 * ra < upper:
                upper = d + 2.0 * ra
        else:
            bx, by, bz = bound_centre(wf, wi, b)
            dd = (ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2
            d = math.sqrt(dd) - ra - mover_radius(fb, ib, b)
        row[k] = d
    return upper


@_helper
def _refine(fb, ib, Rw, pw, wf, wi, floor, dist, upper, row):  # noqa: N803
    """Refine the bounds in ``row`` below what the caller can use (see
    :func:`pair_bounds`); a bound not beyond its pair's margin and ``free_eps`` (the
    finer tests stop early there: not a bound) becomes ``-inf``."""
    eps = free_eps(fb, ib)
    for k in range(n_pairs(ib)):
        sm = max(pair_margin(fb, ib, k), 0.0)
        want = floor[k]
        if dist[k] and upper > want:
            want = upper
        d = row[k]
        if d < want:
            d = max(d, _pair_bound(k, fb, ib, Rw, pw, wf, wi, want - sm))
        row[k] = d if d > sm + eps else -math.inf
