"""A safepath path as a ``toppra`` geometric path, for the jerk-free references.

``toppra.SplineInterpolator(path.x, path(path.x))`` re-interpolates a path through its
breakpoints: the same curve only when the path is the not-a-knot spline through them. The
exact corner blends (:func:`safepath.timing._blend.corner_pieces`) are cubic pieces given
piece by piece, which that spline would replace by another path; this wraps the path
itself.
"""

from __future__ import annotations

import numpy as np
import toppra.interpolator as interpolator

from safepath.timing import PathSpline


class ToppraPath(interpolator.AbstractGeometricPath):  # type: ignore[misc]
    """``path`` as ``toppra`` evaluates a geometric path.

    Args:
        path: The path (a :class:`~safepath.timing.PathSpline`).
        dof: Its dimension.
    """

    def __init__(self, path: PathSpline, dof: int) -> None:
        self._path = path
        self._dof = dof

    def __call__(self, s: float | np.ndarray, order: int = 0) -> np.ndarray:
        return np.asarray(self._path(s, order))

    @property
    def dof(self) -> int:
        return self._dof

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([0.0, float(self._path.x[-1])])
