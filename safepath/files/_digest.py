"""Hashers without ``hashlib``: importing it loads OpenSSL (~3 ms), which a new process
would pay for a cache key alone (the compiled kernels' key, a hull's sphere-fit key).
CPython's own implementations serve instead where it has them (the standard library's
``random`` does the same); otherwise ``hashlib``'s."""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["sha256", "blake2b"]


def _builtin(modules: tuple[str, ...], name: str) -> Any:
    for module in modules:
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            continue
    import hashlib

    return getattr(hashlib, name)


def sha256() -> Any:
    """A new SHA-256 hasher."""
    return _builtin(("_sha256", "_sha2"), "sha256")()  # CPython 3.11; 3.12 and later


def blake2b(data: bytes, digest_size: int = 16) -> bytes:
    """The BLAKE2b digest of ``data``."""
    return _builtin(("_blake2",), "blake2b")(data, digest_size=digest_size).digest()  # type: ignore[no-any-return]
