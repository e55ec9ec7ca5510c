"""The layers are a contract (issue 26): import-linter checks the contracts of
pyproject.toml's ``[tool.importlinter]`` over safepath's import graph.

* no import runs up a layer (errors -> files -> _aot -> model -> collision | verify |
  timing | kinematics | description -> cell -> planning -> the applications), and every
  module of the library sits in a package the contract places (a stray one breaks it);
* collision, the release check, timing and kinematics (IK) are independent of each other;
* the release check (safepath.verify) imports nothing of the planner's collision code,
  planning or timing: its geometry is its own;
* no circle between the packages and modules of safepath, at any depth, imports made for
  type checking included;
* the bundled cells (safepath.cells) are applications: a layer above planning, ros and
  monitor, imported by nothing of the library below.

No contract ignores an import (a test below keeps it so).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_import_contracts_are_kept() -> None:
    lint = Path(sys.executable).with_name("lint-imports")
    assert lint.exists(), "import-linter is missing: pip install -e '.[dev]'"
    run = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert "Contracts: 7 kept, 0 broken." in run.stdout, run.stdout[-2000:]


def test_the_contracts_cover_the_layers_and_count_type_checking_imports() -> None:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    assert config["exclude_type_checking_imports"] is False
    contracts = {c["id"]: c for c in config["contracts"]}
    assert contracts["acyclic"]["ancestors"] == ["safepath"]
    assert set(contracts["verify-stands-alone"]["forbidden_modules"]) >= {
        "safepath.collision", "safepath.planning"}
    assert contracts["layers"]["containers"] == ["safepath"]
    assert contracts["layers"]["exhaustive"] is True
    assert "collision | verify | timing | kinematics | description" in (
        contracts["layers"]["layers"])
    # No contract ignores an import: nothing below the planner imports it (loading TCP
    # pose targets solves IK in safepath.kinematics), and the library does not re-export
    # the cells' names (issue 26).
    assert [i for c in config["contracts"] for i in c.get("ignore_imports", [])] == []
    assert contracts["cells-are-applications"]["forbidden_modules"] == ["safepath.cells"]


def test_a_module_outside_every_package_breaks_the_layer_contract(tmp_path: Path) -> None:
    """The layer contract is exhaustive: a module added at the package's root that no
    layer places fails ``lint-imports`` (a copy of the package, with one stray module)."""
    import shutil

    lint = Path(sys.executable).with_name("lint-imports")
    shutil.copytree(ROOT / "safepath", tmp_path / "safepath",
                    ignore=shutil.ignore_patterns("__pycache__", "_data"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / "safepath" / "stray.py").write_text('"""A module no layer lists."""\n')
    run = subprocess.run([str(lint), "--no-cache"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300, env={"PYTHONPATH": str(tmp_path),
                                                      "PATH": "/usr/bin:/bin"})
    assert run.returncode != 0, run.stdout[-2000:]
    assert "every package has its place BROKEN" in run.stdout, run.stdout[-2000:]
    assert "safepath.stray" in run.stdout, run.stdout[-3000:]
