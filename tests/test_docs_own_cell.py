"""Every Python block of docs/your_own_robot_and_cell.md runs, in order, as a reader would."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "your_own_robot_and_cell.md"


def test_the_page_is_linked_from_the_readme() -> None:
    assert "docs/your_own_robot_and_cell.md" in (ROOT / "README.md").read_text()


def test_every_python_block_of_the_page_runs() -> None:
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)
    assert len(blocks) >= 2
    script = "\n".join(blocks) + (
        "\nassert traj.robot == 'ur5' and traj.info['min_clearance'] >= 0.01 - 1e-9\n"
        "assert set(trajectories) == {'over_the_wall', 'back'}\n"
        "assert goal.goal_tolerance == [] or len(goal.goal_tolerance) == 0\n"
        "assert bag.is_dir() and set(panda_plans) == {'left_to_right'}\n"
        "assert arm.dof == 4 and arm_motion.duration > 0\n"
        "assert held_cell.robot.tool == franka_hand and carried.duration > 0\n"
        "print('page ok')\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    result = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.rstrip().endswith("page ok")
    assert "/scaled_joint_trajectory_controller/follow_joint_trajectory" in result.stdout


def test_ros_page_says_how_to_stop_a_pour_on_your_own_scale() -> None:
    """The ROS page's recipe (linked from the README) names the calls as they are
    (issue 28): build_pour, start, on_weight(mass, stamp, now), and says what ``stamp`` is."""
    import inspect

    from safepath.cells.pouring import PourController
    from safepath.cells.pouring.setup import PourSetup, build_pour

    assert "docs/ros.md" in (ROOT / "README.md").read_text()
    page = (ROOT / "docs" / "ros.md").read_text()
    section = page.split("**Stopping a pour on your own scale**")[1].split("\n## ")[0]
    assert "build_pour(PourParameters.from_mapping(" in section and callable(build_pour)
    assert "controller.on_weight(mass_g, stamp, now)" in section
    assert list(inspect.signature(PourController.on_weight).parameters) == [
        "self", "mass", "stamp", "now"]
    assert "controller" in PourSetup.__dataclass_fields__
    assert "`stamp` is **when the scale measured it** [s]" in section
