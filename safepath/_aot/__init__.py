"""safepath's numba kernels, compiled ahead of time when a current build exists.

``safepath build-kernels`` (run by ``make setup``) compiles every kernel of
:mod:`.table` into one C extension with ``numba.pycc`` and stores it in a user cache
directory, under a key made of the kernel modules' sources, the table, the builder, the
Python ABI, the installed numba/llvmlite versions and the CPU. A process that plans then
loads that extension (a fraction of a millisecond) and never imports numba nor LLVM: the
first plan in a new process runs as fast as the next ones.

The kernel modules decorate their functions with :func:`njit` instead of numba's. While a
build for the current key exists (and ``SAFEPATH_AOT`` is not ``0``), an exported kernel
is the compiled function behind an argument check (:mod:`.guard`), and every other
decorated function is compiled by numba only if something calls it from Python (tests
and diagnostics). Otherwise :func:`njit` is ``numba.njit``: the kernels compile on first
use, or load from numba's on-disk cache, as before. A build made from other sources is
never found (its key differs), so a stale extension is never used.

Environment:
    SAFEPATH_KERNEL_CACHE: Where builds are kept (default: the ``kernels`` folder of
        :func:`safepath.files._home.cache_base`: in a virtual environment
        ``<venv>/var/cache/safepath/kernels``, else ``$XDG_CACHE_HOME/safepath/kernels``
        or ``~/.cache/safepath/kernels``).
    SAFEPATH_AOT: ``0`` to always use numba's JIT.
    SAFEPATH_AOT_STRICT: ``1`` to raise (TypeError) when a call's arguments do not match
        its kernel's signature, instead of running the JIT kernel (the test suite).
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import logging
import os
import platform
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from ..files._digest import sha256
from ..files._home import cache_base
from .table import ENTRIES, MODULES, PLANNING_MODULES

__all__ = ["njit", "compiled", "status", "source_key", "build_dir", "cache_root",
           "fallback", "load", "materialize", "strict", "PLANNING_MODULES"]

log = logging.getLogger(__name__)

#: The package folder (``.../safepath``).
PACKAGE = Path(__file__).resolve().parents[1]
ENV_CACHE, ENV_MODE, ENV_STRICT = "SAFEPATH_KERNEL_CACHE", "SAFEPATH_AOT", "SAFEPATH_AOT_STRICT"
META = "build.json"
#: Files of this package that shape the compiled code besides the kernel modules.
_OWN = ("table.py", "build.py")

_lock = threading.RLock()
_loaded: dict[str, Any] = {}  # "module": the extension or None, "reason": why not
#: Every function decorated by njit while the extension is in use (materialize's work).
_lazies: list[_Lazy] = []
#: (module, qualified name) of every function decorated by njit, in either mode.
decorated: list[tuple[str, str]] = []
_warned: set[str] = set()


def cache_root() -> Path:
    """The folder that holds the builds."""
    env = os.environ.get(ENV_CACHE)
    if env:
        return Path(env)
    return cache_base() / "kernels"


def _module_path(name: str, root: Path) -> Path:
    return root.parent.joinpath(*name.split(".")).with_suffix(".py")


def _cpu() -> str:
    """What identifies this machine's CPU for code generation (model and features)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            lines = [line for line in f.read().split("\n\n")[0].splitlines()
                     if line.startswith(("model name", "flags", "Features", "CPU part"))]
        if lines:
            return "\n".join(lines)
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()}"


def _package_version_file(package: str) -> bytes:
    """The version file of an installed package (read, not imported), or its name."""
    spec = importlib.util.find_spec(package)
    if spec is None or spec.origin is None:
        return f"{package} missing".encode()
    path = Path(spec.origin).with_name("_version.py")
    try:
        return path.read_bytes()
    except OSError:
        return f"{package} at {spec.origin}".encode()


def source_key(root: Path = PACKAGE) -> str:
    """The key of a build made from the package at ``root`` on this machine (hex).

    Hashes the kernel modules' and this package's own sources, the Python ABI, the
    numba and llvmlite versions, the machine and the CPU.
    """
    h = sha256()
    files = [_module_path(m, root) for m in sorted(MODULES)]
    files += [root / "_aot" / name for name in _OWN]
    for path in files:
        h.update(str(path.relative_to(root.parent)).encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    from importlib.machinery import EXTENSION_SUFFIXES

    for part in (sys.implementation.cache_tag or "", EXTENSION_SUFFIXES[0], platform.machine(),
                 _cpu()):
        h.update(part.encode() + b"\0")
    for package in ("numba", "llvmlite"):
        h.update(_package_version_file(package) + b"\0")
    return h.hexdigest()


def module_name(key: str) -> str:
    """The extension's module name for a key (unique, so that two builds can coexist)."""
    return f"_safepath_kernels_{key[:16]}"


def build_dir(key: str) -> Path:
    """The folder of the build with this key."""
    return cache_root() / key[:24]


def find(root: Path = PACKAGE) -> tuple[Path | None, str]:
    """The extension built from the sources at ``root``, or None and why not."""
    key = source_key(root)
    folder = build_dir(key)
    try:
        meta = json.loads((folder / META).read_text())
    except FileNotFoundError:
        return None, f"no build for these sources in {cache_root()} (safepath build-kernels)"
    except (OSError, ValueError) as exc:
        return None, f"unreadable build record {folder / META}: {exc}"
    if not isinstance(meta, dict) or meta.get("key") != key:
        return None, f"build record {folder / META} is for other sources"
    missing = sorted(set(ENTRIES) - set(meta.get("exports", ())))
    if missing:
        return None, f"build in {folder} lacks kernels {', '.join(missing)}"
    path = folder / str(meta.get("file", ""))
    if not path.is_file():
        return None, f"build in {folder} lacks its extension {path.name}"
    return path, ""


def _enabled() -> bool:
    return os.environ.get(ENV_MODE, "1") != "0"


def strict() -> bool:
    """Whether a call that does not match its kernel's signature raises."""
    return os.environ.get(ENV_STRICT, "0") == "1"


def compiled() -> ModuleType | None:
    """The ahead-of-time extension of the current sources, loaded once; None if there
    is none (or ``SAFEPATH_AOT=0``): then numba's JIT compiles the kernels."""
    with _lock:
        if "module" in _loaded:
            return _loaded["module"]  # type: ignore[no-any-return]
        module, reason = None, "disabled (SAFEPATH_AOT=0)"
        if _enabled():
            path, reason = find()
            if path is not None:
                module, reason = load(path)
                if module is not None:
                    from .guard import keep_code_in

                    keep_code_in(path.parent)
        if module is None and _enabled():
            level = logging.INFO if reason.startswith("no build") else logging.WARNING
            log.log(level, "kernels compiled by numba on first use: %s", reason)
        _loaded["module"], _loaded["reason"] = module, reason
        return module


def load(path: Path) -> tuple[ModuleType | None, str]:
    """The extension module built at ``path``, and "" (or None, and why it is not used:
    it does not load, or lacks an exported kernel)."""
    name = path.name.split(".")[0]
    try:
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            return None, f"{path} is not an extension module"
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except (ImportError, OSError) as exc:
        return None, f"{path} does not load: {exc}"
    missing = [n for n in ENTRIES if not callable(getattr(module, n, None))]
    if missing:
        return None, f"{path} lacks {', '.join(missing)}"
    return module, ""


def status() -> str:
    """How the kernels run in this process, in words (for benchmarks and logs)."""
    module = compiled()
    if module is None:
        return f"numba JIT ({_loaded['reason']})"
    return f"ahead-of-time ({module.__file__})"


class _Lazy:
    """A kernel left to numba's JIT while the extension is in use: compiled when first
    called from Python (see :func:`materialize`)."""

    def __init__(self, function: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = function
        self.options = options
        self.dispatcher: Any = None
        self.__doc__ = function.__doc__
        self.__name__ = function.__name__
        self.__qualname__ = function.__qualname__
        self.__module__ = function.__module__

    def __call__(self, *args: Any) -> Any:
        if self.dispatcher is None:
            materialize()
        return self.dispatcher(*args)

    def __repr__(self) -> str:
        return f"<safepath kernel {self.__module__}.{self.__qualname__} (numba on first call)>"


def materialize() -> None:
    """Give every decorated function its numba dispatcher, and bind the dispatchers in the
    kernel modules in place of the lazy and exported functions (numba resolves a
    kernel's callees from its module's globals when it compiles). Imports numba."""
    with _lock:
        pending = [lazy for lazy in _lazies if lazy.dispatcher is None]
        if not pending:
            return
        import numba

        for lazy in pending:
            lazy.dispatcher = numba.njit(**lazy.options)(lazy.py_func)
        for namespace in {id(lz.py_func.__globals__): lz.py_func.__globals__
                          for lz in _lazies}.values():
            for name, value in list(namespace.items()):
                twin = getattr(value, "_safepath_lazy", None) or value
                if isinstance(twin, _Lazy) and twin.dispatcher is not None:
                    namespace[name] = twin.dispatcher
        log.debug("numba dispatchers bound for %d kernels", len(pending))


def fallback(name: str, args: tuple[Any, ...]) -> Any:
    """A call whose arguments do not match the exported signature: numba's JIT kernel
    (compiled for whatever was passed), or TypeError in strict mode."""
    from .guard import describe

    entry = ENTRIES[name]
    message = (f"kernel {entry.module}.{entry.function}: arguments "
               f"{describe(args)} do not match its signature "
               f"({', '.join(map(str, entry.args))}) in safepath/_aot/table.py")
    if strict():
        raise TypeError(message)
    if name not in _warned:
        _warned.add(name)
        log.warning("%s; running numba's JIT kernel instead", message)
    with _lock:
        lazy = _EXPORTED.get(name)
        if lazy is None:  # a guard made outside the kernel modules (tests): numba's twin
            import importlib

            value = getattr(importlib.import_module(entry.module), entry.function)
            lazy = _EXPORTED[name] = _Lazy(getattr(value, "py_func", value),
                                           {"cache": True, "nogil": True})
            _lazies.append(lazy)
    return lazy(*args)


#: The lazy numba twin of every exported kernel in use, by export name.
_EXPORTED: dict[str, _Lazy] = {}
_EXPORT_OF = {(e.module, e.function): name for name, e in ENTRIES.items()}


def njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(**options)``, or the ahead-of-time kernel (see the module doc)."""

    def decorate(function: Callable[..., Any]) -> Any:
        decorated.append((function.__module__, function.__qualname__))
        module = compiled()
        if module is None:
            import numba

            return numba.njit(**options)(function)
        lazy = _Lazy(function, options)
        with _lock:
            _lazies.append(lazy)
        name = _EXPORT_OF.get((function.__module__, function.__qualname__))
        if name is None:
            return lazy
        from .guard import wrap

        _EXPORTED[name] = lazy
        wrapped = wrap(name, ENTRIES[name], getattr(module, name), fallback)
        wrapped._safepath_lazy = lazy  # type: ignore[attr-defined]
        wrapped.py_func = function  # type: ignore[attr-defined]
        return wrapped

    return decorate


def load_planning_kernels() -> None:
    """Load the kernel modules every plan calls (:data:`PLANNING_MODULES`), where a
    current build of the kernels is loaded (~2 ms), so that a loaded cell's first plan
    pays for planning, not for loading code. Without one, nothing is loaded here: numba
    (tenths of a second) is imported by the first kernel call."""
    if compiled() is None:
        return
    for name in PLANNING_MODULES:
        importlib.import_module(name)
