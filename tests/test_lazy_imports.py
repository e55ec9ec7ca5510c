"""Heavy or optional dependencies load only where they are used (STYLE.md, point 8).

Each check runs in a new interpreter, so that modules imported by other tests do not
hide an eager import. The cold-start figures themselves are printed by
``benchmarks/cold_start.py``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "scenes" / "quality_check_cell"
#: Packages that cost tenths of a second to import, or are optional.
HEAVY = ("viser", "rosbags", "matplotlib", "scipy", "toppra", "ompl", "numba", "fcl", "ray")


def _loaded_after(code: str, **env: str) -> list[set[str]]:
    """Top-level packages of ``sys.modules`` wherever ``code`` calls ``mark()``."""
    script = ("import sys\n"
              "def mark():\n"
              "    print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))\n" + code)
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=300,
                         env={**os.environ, **env}).stdout
    return [set(line.split()) for line in out.splitlines()]


def test_import_safepath_and_its_command_line_load_no_heavy_package() -> None:
    (after_import, after_parser) = _loaded_after(
        "import safepath\n"
        "mark()\n"
        "from safepath.cli._main import _load_extra, build_parser\n"
        "_load_extra()\n"
        "build_parser().parse_args(['plan', 'scenes/quality_check_cell'])\n"
        "mark()\n")
    assert "safepath" in after_import and "pinocchio" in after_import
    assert after_import.isdisjoint(HEAVY), sorted(after_import & set(HEAVY))
    assert after_parser.isdisjoint(HEAVY), sorted(after_parser & set(HEAVY))


@pytest.mark.parametrize("aot", ["0", "1"])
def test_numba_loads_with_the_first_cartesian_line_unless_the_kernels_are_built(aot: str
                                                                               ) -> None:
    """With the kernels compiled ahead of time (``safepath build-kernels``, run by ``make
    setup``) no planning step imports numba; without (or with SAFEPATH_AOT=0), the first
    kernel call does."""
    from safepath import _aot

    before, after = _loaded_after(
        "import safepath\n"
        f"cell = safepath.load_cell({str(CELL)!r})\n"
        "mark()\n"
        "safepath.planning.cartesian_line(cell.robot, cell.pose('high2'), cell.pose('low1'))\n"
        "mark()\n", SAFEPATH_AOT=aot)
    built = aot == "1" and _aot.find()[0] is not None
    assert "numba" not in before
    assert ("numba" in after) is not built
    assert after.isdisjoint({"viser", "rosbags", "matplotlib", "toppra", "ompl"})


@pytest.mark.parametrize("aot", ["0", "1"])
def test_load_cell_loads_the_release_check_and_the_built_kernels_but_not_numba(aot: str
                                                                            ) -> None:
    """A loaded cell's first plan loads no code: ``load_cell`` loads python-fcl and the
    kernels compiled ahead of time (when there is a current build), never numba."""
    from safepath import _aot

    packages, kernels = _loaded_after(
        "import safepath\n"
        f"safepath.load_cell({str(CELL)!r})\n"
        "mark()\n"
        "print(' '.join(m for m in sys.modules if m.endswith('_kernel')))\n", SAFEPATH_AOT=aot)
    built = aot == "1" and _aot.find()[0] is not None
    assert "fcl" in packages
    assert packages.isdisjoint({"numba", "llvmlite"})
    assert ("safepath.verify._kernel" in kernels) is built
    assert ("safepath.kinematics._ik_kernel" in kernels) is built


def test_a_sweep_on_this_machine_loads_no_ray() -> None:
    """Ray (the optional ``cluster`` extra) loads only for a sweep on a cluster."""
    (after,) = _loaded_after(
        "import safepath.sweeps, safepath.sim.sweep_tasks, safepath.sim.sweep_cli\n"
        "from safepath.sweeps.backends import make_backend\n"
        "make_backend(workers=2).close()\n"
        "mark()\n")
    assert "safepath" in after and "ray" not in after


def test_a_plan_loads_no_sweep_runner_and_no_name_suggestions() -> None:
    """``import safepath`` and a cell's plan load neither the sweep runner (with its process
    pools: multiprocessing, concurrent.futures) nor what only a wrong name or a temporary
    file's name needs (difflib, secrets), nor numpy's masked arrays (which ``np.unique``
    imports): each cost a plan process milliseconds."""
    unneeded = {"multiprocessing", "concurrent", "difflib", "secrets"}
    packages, sweeps = _loaded_after(
        "import safepath\n"
        f"safepath.plan_cell(safepath.load_cell({str(CELL)!r}))\n"
        "mark()\n"
        "print(' '.join(m for m in sys.modules "
        "if m.startswith('safepath.sweeps') or m == 'numpy.ma'))\n")
    assert "safepath" in packages and "pinocchio" in packages
    assert packages.isdisjoint(unneeded), sorted(packages & unneeded)
    assert not sweeps, sweeps  # nor numpy.ma (np.unique imports it: ~8 ms)
