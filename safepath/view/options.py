"""Options of the browser review session (no GUI import here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .access import check_token
from .backend import BackendKind

__all__ = ["ViewOptions"]


@dataclass(frozen=True, kw_only=True)
class ViewOptions:
    """Options of a review session.

    Attributes:
        host: Address to listen on (local only by default). Beyond loopback, pages are
            read-only until unlocked with the token.
        port: Port to listen on; 0 lets the system pick one.
        strict_port: Fail when ``port`` is taken instead of using the next free one.
        rate: Playback updates per second [Hz].
        sample_period: Period of the clearance and speed curves [s].
        seed: Planner seed for start-up planning and re-planning.
        backend: Where planning runs (``auto``: the runtime planner if available,
            else a worker process).
        plan_on_start: Plan the cell at start-up when no plans are given.
        token: The token that unlocks editing (at least 8 characters); None: one is
            made up when the host is not loopback. Given, it is needed on loopback too.
        allow_anonymous_edit: Every page may edit and save without a token, whatever
            the host (for a trusted lab network).
        token_attempts: Wrong tokens allowed per page and minute.
        token_host_attempts: Wrong tokens allowed per client host (all its pages) and
            minute.
        replan_on_save: Re-plan the routes a save affects (else they are marked stale).
    """

    host: str = "127.0.0.1"
    port: int = 8080
    strict_port: bool = False
    rate: float = 30.0
    sample_period: float = 0.02
    seed: int = 0
    backend: BackendKind = "auto"
    plan_on_start: bool = True
    token: str | None = None
    allow_anonymous_edit: bool = False
    token_attempts: int = 5
    token_host_attempts: int = 20
    replan_on_save: bool = True

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise InputError(f"port must be in [0, 65535], got {self.port}", key="port")
        if not (np.isfinite(self.rate) and 1.0 <= self.rate <= 120.0):
            raise InputError(f"rate must be in [1, 120] Hz, got {self.rate}", key="rate")
        if not (np.isfinite(self.sample_period) and 0.0 < self.sample_period <= 1.0):
            raise InputError(f"sample_period must be in (0, 1] s, got {self.sample_period}",
                             key="sample_period")
        if self.token is not None:
            check_token(self.token)
            if self.allow_anonymous_edit:
                raise InputError("a token and allow_anonymous_edit exclude each other",
                                 key="allow_anonymous_edit")
        if not 1 <= self.token_attempts <= 100:
            raise InputError(f"token_attempts must be in [1, 100], got {self.token_attempts}",
                             key="token_attempts")
        if not self.token_attempts <= self.token_host_attempts <= 1000:
            raise InputError(f"token_host_attempts must be in [token_attempts, 1000], got "
                             f"{self.token_host_attempts}", key="token_host_attempts")
        if self.backend not in ("auto", "process", "runtime"):
            raise InputError(f"backend must be 'auto', 'process' or 'runtime', got "
                             f"{self.backend!r}", key="backend")
