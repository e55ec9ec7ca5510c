"""The ``safepath check`` command, run as a user runs it (a subprocess of the venv)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from safepath import Cell, dump_poses
from safepath.kinematics import solve_ik

ENTRY = Path(sys.executable).with_name("safepath")
ROW = re.compile(r"^(\w+)\s+(empty|vial)\s+(ok|OUT)\s+(yes|NO)\s+(-?\d+\.\d)\s+(ok|LOW)\s+(.*)$")


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run ``safepath ARGS`` with the venv's entry point (or ``python -m safepath.cli``)."""
    cmd = [str(ENTRY)] if ENTRY.exists() else [sys.executable, "-m", "safepath.cli"]
    return subprocess.run([*cmd, *args], cwd=cwd, capture_output=True, text=True, timeout=120,
                          check=False)


def _rows(stdout: str) -> list[re.Match[str]]:
    return [m for m in (ROW.match(line) for line in stdout.splitlines()) if m]


def test_check_bundled_cell(repo_root: Path, cell: Cell) -> None:
    result = run("check", "scenes/quality_check_cell", cwd=repo_root)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    rows = _rows(result.stdout)
    assert [(m[1], m[2]) for m in rows] == [
        (name, state) for name in cell.poses for state in ("empty", "vial")]
    for m in rows:
        assert m[3] == "ok" and m[4] == "yes" and m[6] == "ok", m[0]
        assert float(m[5]) >= 10.0  # clearance [mm] above the 10 mm margin
        assert " / " in m[7]  # the closest pair
    assert "12/12 states valid, 0 below margin" in result.stdout
    assert "margin 10 mm" in result.stdout


def test_clearance_column_matches_the_library(repo_root: Path, cell: Cell) -> None:
    from safepath import check_poses

    result = run("check", "scenes/quality_check_cell", cwd=repo_root)
    rows = _rows(result.stdout)
    for m, row in zip(rows, check_poses(cell), strict=True):
        assert float(m[5]) == pytest.approx(row.report.clearance * 1000, abs=0.051)


def test_margin_option_and_strict(repo_root: Path) -> None:
    # low1 keeps 38 mm from the camera: a 50 mm margin is not kept there.
    result = run("check", "scenes/quality_check_cell", "--margin", "0.05", cwd=repo_root)
    assert result.returncode == 0, result.stderr
    assert "margin 50 mm" in result.stdout
    low = [m for m in _rows(result.stdout) if m[6] == "LOW"]
    assert ("low1", "empty") in {(m[1], m[2]) for m in low}
    strict = run("check", "scenes/quality_check_cell", "--margin", "0.05", "--strict",
                 cwd=repo_root)
    assert strict.returncode == 1


def test_pose_in_collision_exits_1_and_names_the_pair(cell_copy: Path, cell: Cell) -> None:
    robot = cell.robot
    q_grip = cell.pose("grip")
    T = robot.frame_pose(q_grip)
    # 15 cm further along the belt than grip (clear of the vial) and 7 cm lower.
    crash = solve_ik(robot, pin.SE3(T.rotation, T.translation + [0.15, 0.0, -0.07]), q_grip)
    assert crash is not None
    poses = {**cell.poses, "crash": crash}
    (cell_copy / "poses.yaml").write_text(dump_poses(poses))
    result = run("check", str(cell_copy), cwd=cell_copy)
    assert result.returncode == 1, result.stdout + result.stderr
    rows = {(m[1], m[2]): m for m in _rows(result.stdout)}
    bad = rows[("crash", "empty")]
    assert bad[4] == "NO" and float(bad[5]) < 0
    first, second = bad[7].split(" / ")
    assert first in {"mors_1", "mors_2", "base_gripper_1", "hand_link"}
    assert second == "qc_conveyor"
    assert rows[("grip", "empty")][4] == "yes"
    assert "12/13 states valid" in result.stdout


def test_pose_outside_the_limits_is_an_input_error(cell_copy: Path, cell: Cell) -> None:
    q = cell.pose("grip").copy()
    q[1] = 1.0  # joint_2 beyond 0.44 rad
    (cell_copy / "poses.yaml").write_text(dump_poses({**cell.poses, "wild": q}))
    result = run("check", str(cell_copy), cwd=cell_copy)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "joint_2" in lines[0] and "wild" in lines[0]


@pytest.mark.parametrize(
    ("file", "text", "needle"),
    [
        ("poses.yaml", "poses:\n  grip: [0.0, 0.0\n", "malformed YAML"),
        ("poses.yaml", "poses:\n  grip: [0.0, 0.0, 0.0, 0.0, 0.0]\n", "expected 6"),
        ("scene.yaml", "name: x\nrobot: ned3pro\nobjects: {a: {shape: cone, xyz: [0,0,0]}}\n",
         "unknown shape 'cone'"),
        ("scene.yaml", "name: x\nrobot: [ned3pro\n", "malformed YAML"),
    ],
)
def test_malformed_file_exits_2_with_one_line(cell_copy: Path, file: str, text: str,
                                              needle: str) -> None:
    (cell_copy / file).write_text(text)
    result = run("check", str(cell_copy), cwd=cell_copy)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("safepath check: error:")
    assert str(cell_copy / file) in lines[0] and needle in lines[0]


def test_missing_scene_folder_exits_2(tmp_path: Path) -> None:
    result = run("check", str(tmp_path / "nowhere"), cwd=tmp_path)
    assert result.returncode == 2
    assert len(result.stderr.splitlines()) == 1 and "not found" in result.stderr
    assert "Traceback" not in result.stderr


def test_in_process_main_matches(repo_root: Path, capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    from safepath.cli import main

    monkeypatch.chdir(repo_root)
    assert main(["check", "scenes/quality_check_cell"]) == 0
    out = capsys.readouterr().out
    assert len(_rows(out)) == 12
    assert np.isfinite([float(m[5]) for m in _rows(out)]).all()


def test_check_pouring_cell(repo_root: Path, tmp_path: Path) -> None:
    result = run("check", "scenes/pouring_cell", cwd=repo_root)
    assert result.returncode == 0, result.stderr
    assert "robot gen3_lite" in result.stdout
    assert "8/8 states valid, 0 below margin" in result.stdout
    # The brief's non-unit quaternion: one line naming file and key, exit status 2.
    import shutil

    copy = tmp_path / "pouring_cell"
    shutil.copytree(repo_root / "scenes" / "pouring_cell", copy)
    poses = copy / "poses.yaml"
    poses.write_text(poses.read_text().replace(
        "position: [0.40, 0.20, 0.22]\n    orientation: [0.5, 0.5, 0.5, 0.5]",
        "position: [0.40, 0.20, 0.22]\n    orientation: [0.5, 0.5, 0.5, 0.9]"))
    bad = run("check", str(copy), cwd=repo_root)
    assert bad.returncode == 2
    assert bad.stdout == ""
    (line,) = bad.stderr.strip().splitlines()
    assert "poses.above_bowl.orientation" in line and "not a unit quaternion" in line


def test_check_names_the_renamed_ik_start_key(repo_root: Path, tmp_path: Path) -> None:
    # A TCP pose's IK start was written `seed:`; "seed" now means a random seed only, so
    # the old key is refused with one line naming file, key and the new name.
    import shutil

    copy = tmp_path / "pouring_cell"
    shutil.copytree(repo_root / "scenes" / "pouring_cell", copy)
    poses = copy / "poses.yaml"
    text = poses.read_text()
    assert text.count("ik_start: above_cup") == 2
    poses.write_text(text.replace("ik_start: above_cup", "seed: above_cup", 1))
    bad = run("check", str(copy), cwd=repo_root)
    assert bad.returncode == 2
    (line,) = bad.stderr.strip().splitlines()
    assert str(poses) in line and "seed" in line and "`ik_start:`" in line


def test_check_refuses_a_line_target_out_of_reach(repo_root: Path, cell_copy: Path) -> None:
    # A TCP pose 2.6 m beyond the Ned3 Pro's reach, in the third route: the poses are
    # all fine, but `plan` would refuse the route (issue 28: `check` said exit 0).
    import yaml

    routes = cell_copy / "routes.yaml"
    data = yaml.safe_load(routes.read_text())
    data["routes"]["phase2_unsafe"]["steps"][0] = {
        "line": {"position": [3.0, 0.0, 0.2], "orientation": [0.0, 1.0, 0.0, 0.0]}}
    routes.write_text(yaml.safe_dump(data, sort_keys=False))
    result = run("check", str(cell_copy), cwd=repo_root)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "12/12 states valid" in result.stdout
    (line,) = [ln for ln in result.stdout.splitlines() if ln.startswith("unreachable")]
    assert f"{routes}, route 'phase2_unsafe', step '0 line tcp(3.000,0.000,0.200)'" in line
    assert "no inverse-kinematics solution" in line


def test_many_poses_share_their_checkers(cell_copy: Path, cell: Cell,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """2,000 poses are checked with one collision checker per gripper state and set of
    allowed contacts (a checker per pose once made 30,000 poses need 22 GB), and each
    pose's report is the one a checker of its own gives."""
    import safepath.cell._cell as cell_module
    from safepath import load_cell
    from safepath.cell import check_poses

    rng = np.random.default_rng(5)
    base = cell.pose("high1")
    poses = dict(cell.poses)
    poses.update({f"extra_{i}": base + rng.uniform(-0.05, 0.05, base.size)
                  for i in range(2000)})
    (cell_copy / "poses.yaml").write_text(dump_poses(poses))
    big = load_cell(cell_copy)
    built: list[object] = []
    real = cell_module.CollisionChecker

    def counting(*args: object, **kwargs: object) -> object:
        built.append(kwargs.get("allowed"))
        return real(*args, **kwargs)

    monkeypatch.setattr(cell_module, "CollisionChecker", counting)
    checks = check_poses(big)
    monkeypatch.undo()
    assert len(checks) == 2000 + sum(2 if n in big.scene.grasp.poses else 1
                                     for n in cell.poses)
    distinct = {(c.held, tuple(big.scene.contacts_at(c.pose))) for c in checks}
    assert len(built) == len(distinct) <= 2 * (len(cell.poses) + 1)
    for c in checks[::250]:
        own = big.checker(held=c.held, at=c.pose).check(big.pose(c.pose))
        assert own.collisions == c.report.collisions
        assert own.closest_pair == c.report.closest_pair
        assert own.clearance == pytest.approx(c.report.clearance, abs=1e-12)


def _coal_verdict(checker: object, q: np.ndarray) -> tuple[Any, ...]:
    """A state's verdict from coal alone, every pair read (what ``check`` reported before
    it read only what its answer needs): colliding pairs, the distance of every pair of
    names and the margin each keeps."""
    from safepath.collision import CollisionChecker

    assert isinstance(checker, CollisionChecker)
    return tuple(checker.collisions(q)), dict(checker.distances(q)), checker.margins()


@pytest.mark.parametrize("seed", [11, 12])
def test_pose_checks_give_coal_s_verdicts(cell: Cell, seed: int) -> None:
    """``check`` on 300 random poses (inside the limits, and near the taught poses where
    the margins and the allowed contacts matter), empty and holding the vial at a pose
    with contacts: exactly coal's colliding pairs, clearance, closest pair and margin
    shortfalls, though it asks coal for collisions only where the sphere layer cannot
    prove a state free and reads every distance only near contact. (coal starts each
    distance query from the last one's answer: distances agree to 1e-6 m, and of two
    pairs that close, such as the two jaws, either may be named the closest.)"""
    rng = np.random.default_rng(seed)
    lo, hi = cell.robot.lower, cell.robot.upper
    taught = np.array(list(cell.poses.values()))
    near = taught[rng.integers(0, len(taught), 150)] + rng.normal(0.0, 0.05, (150, lo.size))
    states = np.vstack([rng.uniform(lo, hi, (150, lo.size)), np.clip(near, lo, hi)])
    kinds = {"free": 0, "colliding": 0, "short": 0}
    for held, at in ((False, None), (True, "grip"), (False, "grip")):
        checker = cell.checker(held=held, at=at)
        for q in states:
            report = checker.check(q)
            collisions, dists, margins = _coal_verdict(checker, q)
            assert report.collisions == collisions
            assert report.clearance == pytest.approx(min(dists.values()), abs=1e-6)
            assert dists[report.closest_pair] == pytest.approx(report.clearance, abs=1e-6)
            short = {p: d for p, d, _ in report.margin_violations}
            assert short.keys() == {p for p, d in dists.items() if d < margins[p]}
            assert all(d == pytest.approx(dists[p], abs=1e-6) for p, d in short.items())
            assert all(m == margins[p] for p, _, m in report.margin_violations)
            assert list(short.values()) == sorted(short.values())
            kinds["colliding" if report.collisions else
                  "short" if report.margin_violations else "free"] += 1
    assert min(kinds.values()) >= 20, kinds  # every kind of verdict was compared
