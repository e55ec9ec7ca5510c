"""File helpers: YAML reading that names the file on failure, atomic writes with backup."""

from __future__ import annotations

import glob
import math
import os
import secrets
import shutil
import stat
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import yaml

from .errors import ConfigError, InputError, unknown_name

try:  # libyaml's parser: about 7x faster than PyYAML's own on the cell's files
    from yaml import CSafeLoader as _SafeBase
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    from yaml import SafeLoader as _SafeBase  # type: ignore[assignment]

__all__ = ["read_yaml", "atomic_write", "atomic_write_text", "leftover_temporaries", "get_key",
           "as_float", "as_vector", "as_str", "check_names", "check_keys"]


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


def read_yaml(path: str | Path, *, error: type[InputError] = ConfigError) -> Any:
    """Read a YAML file; a key given twice in one mapping is an error.

    Raises:
        InputError: The file is missing, unreadable, not valid YAML, or repeats a key.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error("file not found", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"cannot read file ({exc})", path=path) from None
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
        raise error(f"expected a number, got {value!r}", path=path, key=key)
    out = float(value)
    if not math.isfinite(out):
        raise error(f"value {value!r} is not finite", path=path, key=key)
    if positive and out <= 0.0:
        raise error(f"must be > 0, got {out:g}", path=path, key=key)
    if non_negative and out < 0.0:
        raise error(f"must be >= 0, got {out:g}", path=path, key=key)
    return out


def as_vector(value: Any, n: int | None, *, path: Path | None, key: str,
              error: type[InputError] = ConfigError) -> list[float]:
    """Convert a YAML list to ``n`` finite floats, or raise a typed error."""
    if not isinstance(value, (list, tuple)):
        raise error(f"expected a list of {n or ''} numbers, got {value!r}".replace("  ", " "),
                    path=path, key=key)
    if n is not None and len(value) != n:
        raise error(f"expected {n} values, got {len(value)}", path=path, key=key)
    return [as_float(v, path=path, key=f"{key}[{i}]", error=error) for i, v in enumerate(value)]


def as_str(value: Any, *, path: Path | None, key: str,
           error: type[InputError] = ConfigError) -> str:
    """Check that a YAML value is a non-empty string."""
    if not isinstance(value, str) or not value:
        raise error(f"expected a non-empty string, got {value!r}", path=path, key=key)
    return value


@contextmanager
def atomic_write(path: str | Path, *, mode: str = "w", backup: bool = False,
                 before_replace: Callable[[Path], None] | None = None) -> Iterator[IO[Any]]:
    """Write a file so that it is either wholly replaced or left untouched.

    The content goes to a temporary file ``.<name>.<random>.tmp`` in the same folder, is
    flushed to disk, and only then renamed over ``path``. The new file keeps the mode
    (and, where allowed, the owner and group) of the one it replaces; a new file gets
    the mode the umask gives. With ``backup``, the previous file is kept as ``path~``
    (copied before the rename). On an exception the temporary file is removed and
    ``path`` is unchanged; a process killed meanwhile leaves the temporary file behind
    (see :func:`leftover_temporaries`).

    Args:
        path: The file to replace.
        mode: ``"w"`` (text, UTF-8) or ``"wb"``.
        backup: Keep the previous file as ``path~``.
        before_replace: Called with the temporary file once it holds the whole new
            content on disk, before anything is renamed (a write-ahead log goes there).
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
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
        if backup and path.exists():
            shutil.copy2(path, path.with_name(path.name + "~"))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def leftover_temporaries(path: str | Path) -> list[Path]:
    """Temporary files of :func:`atomic_write` for ``path`` left by killed writers (and
    by a write in progress: remove them only while no one writes ``path``)."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    return sorted(folder.glob(f".{glob.escape(path.name)}.*.tmp"))


def _create_temporary(path: Path) -> tuple[int, Path]:
    """A new temporary file beside ``path``, created with the umask's mode (mkstemp's
    0600 would be kept by the rename)."""
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


def _keep_mode_and_owner(fd: int, path: Path) -> None:
    """Give the temporary file ``fd`` the mode of ``path`` (if it exists), and its owner
    and group where this process may (a robot process running as another user or
    group must still read the file after it is replaced)."""
    try:
        st = path.stat()
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
        InputError: The file cannot be written (``path`` is left as it was).
    """
    try:
        with atomic_write(path, backup=backup, before_replace=before_replace) as handle:
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
