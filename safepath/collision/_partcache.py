"""A user cache on disk of what the sphere layer makes from a robot alone (its joints'
tables and each shape's sphere fit, hull tables and reach per joint: ``_pack``'s robot
part), so that a new process's first plan does not fit them again (~4 ms for the Ned3
Pro, its first plan's ~9 %).

An entry is named by a digest of everything it is made from: the code that makes it (the
sources of ``_pack``, ``_layout``, ``spheres`` and ``_gjk``), the layer's options, the robot's
kinematics (joint placements, kinds, axes, limits) and every collision shape (its joint,
placement, kind and dimensions, a mesh's or hull's points). Another robot, shape, option or
version of that code is another entry, so a stale entry is never read; a missing one is
made and written. An entry holds plain arrays only (a small JSON header, then their
bytes, with a digest of all of it): one that does not read back whole is ignored with a
warning and made again. Entries are written whole or not at all (a temporary file, then
renamed), so concurrent processes never read half of one; a cache that cannot be written
is only logged.

Environment:
    SAFEPATH_CACHE: The cache folder (default ``$XDG_CACHE_HOME/safepath``, else
        ``~/.cache/safepath``); entries go to its ``robot-parts`` folder. ``0`` or an
        empty value: no disk cache.
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._digest import blake2b, sha256

__all__ = ["load_or_make", "folder"]

log = logging.getLogger(__name__)

ENV = "SAFEPATH_CACHE"
MAGIC = b"SAFEPATH-PART-1\n"
#: The modules whose code makes an entry (their sources are part of its name).
_MAKERS = ("_pack.py", "_layout.py", "spheres.py", "_gjk.py", "_partcache.py")
_DTYPES = {"f8": np.float64, "i8": np.int64, "b1": np.bool_}
_code_digest: list[bytes] = []


def folder() -> Path | None:
    """Where entries are kept (None: the disk cache is off)."""
    env = os.environ.get(ENV)
    if env is not None:
        return Path(env) / "robot-parts" if env not in ("", "0") else None
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "safepath" / "robot-parts"


def _code() -> bytes:
    """A digest of the sources of the code that makes an entry (read once a process)."""
    if not _code_digest:
        h = sha256()
        here = Path(__file__).resolve().parent
        for name in _MAKERS:
            h.update(name.encode() + b"\0" + (here / name).read_bytes() + b"\0")
        _code_digest.append(h.digest())
    return _code_digest[0]


def key(parts: list[Any]) -> str:
    """An entry's name: a digest of the code and of ``parts`` (bytes, strings, numbers
    and arrays, in order)."""
    h = sha256()
    h.update(_code())
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"{a.dtype.str}{a.shape}".encode() + b"\0" + a.tobytes() + b"\0")
        elif isinstance(part, bytes):
            h.update(part + b"\0")
        else:
            h.update(repr(part).encode() + b"\0")
    return str(h.hexdigest())


def _encode(arrays: dict[str, np.ndarray]) -> bytes:
    header, blobs, offset = [], [], 0
    for name, value in arrays.items():
        a = np.ascontiguousarray(value)
        kind = a.dtype.kind + str(a.dtype.itemsize)
        if kind not in _DTYPES:
            raise TypeError(f"{name}: dtype {a.dtype} is not kept on disk")
        data = a.tobytes()
        header.append([name, kind, list(a.shape), offset, len(data)])
        blobs.append(data)
        offset += len(data)
    head = json.dumps(header).encode()
    payload = b"".join(blobs)
    body = len(head).to_bytes(8, "little") + head + payload
    return MAGIC + blake2b(body, 16) + body


def _decode(raw: bytes) -> dict[str, np.ndarray]:
    """The arrays of an entry; ValueError if it does not read back whole."""
    if not raw.startswith(MAGIC):
        raise ValueError("not an entry of this format")
    digest, body = raw[len(MAGIC):len(MAGIC) + 16], raw[len(MAGIC) + 16:]
    if len(digest) != 16 or blake2b(body, 16) != digest:
        raise ValueError("its digest does not match its content")
    size = int.from_bytes(body[:8], "little")
    header = json.loads(body[8:8 + size])
    payload = memoryview(body)[8 + size:]
    out = {}
    dtypes = {k: np.dtype(v) for k, v in _DTYPES.items()}
    for name, kind, shape, offset, length in header:
        dtype = dtypes[kind]
        if offset + length > len(payload) or length != dtype.itemsize * math.prod(shape):
            raise ValueError(f"array {name!r} does not fit")
        out[name] = np.frombuffer(payload, dtype, math.prod(shape), offset).reshape(shape)
    return out


def load_or_make(name: str, make: Callable[[], dict[str, np.ndarray]]
                 ) -> dict[str, np.ndarray]:
    """The arrays of entry ``name``: read from the cache, or made by ``make()`` (and
    written). Read arrays are read-only."""
    where = folder()
    if where is None:
        return make()
    path = where / f"{name}.part"
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raw = None
    except OSError as exc:
        log.debug("robot-part cache %s not read: %s", path, exc)
        raw = None
    if raw is not None:
        try:
            return _decode(raw)
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            log.warning("robot-part cache entry %s ignored (%s): made again", path, exc)
    arrays = make()
    try:
        where.mkdir(parents=True, exist_ok=True)
        part = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        part.write_bytes(_encode(arrays))
        os.replace(part, path)
    except (OSError, TypeError) as exc:
        log.debug("robot-part cache %s not written: %s", path, exc)
    return arrays
