"""File helpers: YAML reading that names the file on failure, atomic writes with backup.

How safepath reads and writes a user's files (robot, scene, routes, poses, the save log):

* A file is read only if it is a regular file (a link to one is followed; a named pipe,
  a device or a folder is refused before it is opened, so a pipe cannot block the reader
  and ``/dev/zero`` cannot fill the memory) of at most :data:`MAX_FILE_BYTES`.
* A file is written by creating a new temporary file beside it (``O_CREAT | O_EXCL |
  O_NOFOLLOW``) and renaming it over the name. A name that is a symbolic link or not a
  regular file is refused, never written through; so is a backup name ``<file>~`` that
  is not a regular file. The backup is itself a fresh temporary file renamed into place,
  so a link planted at that name between the check and the rename is replaced, not
  followed.
"""

from __future__ import annotations

import errno
import glob
import math
import os
import re
import reprlib
import stat
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import yaml

from ..errors import ConfigError, InputError, unknown_name

try:  # libyaml's parser: about 7x faster than PyYAML's own on the cell's files
    from yaml import CSafeLoader as _SafeBase
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    from yaml import SafeLoader as _SafeBase  # type: ignore[assignment]

__all__ = ["MAX_FILE_BYTES", "check_readable", "read_bytes", "read_text", "read_yaml",
           "parse_yaml",
           "atomic_write", "atomic_write_text", "keep_backup", "check_replaceable",
           "open_no_follow", "leftover_temporaries", "get_key", "as_float", "as_vector",
           "as_str", "brief", "check_names", "check_keys"]

#: The largest file safepath reads [bytes] (16 MiB): a cell's YAML files are kilobytes;
#: a poses file of 30,000 poses is 2 MB. A larger file is refused, naming this limit.
MAX_FILE_BYTES = 16 << 20

#: Flags of every file safepath opens: not inherited by a child process; never blocking
#: on a named pipe (one is refused after ``fstat``).
_OPEN_FLAGS = os.O_CLOEXEC | os.O_NONBLOCK


class _DuplicateKey(Exception):
    def __init__(self, key: str, line: int) -> None:
        super().__init__(key, line)
        self.key = key
        self.line = line


class _StrictLoader(_SafeBase):
    """A safe loader that refuses a key given twice in one mapping (PyYAML keeps the
    last one silently, which would lose a recorded pose)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable keys: let PyYAML report them
                duplicate = False
            if duplicate:
                raise _DuplicateKey(str(key), key_node.start_mark.line + 1)
            try:
                seen.add(key)
            except TypeError:
                pass
        return super().construct_mapping(node, deep=deep)


# YAML 1.2 reads ``1e-05`` as a float; PyYAML (YAML 1.1) wants a dot in the mantissa and
# reads it as the string "1e-05" (which Python's repr writes, and a pose is then "not a
# number"). Checked after PyYAML's own resolvers: an integer stays an integer.
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def _kind(mode: int) -> str:
    """What a file that is not a regular file is, for a message."""
    for test, name in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISDIR, "a folder"),
                       (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _check_readable(st: os.stat_result, path: Path, error: type[InputError],
                    limit: int) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise error(f"is {_kind(st.st_mode)}: safepath reads regular files only",
                    path=path)
    if st.st_size > limit:
        raise error(f"file too large ({st.st_size / (1 << 20):.1f} MiB; safepath reads at "
                    f"most {limit / (1 << 20):g} MiB, safepath.files._io.MAX_FILE_BYTES)",
                    path=path)


def check_readable(path: str | Path, *, error: type[InputError] = ConfigError,
                   limit: int = MAX_FILE_BYTES) -> None:
    """Refuse a file that another library is about to open by its name (a URDF given to
    Pinocchio) unless it is a regular file of at most ``limit`` [bytes].

    Raises:
        InputError: The file is missing, not a regular file or too large.
    """
    path = Path(path)
    try:
        _check_readable(os.stat(path), path, error, limit)
    except FileNotFoundError:
        raise error("file not found", path=path) from None
    except OSError as exc:
        raise error(f"cannot read file ({exc.strerror or exc})", path=path) from None


def read_bytes(path: str | Path, *, error: type[InputError] = ConfigError,
               limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a user's file, read only if it is a regular file of at most ``limit``.

    The path is checked with ``stat`` before it is opened (a device or a named pipe is
    never opened), opened with ``O_NONBLOCK`` and checked again on the open file (it may
    have been swapped meanwhile), and at most ``limit + 1`` bytes are read (it may grow
    meanwhile). A symbolic link to a regular file is read.

    Args:
        path: The file.
        error: Error class raised.
        limit: The largest size read [bytes].

    Raises:
        InputError: The file is missing, unreadable, not a regular file, or larger than
            ``limit`` (names the file and the reason).
    """
    path = Path(path)
    try:
        _check_readable(os.stat(path), path, error, limit)
        fd = os.open(path, os.O_RDONLY | _OPEN_FLAGS)
    except FileNotFoundError:
        raise error("file not found", path=path) from None
    except OSError as exc:
        raise error(f"cannot read file ({exc.strerror or exc})", path=path) from None
    try:
        _check_readable(os.fstat(fd), path, error, limit)
        chunks = []
        left = limit + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as exc:
        raise error(f"cannot read file ({exc.strerror or exc})", path=path) from None
    finally:
        os.close(fd)
    if left <= 0:
        raise error(f"file too large (grew beyond {limit / (1 << 20):g} MiB while it was "
                    "read; safepath.files._io.MAX_FILE_BYTES)", path=path)
    return b"".join(chunks)


def read_text(path: str | Path, *, error: type[InputError] = ConfigError) -> str:
    """The UTF-8 text of a user's file, read as :func:`read_bytes` reads it.

    Raises:
        InputError: As :func:`read_bytes`, or the file is not UTF-8.
    """
    raw = read_bytes(path, error=error)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"cannot read file (not UTF-8: {exc.reason} at byte {exc.start})",
                    path=Path(path)) from None


def read_yaml(path: str | Path, *, error: type[InputError] = ConfigError) -> Any:
    """Read a YAML file; a key given twice in one mapping is an error.

    Raises:
        InputError: The file is missing, unreadable, not a regular file, larger than
            :data:`MAX_FILE_BYTES`, not valid YAML, or repeats a key.
    """
    path = Path(path)
    return parse_yaml(read_text(path, error=error), path, error=error)


def parse_yaml(text: str, path: Path, *, error: type[InputError] = ConfigError) -> Any:
    """The YAML of ``text`` read from ``path``, as :func:`read_yaml` reads a file.

    Raises:
        InputError: Not valid YAML, or a key given twice in one mapping.
    """
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKey as exc:
        raise error(f"defined twice (line {exc.line})", path=path, key=exc.key) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"malformed YAML{where}: {problem}", path=path) from None


def read_mapping(path: Path, known: Iterable[str]) -> dict[Any, Any]:
    """A YAML file whose top level is a mapping of the ``known`` keys (a data folder's
    robot.yaml, controller.yaml, scene.yaml, routes.yaml).

    Raises:
        ConfigError: Malformed YAML, another top level, or an unknown key (naming the
            closest known one); names the file and key.
    """
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping at the top level", path=path)
    check_keys(data, known, path=path)
    return data


def brief(value: Any) -> str:
    """``repr(value)`` cut short for a message (a few items of a list or mapping, two
    levels deep, at most 80 characters): a misplaced mapping may hold the whole file."""
    shortener = reprlib.Repr()
    shortener.maxlevel, shortener.maxdict, shortener.maxlist = 2, 3, 8
    shortener.maxstring = shortener.maxother = 40
    text = shortener.repr(value)
    return text if len(text) <= 80 else text[:76] + " ..."


def get_key(mapping: Any, key: str, *, path: Path | None, prefix: str = "",
            default: Any = ..., error: type[InputError] = ConfigError) -> Any:
    """Return ``mapping[key]``, or raise a typed error naming the file and dotted key."""
    full = f"{prefix}.{key}" if prefix else key
    if not isinstance(mapping, dict):
        raise error("expected a mapping", path=path, key=prefix or None)
    if key not in mapping:
        if default is not ...:
            return default
        raise error("missing key", path=path, key=full)
    return mapping[key]


def as_float(value: Any, *, path: Path | None, key: str, positive: bool = False,
             non_negative: bool = False, error: type[InputError] = ConfigError) -> float:
    """Convert a YAML scalar to a finite float, or raise a typed error."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f"expected a number, got {brief(value)}", path=path, key=key)
    out = float(value)
    if not math.isfinite(out):
        raise error(f"value {brief(value)} is not finite", path=path, key=key)
    if positive and out <= 0.0:
        raise error(f"must be > 0, got {out:g}", path=path, key=key)
    if non_negative and out < 0.0:
        raise error(f"must be >= 0, got {out:g}", path=path, key=key)
    return out


def as_vector(value: Any, n: int | None, *, path: Path | None, key: str,
              error: type[InputError] = ConfigError) -> list[float]:
    """Convert a YAML list to ``n`` finite floats, or raise a typed error."""
    if not isinstance(value, (list, tuple)):
        raise error(f"expected a list of {n or ''} numbers, got {brief(value)}".replace("  ", " "),
                    path=path, key=key)
    if n is not None and len(value) != n:
        raise error(f"expected {n} values, got {len(value)}", path=path, key=key)
    return [as_float(v, path=path, key=f"{key}[{i}]", error=error) for i, v in enumerate(value)]


def as_str(value: Any, *, path: Path | None, key: str,
           error: type[InputError] = ConfigError) -> str:
    """Check that a YAML value is a non-empty string."""
    if not isinstance(value, str) or not value:
        raise error(f"expected a non-empty string, got {brief(value)}", path=path, key=key)
    return value


@contextmanager
def atomic_write(path: str | Path, *, mode: str = "w", backup: bool = False,
                 before_replace: Callable[[Path], None] | None = None,
                 error: type[InputError] = InputError) -> Iterator[IO[Any]]:
    """Write a file so that it is either wholly replaced or left untouched.

    The content goes to a temporary file ``.<name>.<random>.tmp`` in the same folder
    (created exclusively, never through a link), is flushed to disk, and only then
    renamed over ``path``. The new file keeps the mode (and, where allowed, the owner
    and group) of the one it replaces; a new file gets the mode the umask gives. With
    ``backup``, the previous file is kept as ``path~`` (see :func:`keep_backup`). On an
    exception the temporary file is removed and ``path`` is unchanged; a process killed
    meanwhile leaves the temporary file behind (see :func:`leftover_temporaries`).

    Args:
        path: The file to replace.
        mode: ``"w"`` (text, UTF-8) or ``"wb"``.
        backup: Keep the previous file as ``path~``.
        before_replace: Called with the temporary file once it holds the whole new
            content on disk, before anything is renamed (a write-ahead log goes there).
        error: Error class of a refusal.

    Raises:
        InputError: ``path`` (or, with ``backup``, ``path~``) is a symbolic link or not a
            regular file (see :func:`check_replaceable`); nothing is written.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    check_replaceable(path, backup=backup, error=error)
    fd, tmp = _create_temporary(path)
    try:
        _keep_mode_and_owner(fd, path)
        encoding = None if "b" in mode else "utf-8"
        with os.fdopen(fd, mode, encoding=encoding) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        if before_replace is not None:
            before_replace(tmp)
        if backup:
            keep_backup(path, error=error)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def check_replaceable(path: Path, *, backup: bool, error: type[InputError]) -> None:
    """Refuse to replace ``path`` if it is a symbolic link (replacing it would cut the
    link, writing through it would change a file elsewhere) or not a regular file; with
    ``backup``, refuse a ``path~`` that is not a regular file (a link planted there
    would make the backup overwrite the file it points to).

    Raises:
        InputError: Names the file (``path`` or ``path~``) and what it is.
    """
    names = [(path, "not replaced (safepath replaces regular files only, never through a "
                    "link); give the file itself")]
    if backup:
        names.append((_backup_name(path), "the backup of the previous file goes here and "
                                          "safepath writes none through a link; remove it"))
    for name, why in names:
        try:
            st = os.lstat(name)
        except FileNotFoundError:
            continue
        if not stat.S_ISREG(st.st_mode):
            raise error(f"is {_kind(st.st_mode)}: {why}", path=name)


def keep_backup(path: Path, *, error: type[InputError] = InputError) -> None:
    """Copy ``path`` (if it exists) to ``path~``, keeping its mode and times, without
    following a link at either name.

    The copy is a new temporary file (created exclusively) renamed over ``path~``: a link
    at that name is replaced, never written through.

    Raises:
        InputError: ``path`` or ``path~`` is a link or not a regular file.
        OSError: The copy cannot be written.
    """
    check_replaceable(path, backup=True, error=error)
    try:
        src = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | _OPEN_FLAGS)
    except FileNotFoundError:
        return
    try:
        st = os.fstat(src)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"is {_kind(st.st_mode)}: not copied to its backup", path=path)
        fd, tmp = _create_temporary(path)
        try:
            os.fchmod(fd, stat.S_IMODE(st.st_mode))
            while chunk := os.read(src, 1 << 20):
                view = memoryview(chunk)
                while view:
                    view = view[os.write(fd, view):]
            os.utime(fd, ns=(st.st_atime_ns, st.st_mtime_ns))
            os.fsync(fd)
        except BaseException:
            os.close(fd)
            tmp.unlink(missing_ok=True)
            raise
        os.close(fd)
        try:
            os.replace(tmp, _backup_name(path))
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    finally:
        os.close(src)


def _backup_name(path: Path) -> Path:
    return path.with_name(path.name + "~")


def open_no_follow(path: Path, flags: int, *, error: type[InputError] = InputError) -> int:
    """Open (or, with ``os.O_CREAT``, create) a regular file, never through a link.

    Returns:
        The file descriptor.

    Raises:
        InputError: ``path`` is a symbolic link or not a regular file (names it).
        OSError: It cannot be opened.
    """
    try:
        fd = os.open(path, flags | os.O_NOFOLLOW | _OPEN_FLAGS, 0o666)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error("is a symbolic link: safepath opens this file only as a regular "
                        "file, never through a link; remove it", path=path) from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise error(f"is {_kind(st.st_mode)}, not a regular file", path=path)
    os.set_blocking(fd, True)
    return fd


def leftover_temporaries(path: str | Path) -> list[Path]:
    """Temporary files of :func:`atomic_write` for ``path`` left by killed writers (and
    by a write in progress: remove them only while no one writes ``path``)."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    return sorted(folder.glob(f".{glob.escape(path.name)}.*.tmp"))


def _create_temporary(path: Path) -> tuple[int, Path]:
    """A new temporary file beside ``path``, created exclusively (a name that exists, a
    link included, is never opened), with the umask's mode (mkstemp's 0600 would be kept
    by the rename)."""
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{os.urandom(4).hex()}.tmp")
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                           | os.O_CLOEXEC, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


def _keep_mode_and_owner(fd: int, path: Path) -> None:
    """Give the temporary file ``fd`` the mode of ``path`` (if it exists), and its owner
    and group where this process may (a robot process running as another user or
    group must still read the file after it is replaced)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    os.fchmod(fd, stat.S_IMODE(st.st_mode))
    for uid in (st.st_uid, -1):
        try:
            os.fchown(fd, uid, st.st_gid)
            return
        except PermissionError:
            continue


def atomic_write_text(path: str | Path, text: str, *, backup: bool = False,
                      error: type[InputError] = InputError,
                      before_replace: Callable[[Path], None] | None = None) -> None:
    """Atomically replace ``path`` with ``text`` (see :func:`atomic_write`).

    Raises:
        InputError: The file cannot be written, or ``path`` or its backup name is a
            link or not a regular file (``path`` is left as it was).
    """
    try:
        with atomic_write(path, backup=backup, before_replace=before_replace,
                          error=error) as handle:
            handle.write(text)
    except OSError as exc:
        raise error(f"cannot write file ({exc.strerror or exc})", path=path) from None


def check_names(names: Iterable[Any], known: Iterable[str], *, path: Path | None,
                key: str | None, what: str, error: type[InputError] = ConfigError) -> None:
    """Raise a typed error for the first of ``names`` not in ``known``.

    The message names the closest known names (see :func:`safepath.errors.unknown_name`).
    """
    known = list(known)
    for name in names:
        if name not in known:
            raise error(unknown_name(what, str(name), known), path=path, key=key)


def check_keys(mapping: Mapping[Any, Any], known: Iterable[str], *, path: Path | None,
               prefix: str = "", error: type[InputError] = ConfigError) -> None:
    """Refuse a key of ``mapping`` that is not in ``known``, naming the closest known key.

    Args:
        mapping: A mapping read from a file (or given as an argument).
        known: The keys allowed at this level.
        path: The file, for the message.
        prefix: Dotted key of ``mapping`` in the file ("" at the top level).
        error: Error class raised.
    """
    known = list(known)
    for name in mapping:
        if name not in known:
            full = f"{prefix}.{name}" if prefix else str(name)
            raise error(unknown_name("key", str(name), known), path=path, key=full)
