"""The numbered examples (``examples/NN_*.py``) run as a user runs them, each in its own
process, and print what they promise."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))

#: What each example's output must show (a pattern per example, by number).
PROMISES = {
    "01": r"ned3pro: 6 joints",
    "02": r"low1 +holding +valid True",
    "03": r"motion \d+\.\d+ s, clearance \d+\.\d mm, certified bound \d+\.\d+ mm",
    "04": r"phase2_unsafe +\d+ steps, +(\d+\.\d+) s, read back +\1 s",
    "05": r"collision-free True",
    "06": r"goal: \d+ points, \d+ CDR bytes.*\n.*/joint_states x\d+",
    "07": r"decisions: .*stop",
    "08": r"60 s simulated: \d+ vials arrived, [1-9]\d* cycles, .* 0 unsafe packaged; 0 physics",
}


def test_every_example_is_numbered_and_promised() -> None:
    assert [p.name[:2] for p in EXAMPLES] == sorted(PROMISES), [p.name for p in EXAMPLES]


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.name)
def test_the_example_runs(example: Path, tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(example)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, env={"TMPDIR": str(tmp_path),
                                                       **_env()})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert re.search(PROMISES[example.name[:2]], proc.stdout), proc.stdout


def _env() -> dict[str, str]:
    import os

    return {k: v for k, v in os.environ.items() if k != "TMPDIR"}
