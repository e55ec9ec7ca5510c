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

__all__ = ["RISE", "blended_points", "corner_pieces", "resampled"]

#: Samples of a blend curve per output point, to find its arc length.
_FINE = 16
#: How the exact blends' curvature (:func:`corner_pieces`) rises: over this fraction of
#: the radius, linearly, then it holds and falls back as fast. 1 (a triangle) gives the
#: smallest peak rate of curvature (the speed the jerk limits allow through a blend goes
#: with its cube root), at a peak curvature 4/3 of the quintic blend's (the acceleration
#: limits' speed goes with its square root); on ``benchmarks/timing_quality.py``'s paths
#: it timed nearest the jerk-free optimum on every robot (2/3 and 1/2 were tried).
RISE = 1.0
#: Turn at a corner (``|d_a + d_b|``, unit directions) below which the exact blend's
#: tangent would come too near zero: such a path keeps the quintic blend.
_SHARPEST = 0.1


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


def corner_pieces(waypoints: np.ndarray, corners: Sequence[tuple[int, float]],
                  rise: float = RISE) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A polyline with every via point blended, as exact cubic pieces.

    The path parameter is the arc length ``s`` along the polyline. Each blend is the
    polyline around its corner averaged by a symmetric kernel ``K`` of support
    ``[-r, r]`` (``q(s) = int p(s - t) K(t) dt``): it leaves the polyline ``r`` before the
    corner and rejoins it ``r`` after, exactly, and its second derivative is
    ``(d_b - d_a) K(s - s_c)``. ``K`` is a trapezoid (it rises linearly over ``rise r``,
    holds, and falls as fast), so the blend is three cubic pieces whose curvature is
    continuous and whose third derivative is piecewise constant, as small as the
    trapezoid allows: a spline through points sampled along a curve has a third
    derivative far larger than the curve's, and the jerk limits cap the speed by it.

    Args:
        waypoints: The polyline (n, dof), no point repeating the one before it.
        corners: The blended via points (index, radius [rad]); radii as in
            :func:`blended_points`.
        rise: The kernel's rise, as a fraction of the radius, in (0, 1].

    Returns:
        The breakpoints (pieces + 1,), each piece's ``y, m, c2, c3`` (pieces, 4, dof) for
        :meth:`~safepath.timing._spline.CubicPath.from_pieces`, and the path parameter of
        each waypoint; None unless every via point is blended and none turns (almost)
        back, or if a leg has no length.
    """
    W = np.asarray(waypoints, dtype=float)  # noqa: N806
    legs = np.linalg.norm(np.diff(W, axis=0), axis=1)
    if not np.all(legs > 1e-12):
        return None
    s_way = np.concatenate([[0.0], np.cumsum(legs)])
    d = np.diff(W, axis=0) / legs[:, None]
    radius = dict(_radii(s_way, corners))
    inner = range(1, len(W) - 1)
    if sorted(radius) != list(inner) or any(
            np.linalg.norm(d[c - 1] + d[c]) < _SHARPEST for c in inner):
        return None
    r = np.array([0.0, *(radius[c] for c in inner), 0.0])
    pieces: list[tuple[float, float, np.ndarray]] = []  # start, end, coefficients
    for k in range(len(W) - 1):
        if k > 0:
            pieces.extend(_blend_pieces(W[k], d[k - 1], d[k], s_way[k], r[k], rise))
        a, b = s_way[k] + r[k], s_way[k + 1] - r[k + 1]
        zero = np.zeros_like(d[k])
        pieces.append((a, b, np.stack([W[k] + r[k] * d[k], d[k], zero, zero])))
    tiny = 1e-12 * max(1.0, float(s_way[-1]))
    kept = [(a, c) for a, b, c in pieces if b - a > tiny]
    breaks = np.array([a for a, _ in kept] + [float(s_way[-1])])
    breaks[0] = 0.0
    return breaks, np.stack([c for _, c in kept]), s_way


def _blend_pieces(corner: np.ndarray, d_a: np.ndarray, d_b: np.ndarray, s_c: float,
                  r: float, rise: float) -> list[tuple[float, float, np.ndarray]]:
    """The three cubic pieces of the blend at ``corner`` (path parameter ``s_c``, radius
    ``r``) from direction ``d_a`` to ``d_b``: (start, end, ``y, m, c2, c3``) each."""
    w2 = rise * r  # the kernel rises over w2, holds over w1 - w2, falls over w2
    w1 = 2.0 * r - w2
    height = 1.0 / w1  # its integral is 1
    turn = d_b - d_a
    y, m, k = corner - r * d_a, d_a.copy(), 0.0
    start = s_c - r
    out = []
    for length, slope in ((w2, height / w2), (w1 - w2, 0.0), (w2, -height / w2)):
        out.append((start, start + length,
                    np.stack([y, m, turn * (k / 2.0), turn * (slope / 6.0)])))
        y = y + m * length + turn * (k * length ** 2 / 2.0 + slope * length ** 3 / 6.0)
        m = m + turn * (k * length + slope * length ** 2 / 2.0)
        k = k + slope * length
        start += length
    return out
