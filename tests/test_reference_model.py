"""The robot descriptions against the makers' references (Niryo's Ned3 Pro, Kinova's Gen3
Lite), and the Ned3 Pro's allowed pairs up to date."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from safepath import Cell, Robot, load_poses
from safepath.collision import compute_allowed_pairs

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED = REPO_ROOT.parent / "shared"
CHECK_TOOL = SHARED / "tools" / "check_robot_model.py"
REFERENCE_POSES = SHARED / "reference" / "roscon2025_cell" / "quality_check_poses.yaml"


@pytest.mark.skipif(not CHECK_TOOL.is_file(), reason="no ../shared/tools next to the repo")
@pytest.mark.parametrize("args", [["robots/ned3pro/ned3pro.urdf"],
                                  ["robots/gen3_lite/gen3_lite.urdf", "--reference",
                                   "gen3_lite"]], ids=["ned3pro", "gen3_lite"])
def test_urdf_passes_the_reference_model_check(args: list[str]) -> None:
    result = subprocess.run(
        [sys.executable, str(CHECK_TOOL), *args],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "PASS" in result.stdout.splitlines()[-1]
    assert "FAIL" not in result.stdout
    assert "worst position error 0.000 mm" in result.stdout


@pytest.mark.skipif(not REFERENCE_POSES.is_file(), reason="no ../shared/reference")
def test_taught_poses_are_niryos(cell: Cell, robot: Robot) -> None:
    reference = load_poses(REFERENCE_POSES, robot)
    assert list(reference) == list(cell.poses)
    for name, q in reference.items():
        np.testing.assert_array_equal(cell.pose(name), q)


def test_allowed_collisions_are_up_to_date(robot: Robot) -> None:
    """No pair seen colliding in some (< 95 %) of the samples is skipped by the file."""
    stats = compute_allowed_pairs(robot, samples=20_000, seed=0)
    disabled = robot.allowed_self_pairs
    sometimes = {s.links for s in stats if s.reason == "sometimes"}
    assert sometimes, "the sample found no self-collision at all"
    wrongly_skipped = sorted(p for p in sometimes if p in disabled)
    assert wrongly_skipped == []
    # Everything the file skips is adjacent, never seen, or nearly always in contact.
    reasons = {s.links: s.reason for s in stats}
    for a, b in disabled:
        reason = reasons.get((a, b))
        assert reason is not None and reason in {"adjacent", "never", "always"}, (a, b)
    # And every pair the sample would skip is in the file (nothing left to check).
    skipped = {s.links for s in stats if s.reason in ("adjacent", "always")}
    assert skipped <= disabled
    # The gripper hitting the base is a real, checked case.
    assert ("base_gripper_1", "base_link") in sometimes
