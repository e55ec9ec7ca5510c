"""What collision checking answers: the report of a state and of a segment."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["StateReport", "SegmentReport", "Pair"]

#: A pair of names: robot links (``forearm_link``) or scene objects (``qc_conveyor``).
Pair = tuple[str, str]


@dataclass(frozen=True)
class StateReport:
    """What the checker found at one joint vector.

    Attributes:
        q: The joint vector [rad].
        within_limits: Every joint inside its position limits.
        limit_violation: Which joint is outside, if any.
        collisions: Colliding pairs (empty when collision-free).
        clearance: Smallest distance to the environment [m] (<= 0 in contact).
        closest_pair: The pair at that distance.
        margin_violations: Pairs closer than their required margin, with distance [m]
            and margin [m].
    """

    q: np.ndarray = field(repr=False)
    within_limits: bool
    limit_violation: str | None
    collisions: tuple[Pair, ...]
    clearance: float
    closest_pair: Pair | None
    margin_violations: tuple[tuple[Pair, float, float], ...] = ()

    @property
    def valid(self) -> bool:
        """Inside the limits and collision-free."""
        return self.within_limits and not self.collisions

    @property
    def margin_ok(self) -> bool:
        """Valid, and every object's safety margin is kept."""
        return self.valid and not self.margin_violations


@dataclass(frozen=True)
class SegmentReport:
    """Result of checking a straight joint-space segment.

    Attributes:
        valid: Every checked state is valid.
        checked: How many states were checked.
        fraction: Where the first invalid state lies, in [0, 1] (None if valid).
        q: The first invalid state found [rad] (None if valid).
        collisions: Its colliding pairs.
        limit_violation: Its limit violation, if that is why.
    """

    valid: bool
    checked: int
    fraction: float | None = None
    q: np.ndarray | None = field(default=None, repr=False)
    collisions: tuple[Pair, ...] = ()
    limit_violation: str | None = None
