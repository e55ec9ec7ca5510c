"""Tests exercise the public API (docs/STYLE: "a test that must read a private attribute
is asking for a public accessor or a smaller unit"), so the count of private reads in the
tests cannot grow back.

Every test file is parsed: an attribute ``x._name`` (not a dunder) is refused unless its
base is the test's own ``self`` or ``cls`` (a test helper's own state), and so is a name
imported from a safepath module that is a private function, class or constant rather
than a private module (``from safepath.collision import _gjk`` is a smaller unit: a
kernel module tested on its own; ``from safepath.collision._gjk import _climb`` is not).
Patching by name (``monkeypatch.setattr(module, "_NAME", ...)``) is not a read.
"""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent

#: Reads allowed, as (file, expression): at most this many each. None today; add none.
ALLOWED: dict[tuple[str, str], int] = {}


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _is_module(package: str, name: str) -> bool:
    """Whether ``package.name`` is a module of the source tree (not a name in one)."""
    folder = ROOT.joinpath(*package.split("."))
    return (folder / f"{name}.py").is_file() or (folder / name / "__init__.py").is_file()


def private_reads(source: str) -> list[tuple[int, str]]:
    """(line, expression) of every private read in a test file's ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            base = node.value
            if not (isinstance(base, ast.Name) and base.id in ("self", "cls")):
                found.append((node.lineno, ast.unparse(node)))
        elif (isinstance(node, ast.ImportFrom) and node.module is not None
              and node.module.split(".")[0] == "safepath"):
            found += [(node.lineno, f"from {node.module} import {alias.name}")
                      for alias in node.names
                      if _private(alias.name) and not _is_module(node.module, alias.name)]
    return sorted(found)


def test_the_scan_finds_what_it_must() -> None:
    source = ("from safepath.collision import _gjk\n"
              "from safepath.collision._gjk import _climb, climb\n"
              "class Fake:\n"
              "    def go(self):\n"
              "        self._queue = []\n"
              "        return cls._seen, checker._pairs, a.b._c, _aot._load(1), x.__dict__\n")
    assert private_reads(source) == [
        (2, "from safepath.collision._gjk import _climb"), (6, "_aot._load"),
        (6, "a.b._c"), (6, "checker._pairs")]


def test_no_test_reads_a_private_attribute() -> None:
    seen: Counter[tuple[str, str]] = Counter()
    refused = []
    for path in sorted(TESTS.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for line, expression in private_reads(path.read_text()):
            seen[rel, expression] += 1
            if seen[rel, expression] > ALLOWED.get((rel, expression), 0):
                refused.append(f"{rel}:{line}: {expression}")
    assert not refused, ("private reads in the tests (give the library a public accessor, "
                         "or test a smaller public unit):\n" + "\n".join(refused))


#: The sphere layer's buffer layout (offset constants): tests read its buffers through
#: named views (``safepath.collision._probe``), never by offset.
LAYOUT = "safepath.collision._layout"


def _layout_imports(source: str) -> list[int]:
    """Lines of ``source`` that import the sphere layer's buffer layout."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module is not None:
            names = {f"{node.module}.{a.name}" for a in node.names}
            if node.module == LAYOUT or LAYOUT in names:
                lines.append(node.lineno)
        elif isinstance(node, ast.Import) and any(a.name == LAYOUT for a in node.names):
            lines.append(node.lineno)
    return lines


def test_layout_imports_are_found() -> None:
    assert _layout_imports("from safepath.collision._layout import H_V\n"
                           "from safepath.collision import _layout as K\n"
                           "import safepath.collision._layout\n"
                           "from safepath.collision._probe import pair_buffers\n") == [1, 2, 3]


def test_no_test_imports_buffer_offsets() -> None:
    found = [f"{path.relative_to(ROOT).as_posix()}:{line}"
             for path in sorted(TESTS.rglob("*.py")) if path.name != Path(__file__).name
             for line in _layout_imports(path.read_text())]
    assert not found, ("tests import the sphere layer's buffer offsets (read the buffers "
                       "through safepath.collision._probe):\n" + "\n".join(found))
