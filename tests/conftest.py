"""Shared fixtures of the test suite: the bundled cell, its folder and its robot.

The session-scoped objects are read-only: a test that needs to change a cell takes
``cell_copy`` (the cell's YAML files copied to a temporary folder) instead.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

from safepath import Cell, Robot, load_cell

# A kernel call whose arguments do not match its ahead-of-time signature raises in the
# tests (a user's process runs numba's JIT kernel instead); child processes inherit it.
os.environ.setdefault("SAFEPATH_AOT_STRICT", "1")
# The sphere layer's disk cache of robot parts (safepath.collision._partcache): one of the session's
# own, empty at its start, never the user's.
os.environ.setdefault("SAFEPATH_CACHE", tempfile.mkdtemp(prefix="safepath-tests-cache-"))

#: The repository root (``tests/`` is one level below it).
REPO_ROOT = Path(__file__).resolve().parents[1]
#: The bundled quality-check cell.
CELL_DIR = REPO_ROOT / "scenes" / "quality_check_cell"


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository root."""
    return REPO_ROOT


@pytest.fixture(scope="session")
def cell_dir() -> Path:
    """The bundled cell's folder, ``scenes/quality_check_cell``."""
    return CELL_DIR


@pytest.fixture(scope="session")
def cell() -> Cell:
    """The bundled quality-check cell (do not mutate)."""
    return load_cell(CELL_DIR)


@pytest.fixture(scope="session")
def robot(cell: Cell) -> Robot:
    """The cell's robot, the Ned3 Pro with Gripper 1 (do not mutate)."""
    return cell.robot


@pytest.fixture()
def cell_copy(tmp_path: Path) -> Path:
    """A writable copy of the bundled cell's YAML files, in a temporary folder."""
    target = tmp_path / "cell"
    target.mkdir()
    for item in CELL_DIR.glob("*.yaml"):
        shutil.copy2(item, target / item.name)
    return target
