"""The warnings a cell's controller logs during a twin's run, kept with the run's figures.

A controller logs a warning where a real cell's operator should look (a verdict that
came too late, one that did not come). In the twin the same events are the figures of
the run: :func:`kept_warnings` keeps them in a list that the run's result carries and the
report counts, instead of printing them (a run in a pool's worker would print them
before the report, unattributed to its seed). Only the records of the thread that runs
the twin are kept; another thread's, and records below ``WARNING``, pass as before.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["kept_warnings"]


@contextmanager
def kept_warnings(logger_name: str) -> Iterator[list[str]]:
    """Keep the warnings (and errors) that logger ``logger_name`` logs from this thread.

    Args:
        logger_name: The controller module's logger (a filter acts on the logger the
            record is logged on, not on its parents).

    Yields:
        The kept messages, in order (filled while the block runs).
    """
    kept: list[str] = []
    thread = threading.get_ident()

    def keep(record: logging.LogRecord) -> bool:
        if record.thread != thread or record.levelno < logging.WARNING:
            return True
        kept.append(record.getMessage())
        return False

    logger = logging.getLogger(logger_name)
    logger.addFilter(keep)
    try:
        yield kept
    finally:
        logger.removeFilter(keep)
