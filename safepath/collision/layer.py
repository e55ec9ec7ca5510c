"""The fast layer of the collision checker: spheres that decide most states, exactly.

A :class:`SphereLayer` is built from what a :class:`~safepath.collision.CollisionChecker`
mirrors to it (its :class:`~safepath.collision._pack.LayerSource`: same robot, scene,
world state, pairs and margins) and answers, for a state:

* ``FREE``: every checked pair is farther apart than its margin. Certain: the robot's
  and held object's shapes are enclosed by their outer spheres (:mod:`safepath.collision.spheres`)
  and the scene's primitives are measured exactly, so sphere distances are lower bounds
  of the true ones; pairs of primitives are refined by separating axes, pairs with a
  convex hull (mesh links) by GJK on the hull's own vertices (:mod:`safepath.collision._gjk`),
  both lower bounds too;
* ``COLLIDES``: outside the joint limits, an inner sphere (inside a shape) is closer
  to another shape than the margin, or GJK's upper bound on the signed distance of two
  exact shapes (primitives, convex hulls) is below it (:mod:`safepath.collision._gjk`). Certain
  too;
* ``UNSURE``: anything else; the exact coal check decides.

So the checker's answers do not change; only the time to reach them does. For a
straight joint segment the layer also certifies *intervals*: a state whose clearance
lower bound exceeds the margin by ``d`` proves every state closer than
``d / (rate of approach)`` free, the rate being bounded per pair from the per-joint
reach of each body (Σ_j w_j |Δq_j|, joints that carry both bodies of a pair left out),
or from the bodies' distances to the joint axes at that state, whichever proves more.
A pair's clearance is its bounding spheres' unless they come within ``refine`` of the
margin; the pair that binds a state's radius is then measured by its finer bound (GJK on
a hull, separating axes, fine spheres) and certified again, so the radius only grows.
Segments are walked middle first, so open space costs a few evaluations and narrow
places are cut down to the checker's grid (hpp-core's progressive / dichotomy continuous
validation works this way); along a polyline, a certificate that reaches a segment's end
carries on into the next segments while every pair's budget lasts.

The kernels are compiled with numba on first use (cached on disk afterwards).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from . import _layout
from ._layout import COLLIDES, FREE, OUTSIDE, UNSURE
from ._pack import LayerSource, pack
from .options import LayerOptions
from .spheres import SphereFit

__all__ = ["SphereLayer", "FREE", "COLLIDES", "UNSURE", "OUTSIDE"]


def _kernels() -> Any:
    """The kernels, imported when first used (numba, or the build of :mod:`safepath._aot`)."""
    from . import _kernels

    return _kernels


class SphereLayer:
    """Sphere-based certificates for one collision checker (see the module doc).

    Args:
        source: What the exact checker mirrors: its geometry, pairs, margins and limits.
        options: Sphere fitting and tolerances.

    Raises:
        ValueError: A robot or held shape has no sphere fit (the caller stays exact).
    """

    def __init__(self, source: LayerSource, options: LayerOptions | None = None) -> None:
        self.options = options or LayerOptions()
        self.F, self.I, self._fits = pack(source, self.options)

    def with_security(self, security: np.ndarray) -> SphereLayer:
        """This layer for a checker with the same pairs and other security margins
        (other allowed contact depths): the tables copied, the margins replaced."""
        K = _layout  # noqa: N806
        F, I_ = self.F.copy(), self.I.copy()
        n, at = int(I_[K.H_NP]), int(I_[K.H_P])
        F[at:at + n] = security
        pairs = I_[int(I_[K.H_PI]):int(I_[K.H_PI]) + K.PIW * n].reshape(n, K.PIW)
        pairs[:, K.PI_PROOF] = np.asarray(security) >= 0
        out = copy.copy(self)
        out.F, out.I = F, I_
        return out

    # -- queries ------------------------------------------------------------------------
    @staticmethod
    def kernel(name: str) -> Any:
        """A compiled kernel of :mod:`safepath.collision._kernels` by name."""
        return getattr(_kernels(), name)

    def classify(self, q: np.ndarray) -> int:
        """FREE, COLLIDES (or outside the limits) or UNSURE for one joint vector."""
        return int(_kernels().classify(q, self.F, self.I))

    def classify_many(self, Q: np.ndarray) -> np.ndarray:  # noqa: N803
        """The status of every row of ``Q``."""
        out = np.empty(len(Q), dtype=np.int64)
        _kernels().classify_many(np.ascontiguousarray(Q, dtype=float), self.F, self.I, out)
        return out

    def certify(self, P: np.ndarray, n: np.ndarray, lo: np.ndarray, hi: np.ndarray,  # noqa: N803
                max_unsure: int | None = None
                ) -> tuple[int, int, int, int, np.ndarray, np.ndarray]:
        """Certify grid states of a polyline (see ``certify_polyline`` in the kernels);
        with ``max_unsure``, stop once that many states are left undecided.

        Returns:
            (status, segment, index, evaluated, unsure segments, unsure indices).
        """
        total = int(np.sum(np.maximum(hi - lo + 1, 0)))
        seg = np.empty(max(total, 1), dtype=np.int64)
        idx = np.empty(max(total, 1), dtype=np.int64)
        status, k, i, evaluated, m = _kernels().certify_polyline(
            np.ascontiguousarray(P, dtype=float), n.astype(np.int64), lo.astype(np.int64),
            hi.astype(np.int64), self.F, self.I, seg, idx,
            total + 1 if max_unsure is None else max_unsure)
        return int(status), int(k), int(i), int(evaluated), seg[:m], idx[:m]

    def certify_segment(self, q0: np.ndarray, q1: np.ndarray, skip_start: bool,
                        skip_end: bool, unsure_idx: np.ndarray
                        ) -> tuple[int, int, int, int, int]:
        """Limits, grid count and certification of one segment in one kernel call (see
        ``certify_segment`` in the kernels). The walk stops once ``len(unsure_idx)``
        (at least 1) states are left undecided; their grid indices are written to
        ``unsure_idx`` (int64), in the order found.

        Returns:
            (status, index, evaluated, unsure, states): status OUTSIDE (index 0: the
            start, 1: the end), COLLIDES (at grid index), UNSURE (the walk stopped) or
            FREE (``unsure`` states left undecided); the segment is cut into ``states``
            steps.
        """
        return _kernels().certify_segment(q0, q1, self.F, self.I, skip_start, skip_end,
                                          unsure_idx)  # type: ignore[no-any-return]

    @property
    def fits(self) -> list[SphereFit]:
        """The sphere fit of every moving body (the robot's geometries in model order, then
        the held object), in the frame of the joint that carries it."""
        return list(self._fits)
