"""How a ``safepath`` process ends: the command line's own run leaves its objects to the
operating system (the collector's walk over them at exit is skipped), a call with
arguments, as from a test or a program, leaves the caller's process as it was."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "scenes" / "quality_check_cell"

_RUN = """
import gc, sys
from safepath.cli import main
sys.argv = {argv!r}
status = main({args})
print(status, gc.get_freeze_count())
"""


def _status_and_frozen(argv: list[str], args: str) -> tuple[int, int]:
    out = subprocess.run([sys.executable, "-c", _RUN.format(argv=argv, args=args)], cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=300).stdout
    status, frozen = out.split()[-2:]
    return int(status), int(frozen)


def test_the_command_line_run_freezes_its_objects_before_exit() -> None:
    status, frozen = _status_and_frozen(["safepath", "check", str(CELL)], "")
    assert status == 0
    assert frozen > 10_000  # the modules, the cell, its checkers: all of them


def test_a_call_with_arguments_leaves_the_collector_alone() -> None:
    status, frozen = _status_and_frozen(["python"], repr(["check", str(CELL)]))
    assert (status, frozen) == (0, 0)


def test_a_failing_command_line_run_freezes_too(tmp_path: Path) -> None:
    status, frozen = _status_and_frozen(["safepath", "check", str(tmp_path / "none")], "")
    assert status == 2  # bad input
    assert frozen > 0


def test_a_run_that_loaded_ompl_exits_without_nanobind_leak_reports() -> None:
    """OMPL's nanobind bindings report the instances alive at the interpreter's end as
    leaks: a command line that planned with OMPL is left to the collector, and its
    process prints nothing but its own output."""
    run = _RUN.format(argv=["safepath", "check", str(CELL)], args="")
    script = run.replace("from safepath.cli import main",
                         "import ompl.base\nkeep = ompl.base.RealVectorStateSpace(2)\n"
                         "from safepath.cli import main")
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                          text=True, check=True, timeout=300)
    status, frozen = done.stdout.split()[-2:]
    assert (int(status), int(frozen)) == (0, 0)
    assert "leaked" not in done.stderr, done.stderr[:300]
