"""Where safepath keeps what it builds and caches on disk, unless told otherwise."""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["cache_base"]


def cache_base() -> Path:
    """The folder safepath's disk caches go in by default (each cache has its own
    environment variable besides).

    In a virtual environment it is ``<venv>/var/cache/safepath``: what is kept there
    (kernels compiled for that environment's Python and numba, the parts its safepath
    makes from a robot, the message classes of its rosbags) belongs to the environment.
    A process under any home directory (a check that clears ``~/.cache``) finds it, and
    it goes when the environment is deleted (its files are the owner's: the kernel
    build's folder is private to them). Outside one, or in one that cannot be written and holds no
    such folder: ``$XDG_CACHE_HOME/safepath``, else ``~/.cache/safepath``.
    """
    if sys.prefix != sys.base_prefix:
        local = Path(sys.prefix) / "var" / "cache" / "safepath"
        if local.is_dir() or os.access(sys.prefix, os.W_OK):
            return local
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "safepath"
