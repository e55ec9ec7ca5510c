"""The not-a-knot cubic spline the timed paths follow (numpy, one banded solve).

The same spline as scipy's ``CubicSpline(x, y, bc_type="not-a-knot")`` (its slopes solve
the same tridiagonal system), without importing ``scipy.interpolate``, which costs a
new process several tenths of a second before its first plan. Evaluation follows
:class:`~safepath.timing._path_limits.PathSpline`: ``path(s)``, ``path(s, 1)``,
``path(s, 2)``, ``path.x``; outside ``[x[0], x[-1]]`` the end pieces extend.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CubicPath", "solve_tridiagonal"]


class CubicPath:
    """A C2 cubic spline through points ``y`` (rows) at increasing parameters ``x``,
    with not-a-knot ends (three points: the parabola through them).

    Args:
        x: Parameters, strictly increasing: (n,), n >= 2.
        y: Values: (n, d).
    """

    def __init__(self, x: np.ndarray, y: np.ndarray) -> None:
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        if x.ndim != 1 or y.ndim != 2 or len(x) != len(y) or len(x) < 2:
            raise ValueError(f"need n >= 2 parameters and n rows of values, got x "
                             f"{x.shape} and y {y.shape}")
        h = np.diff(x)
        if not np.all(h > 0):
            raise ValueError("the parameters must increase strictly")
        self.x = x
        delta = np.diff(y, axis=0) / h[:, None]
        m = self._slopes(x, h, y, delta)
        # Piece i: y_i + m_i t + c2_i t^2 + c3_i t^3 for t = s - x_i; the four
        # coefficients of a piece side by side (pieces, 4, d), so that one gather fetches
        # them.
        c2 = (3.0 * delta - 2.0 * m[:-1] - m[1:]) / h[:, None]
        c3 = (m[:-1] + m[1:] - 2.0 * delta) / (h * h)[:, None]
        self._coef = np.stack([y[:-1], m[:-1], c2, c3], axis=1)

    @classmethod
    def from_pieces(cls, x: np.ndarray, coefficients: np.ndarray) -> CubicPath:
        """A piecewise cubic given piece by piece (no interpolation): piece ``i`` is
        ``y + m t + c2 t^2 + c3 t^3`` for ``t = s - x[i]``.

        Args:
            x: Breakpoints, strictly increasing: (pieces + 1,).
            coefficients: Each piece's ``y, m, c2, c3`` (pieces, 4, d).
        """
        x = np.asarray(x, dtype=float)
        coef = np.ascontiguousarray(coefficients, dtype=float)
        if x.ndim != 1 or coef.ndim != 3 or coef.shape[:2] != (x.size - 1, 4) or x.size < 2:
            raise ValueError(f"need n >= 2 breakpoints and (n - 1, 4, d) coefficients, "
                             f"got x {x.shape} and coefficients {coef.shape}")
        if not np.all(np.diff(x) > 0):
            raise ValueError("the breakpoints must increase strictly")
        path = cls.__new__(cls)
        path.x = x
        path._coef = coef
        return path

    @staticmethod
    def _slopes(x: np.ndarray, h: np.ndarray, y: np.ndarray, delta: np.ndarray
                ) -> np.ndarray:
        """The slope at every point: continuity of the second derivative inside, and of
        the third at the second and the second-to-last point (not-a-knot)."""
        n = len(x)
        if n == 2:
            return np.repeat(delta, 2, axis=0)
        if n == 3:  # both conditions fall on the one inner point: the parabola
            c = (delta[1] - delta[0]) / (x[2] - x[0])  # its second derivative / 2
            return np.vstack([delta[0] - c * h[0], delta[0] + c * h[0],
                              delta[1] + c * h[1]])
        ab = np.zeros((3, n))  # upper, main, lower diagonal (solve_banded's layout)
        b = np.empty_like(y)
        ab[1, 1:-1] = 2.0 * (h[:-1] + h[1:])
        ab[0, 2:] = h[:-1]
        ab[2, :-2] = h[1:]
        b[1:-1] = 3.0 * (h[1:, None] * delta[:-1] + h[:-1, None] * delta[1:])
        d = x[2] - x[0]
        ab[1, 0], ab[0, 1] = h[1], d
        b[0] = ((h[0] + 2.0 * d) * h[1] * delta[0] + h[0] ** 2 * delta[1]) / d
        d = x[-1] - x[-3]
        ab[1, -1], ab[2, -2] = h[-2], d
        b[-1] = (h[-1] ** 2 * delta[-2] + (2.0 * d + h[-1]) * h[-2] * delta[-1]) / d
        return solve_tridiagonal(ab[2, :-1], ab[1], ab[0, 1:], b)

    @property
    def coefficients(self) -> np.ndarray:
        """Each piece's ``y, m, c2, c3`` of ``y + m x + c2 x^2 + c3 x^3`` in the offset
        ``x`` from its start (pieces, 4, d), C-contiguous."""
        return self._coef

    def __call__(self, s: np.ndarray | float, nu: int = 0) -> np.ndarray:
        """Values (``nu`` = 0) or their first, second or third derivative at ``s``: (len(s), d),
        or (d,) for a scalar ``s``."""
        if nu not in (0, 1, 2, 3):
            raise ValueError(f"nu must be 0, 1, 2 or 3, got {nu}")
        s_arr = np.asarray(s, dtype=float)
        t, c = self._pieces(np.atleast_1d(s_arr))
        y, m, c2, c3 = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
        if nu == 0:
            out = y + t * (m + t * (c2 + t * c3))
        elif nu == 1:
            out = m + t * (2.0 * c2 + 3.0 * t * c3)
        elif nu == 2:
            out = 2.0 * c2 + 6.0 * t * c3
        else:
            out = 6.0 * c3
        return out[0] if s_arr.ndim == 0 else out

    def jet(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Values and first and second derivatives at the points ``s`` (each (len(s), d)):
        ``path(s), path(s, 1), path(s, 2)`` with one piece lookup, in one compiled pass
        (``_topp_kernels.jet``)."""
        from ._topp import compiled_kernels

        flat = np.ascontiguousarray(np.atleast_1d(np.asarray(s, dtype=float)))
        shape = (flat.size, self._coef.shape[2])
        q, dq, ddq = np.empty(shape), np.empty(shape), np.empty(shape)
        compiled_kernels()["jet"](np.ascontiguousarray(self.x, dtype=np.float64), self._coef,
                                  flat, q, dq, ddq)
        return q, dq, ddq

    def _pieces(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For points ``flat`` (n,): their offsets into their pieces (n, 1) and the
        pieces' coefficients (n, 4, d)."""
        # (np.clip checks its arguments' types on every call: ~4 us here.)
        i = np.minimum(np.maximum(np.searchsorted(self.x, flat, side="right") - 1, 0),
                       len(self.x) - 2)
        return (flat - self.x[i])[:, None], self._coef[i]


def solve_tridiagonal(dl: np.ndarray, d: np.ndarray, du: np.ndarray, b: np.ndarray
                       ) -> np.ndarray:
    """Solve the tridiagonal system (sub-diagonal ``dl``, diagonal ``d``, super-diagonal
    ``du``) for the right-hand sides ``b`` (n, k), n >= 3: LAPACK's ``dgtsv`` (Gaussian
    elimination with partial pivoting) step for step, which is what scipy's
    ``solve_banded((1, 1), ...)`` calls; the same operations in the same order give the
    same bits (tests/planning/test_spline.py compares them), without importing
    ``scipy.linalg`` (0.15 s in a new process): the compiled ``_topp_kernels.tridiagonal``
    (a Python loop over the rows took ~0.4 ms per spline). The inputs are not modified.
    """
    from ._topp import compiled_kernels

    dl, d, du = (np.array(x, dtype=float) for x in (dl, d, du))
    b = np.array(b, dtype=float)
    singular = compiled_kernels()["tridiagonal"](dl, d, du, b)
    if singular:
        raise ValueError(f"singular tridiagonal system (row {singular - 1})")
    return b
