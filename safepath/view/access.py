"""Who may edit in a review session: watching is open, editing may need a token.

A session bound to a loopback address serves only this machine: every page may edit
(unless a token is set). Bound beyond loopback, pages are read-only until unlocked
with the session's token (printed on the server console, or given); wrong tokens are
refused. After ``attempts`` wrong ones within ``window`` seconds from one page, that
page is refused without a check until the window has passed; after ``host_attempts``
from one host (all its pages: a page that reloads is a new page), every page of that
host is. So one page guessing does not lock out the other pages of its host (or of a
reverse proxy), and reloading does not buy more guesses than the host's ceiling.
``allow_anonymous_edit`` turns the token off (a trusted lab network).
"""

from __future__ import annotations

import hmac
import logging
import secrets
import threading
import time
from collections import deque
from collections.abc import Callable

from ..errors import InputError, SafepathError

__all__ = ["AccessDenied", "Access", "new_token", "check_token"]

log = logging.getLogger(__name__)

#: Shortest token accepted from the user [characters].
MIN_TOKEN_LENGTH = 8


class AccessDenied(SafepathError):
    """An edit from a page that has not been unlocked, or a wrong token.

    Attributes:
        client: The page's address (``host:port``).
        reason: What is refused and why.
        retry_after: Seconds until the address may try a token again (rate limit), or 0.
    """

    def __init__(self, reason: str, *, client: str, retry_after: float = 0.0) -> None:
        self.client = client
        self.reason = reason
        self.retry_after = retry_after
        super().__init__(reason)


def new_token() -> str:
    """A fresh random token (12 URL-safe characters, 72 bits)."""
    return secrets.token_urlsafe(9)


def check_token(token: str, *, key: str = "token") -> str:
    """``token`` if it is usable: at least 8 characters, no spaces.

    Raises:
        InputError: Too short or with whitespace.
    """
    if len(token) < MIN_TOKEN_LENGTH or any(c.isspace() for c in token):
        raise InputError(f"the token must be at least {MIN_TOKEN_LENGTH} characters without "
                         "spaces", key=key)
    return token


class Access:
    """Edit rights of the pages of one session.

    Args:
        token: The token that unlocks editing; None: editing is open to every page.
        given: Whether the token was given (``--token``, ``$SAFEPATH_VIEW_TOKEN``,
            ``ViewOptions.token``) rather than made up and printed on the console: the
            pages say where to find it.
        attempts: Wrong tokens allowed from one page within ``window``.
        host_attempts: Wrong tokens allowed from one host (all its pages) within
            ``window``.
        window: Length of the rate-limit window [s].
        clock: Monotonic time source [s] (tests give their own).
    """

    def __init__(self, token: str | None, *, given: bool = False, attempts: int = 5,
                 host_attempts: int = 20, window: float = 60.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.token = token
        self.given = given
        self.attempts = attempts
        self.host_attempts = host_attempts
        self.window = window
        self._clock = clock
        self._unlocked: set[int] = set()
        self._page_failures: dict[int, deque[float]] = {}
        self._host_failures: dict[str, deque[float]] = {}
        self._lock = threading.Lock()

    @property
    def where(self) -> str:
        """Where a reviewer finds the token, for the pages' prompts."""
        return ("the token this session was started with" if self.given
                else "printed on the server console")

    @property
    def required(self) -> bool:
        """Whether editing needs the token."""
        return self.token is not None

    def may_edit(self, client_id: int) -> bool:
        """Whether page ``client_id`` may edit and save."""
        return not self.required or client_id in self._unlocked

    def check(self, client_id: int, address: str, what: str = "edit poses") -> None:
        """Refuse ``what`` from a page that may not edit.

        Raises:
            AccessDenied: The page is read-only.
        """
        if not self.may_edit(client_id):
            raise AccessDenied(f"read-only: enter the edit token ({self.where}) to {what}",
                               client=address)

    def unlock(self, client_id: int, attempt: str, *, host: str, address: str) -> None:
        """Unlock editing for page ``client_id`` if ``attempt`` is the token.

        Args:
            client_id: The page.
            attempt: The token typed in the page.
            host: The page's host address (the ceiling counts per host).
            address: The page's ``host:port`` (for the messages and the log).

        Raises:
            AccessDenied: A wrong token, or too many wrong ones from this page or host
                lately.
        """
        if self.token is None:
            return
        with self._lock:
            now = self._clock()
            page = self._recent(self._page_failures.setdefault(client_id, deque()), now)
            from_host = self._recent(self._host_failures.setdefault(host, deque()), now)
            if len(page) >= self.attempts:
                wait = page[0] + self.window - now
                raise AccessDenied(f"too many wrong tokens from this page: try again in "
                                   f"{wait:.0f} s", client=address, retry_after=wait)
            if len(from_host) >= self.host_attempts:
                wait = from_host[0] + self.window - now
                raise AccessDenied(f"too many wrong tokens from {host} (all its pages): try "
                                   f"again in {wait:.0f} s", client=address, retry_after=wait)
            if not hmac.compare_digest(attempt.strip().encode(), self.token.encode()):
                page.append(now)
                from_host.append(now)
                left = min(self.attempts - len(page), self.host_attempts - len(from_host))
                log.warning("wrong edit token from %s", address)
                raise AccessDenied(f"wrong token ({left} more tries from this page in the "
                                   f"next {self.window:.0f} s)", client=address,
                                   retry_after=0.0 if left else self.window)
            self._unlocked.add(client_id)
        log.info("editing unlocked for %s", address)

    def _recent(self, failures: deque[float], now: float) -> deque[float]:
        """``failures`` without those older than the window."""
        while failures and failures[0] <= now - self.window:
            failures.popleft()
        return failures

    def forget(self, client_id: int) -> None:
        """A page went away: its unlock ends with it (its host's count stays)."""
        with self._lock:
            self._unlocked.discard(client_id)
            self._page_failures.pop(client_id, None)
