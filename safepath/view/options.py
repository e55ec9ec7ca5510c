"""Options of the browser review session (no GUI import here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .backend import BackendKind

__all__ = ["ViewOptions"]


@dataclass(frozen=True)
class ViewOptions:
    """Options of a review session.

    Attributes:
        host: Address to listen on (local only by default).
        port: Port to listen on; 0 lets the system pick one.
        strict_port: Fail when ``port`` is taken instead of using the next free one.
        rate: Playback updates per second [Hz].
        sample_period: Period of the clearance and speed curves [s].
        seed: Planner seed for start-up planning and re-planning.
        backend: Where planning runs (``auto``: the runtime planner if available,
            else a worker process).
        plan_on_start: Plan the cell at start-up when no plans are given.
    """

    host: str = "127.0.0.1"
    port: int = 8080
    strict_port: bool = False
    rate: float = 30.0
    sample_period: float = 0.02
    seed: int = 0
    backend: BackendKind = "auto"
    plan_on_start: bool = True

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise InputError(f"port must be in [0, 65535], got {self.port}", key="port")
        if not (np.isfinite(self.rate) and 1.0 <= self.rate <= 120.0):
            raise InputError(f"rate must be in [1, 120] Hz, got {self.rate}", key="rate")
        if not (np.isfinite(self.sample_period) and 0.0 < self.sample_period <= 1.0):
            raise InputError(f"sample_period must be in (0, 1] s, got {self.sample_period}",
                             key="sample_period")
        if self.backend not in ("auto", "process", "runtime"):
            raise InputError(f"backend must be 'auto', 'process' or 'runtime', got "
                             f"{self.backend!r}", key="backend")
