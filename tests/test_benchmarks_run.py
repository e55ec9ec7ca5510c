"""Every benchmark script still runs (tiny settings) and prints its figures.

The figures themselves are not asserted (speed is measured by the scripts, not by
tests); this only keeps the scripts from rotting when the library changes.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CASES = [
    ("collision_checks.py", ["--n", "300"], "state checks/s"),
    ("check_poses.py", ["--sizes", "40", "--seed", "3"], "poses/s"),
    ("plan_cycle.py", ["--runs", "1"], "motion time against the stop-and-go baseline"),
    ("runtime_heartbeat.py", ["--runs", "1"], "heartbeat gap"),
    ("runtime_recovery.py", ["--runs", "1", "--no-compare"], "timeout overshoot"),
    ("verify.py", ["--runs", "1", "--dense-calls", "1"], "per plan"),
    ("timing.py", ["--runs", "1", "--random", "1"], "median speed-up"),
    ("timing_quality.py", ["--paths", "1", "--runs", "1", "--robots", "ned3pro"],
     "median straight move / S-curve"),
    ("timing_suite.py", ["--paths", "2", "--robots", "ned3pro"], "overruns in all: 0"),
    ("timing_profile.py", ["--paths", "2", "--robots", "ned3pro"], "TOPP-RA solve"),
    ("view_startup.py", ["--runs", "1"], ""),
    ("cold_start.py", ["--runs", "1", "--warmup", "0"], "first / second plan_cell"),
    ("monitor.py", ["--decisions", "20", "--speeds", "1.6"], "decision latency"),
    ("switches.py", ["--runs", "2"], "largest step at a switch"),
    ("stop_search.py", ["--chains", "3", "--paths", "1", "--sources", "ned3pro",
                        "--knot-period", "0.01"], "beyond a limit: 0 of"),
    ("live_safety.py", ["--runs", "1", "--seed", "24"], "contacts while the arm moves"),
    ("panda_set.py", ["--limit", "2"], "the same, CPU time"),
    ("pour.py", ["--runs", "2", "--events", "20"], "seed measured ~103 g"),
    ("pour_controller.py", ["--runs", "1"], "final masses"),
    ("sweeps.py", ["--runs", "2", "--duration", "5", "--no-ray"],
     "the same results on every backend: yes"),
    ("planners_any_arm.py", ["--seeds", "1", "--time-limit", "0.2", "--robots", "ur5",
                             "--planners", "RRT,SORRTstar"], "first path"),
]


@pytest.mark.parametrize(("script", "args", "expected"), CASES, ids=[c[0] for c in CASES])
def test_benchmark_script_runs(script: str, args: list[str], expected: str) -> None:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip(), "the script printed nothing"
    assert expected in proc.stdout


def test_timing_suite_with_out_is_a_resumable_sweep(tmp_path: Path) -> None:
    """``--out``: the overruns per robot with their interval, and a second start that
    runs nothing."""
    argv = [sys.executable, str(ROOT / "benchmarks" / "timing_suite.py"), "--paths", "2",
            "--robots", "ned3pro", "--workers", "1", "--out", str(tmp_path / "t")]
    first = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr[-2000:]
    assert "ned3pro: overruns 0 / 2, 0.0000 % [0.0000, 65.7620] 95 % CI" in first.stdout
    assert "ran 2 of 2 seeds on this process" in first.stdout
    again = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert "overruns in all: 0; ran 0 of 2 seeds" in again.stdout, again.stderr[-2000:]
