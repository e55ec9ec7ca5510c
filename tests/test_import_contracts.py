"""The layers are a contract (issue 26): import-linter checks the contracts of
pyproject.toml's ``[tool.importlinter]`` over safepath's import graph.

* no import runs up a layer (robot & scene -> collision | verify | timing | kinematics ->
  cell -> planning -> the applications);
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
    assert "Contracts: 6 kept, 0 broken." in run.stdout, run.stdout[-2000:]


def test_the_contracts_cover_the_layers_and_count_type_checking_imports() -> None:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    assert config["exclude_type_checking_imports"] is False
    contracts = {c["id"]: c for c in config["contracts"]}
    assert contracts["acyclic"]["ancestors"] == ["safepath"]
    assert set(contracts["verify-stands-alone"]["forbidden_modules"]) >= {
        "safepath.collision", "safepath.planning"}
    assert "safepath.collision | safepath.verify | safepath.timing | safepath.kinematics" in (
        contracts["layers"]["layers"])
    # No contract ignores an import: nothing below the planner imports it (loading TCP
    # pose targets solves IK in safepath.kinematics), and the library does not re-export
    # the cells' names (issue 26).
    assert [i for c in config["contracts"] for i in c.get("ignore_imports", [])] == []
    assert contracts["cells-are-applications"]["forbidden_modules"] == ["safepath.cells"]
