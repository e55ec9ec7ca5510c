"""Corner blends of a joint polyline whose curvature is continuous (G2).

A via point is blended by leaving the polyline ``r`` [rad] before the corner and joining
it again ``r`` after (measured along the polyline), along the quintic Hermite curve from
``A`` to ``B`` with tangents ``2 r d_A`` and ``2 r d_B`` (the polyline's directions
there) and zero second derivatives at both ends: its curvature starts from 0 where it
leaves the polyline and returns to 0 where it rejoins it, so the path's curvature has no
jump at either end. The construction it replaces left the interpolation points within
``r`` of the corner out and let the spline bridge the gap: that path passed about twice
as far from the corner, and its time-optimal jerk-limited timing came out well above the
jerk-free optimum of the same path on the fast arms (``benchmarks/timing_quality.py``
prints both figures; the jerk limits bind where the curvature changes fast).

The curve is sampled by arc length, about ``spacing`` apart, like the straight parts; the
caller's spline interpolates the points.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["blended_points", "resampled"]

#: Samples of a blend curve per output point, to find its arc length.
_FINE = 16


def _blend(a: np.ndarray, d_a: np.ndarray, b: np.ndarray, d_b: np.ndarray,
           tangent: float, spacing: float) -> np.ndarray:
    """Points of the G2 blend from ``a`` (leaving along the unit direction ``d_a``) to
    ``b`` (arriving along ``d_b``), ``a`` excluded, ``b`` included, about ``spacing``
    [rad] apart along it; ``tangent`` is the tangents' length [rad per unit of the
    curve's parameter]: the way the polyline takes from ``a`` to ``b``."""
    m = max(2, int(np.ceil(1.2 * tangent / spacing)))
    lam = np.linspace(0.0, 1.0, _FINE * m + 1)[:, None]
    l3, l4, l5 = lam ** 3, lam ** 4, lam ** 5
    # The quintic Hermite basis of the end points and the end tangents (the end second
    # derivatives are 0).
    h_b = 10 * l3 - 15 * l4 + 6 * l5
    h_ta = lam - 6 * l3 + 8 * l4 - 3 * l5
    h_tb = -4 * l3 + 7 * l4 - 3 * l5
    curve = a + h_b * (b - a) + tangent * (h_ta * d_a + h_tb * d_b)
    curve[-1] = b  # exactly (a + (b - a) may differ from b in the last bit)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    count = max(2, int(np.ceil(arc[-1] / spacing)))
    # The fine samples nearest to even arc lengths; the last one is b itself.
    at = np.minimum(np.searchsorted(arc, np.arange(1, count + 1) * (arc[-1] / count)),
                    curve.shape[0] - 1)
    at[-1] = curve.shape[0] - 1
    return curve[at]


def resampled(waypoints: np.ndarray, spacing: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The polyline with points added so that none lie more than ``spacing`` [rad] apart.

    Returns:
        The points (m, dof), their path parameter (arc length along the polyline, (m,)),
        and the path parameter of each waypoint.
    """
    W = np.asarray(waypoints, dtype=float)  # noqa: N806
    legs = np.linalg.norm(np.diff(W, axis=0), axis=1)
    s_way = np.concatenate([[0.0], np.cumsum(legs)])
    # Segment k gets m_k points, at fractions j / m_k (j = 1..m_k) of it.
    m = np.maximum(1, np.ceil(legs / spacing).astype(int))
    k = np.repeat(np.arange(legs.size), m)
    frac = (np.arange(k.size) - np.repeat(np.cumsum(m) - m, m) + 1) / m[k]
    P = np.vstack([W[:1], W[k] + frac[:, None] * (W[k + 1] - W[k])])  # noqa: N806
    S = np.concatenate([[0.0], s_way[k] + frac * legs[k]])  # noqa: N806
    return P, S, s_way


def blended_points(waypoints: np.ndarray, corners: Sequence[tuple[int, float]],
                   spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolation points along a polyline with G2 blends at some of its corners.

    Args:
        waypoints: The polyline (n, dof), no point repeating the one before it.
        corners: Interior waypoint indices to blend, each with its radius [rad]: the
            blend leaves the polyline that far before the corner and joins it that far
            after, measured along the polyline (across as many of its segments as it
            takes); a radius over half the way to the next blended corner (or an end) is
            reduced to that, so that blends do not overlap. Radius 0 passes through.
        spacing: Largest distance between points on the polyline's parts [rad]; about
            that along the blends.

    Returns:
        The points (m, dof), their path parameter (cumulative chord length, (m,)), and
        the path parameter of each waypoint (of the blend's middle for a blended corner).
    """
    W = np.asarray(waypoints, dtype=float)  # noqa: N806
    # The polyline resampled; the points a blend replaces are then left out.
    P, S, s_way = resampled(W, spacing)  # noqa: N806
    blends = _radii(s_way, corners)
    parts: list[np.ndarray] = []
    # Each output point's place along the polyline (a blend's points spread evenly by
    # chord from its start to its end): maps the waypoints onto the output's chord.
    places: list[np.ndarray] = []
    start = 0
    for c, r in blends:
        s_a, s_b = s_way[c] - r, s_way[c] + r
        # Polyline points too close to the blend's ends would make near-repeated knots.
        gap = 0.25 * min(spacing, r)
        keep_to = int(np.searchsorted(S, s_a - gap, side="right"))
        parts.append(P[start:keep_to])
        places.append(S[start:keep_to])
        a, d_a = _on_polyline(W, s_way, s_a)
        b, d_b = _on_polyline(W, s_way, s_b)
        curve = np.vstack([a[None, :], _blend(a, d_a, b, d_b, s_b - s_a, spacing)])
        along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0),
                                                                axis=1))])
        # A blend that starts where the one before it ended (each radius half the way
        # between them) does not repeat that point.
        first = int(len(parts) > 1 and start >= keep_to and parts[-2].shape[0] > 0
                    and np.array_equal(parts[-2][-1], a))
        parts.append(curve[first:])
        places.append((s_a + (s_b - s_a) * along / along[-1])[first:])
        start = int(np.searchsorted(S, s_b + gap, side="left"))
    parts.append(P[start:])
    places.append(S[start:])
    points = np.vstack(parts)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    return points, chord, np.interp(s_way, np.concatenate(places), chord)


def _radii(s_way: np.ndarray, corners: Sequence[tuple[int, float]]
           ) -> list[tuple[int, float]]:
    """The blended corners in order, each radius at most half the way to the blended
    corners (or ends) beside it."""
    asked = sorted((c, float(r)) for c, r in corners if 0 < c < len(s_way) - 1 and r > 0)
    where = [0.0, *(float(s_way[c]) for c, _ in asked), float(s_way[-1])]
    return [(c, min(r, 0.5 * (where[n + 1] - where[n]), 0.5 * (where[n + 2] - where[n + 1])))
            for n, (c, r) in enumerate(asked)]


def _on_polyline(W: np.ndarray, s_way: np.ndarray, s: float  # noqa: N803
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The point of the polyline at arc length ``s`` and its segment's unit direction."""
    k = int(np.clip(np.searchsorted(s_way, s, side="right") - 1, 0, len(W) - 2))
    leg = W[k + 1] - W[k]
    length = float(s_way[k + 1] - s_way[k])
    return W[k] + (s - s_way[k]) / length * leg, leg / length
