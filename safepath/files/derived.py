"""What is computed from a robot alone, kept in one place: in memory per robot and, for
the kinds that say how, on disk between processes.

A planner builds a collision checker and a release verifier per world state and
allowed-contact set (a dozen for a cell), and each would otherwise make again what
depends on the robot's shapes alone: sphere fits placed on their joints, hull tables,
reach per joint, FCL shapes. The code that makes such a value declares its kind once, as
a module constant (a :class:`DerivedKind`, or a :class:`StoredKind` to keep it on disk
too), and asks the robot for it: ``robot.derived.get(KIND, make)``. The robot keeps it
while its kinematics, collision geometry and limits stay as they were made from; a robot
whose models are replaced, whose geometry is moved or whose limits change gets it made
again (the shapes themselves are taken as they were: safepath never changes a loaded
robot's shapes). A value is shared, so it must not be changed. :meth:`Derived.held` lists
what a robot holds, :meth:`Derived.forget` drops it.

On disk, an entry is named by a digest of everything it is made from: the code that makes
it (the kind's source files and this module's), the kind's name and options, and what the
kind's maker reads of the robot (its ``inputs``). Another robot, shape, option or version
of that code is another entry, so a stale entry is never read; a missing one is made and
written. An entry holds plain arrays only (a small JSON header, then their bytes, with a
digest of all of it): one that does not read back whole is ignored with a warning and made
again. Entries are written whole or not at all (a temporary file, then renamed), so
concurrent processes never read half of one; a cache that cannot be written is only
logged.

Environment:
    SAFEPATH_CACHE: The cache folder (default: in a virtual environment
        ``<venv>/var/cache/safepath``, else ``$XDG_CACHE_HOME/safepath`` or
        ``~/.cache/safepath``, see :func:`safepath.files._home.cache_base`); entries go
        to its ``robot-parts`` folder (and the classes of the ROS 2 messages safepath
        writes to ``ros-types``, see
        :mod:`safepath.ros._type_cache`). ``0`` or an empty value: no disk cache.
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from ..errors import InputError
from ._digest import blake2b, sha256
from ._home import cache_base
from ._io import read_bytes

__all__ = ["DerivedKind", "StoredKind", "Derived", "DerivedValues", "CACHE_ENV",
           "cache_folder", "disk_folder", "read_cache_file", "read_entry",
           "write_cache_file"]

log = logging.getLogger(__name__)

#: The largest cache entry read back [bytes] (entries are a robot's fitted geometry:
#: kilobytes to a few megabytes).
_ENTRY_LIMIT = 256 << 20

T = TypeVar("T")

#: The environment variable that names the cache folder (see the module doc).
CACHE_ENV = "SAFEPATH_CACHE"
_MAGIC = b"SAFEPATH-PART-1\n"
_DTYPES = {"f8": np.float64, "i8": np.int64, "b1": np.bool_}


@dataclass(frozen=True, eq=False)
class DerivedKind(Generic[T]):
    """A kind of value computed from a robot alone, kept in memory per robot. Declared
    once, as a module constant of the code that makes it; kinds are told apart by
    identity, never by name.

    Attributes:
        name: What it holds, for people (and part of a disk entry's name).
    """

    name: str

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


@dataclass(frozen=True, eq=False, kw_only=True)
class StoredKind(DerivedKind[T]):
    """A kind of value also kept on disk, so that a new process reads it instead of
    making it again.

    Attributes:
        makers: The source files of the code that makes it: their text is part of every
            entry's name, so another version of that code makes another entry.
        to_arrays: The value as named arrays (float64, int64 or bool): what an entry holds.
        from_arrays: The value of an entry's arrays (read-only where read from disk).
    """

    makers: tuple[Path, ...]
    to_arrays: Callable[[T], dict[str, np.ndarray]]
    from_arrays: Callable[[Mapping[str, np.ndarray]], T]


class _Source(Protocol):
    """What is read of a robot to tell whether a value kept for it is still current."""

    model: Any
    collision_model: Any
    lower: np.ndarray
    upper: np.ndarray


@dataclass(frozen=True)
class _Entry:
    models: tuple[Any, Any]  # kept, so that their ids are never reused for others
    stamp: tuple[Any, ...]
    value: Any

    def current(self, models: tuple[Any, Any], stamp: tuple[Any, ...]) -> bool:
        """Whether it was made from these models (the same objects) and this stamp."""
        return (self.models[0] is models[0] and self.models[1] is models[1]
                and self.stamp == stamp)


class DerivedValues:
    """The values kept for one robot (its copies with another tool share them): held by
    the robot, read through :attr:`safepath.Robot.derived`."""

    def __init__(self) -> None:
        self._entries: dict[tuple[DerivedKind[Any], Hashable], _Entry] = {}


class Derived:
    """What is computed from ``robot`` alone and kept for it (``robot.derived``)."""

    def __init__(self, robot: _Source, values: DerivedValues) -> None:
        self._robot = robot
        self._entries = values._entries

    def get(self, kind: DerivedKind[T], make: Callable[[], T], *,
            options: Hashable = None,
            inputs: Callable[[], Sequence[Any]] | None = None) -> T:
        """The value of ``kind`` (with ``options``) for the robot: kept, else read from
        disk (a :class:`StoredKind`), else ``make()``.

        Args:
            kind: What is asked for.
            make: Makes it from the robot.
            options: What else it is made from (hashable; its ``repr`` names disk entries).
            inputs: For a :class:`StoredKind`: what ``make`` reads of the robot (bytes,
                strings, numbers, tuples and arrays), part of the disk entry's name.
        """
        models, stamp = self._state()
        key = (kind, options)
        made = self._entries.get(key)
        if made is None or not made.current(models, stamp):
            value = _load_or_make(kind, make, options, inputs) \
                if isinstance(kind, StoredKind) else make()
            made = self._entries[key] = _Entry(models, stamp, value)
        return made.value  # type: ignore[no-any-return]

    def held(self) -> dict[tuple[DerivedKind[Any], Hashable], Any]:
        """The values kept and still current, by kind and options."""
        models, stamp = self._state()
        return {key: e.value for key, e in self._entries.items() if e.current(models, stamp)}

    def forget(self) -> None:
        """Drop every value kept for the robot (and its copies with another tool): the
        next asks make them again, or read them from disk."""
        self._entries.clear()

    def _state(self) -> tuple[tuple[Any, Any], tuple[Any, ...]]:
        robot = self._robot
        geoms = robot.collision_model.geometryObjects
        stamp = (tuple(int(g.parentJoint) for g in geoms),
                 b"".join(g.placement.homogeneous.tobytes() for g in geoms),
                 robot.lower.tobytes(), robot.upper.tobytes())
        return (robot.model, robot.collision_model), stamp


# -- on disk ----------------------------------------------------------------------------
def cache_folder(name: str) -> Path | None:
    """The folder ``name`` of safepath's cache (``robot-parts``, ``ros-types``); None:
    the disk cache is off (see the module doc)."""
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return Path(env) / name if env not in ("", "0") else None
    return cache_base() / name


def disk_folder() -> Path | None:
    """Where disk entries are kept (None: the disk cache is off, see the module doc)."""
    return cache_folder("robot-parts")


_code_digests: dict[StoredKind[Any], bytes] = {}


def _code(kind: StoredKind[Any]) -> bytes:
    """A digest of the sources of the code that makes ``kind`` (read once a process)."""
    digest = _code_digests.get(kind)
    if digest is None:
        h = sha256()
        for path in (*kind.makers, Path(__file__)):
            h.update(path.name.encode() + b"\0" + Path(path).read_bytes() + b"\0")
        digest = _code_digests[kind] = h.digest()
    return digest


def _entry_name(kind: StoredKind[Any], parts: Sequence[Any]) -> str:
    """An entry's name: a digest of the code and of ``parts`` (bytes, strings, numbers
    and arrays, in order)."""
    h = sha256()
    h.update(_code(kind))
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"{a.dtype.str}{a.shape}".encode() + b"\0" + a.tobytes() + b"\0")
        elif isinstance(part, bytes):
            h.update(part + b"\0")
        else:
            h.update(repr(part).encode() + b"\0")
    return str(h.hexdigest())


def _encode(arrays: Mapping[str, np.ndarray]) -> bytes:
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
    return _MAGIC + blake2b(body, 16) + body


def read_entry(raw: bytes) -> dict[str, np.ndarray]:
    """The arrays of a disk entry's bytes (read-only).

    Raises:
        ValueError: It does not read back whole (another format, a digest that does
            not match, an array that does not fit).
    """
    if not raw.startswith(_MAGIC):
        raise ValueError("not an entry of this format")
    digest, body = raw[len(_MAGIC):len(_MAGIC) + 16], raw[len(_MAGIC) + 16:]
    if len(digest) != 16 or blake2b(body, 16) != digest:
        raise ValueError("its digest does not match its content")
    size = int.from_bytes(body[:8], "little")
    header = json.loads(body[8:8 + size])  # a header that does not read: ValueError
    payload = memoryview(body)[8 + size:]
    out = {}
    dtypes = {k: np.dtype(v) for k, v in _DTYPES.items()}
    try:
        for name, kind, shape, offset, length in header:
            dtype = dtypes[kind]
            if offset + length > len(payload) or length != dtype.itemsize * math.prod(shape):
                raise ValueError(f"array {name!r} does not fit")
            out[name] = np.frombuffer(payload, dtype, math.prod(shape), offset).reshape(shape)
    except (KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"its header does not describe arrays ({exc!r})") from None
    return out


def _load_or_make(kind: StoredKind[T], make: Callable[[], T], options: Hashable,
                  inputs: Callable[[], Sequence[Any]] | None) -> T:
    """The value of ``kind``: read from its disk entry, or made by ``make()`` (and
    written). Either way it is the value of its arrays, so one read back is the one
    made, bit for bit."""
    if inputs is None:
        raise TypeError(f"{kind!r}: a stored kind needs the inputs that name its entry")
    where = disk_folder()
    if where is None:
        return kind.from_arrays(kind.to_arrays(make()))
    path = where / f"{_entry_name(kind, [kind.name, repr(options), *inputs()])}.part"
    raw = read_cache_file(path, _ENTRY_LIMIT)
    if raw is not None:
        try:
            return kind.from_arrays(read_entry(raw))
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            log.warning("robot-part cache entry %s ignored (%s): made again", path, exc)
    arrays = kind.to_arrays(make())
    try:
        write_cache_file(path, _encode(arrays))
    except (OSError, TypeError) as exc:
        log.debug("robot-part cache %s not written: %s", path, exc)
    return kind.from_arrays(arrays)


def read_cache_file(path: Path, limit: int) -> bytes | None:
    """The bytes of the cache file ``path``; None when there is none, or it is not a
    regular file of at most ``limit`` [bytes] (a pipe or device planted there is never
    opened; logged)."""
    if not os.path.lexists(path):
        return None
    try:
        return read_bytes(path, error=InputError, limit=limit)
    except InputError as exc:
        log.debug("cache file %s not read: %s", path, exc)
        return None


def write_cache_file(path: Path, data: bytes) -> None:
    """Write the cache file ``path`` whole or not at all: a temporary file beside it,
    created exclusively and never through a link, renamed over it (which replaces a link
    at ``path`` itself, not what it points to), so that concurrent processes never read
    half of one.

    Raises:
        OSError: It cannot be written.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_name(f"{path.name}.{os.getpid()}.{os.urandom(4).hex()}.tmp")
    fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(data)
    os.replace(part, path)
