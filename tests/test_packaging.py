"""Installed as a library (a wheel, not editable), the bundled robots and scenes come along.

The wheel is built from a copy of the source tree (so the build leaves nothing in the
checkout; the copy resolves ``safepath/_data``'s links as an sdist would) and installed
with ``--no-deps`` into a new virtualenv whose dependencies come from the running
interpreter's site-packages through a ``.pth`` file (no download). It is then used from
a folder outside the repository, where a source checkout cannot be found.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_CHECK = """
import os, sys
from pathlib import Path
import safepath
from safepath import load_cell, load_robot
from safepath.files._paths import ROBOTS_DIR, SCENES_DIR

package = Path(safepath.__file__).resolve().parent
assert Path(sys.prefix).resolve() in package.parents, package
assert Path(os.environ["REPO"]).resolve() not in package.parents
assert not ROBOTS_DIR.is_symlink() and ROBOTS_DIR.resolve().parent.parent == package
robot = load_robot("ned3pro")
assert robot.source.resolve().is_relative_to(package), robot.source
assert robot.controller.source.is_relative_to(package)
assert load_robot("ur5").controller.follow_joint_trajectory_action.startswith("/scaled")
cell = load_cell("quality_check_cell")
assert cell.folder.resolve().is_relative_to(package), cell.folder
assert set(cell.route_table()) == {"phase1", "phase2_safe", "phase2_unsafe"}
print("ok", len(cell.poses), sorted(p.name for p in SCENES_DIR.iterdir()))
"""


def _copy_source(target: Path) -> None:
    """The files a wheel is built from, links resolved (``symlinks=False``)."""
    target.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, target / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for name in ("safepath", "robots", "scenes"):
        shutil.copytree(ROOT / name, target / name, symlinks=False, ignore=ignore)


def _build_wheel(source: Path, dist: Path) -> Path:
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist)]
    # Reuse this interpreter's setuptools when it can build the wheel (no download);
    # otherwise pip fetches the build requirements of pyproject.toml.
    have = importlib.util.find_spec("setuptools") and importlib.util.find_spec("wheel")
    if have:
        import setuptools

        if int(setuptools.__version__.split(".")[0]) >= 68:
            cmd.append("--no-build-isolation")
    result = subprocess.run([*cmd, str(source)], capture_output=True, text=True,
                            timeout=600)
    if result.returncode != 0 and "--no-build-isolation" not in cmd and (
            "Could not find a version" in result.stderr or "NewConnectionError" in result.stderr):
        pytest.skip(f"cannot fetch setuptools to build the wheel: {result.stderr[-300:]}")
    assert result.returncode == 0, result.stderr[-3000:]
    wheels = list(dist.glob("safepath-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def test_wheel_ships_robots_and_scenes_and_works_from_any_folder(tmp_path: Path) -> None:
    source = tmp_path / "src"
    _copy_source(source)
    wheel = _build_wheel(source, tmp_path / "dist")

    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    target_site = Path(subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True).stdout.strip())
    # Dependencies from the running interpreter's site-packages, added after the new
    # venv's own (so the wheel's safepath comes first), with their .pth files (cmeel's
    # pinocchio and coal live in a sub-folder registered by one).
    deps = sysconfig.get_paths()["purelib"]
    (target_site / "_safepath_test_deps.pth").write_text(
        f"import site; site.addsitedir({deps!r})\n")
    # Nothing of the checkout on the path: pip would take it for an installed safepath.
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "SAFEPATH_ROBOTS", "SAFEPATH_SCENES")}
    env["REPO"] = str(ROOT)
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--no-index", str(wheel)], capture_output=True, text=True, timeout=600, env=env)
    assert install.returncode == 0, install.stderr[-3000:]
    assert "Successfully installed safepath" in install.stdout, install.stdout

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    result = subprocess.run([str(python), "-c", _CHECK], cwd=elsewhere, env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.startswith("ok 6 ") and "quality_check_cell" in result.stdout

    # The command line of the installed library, on the bundled cell by name.
    check = subprocess.run([str(env_dir / "bin" / "safepath"), "check", "quality_check_cell"],
                           cwd=elsewhere, env=env, capture_output=True, text=True, timeout=600)
    assert check.returncode == 0, check.stderr[-3000:]
    assert "cell quality_check_cell: robot ned3pro" in check.stdout
