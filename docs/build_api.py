"""Build safepath's HTML API reference from its docstrings with pdoc (``make docs``).

The reference covers ``safepath`` and every package of it whose dotted name has no part
starting with ``_`` (a package with ``__all__`` shows what it lists; one without, its
public modules too). Docstrings are read as Google style. Any warning pdoc gives (a
module that does not import, an annotation or a cross-reference it cannot resolve, ...)
fails the build, and so does a cross-reference in a docstring (``:func:`safepath...```)
to a name that does not exist, which pdoc would show as plain code without a word: each
is printed on standard error and the exit status is 1.

Usage::

    python docs/build_api.py [OUT]     # default: out/api; open OUT/index.html
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import pkgutil
import re
import sys
import warnings
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO_ROOT / "out" / "api"


def public_packages() -> list[str]:
    """``safepath`` and its packages whose dotted names have no part starting with ``_``,
    except those pdoc reaches itself (below a listed package without ``__all__``)."""
    import safepath

    names = ["safepath"]
    for info in pkgutil.walk_packages(safepath.__path__, "safepath."):
        if not info.ispkg or any(part.startswith("_") for part in info.name.split(".")):
            continue
        parent = importlib.import_module(info.name.rpartition(".")[0])
        if hasattr(parent, "__all__"):
            names.append(info.name)
    return names


def _load_lazy_names(package: str) -> None:
    """Bind the names a package exports lazily (a module ``__getattr__``, e.g.
    :mod:`safepath.view`, which loads viser on first use) in its namespace, where pdoc
    looks for the names of ``__all__``."""
    module = importlib.import_module(package)
    for name in getattr(module, "__all__", ()):
        if name not in vars(module):
            setattr(module, name, getattr(module, name))


#: A Sphinx role naming a safepath object: :func:`safepath.x.y`, :class:`~safepath.X`, ...
_REFERENCE = re.compile(r":(?:py:)?(?:mod|func|data|const|class|meth|attr|exc|obj):"
                        r"`~?(safepath[^`]*?)(?:\(\))?`")


def _resolves(target: str) -> bool:
    """Whether a dotted name is a module, or an object or attribute reached from one (an
    instance attribute counts when the class annotates or assigns ``self.<name>``)."""
    parts = target.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for i, name in enumerate(parts[cut:], start=cut):
            if hasattr(obj, name):
                obj = getattr(obj, name)
            elif i == len(parts) - 1 and isinstance(obj, type):
                return name in getattr(obj, "__annotations__", {}) or bool(
                    re.search(rf"self\.{name}\s*[:=]", inspect.getsource(obj)))
            else:
                return False
        return True
    return False


def broken_references(source: Path = REPO_ROOT / "safepath") -> list[str]:
    """Every cross-reference to a ``safepath`` name in the Python files under ``source``
    that names nothing, as ``file:line: name`` (pdoc shows one as plain code, without a
    warning)."""
    broken = []
    for path in sorted(source.rglob("*.py")):
        text = path.read_text()
        for match in _REFERENCE.finditer(text):
            target = match.group(1)
            # A name split over two lines is no name to pdoc either.
            why = ("is split over lines" if re.search(r"\s", target)
                   else None if _resolves(target) else "names nothing")
            if why:
                line = text.count("\n", 0, match.start()) + 1
                broken.append(f"{path.relative_to(source.parent)}:{line}: cross-reference "
                              f"{target!r} {why}")
    return broken


def build(out: Path) -> list[str]:
    """Write the reference into ``out``; return pdoc's warnings and the broken
    cross-references (empty when clean)."""
    import pdoc
    import pdoc.render

    pdoc.render.configure(docformat="google", search=True, show_source=False,
                          footer_text="safepath API reference")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        packages = public_packages()
        for package in packages:
            _load_lazy_names(package)
        # Private modules (a part starting with "_") are left out where pdoc walks a
        # package's modules itself.
        pdoc.pdoc(*packages, r"!.*\._", output_directory=out)
    return [f"{w.category.__name__}: {w.message}" for w in caught
            if Path(w.filename).parent.name == "pdoc"] + broken_references()


def main(argv: list[str] | None = None) -> int:
    """Build into the folder given (default ``out/api``); 1 when pdoc warned."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    problems = build(args.out)
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        print(f"API reference: {len(problems)} warning(s)", file=sys.stderr)
        return 1
    print(f"API reference written to {args.out / 'index.html'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
