"""The one knot lookup: which interval of increasing breakpoints holds each value."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["interval_index"]


def interval_index(breaks: Any, x: Any, count: int) -> Any:
    """Index k of the interval ``[breaks[k], breaks[k + 1])`` holding each ``x``.

    Values before the first breakpoint get 0, values at or after the last get
    ``count - 1``: ``count`` is the number of intervals (``len(breaks) - 1``) to
    interpolate between knots, or the number of knots (``len(breaks)``) for "the last
    knot at or before x".

    Args:
        breaks: Increasing breakpoints (knot times [s], path parameters, ...).
        x: A value or an array of values.
        count: The number of indices allowed, ``>= 1``.

    Returns:
        An integer array shaped like ``x`` (a numpy integer for a scalar ``x``).
    """
    # (np.minimum/np.maximum, not np.clip, which checks its arguments' types on every
    # call: several microseconds, more than the lookup itself on a short array.)
    return np.minimum(np.maximum(np.searchsorted(breaks, x, side="right") - 1, 0), count - 1)
