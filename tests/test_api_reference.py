"""The API reference: ``make docs`` builds it with pdoc from the docstrings, and any
warning fails it (pdoc's own, and a cross-reference to a safepath name that names
nothing)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
BUILD = ROOT / "docs" / "build_api.py"


def _builder() -> ModuleType:
    spec = importlib.util.spec_from_file_location("build_api", BUILD)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_api_reference_builds_without_a_warning(tmp_path: Path) -> None:
    """The build ``make docs`` runs, into a temporary folder: no warning, and a page for
    safepath and each public package, none for a private module."""
    proc = subprocess.run([sys.executable, str(BUILD), str(tmp_path)], cwd=ROOT,
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and not proc.stderr.strip(), proc.stderr[-3000:]
    pages = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.html")}
    for package in _builder().public_packages():
        assert f"{package.replace('.', '/')}.html" in pages
    assert not [p for p in pages if "/_" in p]
    timing = (tmp_path / "safepath" / "timing.html").read_text()
    assert "time_path" in timing and "TimingOptions" in timing


def test_a_broken_cross_reference_is_a_warning(tmp_path: Path) -> None:
    source = tmp_path / "safepath"
    source.mkdir()
    (source / "module.py").write_text(
        '"""See :func:`safepath.timing.time_path`, :class:`~safepath.Robot`,\n'
        ':attr:`safepath.Robot.controller`, :mod:`safepath.timing` and\n'
        ':func:`safepath.timing.time_paths` and :class:`safepath.timing.\n'
        'TimingOptions`."""\n')
    assert _builder().broken_references(source) == [
        "safepath/module.py:3: cross-reference 'safepath.timing.time_paths' names nothing",
        "safepath/module.py:3: cross-reference 'safepath.timing.\\nTimingOptions' is split "
        "over lines"]
