"""A cup that empties over its lip: what it holds at a tilt, and how fast it pours.

The cup is a cylinder (inner ``radius``, ``depth``) holding ``fill`` grams of a material
of bulk ``density``; a granular material (the brief's rice) keeps a surface that leans
back by up to its angle of ``repose`` from the horizontal. Tilted by ``theta``, the
cup keeps at most :meth:`Cup.held` (the material below the plane through the lowest
point of the rim, leaning back by the repose angle); more flows out. Its *spill angle*
for a content ``m`` (:meth:`Cup.spill_angle`) is the tilt at which ``m`` reaches the
lip: it rises as the cup empties. The flow out is ``gain * (theta - spill_angle(m)) **
1.5`` [g/s] (the rate grows with the depth of the lip below the surface, as over a
weir), so that at a fixed tilt the flow dies out by itself once the cup holds what that
tilt keeps, and each small step of a stepwise tilt pours a bounded amount.

The defaults are the brief's cup (70 x 100 mm outside) with walls of a few millimetres,
holding rice (0.8 g/cm^3); the fill (115 g) and the repose (0: the rice treated as a
liquid) were fitted, with the flow gain of
:class:`~safepath.cells.pouring.flow.FlowModel`, to the brief's two measured figures
(``scenes/pouring_cell/README.md`` says what was fitted to what; ``benchmarks/pour.py``
prints the result).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import ConfigError

__all__ = ["Cup"]

_GRID = 2001  # tilts tabulated over [0, pi]


@dataclass(frozen=True, kw_only=True)
class Cup:
    """A cylindrical cup and its content.

    Attributes:
        radius: Inner radius [m].
        depth: Inner depth [m].
        fill: Content at the start [g].
        density: Bulk density of the content [g/cm^3] (rice ~0.8, water 1.0).
        repose: Angle of repose of the content [rad] (0 for a liquid): its surface may
            lean back by this much from the horizontal before it flows.
        exponent: Exponent of the flow law (1.5: a weir's head^1.5).
    """

    radius: float = 0.032
    depth: float = 0.095
    fill: float = 115.0
    density: float = 0.8
    repose: float = 0.0
    exponent: float = 1.5
    _table: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("radius", "depth", "fill", "density", "exponent"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"must be a number > 0, got {value!r}", key=name)
        if not (isinstance(self.repose, (int, float)) and 0 <= self.repose < math.pi / 2):
            raise ConfigError(f"must lie in [0, pi/2) [rad], got {self.repose!r}",
                              key="repose")
        if self.fill > self.capacity:
            raise ConfigError(f"the cup holds at most {self.capacity:.1f} g, got "
                              f"{self.fill:g}", key="fill")
        tilt = np.linspace(0.0, math.pi, _GRID)
        object.__setattr__(self, "_table", (tilt, self._below_lip(tilt - self.repose)))

    @property
    def capacity(self) -> float:
        """The cup's content when full [g]."""
        return math.pi * self.radius ** 2 * self.depth * self.density * 1e6

    def _below_lip(self, phi: np.ndarray) -> np.ndarray:
        """Mass below the plane through the rim's lowest point at ``phi`` from the
        horizontal (in the cup's frame: z < depth - (radius - x) tan(phi)) [g]."""
        r, h = self.radius, self.depth
        x = np.linspace(-r, r, 801)
        width = 2.0 * np.sqrt(np.maximum(r * r - x * x, 0.0))
        out = np.empty(phi.size)
        for k, p in enumerate(phi):
            if p <= 0.0:
                out[k] = self.capacity
                continue
            if p >= math.pi / 2:
                out[k] = 0.0
                continue
            height = np.clip(h - (r - x) * math.tan(p), 0.0, h)
            area = float(np.sum(0.5 * (width[1:] * height[1:] + width[:-1] * height[:-1])
                                * np.diff(x)))
            out[k] = area * self.density * 1e6
        return np.minimum(out, self.capacity)

    def held(self, tilt: np.ndarray | float) -> np.ndarray:
        """The most the cup keeps at ``tilt`` [rad] (array) [g]; at most :attr:`fill`."""
        t, m = self._table
        return np.minimum(np.interp(np.asarray(tilt, dtype=float), t, m), self.fill)

    def spill_angle(self, content: float) -> float:
        """The tilt at which ``content`` [g] reaches the lip [rad]."""
        t, m = self._table
        # m decreases with the tilt: interpolate on the reversed table.
        return float(np.interp(content, m[::-1], t[::-1]))

    def pour(self, t: np.ndarray, tilt: np.ndarray, gains: np.ndarray | float, *,
             content: np.ndarray | float | None = None) -> np.ndarray:
        """Mass that has left the cup at times ``t`` [s] for a tilt history ``tilt``
        [rad] sampled at ``t``: flow ``gain * (tilt - spill_angle(content)) ** 1.5``
        [g/s], explicit Euler on the history's steps (numba), for each of ``gains``.

        Args:
            t: Times [s] (N,).
            tilt: Tilt at each time [rad] (N,).
            gains: Flow gain(s) [g/s/rad^1.5], a number or an array (G,).
            content: Content at ``t[0]`` [g] (per gain, or one for all); default
                :attr:`fill`.

        Returns:
            Mass out [g], (N,) for one gain, else (G, N).
        """
        g = np.atleast_1d(np.asarray(gains, dtype=float))
        c0 = np.broadcast_to(np.asarray(self.fill if content is None else content,
                                        dtype=float), g.shape).copy()
        tab_t, tab_m = self._table
        out = _kernel()(np.ascontiguousarray(t, dtype=float),
                        np.ascontiguousarray(tilt, dtype=float), g, c0,
                        np.ascontiguousarray(tab_m[::-1]), np.ascontiguousarray(tab_t[::-1]),
                        float(self.exponent))
        return out[0] if np.ndim(gains) == 0 else out


_KERNEL = None


def _kernel():  # type: ignore[no-untyped-def]
    """The Euler integration of the flow, compiled by numba on first use (lazily: numba
    is heavy to import)."""
    global _KERNEL
    if _KERNEL is None:
        import numba

        @numba.njit(cache=True)
        def pour(t, tilt, gains, content0, rev_m, rev_t, exponent):  # type: ignore[no-untyped-def]
            out = np.zeros((gains.size, t.size))
            for g in range(gains.size):
                content = content0[g]
                start = content
                for k in range(1, t.size):
                    theta = 0.5 * (tilt[k] + tilt[k - 1])
                    x = theta - np.interp(content, rev_m, rev_t)
                    if x > 0.0 and content > 0.0:
                        content = max(0.0, content - gains[g] * x ** exponent * (t[k] - t[k - 1]))
                    out[g, k] = start - content
            return out

        _KERNEL = pour
    return _KERNEL
