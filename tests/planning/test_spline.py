"""The timed paths' cubic spline equals scipy's not-a-knot ``CubicSpline``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from safepath.planning._spline import CubicPath


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


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="increase"):
        CubicPath(np.array([0.0, 1.0, 1.0]), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="nu"):
        CubicPath(np.array([0.0, 1.0, 2.0]), np.zeros((3, 2)))(0.5, 3)
