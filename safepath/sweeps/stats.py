"""The report's statistics: rates with their Wilson score interval, distributions.

The Wilson score interval (Wilson, "Probable inference, the law of succession, and
statistical inference", JASA 22, 1927) keeps its coverage near the nominal level for
rates close to 0 or 1 and few runs, where the normal approximation's interval leaves
[0, 1] or shrinks to nothing (0 of n failures gives [0, 0] there).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..errors import InputError

__all__ = ["wilson_interval", "Rate", "Distribution", "distribution"]


def wilson_interval(passed: int, total: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a rate ``passed / total``.

    Args:
        passed: Runs that passed (0 <= passed <= total).
        total: Runs (>= 1).
        confidence: The interval's confidence level, in (0, 1).

    Returns:
        ``(low, high)``, fractions in [0, 1].

    Raises:
        InputError: Counts or a confidence out of range.
    """
    for key, value in (("passed", passed), ("total", total)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise InputError(f"expected an integer, got {value!r}", key=key)
    if total < 1 or not 0 <= passed <= total:
        raise InputError(f"expected 0 <= passed <= total and total >= 1, got {passed} of "
                         f"{total}", key="passed")
    if not 0 < confidence < 1:
        raise InputError(f"expected a level in (0, 1), got {confidence!r}", key="confidence")
    z = NormalDist().inv_cdf(0.5 + confidence / 2)
    p = passed / total
    denominator = 1 + z * z / total
    centre = (p + z * z / (2 * total)) / denominator
    half = z / denominator * math.sqrt(p * (1 - p) / total + z * z / (4 * total * total))
    # Exact at the ends (0 of n, n of n), where rounding could leave a hair outside.
    low = 0.0 if passed == 0 else max(0.0, centre - half)
    high = 1.0 if passed == total else min(1.0, centre + half)
    return low, high


@dataclass(frozen=True)
class Rate:
    """How many runs passed a check, with the rate's 95 % Wilson interval.

    Attributes:
        key: The check's key.
        label: Its words.
        passed: Runs that passed.
        total: Runs that ran the check.
        failed_seeds: The seeds that failed it, ascending.
    """

    key: str
    label: str
    passed: int
    total: int
    failed_seeds: tuple[int, ...]

    @property
    def interval(self) -> tuple[float, float]:
        """The 95 % Wilson score interval (fractions)."""
        return wilson_interval(self.passed, self.total)

    def sentence(self) -> str:
        """``label: 9,987 / 10,000, 99.87 % [99.78, 99.92] 95 % CI``."""
        low, high = self.interval
        return (f"{self.label}: {self.passed:,} / {self.total:,}, "
                f"{100 * self.passed / self.total:.2f} % [{100 * low:.2f}, {100 * high:.2f}] "
                "95 % CI")


@dataclass(frozen=True)
class Distribution:
    """A figure's values over the runs.

    Attributes:
        key: The figure's key.
        label: Its words, unit in brackets.
        values: Every value, in seed order (a run's several values in their order).
        edges: The histogram's bin edges (ascending).
        counts: Values per bin.
    """

    key: str
    label: str
    values: tuple[float, ...]
    edges: tuple[float, ...]
    counts: tuple[int, ...]

    def summary(self) -> dict[str, float]:
        """Count, mean, standard deviation, min, median, 90th percentile and max of the
        finite values."""
        finite = np.asarray([v for v in self.values if math.isfinite(v)], dtype=float)
        if finite.size == 0:
            return {"count": 0.0}
        return {"count": float(finite.size), "mean": float(finite.mean()),
                "std": float(finite.std(ddof=1)) if finite.size > 1 else 0.0,
                "min": float(finite.min()), "median": float(np.median(finite)),
                "p90": float(np.percentile(finite, 90)), "max": float(finite.max())}


def distribution(key: str, label: str, values: Sequence[float], bins: int = 30
                 ) -> Distribution:
    """A figure's values and their histogram (infinite values are counted in none: a
    clearance with no state checked is ``inf``)."""
    finite = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if finite.size == 0:
        return Distribution(key, label, tuple(values), (), ())
    low, high = float(finite.min()), float(finite.max())
    if high == low:
        low, high = low - 0.5, high + 0.5
    counts, edges = np.histogram(finite, bins=min(bins, max(1, finite.size)),
                                 range=(low, high))
    return Distribution(key, label, tuple(float(v) for v in values),
                        tuple(float(e) for e in edges), tuple(int(c) for c in counts))
