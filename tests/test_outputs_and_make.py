"""Chores a newcomer ran into (issue 28): outputs written with the umask's mode like the
bags, ``make test`` timing itself and installing no other planners."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import safepath
from safepath import Scene, load_robot

REPO = Path(__file__).resolve().parents[1]
ARM_URDF = REPO / "tests" / "data" / "box_arm" / "arm.urdf"


def test_json_and_csv_outputs_get_the_umasks_mode(tmp_path: Path) -> None:
    robot = load_robot(ARM_URDF, acceleration_limits=[4.0, 3.0, 3.0, 6.0])
    traj = safepath.plan(robot, Scene(name="empty", robot="box_arm", objects=[]),
                         np.zeros(4), np.array([0.5, 0.2, 0.3, 0.0]))
    previous = os.umask(0o022)
    try:
        traj.to_json(tmp_path / "t.json")
        traj.to_csv(tmp_path / "t.csv")
        os.umask(0o027)
        traj.to_json(tmp_path / "group.json")
    finally:
        os.umask(previous)
    for name, mode in (("t.json", 0o644), ("t.csv", 0o644), ("group.json", 0o640)):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


def _make_dry_run(target: str) -> str:
    make = shutil.which("make")
    if make is None:
        pytest.skip("no make on this machine")
    done = subprocess.run([make, "-n", target], cwd=REPO, capture_output=True, text=True,
                          timeout=60, check=True)
    return done.stdout


def test_make_test_prints_its_wall_time_and_bench_peers_runs_the_smoke_test() -> None:
    recipe = _make_dry_run("test")
    assert "s wall" in recipe and "date +%s" in recipe and "pytest -q" in recipe
    assert "SAFEPATH_PEERS_SMOKE" not in recipe
    assert "SAFEPATH_PEERS_SMOKE=1" in _make_dry_run("bench-peers")


def test_the_peers_smoke_test_is_opt_in() -> None:
    env = {k: v for k, v in os.environ.items() if k != "SAFEPATH_PEERS_SMOKE"}
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
                           "-n", "0", str(REPO / "tests" / "test_peers_smoke.py")],
                          cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "3 skipped" in done.stdout and "SAFEPATH_PEERS_SMOKE=1" in done.stdout
