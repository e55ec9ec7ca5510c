"""The timed paths' cubic spline equals scipy's not-a-knot ``CubicSpline``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from safepath.timing import CubicPath


@pytest.mark.parametrize("n", [2, 3, 4, 5, 17, 300])
def test_values_and_derivatives_match_scipy(n: int) -> None:
    rng = np.random.default_rng(n)
    x = np.concatenate([[0.0], np.cumsum(rng.uniform(0.005, 0.3, n - 1))])
    y = rng.normal(0.0, 1.0, (n, 6))
    ours = CubicPath(x, y)
    ref = CubicSpline(x, y, bc_type="not-a-knot") if n > 2 else None
    s = np.concatenate([np.linspace(x[0] - 0.1, x[-1] + 0.1, 997), x])
    for nu in (0, 1, 2):
        got = ours(s, nu)
        if ref is not None:
            np.testing.assert_allclose(got, ref(s, nu), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ours(x), y, atol=1e-12)  # it interpolates
    assert ours(float(x[1])).shape == (6,)
    if n == 2:  # a line
        np.testing.assert_allclose(ours(s, 2), 0.0, atol=1e-12)


@pytest.mark.parametrize("n", [2, 3, 17])
def test_jet_is_the_three_evaluations_bit_for_bit(n: int) -> None:
    """``jet`` (one piece lookup) gives exactly ``path(s), path(s, 1), path(s, 2)``: the
    timing uses it, and a faster evaluation must not change a trajectory's bits."""
    rng = np.random.default_rng(n)
    x = np.concatenate([[0.0], np.cumsum(rng.uniform(0.005, 0.3, n - 1))])
    path = CubicPath(x, rng.normal(0.0, 1.0, (n, 6)))
    s = np.concatenate([np.linspace(x[0] - 0.1, x[-1] + 0.1, 501), x])
    for got, nu in zip(path.jet(s), (0, 1, 2), strict=True):
        assert got.tobytes() == path(s, nu).tobytes()


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="increase"):
        CubicPath(np.array([0.0, 1.0, 1.0]), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="nu"):
        CubicPath(np.array([0.0, 1.0, 2.0]), np.zeros((3, 2)))(0.5, 4)


def test_tridiagonal_solve_equals_lapack_bit_for_bit() -> None:
    """The slopes' solver repeats LAPACK's dgtsv (what scipy's solve_banded((1, 1), ...)
    calls) operation for operation: the same bits, with and without row interchanges,
    so that dropping scipy.linalg changed no trajectory."""
    from scipy.linalg import solve_banded

    from safepath.timing._spline import solve_tridiagonal

    rng = np.random.default_rng(11)
    pivoted = 0
    for trial in range(3000):
        n, k = int(rng.integers(3, 40)), int(rng.integers(1, 8))
        ab = rng.normal(size=(3, n)) * rng.choice([1e-3, 1.0, 1e3], size=(3, n))
        if trial % 2:  # diagonally dominant, as a spline's slopes
            ab[1] = 3.0 * np.abs(ab[1]) + np.abs(ab[0]) + np.abs(ab[2])
        else:
            pivoted += int(np.any(np.abs(ab[1, :-1]) < np.abs(ab[2, :-1])))
        b = rng.normal(size=(n, k))
        ref = solve_banded((1, 1), ab.copy(), b.copy(), check_finite=False)
        got = solve_tridiagonal(ab[2, :-1], ab[1], ab[0, 1:], b)
        assert got.tobytes() == ref.tobytes(), f"trial {trial}: n={n}, k={k}"
    assert pivoted > 1000
    with pytest.raises(ValueError, match="singular"):
        solve_tridiagonal(np.zeros(3), np.zeros(4), np.zeros(3), np.ones((4, 1)))
