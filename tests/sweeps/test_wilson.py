"""The rates' Wilson score interval against known values."""

from __future__ import annotations

import math

import pytest
from scipy.stats import binomtest

from safepath.errors import InputError
from safepath.sweeps import wilson_interval
from safepath.sweeps.stats import Rate


@pytest.mark.parametrize(("passed", "total"), [(9987, 10000), (6, 6), (0, 10), (81, 263),
                                               (1, 2)])
def test_the_interval_is_scipys_wilson_interval(passed: int, total: int) -> None:
    ci = binomtest(passed, total).proportion_ci(confidence_level=0.95, method="wilson")
    assert wilson_interval(passed, total) == pytest.approx((ci.low, ci.high), abs=1e-12)


def test_the_interval_at_the_ends_and_in_words() -> None:
    # 0 of n: [0, z^2 / (n + z^2)], z = 1.959964 (closed form of the score interval).
    z2 = 1.959963984540054 ** 2
    assert wilson_interval(0, 10) == (0.0, pytest.approx(z2 / (10 + z2), rel=1e-12))
    low, high = wilson_interval(10, 10)
    assert high == 1.0 and math.isclose(low, 10 / (10 + z2), rel_tol=1e-12)
    text = Rate("ok", "pours within tolerance", 9987, 10000, ()).sentence()
    assert text == "pours within tolerance: 9,987 / 10,000, 99.87 % [99.78, 99.92] 95 % CI"
    for bad in ((3, 2), (-1, 2), (1, 0)):
        with pytest.raises(InputError, match="passed"):
            wilson_interval(*bad)
