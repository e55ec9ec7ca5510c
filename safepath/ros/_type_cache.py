"""The Python source of the classes of the messages safepath writes, kept on disk.

Making it needs rosbags' whole ROS 2 Humble store and our definitions parsed (about
0.1 s, :func:`~safepath.ros._definitions.standard_store`); a process that writes a bag
needs a few of its classes only. The first process makes the source and keeps it in the
cache folder ``ros-types`` (``$SAFEPATH_CACHE``, see :mod:`safepath.files.derived`);
the next ones read it back and run it (a few milliseconds).

An entry is named by a digest of everything its source is made from: the text of
rosbags' type system (its code generator, message parser and stores) and of
:mod:`._definitions` (our definitions and the types written) and this module. Another
version of any of them is another entry, so a stale entry is never read. The entry's
first line repeats that key and a digest of the source: an entry that does not match
(damaged, cut short, copied from another key) is ignored with a warning and made again.
Entries are written whole or not at all; a cache that cannot be written is only logged.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import rosbags.interfaces
import rosbags.typesys

from ..errors import RosError
from ..files._digest import blake2b
from ..files.derived import cache_folder, read_cache_file, write_cache_file

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = ["FOLDER", "cached_source", "entry_path", "source_key", "use_written_classes"]

log = logging.getLogger(__name__)

#: The cache folder of the entries (under ``$SAFEPATH_CACHE``).
FOLDER = "ros-types"
_FORMAT = b"safepath-ros-types-1"
_PREFIX = "# safepath ROS 2 message classes"
#: The largest entry read back [bytes] (one is about 10 kB).
_ENTRY_LIMIT = 1 << 20


def _inputs() -> list[Path]:
    """The files an entry's source is made from: rosbags' type system and its message
    interfaces, our definitions, this module."""
    typesys = Path(rosbags.typesys.__file__).parent
    return [*sorted(typesys.rglob("*.py")), Path(rosbags.interfaces.__file__),
            Path(__file__).with_name("_definitions.py"), Path(__file__)]


def source_key(files: Iterable[Path] | None = None) -> str:
    """The key of the entry made from ``files`` (default: :func:`_inputs`): a digest of
    their names and text [hex]."""
    parts = [_FORMAT]
    for path in _inputs() if files is None else files:
        parts += [path.name.encode(), path.read_bytes()]
    return blake2b(b"\0".join(parts), 32).hex()


def entry_path(key: str) -> Path | None:
    """Where the entry of ``key`` is kept; None: the disk cache is off."""
    folder = cache_folder(FOLDER)
    return None if folder is None else folder / f"{key[:32]}.py"


def _header(key: str, body: bytes) -> bytes:
    """An entry's first line: its key and a digest of the rest."""
    return f"{_PREFIX} {key} {blake2b(body, 32).hex()}\n".encode()


def _read(path: Path, key: str) -> str | None:
    """The source kept at ``path`` for ``key``; None when there is none or it does not
    match its first line (logged)."""
    raw = read_cache_file(path, _ENTRY_LIMIT)
    if raw is None:
        return None
    head, newline, body = raw.partition(b"\n")
    if not newline or head + newline != _header(key, body):
        log.warning("ROS 2 message class cache %s ignored (its key or digest does not "
                    "match its content): made again", path)
        return None
    try:
        return body.decode()
    except UnicodeDecodeError:  # a matching digest over bytes we never write
        log.warning("ROS 2 message class cache %s ignored (not text): made again", path)
        return None


def cached_source(make: Callable[[], str], key: str | None = None) -> tuple[str, str]:
    """The source ``make()`` returns, read from its cache entry when there is a current
    one, else made (and written).

    Args:
        make: Makes the source (from :func:`~safepath.ros._definitions.standard_store`).
        key: The entry's key; default :func:`source_key`.

    Returns:
        The source and where it comes from (the entry's path, or ``<made>``: for
        tracebacks).
    """
    key = source_key() if key is None else key
    path = entry_path(key)
    text = None if path is None else _read(path, key)
    if text is not None:
        return text, str(path)
    text = make()
    if path is not None:
        body = text.encode()
        try:
            write_cache_file(path, _header(key, body) + body)
        except OSError as exc:
            log.debug("ROS 2 message class cache %s not written: %s", path, exc)
    return text, "<made: safepath.ros._definitions.written_source>"


def use_written_classes(store: Typestore, written: Typestore) -> None:
    """Give ``store`` the classes of ``written`` (the store of the written types), so that a
    message is one class whichever store built it; each type must have the same definition
    in both.

    Raises:
        RosError: A type defined otherwise in ``written`` (its classes came from other
            definitions than the key of their entry says): the entry is removed, so the
            next process makes it again.
    """
    for name, cls in written.types.items():
        if store.fielddefs.get(name) != written.fielddefs[name]:
            path = entry_path(source_key())
            if path is not None:
                path.unlink(missing_ok=True)
            raise RosError(f"the message classes kept in {path} define '{name}' otherwise "
                           "than rosbags and safepath do now: removed; run again")
        store.types[name] = cls
