"""Shared fixtures of the test suite: the bundled cell, its folder and its robot.

The session-scoped objects are read-only: a test that needs to change a cell takes
``cell_copy`` (the cell's YAML files copied to a temporary folder) instead.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from safepath import Cell, Robot, load_cell

# A kernel call whose arguments do not match its ahead-of-time signature raises in the
# tests (a user's process runs numba's JIT kernel instead); child processes inherit it.
os.environ.setdefault("SAFEPATH_AOT_STRICT", "1")
# The disk cache of what is computed from a robot alone (safepath.files.derived): one of
# the session's own, empty at its start, never the user's.
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



# -- two workers (pytest-xdist) --------------------------------------------------------------
# `make test` runs the suite on two workers (pyproject.toml: addopts `-n 2 --dist
# loadgroup`; the scheduler is this file's, below). The unit a worker takes is one test,
# except:
#
# * a module whose tests share a module- or class-scoped fixture is one unit (the fixture is
#   built once, not once per worker);
# * GROUPS: files that must not run beside each other form one unit;
# * EXCLUSIVE: tests that measure time or a CPU share (heartbeat gaps, timeouts, a thread
#   beside a compiled kernel) run while the other worker runs no test (a lock, below);
# * an ``xdist_group`` mark makes a unit of the tests that carry it.
#
# HEAVY files are collected first, so that their units start first. Without xdist (`-n 0`,
# `-p no:xdist`) one process runs everything, in the same order.
#
# The workers tell the scheduler the unit of each test through a file: xdist's own
# `loadgroup` marks it in the test's id, which pytest 9.2 no longer lets a plugin change.

#: File (relative to tests/) -> unit: the headless Chromium tests, one at a time.
GROUPS = {
    "view/test_browser.py": "chromium",
    "monitor/test_replay_browser.py": "chromium",
    "sweeps/test_report_browser.py": "chromium",
}
#: Files whose every test runs alone on the machine (the `exclusive` mark, per file).
EXCLUSIVE = (
    "runtime/test_runtime_planner.py",  # heartbeat gaps, timeouts against a deadline
    "test_aot.py",  # the GIL test times a thread beside a kernel; builds the user cache
)
#: Files with the longest units (tens of seconds), longest first: scheduled first.
HEAVY = (
    "ros/test_pour_controller.py",
    "view/test_browser.py",
    "ros/test_pour_setup.py",
    "test_docs_own_cell.py",
    "sim/test_outputs.py",
    "test_reference_model.py",
    "test_packaging.py",
    "planning/test_pour_routes.py",
    "test_own_cells.py",
    "test_fastcheck.py",
    "planning/test_executed_motion.py",
)
_LOCK_DIR = "safepath_lock_dir"
#: The controller's folder of lock files for this run's workers (xdist only).
_LOCKS = pytest.StashKey[str]()
_TESTS = Path(__file__).resolve().parent


def _relative(path: Path) -> str:
    """A test file's path relative to tests/ (as given, if outside)."""
    path = path.resolve()
    return path.relative_to(_TESTS).as_posix() if path.is_relative_to(_TESTS) else str(path)


def _unit(item: pytest.Item, rel: str) -> str:
    """The scheduling unit of a test (see above)."""
    marks = sorted(str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                   for m in item.iter_markers("xdist_group"))
    if marks:
        return "group:" + "_".join(marks)
    if rel in GROUPS:
        return "group:" + GROUPS[rel]
    if rel in EXCLUSIVE:
        return rel
    info = getattr(item, "_fixtureinfo", None)
    defs = info.name2fixturedefs.values() if info is not None else ()
    if any(d.scope in ("module", "class", "package") for ds in defs for d in ds):
        return rel
    return item.nodeid


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Heavy files first; exclusive marks; on an xdist worker, each test's unit to a file."""
    rels = {item.nodeid: _relative(item.path) for item in items}
    rank = {rel: k for k, rel in enumerate(HEAVY)}
    items.sort(key=lambda item: rank.get(rels[item.nodeid], len(rank)))
    for item in items:
        if rels[item.nodeid] in EXCLUSIVE:
            item.add_marker(pytest.mark.exclusive)
    workerinput = getattr(config, "workerinput", None)
    if workerinput is not None and _LOCK_DIR in workerinput:
        units = {item.nodeid: _unit(item, rels[item.nodeid]) for item in items}
        path = Path(workerinput[_LOCK_DIR]) / f"units-{workerinput['workerid']}.json"
        path.with_suffix(".part").write_text(json.dumps(units))
        path.with_suffix(".part").replace(path)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node: Any) -> None:
    """xdist's controller: one folder of lock files for the workers of this run."""
    config = node.config
    if _LOCKS not in config.stash:
        config.stash[_LOCKS] = tempfile.mkdtemp(prefix="safepath-tests-locks-")
    node.workerinput[_LOCK_DIR] = config.stash[_LOCKS]


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``--dist loadgroup``: xdist's scope scheduler, with the units the workers wrote."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Units(LoadScopeScheduling):  # type: ignore[misc]
        units: dict[str, str] | None = None

        def _split_scope(self, nodeid: str) -> str:
            if self.units is None:
                folder = Path(config.stash.get(_LOCKS, "/nonexistent"))
                files = sorted(folder.glob("units-*.json"))
                self.units = json.loads(files[0].read_text()) if files else {}
            return self.units.get(nodeid, nodeid.split("::", 1)[0])

    config.option.loadscopereorder = False  # the collection's order: HEAVY first
    return Units(config, log)


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = config.stash.get(_LOCKS, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


_lock_files: list[Any] = []


@contextmanager
def _turn(folder: Path, exclusive: bool) -> Iterator[None]:
    """Hold the run's lock: shared for a test, alone for an exclusive one.

    Writer first: a test takes the gate before the lock and an exclusive one keeps it, so
    once an exclusive test waits, the other worker starts no new test; it runs when the
    other worker's current test ends.
    """
    if not _lock_files:
        _lock_files.extend(open(folder / name, "a+") for name in ("gate", "lock"))  # noqa: SIM115
    gate, lock = _lock_files
    fcntl.flock(gate, fcntl.LOCK_EX)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        try:
            if not exclusive:
                fcntl.flock(gate, fcntl.LOCK_UN)
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    finally:
        fcntl.flock(gate, fcntl.LOCK_UN)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Set-up, call and tear-down of a test under the run's lock (xdist workers only)."""
    folder = getattr(item.config, "workerinput", {}).get(_LOCK_DIR)
    if folder is None:
        return (yield)
    with _turn(Path(folder), item.get_closest_marker("exclusive") is not None):
        return (yield)
