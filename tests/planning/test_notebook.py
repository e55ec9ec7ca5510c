"""``notebooks/quality_check_cell.ipynb`` runs top to bottom and draws its figures.

The kernel is this interpreter (the virtualenv's), through a kernel spec written to a
temporary folder, so the test needs no Jupyter installation beyond the dev extras and
does not depend on which kernels the machine has registered.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from .conftest import ROOT

NOTEBOOK = ROOT / "notebooks" / "quality_check_cell.ipynb"
POURING = ROOT / "notebooks" / "pouring_cell.ipynb"
KERNEL = "safepath-test-venv"


def _kernel_manager(kernel_dir: Path) -> object:
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import AsyncKernelManager

    spec = kernel_dir / KERNEL
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "safepath (test venv)",
        "language": "python",
    }))
    specs = KernelSpecManager(kernel_dirs=[str(kernel_dir)], ensure_native_kernel=False)
    return AsyncKernelManager(kernel_name=KERNEL, kernel_spec_manager=specs)


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
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    pytest.importorskip("matplotlib")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(
        nb, km=_kernel_manager(tmp_path / "kernels"), timeout=120,
        resources={"metadata": {"path": str(NOTEBOOK.parent)}})
    client.execute()  # raises CellExecutionError on the first failing cell
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
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    pytest.importorskip("matplotlib")
    nb = nbformat.read(POURING, as_version=4)
    client = nbclient.NotebookClient(
        nb, km=_kernel_manager(tmp_path / "kernels"), timeout=300,
        resources={"metadata": {"path": str(POURING.parent)}})
    client.execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if o.output_type == "display_data"
              and "image/png" in o.get("data", {})]
    assert len(images) == 3  # tilt + joint speeds, mass curve + tilt, TCP path + speed
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    for expected in ("4 routes planned, timed and verified", "largest tilt of the cup",
                     "slow tilt:", "stop decided at", "final mass", "barista:"):
        assert expected in text
