"""Fixtures of the review-session tests: the bundled cell's routes, planned once; how a
test reads the save log and knows that a save has landed."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pytest

from safepath import Cell, Trajectory, plan_cell


@pytest.fixture(scope="session")
def trajectories(cell: Cell) -> dict[str, Trajectory]:
    """The bundled cell's routes, planned once (seed 0)."""
    return plan_cell(cell)


@pytest.fixture(scope="session")
def plans_dir(trajectories: dict[str, Trajectory], tmp_path_factory: pytest.TempPathFactory
              ) -> Path:
    """A folder of trajectories as ``safepath plan`` writes them (JSON)."""
    folder = tmp_path_factory.mktemp("plans")
    for name, traj in trajectories.items():
        traj.to_json(folder / f"{name}.json")
    (folder / "summary.json").write_text("{}\n")
    return folder


def log_lines(folder: Path) -> list[dict[str, Any]]:
    """The entries of the save log ``poses.log`` in ``folder``."""
    path = folder / "poses.log"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() \
        else []


def saves_landed(folder: Path) -> int:
    """How many saves of ``folder/poses.yaml`` have landed: logged, and the file replaced.

    The log is written ahead (:mod:`safepath.view.store`): a save's line is on disk a
    moment *before* the file is renamed into place, so counting the lines says a save
    landed while ``poses.yaml`` still holds the version before it. The last save has
    landed once the file's hash is its line's ``sha256_after`` (a save withdrawn by an
    ``undone`` line does not count).
    """
    lines = log_lines(folder)
    undone = {line["undone"] for line in lines if "undone" in line}
    saves = [line for line in lines if "undone" not in line and line["time"] not in undone]
    if not saves:
        return 0
    on_disk = hashlib.sha256((folder / "poses.yaml").read_bytes()).hexdigest()
    return len(saves) if saves[-1]["sha256_after"] == on_disk else len(saves) - 1


#: ``python -c VIEW_WITH_CTRL_C ARGS`` runs ``safepath view ARGS`` with Python's own Ctrl-C
#: handler installed, whatever the test run inherited: a run a shell started in the
#: background ignores SIGINT, and so would the view (a fresh-clone ``.ci/run`` started with
#: ``&`` saw it sleep on through the tests' interrupt).
VIEW_WITH_CTRL_C = (
    "import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "sys.argv = ['safepath', 'view', *sys.argv[1:]]; "
    "runpy.run_module('safepath.cli', run_name='__main__', alter_sys=True)")
