"""The sweep's progress bar on standard error: seeds done, rate, estimated time left.

tqdm (installed with viser) draws it; the seeds a resumed sweep found finished count as
done from the start, and the estimate counts only the seeds run now.
"""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["Progress"]


class Progress:
    """A progress bar of a sweep.

    Args:
        total: Seeds of the sweep.
        done: Seeds already finished (a resumed sweep).
        enabled: Draw it (False: silent).
        label: Words before the bar.
    """

    def __init__(self, total: int, done: int = 0, *, enabled: bool = True,
                 label: str = "sweep") -> None:
        self._bar: Any = None
        self._failed = 0
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, desc=label, unit="run",
                             file=sys.stderr, dynamic_ncols=True, smoothing=0.1)

    def advance(self, failed: bool) -> None:
        """One seed finished (``failed``: counted in the bar's postfix)."""
        if self._bar is None:
            return
        if failed:
            self._failed += 1
            self._bar.set_postfix_str(f"{self._failed} failed", refresh=False)
        self._bar.update(1)

    def close(self) -> None:
        """End the bar's line."""
        if self._bar is not None:
            self._bar.close()
