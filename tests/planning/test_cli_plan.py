"""``safepath plan``: writes loadable trajectories and a table; bad input is one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from safepath import load_trajectory
from safepath.cli import main

from .conftest import BUNDLED, ROOT

ROUTES = ("phase1", "phase2_safe", "phase2_unsafe")


def _safepath() -> list[str]:
    """The installed console script next to this interpreter, else ``-m safepath.cli``."""
    script = Path(sys.executable).with_name("safepath")
    return [str(script)] if script.exists() else [sys.executable, "-m", "safepath.cli"]


def test_plan_writes_every_route_and_prints_the_table(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    out = tmp_path / "out"
    assert main(["plan", str(BUNDLED), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    lines = printed.splitlines()
    header = next(line for line in lines if line.startswith("route"))
    for column in ("steps", "plan[ms]", "motion[s]", "stop&go[s]", "ratio", "clearance[mm]"):
        assert column in header
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) == set(ROUTES)
    for name in ROUTES:
        traj = load_trajectory(out / f"{name}.json")
        assert traj.route == name and traj.duration > 0
        assert (out / f"{name}.csv").read_text().count("\n") == traj.t.size + 1
        row = next(line for line in lines if line.startswith(name + " "))
        fields = row.split()
        motion, baseline, ratio = float(fields[3]), float(fields[4]), float(fields[5])
        assert motion == pytest.approx(traj.duration, abs=1e-3)
        assert baseline == pytest.approx(summary[name]["baseline_time"], abs=1e-3)
        assert ratio == pytest.approx(motion / baseline, abs=0.01)
        assert ratio < 1.0
        assert float(fields[6]) >= 10.0  # clearance [mm], at least the margin
    assert "summary.json" in printed and str(out) in printed


def test_unknown_route_is_one_line_and_exit_2(tmp_path: Path) -> None:
    proc = subprocess.run(_safepath() + ["plan", str(BUNDLED), "--out", str(tmp_path),
                                         "--route", "nope"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("safepath plan: error:")
    assert "nope" in lines[0] and "phase1" in lines[0]
    assert not list(tmp_path.iterdir())  # nothing written


def test_route_option_plans_the_route_and_what_it_follows(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "one"
    assert main(["plan", str(BUNDLED), "--out", str(out), "--route", "phase2_unsafe"]) == 0
    written = sorted(p.name for p in out.glob("*.json"))
    assert written == ["phase1.json", "phase2_unsafe.json", "summary.json"]
    assert "phase2_safe" not in capsys.readouterr().out
    # summary.json names each step as routes.yaml writes it: the via points as via.
    steps = list(json.loads((out / "summary.json").read_text())["phase2_unsafe"]
                 ["step_durations"])
    assert steps[3] == "3 move unsafe+0.000,+0.000,+0.060"
    assert steps[7:9] == ["7 via high2", "8 via high1"]


def test_bag_of_the_cycle_holds_both_outcomes_back_to_back(tmp_path: Path) -> None:
    from safepath.ros import read_bag

    bag = tmp_path / "cycle"
    assert main(["plan", str(BUNDLED), "--out", str(tmp_path / "out"), "--bag", str(bag)]) == 0
    contents = read_bag(bag)
    routes = [json.loads(m.msg.data)["route"] for m in contents.on("/safepath/route")]
    assert routes == ["phase1", "phase2_safe", "phase1", "phase2_unsafe"]
    # One message per motion between gripper events (a goal through one never grips).
    motions = {"phase1": 3, "phase2_safe": 2, "phase2_unsafe": 2}
    assert len(contents.on("/safepath/trajectory")) == sum(motions[r] for r in routes)
    # Gripper events: close + open per route.
    assert len(contents.on("/safepath/gripper")) == 8
    # An existing bag is refused before anything is planned.
    assert main(["plan", str(BUNDLED), "--out", str(tmp_path / "again"), "--bag",
                 str(bag)]) == 2
    assert not (tmp_path / "again").exists()


def test_a_bag_that_cannot_be_written_leaves_no_output(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder\n")
    out = tmp_path / "out"
    # Planning succeeds; the bag's folder cannot be made (its parent is a file).
    assert main(["plan", str(BUNDLED), "--out", str(out), "--route", "phase1",
                 "--bag", str(blocker / "cycle")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("safepath plan: error: cannot write bag")
    assert not out.exists()  # no JSON, CSV or summary of the routes planned
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]
    # An output folder that existed keeps exactly what it held.
    out.mkdir()
    (out / "keep.txt").write_text("mine\n")
    assert main(["plan", str(BUNDLED), "--out", str(out), "--route", "phase1",
                 "--bag", str(blocker / "cycle")]) == 2
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]


def test_a_plan_without_compiled_kernels_says_so(tmp_path: Path) -> None:
    """Without a build of the kernels for these sources (an empty kernel cache here) the
    first route waits for numba's kernels (minutes on a fresh or busy machine): a plan
    says so before it plans, once, on standard error, and how to build them."""
    env = {k: v for k, v in os.environ.items() if k != "SAFEPATH_AOT"}
    env["SAFEPATH_KERNEL_CACHE"] = str(tmp_path / "no-kernels")
    proc = subprocess.run(_safepath() + ["plan", str(BUNDLED), "--out", str(tmp_path / "out"),
                                         "--route", "phase1"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("safepath plan: note: numba JIT"), proc.stderr
    assert "safepath build-kernels" in lines[0]


def test_a_line_short_of_its_margin_is_named_so_and_is_no_safe_result(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The camera asks for 60 mm: 'check' passes (its poses only fall below margin), and
    'plan' refuses the line down to the plate, saying it keeps less than the margin and
    no contact, with exit 1 (no safe result, as 'check' says of a collision), not 2 (bad
    input)."""
    import shutil

    cell = tmp_path / "cell"
    shutil.copytree(BUNDLED, cell)
    scene = cell / "scene.yaml"
    text = scene.read_text()
    assert text.count("\n  camera:\n") == 1
    scene.write_text(text.replace("\n  camera:\n", "\n  camera:\n    margin: 0.06\n"))
    assert main(["check", str(cell)]) == 0
    capsys.readouterr()
    assert main(["plan", str(cell), "--route", "phase1", "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "step '4 line low1'" in err[0], err
    assert "/ camera, below its margin of 60 mm (no contact)" in err[0]
    assert "collides" not in err[0]
    assert not (tmp_path / "out").exists()
