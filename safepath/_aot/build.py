"""Build the ahead-of-time kernels (``safepath build-kernels``): numba's ``pycc``.

Every row of :mod:`.table` is compiled from its module's Python function with numba's
own compiler into one C extension (it links numba's small runtime, not numba), for this
machine's CPU (``target_cpu = "host"``, as numba's JIT compiles), releasing the GIL
while a kernel runs (as ``nogil=True`` does for the JIT kernels). The extension and a
record of the build (``build.json``: key, exports, numba version, CPU, build time) are
written to a new folder, which is then renamed into place: a reader sees a whole build
or none. The cache keeps the :data:`KEEP` latest builds.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import platform
import shutil
import tempfile
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import META, PACKAGE, build_dir, cache_root, find, module_name, source_key
from .table import ENTRIES, Entry, Kind

__all__ = ["Build", "build", "prune", "signature"]


@dataclass(frozen=True)
class Build:
    """A build of the kernels.

    Attributes:
        path: The extension module.
        key: Its source key.
        seconds: Time the compilation took [s]; 0 when an existing build was current.
        fresh: Whether this call compiled it.
    """

    path: Path
    key: str
    seconds: float
    fresh: bool


def signature(entry: Entry) -> str:
    """The entry's signature in numba's notation (``i8(f8[::1], ...)``)."""

    def one(kind: Kind) -> str:
        if isinstance(kind, tuple):
            inner = ", ".join(one(k) for k in kind) + ("," if len(kind) == 1 else "")
            return f"Tuple(({inner}))"
        return kind

    return f"{entry.result}({', '.join(one(a) for a in entry.args)})"


def python_function(entry: Entry) -> Any:
    """The plain Python function of an entry, whatever its module's decorator made of it."""
    module = importlib.import_module(entry.module)
    value = getattr(module, entry.function)
    return getattr(value, "py_func", value)


@contextlib.contextmanager
def _releasing_gil() -> Iterator[None]:
    """pycc compiles its exports with default flags; set ``release_gil`` (the JIT
    kernels' ``nogil=True``) on them while this build runs."""
    from numba.pycc import compiler

    original = compiler.Flags

    class Flags(original):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.release_gil = True

    setattr(compiler, "Flags", Flags)  # noqa: B010 - mypy: a class attribute of a module
    try:
        yield
    finally:
        setattr(compiler, "Flags", original)  # noqa: B010


def build(*, force: bool = False) -> Build:
    """Compile the kernels of the current sources into the cache (unless a build of them
    exists and ``force`` is false).

    Raises:
        OSError: The cache folder cannot be written.
        Exception: numba's compiler failed (its own error, with the kernel it was on).
    """
    key = source_key()
    existing, _ = find()
    if existing is not None and not force:
        return Build(existing, key, 0.0, False)
    from . import materialize
    from .table import MODULES

    for name in MODULES:
        importlib.import_module(name)
    materialize()  # kernel modules imported with an extension in use (--force): numba's
    with warnings.catch_warnings():  # pycc is "pending deprecation"; it is what we need
        warnings.simplefilter("ignore")
        from numba.pycc import CC

    root = cache_root()
    root.mkdir(parents=True, exist_ok=True)
    name = module_name(key)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=root, prefix=".build-") as tmp:
        cc = CC(name, source_module="safepath._aot")
        cc.output_dir = tmp
        cc.target_cpu = "host"
        for export, entry in ENTRIES.items():
            cc.export(export, signature(entry))(python_function(entry))
        with _releasing_gil():
            cc.compile()
        seconds = time.perf_counter() - started
        import llvmlite.binding as llvm
        import numba

        meta = {"key": key, "file": Path(cc.output_file).name, "exports": sorted(ENTRIES),
                "numba": numba.__version__, "python": platform.python_version(),
                "cpu": llvm.get_host_cpu_name(), "seconds": round(seconds, 1),
                "built": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "sources": str(PACKAGE)}
        Path(tmp, META).write_text(json.dumps(meta, indent=1) + "\n")
        target = build_dir(key)
        if target.exists():
            shutil.rmtree(target)
        try:
            os.rename(tmp, target)
        except OSError:
            if find()[0] is None:  # not another build of the same key finishing first
                raise
        os.makedirs(tmp, exist_ok=True)  # TemporaryDirectory cleans up its own path
    path, reason = find()
    if path is None:
        raise OSError(f"kernel build in {target} not found after writing it: {reason}")
    prune(root, keep=KEEP, current=target)
    return Build(path, key, seconds, True)


#: Builds kept in the cache (each ~1 MB): one per source state, the latest ones.
KEEP = 16


def prune(root: Path, *, keep: int, current: Path) -> list[Path]:
    """Delete all but the ``keep`` most recently written builds in ``root`` (never
    ``current``), and unfinished build folders older than an hour; returns what was
    deleted. A process that still maps a deleted extension keeps it; one that finds it
    gone runs numba's JIT."""
    builds = sorted((d for d in root.iterdir() if d.is_dir() and (d / META).is_file()
                     and d != current), key=lambda d: (d / META).stat().st_mtime,
                    reverse=True)
    old = builds[max(keep - 1, 0):]
    old += [d for d in root.glob(".build-*")
            if d.is_dir() and time.time() - d.stat().st_mtime > 3600]
    for folder in old:
        shutil.rmtree(folder, ignore_errors=True)
    return old
