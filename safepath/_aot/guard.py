"""Argument checks in front of the ahead-of-time kernels.

An extension built by ``numba.pycc`` converts its arguments without checking them the
way numba's dispatcher does: an int64 array passed for a float64 one, or a strided view
for a contiguous one, would be read as if it were what the signature says. Each
exported kernel is therefore called through a small Python function, generated from its
row of :mod:`.table`, that checks every argument against the signature (~60 ns per array)
and otherwise hands the call to the numba-compiled kernel (or raises, in strict mode).
"""

from __future__ import annotations

import logging
import marshal
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path
from types import CodeType
from typing import Any

import numpy as np

from .table import Entry, Kind

__all__ = ["wrap", "describe"]

log = logging.getLogger("safepath._aot")

_ARRAY = re.compile(r"^(f8|i8|b1)\[((?::, )*)::1\]$")
_DTYPES = {"f8": np.dtype(np.float64), "i8": np.dtype(np.int64), "b1": np.dtype(np.bool_)}
#: C-contiguous, aligned, writeable (numpy's flag bits): what numba types as a mutable,
#: aligned 'C' array.
_FLAGS = 0x1 | 0x100 | 0x400
_INTS = frozenset({int, np.int64, np.int32, np.int16, np.int8, np.uint32, np.uint16,
                   np.uint8})
_FLOATS = frozenset({float, np.float64})
_BOOLS = frozenset({bool, np.bool_})
_UNITUPLE = re.compile(r"^UniTuple\((\w+), (\d+)\)$")
_SCALARS = {"f8": "_FLOATS", "i8": "_INTS", "b1": "_BOOLS"}


def _check(name: str, kind: Kind) -> str:
    """A Python expression true when the value ``name`` matches the type ``kind``."""
    if isinstance(kind, tuple):
        parts = [f"{name}.__class__ is tuple", f"len({name}) == {len(kind)}"]
        parts += [_check(f"{name}[{i}]", k) for i, k in enumerate(kind)]
        return " and ".join(parts)
    match = _ARRAY.match(kind)
    if match:
        ndim = match.group(2).count(":") + 1
        dtype = f"_{match.group(1)}"
        # An unpickled array's dtype is equal to numpy's, not always the same object.
        return (f"{name}.__class__ is _nd and ({name}.dtype is {dtype} or {name}.dtype == "
                f"{dtype}) and {name}.ndim == {ndim} and {name}.flags.num & {_FLAGS} == "
                f"{_FLAGS}")
    if kind in _SCALARS:
        return f"{name}.__class__ in {_SCALARS[kind]}"
    match = _UNITUPLE.match(kind)
    if match:
        return _check(name, (match.group(1),) * int(match.group(2)))
    raise ValueError(f"kernel table: type {kind!r} is not one the guards know")


def describe(value: Any) -> str:
    """A short type description of an argument, for messages."""
    if isinstance(value, np.ndarray):
        layout = "C" if value.flags.c_contiguous else "F" if value.flags.f_contiguous else "A"
        ro = "" if value.flags.writeable else ", read-only"
        return f"{value.dtype}[{value.ndim}d, {layout}{ro}]"
    if isinstance(value, tuple):
        return "(" + ", ".join(describe(v) for v in value) + ")"
    return type(value).__name__


def wrap(name: str, entry: Entry, compiled: Callable[..., Any],
         fallback: Callable[[str, tuple[Any, ...]], Any]) -> Callable[..., Any]:
    """The checked caller of one exported kernel.

    Args:
        name: Its export name.
        entry: Its row of the table.
        compiled: The ahead-of-time function.
        fallback: Called with the name and the arguments when they do not match.
    """
    params = [f"a{i}" for i in range(len(entry.args))]
    test = " and ".join(_check(p, k) for p, k in zip(params, entry.args, strict=True))
    args = ", ".join(params)
    source = (f"def {entry.function}({args}):\n"
              f"    if {test}:\n"
              f"        return _compiled({args})\n"
              f"    return _fallback({name!r}, ({args}{',' if len(params) == 1 else ''}))\n")
    scope: dict[str, Any] = {"_nd": np.ndarray, "_compiled": compiled, "_fallback": fallback,
                             "_INTS": _INTS, "_FLOATS": _FLOATS, "_BOOLS": _BOOLS,
                             **{f"_{k}": v for k, v in _DTYPES.items()}}
    exec(_code(source, name), scope)  # noqa: S102
    function = scope[entry.function]
    function.__doc__ = f"{entry.module}.{entry.function}, compiled ahead of time ({name})."
    function.__qualname__ = entry.function
    function.__module__ = entry.module
    return function  # type: ignore[no-any-return]


#: The guards' compiled code by their source, and the file that keeps it (see
#: :func:`keep_code_in`): compiling them costs ~3 ms in every new process.
_codes: dict[str, CodeType] = {}
_code_file: list[Path] = []


def keep_code_in(folder: Path) -> None:
    """Keep the guards' compiled code in ``folder`` (the build's own): read now, written
    whenever a guard is compiled anew. A missing file is made; one that does not read
    (another Python's, or damaged) is ignored with a warning and replaced."""
    path = folder / f"guards.{sys.implementation.cache_tag}.marshal"
    _code_file[:] = [path]
    try:
        data = marshal.loads(path.read_bytes())
    except FileNotFoundError:
        return
    except (OSError, EOFError, ValueError, TypeError) as exc:
        log.warning("kernel guards' code cache %s ignored (%s): compiled again", path, exc)
        return
    if not isinstance(data, dict) or not all(
            isinstance(k, str) and isinstance(v, CodeType) for k, v in data.items()):
        log.warning("kernel guards' code cache %s ignored (not a table of code): compiled "
                    "again", path)
        return
    _codes.update(data)


def _code(source: str, name: str) -> CodeType:
    """The compiled ``source`` of a guard: kept, or compiled now (and kept)."""
    code = _codes.get(source)
    if code is None:
        code = _codes[source] = compile(source, f"<safepath kernel {name}>", "exec")
        if _code_file:
            path = _code_file[0]
            part = path.with_name(f"{path.name}.{os.getpid()}.part")
            try:
                part.write_bytes(marshal.dumps(_codes))
                os.replace(part, path)  # whole or not at all, for concurrent processes
            except OSError as exc:  # a read-only cache: compiled in every process
                log.debug("kernel guards' code not kept in %s: %s", path, exc)
    return code
