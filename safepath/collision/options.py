"""What collision checking is asked: the checker's options and its sphere layer's."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError

__all__ = ["CheckOptions", "LayerOptions"]


@dataclass(frozen=True, kw_only=True)
class CheckOptions:
    """Options of the collision checker.

    Attributes:
        resolution: Largest motion of any robot point between two checked states of a
            segment [m].
        margin: Safety margin override for every object [m]; None keeps the scene's
            default and per-object margins.
        enforce_margin: Count a state closer to the environment than the margin as
            invalid (planning does; pose checks only report it).
        fast: Decide states with the sphere layer first (:mod:`safepath.collision.layer`);
            answers are the same either way, False checks every state with coal.
    """

    resolution: float = 0.002
    margin: float | None = None
    enforce_margin: bool = False
    fast: bool = True

    def __post_init__(self) -> None:
        if not np.isfinite(self.resolution) or self.resolution <= 0:
            raise ConfigError(f"resolution must be > 0, got {self.resolution}",
                              key="resolution")
        if self.margin is not None and (not np.isfinite(self.margin) or self.margin < 0):
            raise ConfigError(f"margin must be >= 0, got {self.margin}", key="margin")


@dataclass(frozen=True, kw_only=True)
class LayerOptions:
    """Options of the sphere layer (:mod:`safepath.collision.layer`).

    Attributes:
        cell: Edge of the grid cells the outer spheres circumscribe [m].
        refine: A pair whose bounding spheres are farther apart than its margin plus
            this is not refined with its fine spheres when certifying segments [m].
        free_eps: A pair counts as certainly free only beyond its margin plus this [m].
        proof_eps: An inner sphere proves a collision only this far inside [m].
    """

    cell: float = 0.04
    refine: float = 0.01
    free_eps: float = 1e-6
    proof_eps: float = 1e-5
