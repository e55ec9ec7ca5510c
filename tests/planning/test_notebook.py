"""The notebooks run top to bottom, with the command the README gives, and draw their
figures.

The command is read from the README (``.venv/bin/jupyter nbconvert --to notebook --execute
notebooks/NAME.ipynb --output-dir out/notebooks``) and run as written, with this
interpreter's folder for ``.venv/bin`` and a temporary output folder; Jupyter's user and
system folders are emptied (``JUPYTER_PATH``, ``JUPYTER_DATA_DIR``), so the notebook's
``python3`` kernel is the ipykernel installed beside nbconvert, whatever kernels the
machine has registered.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from .conftest import ROOT

NOTEBOOK = ROOT / "notebooks" / "quality_check_cell.ipynb"
POURING = ROOT / "notebooks" / "pouring_cell.ipynb"


def readme_command(notebook: Path) -> list[str]:
    """The README's command that runs ``notebook``, as an argument list."""
    text = (ROOT / "README.md").read_text()
    lines = [line[2:] for line in text.splitlines() if line.startswith("$ ")
             and "nbconvert" in line and f"notebooks/{notebook.name}" in line]
    assert len(lines) == 1, f"the README gives no single command for {notebook.name}"
    return shlex.split(lines[0])


def run_as_the_readme_says(notebook: Path, tmp_path: Path) -> Any:
    """Run the README's command for ``notebook`` (output into ``tmp_path``) and read the
    executed notebook back."""
    import nbformat

    argv = readme_command(notebook)
    assert argv[0] == ".venv/bin/jupyter" and "--execute" in argv
    argv[0] = str(Path(sys.executable).with_name("jupyter"))
    out = argv.index("--output-dir")
    argv[out + 1] = str(tmp_path / "out")
    empty = tmp_path / "jupyter"
    env = {**os.environ, "JUPYTER_PATH": str(empty), "JUPYTER_DATA_DIR": str(empty),
           "JUPYTER_CONFIG_DIR": str(empty), "JUPYTER_PLATFORM_DIRS": "1"}
    proc = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert re.search(r"Writing \d+ bytes", proc.stderr), proc.stderr[-3000:]
    return nbformat.read(tmp_path / "out" / notebook.name, as_version=4)


@pytest.mark.parametrize("path", [NOTEBOOK, POURING], ids=lambda p: p.name)
def test_notebook_is_committed_without_outputs(path: Path) -> None:
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    assert nb.nbformat == 4
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code
    assert all(not c.outputs and c.execution_count is None for c in code)


def test_notebook_runs_and_plots(tmp_path: Path) -> None:
    nb = run_as_the_readme_says(NOTEBOOK, tmp_path)
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if o.output_type == "display_data"
              and "image/png" in o.get("data", {})]
    assert len(images) >= 4  # phase1: positions, velocities, accelerations; summary
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    for expected in ("3 routes planned, timed and verified", "stop-and-go", "ratio",
                     "smallest verified clearance", "phase2_unsafe"):
        assert expected in text
    per_cell = ["".join(o.get("text", "") for o in c.outputs if o.output_type == "stream")
                for c in nb.cells if c.cell_type == "code"]
    poses = next(t for t in per_cell if t.startswith("pose "))
    rows = poses.splitlines()[1:]
    assert len(rows) == 12  # 6 poses, empty and holding the vial
    assert all(" True " in r and " ok " in r for r in rows), poses


def test_pouring_notebook_runs_and_plots(tmp_path: Path) -> None:
    nb = run_as_the_readme_says(POURING, tmp_path)
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if o.output_type == "display_data"
              and "image/png" in o.get("data", {})]
    assert len(images) == 3  # tilt + joint speeds, mass curve + tilt, TCP path + speed
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    for expected in ("4 routes planned, timed and verified", "largest tilt of the cup",
                     "slow tilt:", "stop decided at", "final mass", "barista:"):
        assert expected in text
