"""Teaching poses from TCP targets: ``Cell.pose_from_tcp`` and ``safepath teach``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from safepath import Cell, load_cell
from safepath.cli import main
from safepath.errors import PoseError


def test_pose_from_tcp_puts_the_tcp_where_asked(cell: Cell) -> None:
    """The TCP of low1, asked for from high1, is reached (position and orientation);
    without an orientation the TCP keeps the one it has at ``near``."""
    target = cell.robot.frame_pose(cell.pose("low1"))
    quat = pin.Quaternion(target.rotation).coeffs()
    q = cell.pose_from_tcp(target.translation, quat, near="high1")
    reached = cell.robot.frame_pose(q)
    np.testing.assert_allclose(reached.translation, target.translation, atol=1e-5)
    assert np.linalg.norm(pin.log3(reached.rotation.T @ target.rotation)) < 1e-4
    above = cell.robot.tcp_position(cell.pose("high1")) + [0.0, 0.0, -0.03]
    q = cell.pose_from_tcp(above, near="high1")
    np.testing.assert_allclose(cell.robot.tcp_position(q), above, atol=1e-5)
    kept = cell.robot.frame_pose(q).rotation.T @ cell.robot.frame_pose(cell.pose("high1")).rotation
    assert np.linalg.norm(pin.log3(kept)) < 1e-4
    with pytest.raises(PoseError, match="out of reach"):
        cell.pose_from_tcp([3.0, 0.0, 0.0], near="high1")
    with pytest.raises(PoseError, match="did you mean 'high1'"):
        cell.pose_from_tcp(above, near="hihg1")


def test_teach_writes_a_checked_pose_and_nothing_else(cell_copy: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """'safepath teach' writes the new pose and keeps every other line of poses.yaml (the
    previous file as poses.yaml~); a name taken, a pose in collision or a target out of
    reach writes nothing (exit 2, 1, 2)."""
    poses = cell_copy / "poses.yaml"
    before = poses.read_text()
    plate = [0.044, 0.23, 0.20]
    assert main(["teach", str(cell_copy), "above_plate", "--position", *map(str, plate),
                 "--near", "high1"]) == 0
    assert "taught 'above_plate'" in capsys.readouterr().out
    after = poses.read_text()
    assert (cell_copy / "poses.yaml~").read_text() == before
    assert after.startswith(before.rstrip("\n")) and after.count("\n") == before.count("\n") + 1
    taught = load_cell(cell_copy)
    np.testing.assert_allclose(taught.robot.tcp_position(taught.pose("above_plate")), plate,
                               atol=1e-5)
    for args, status in ((["above_plate", "--position", "0.0", "0.2", "0.2"], 2),
                         (["into_plate", "--position", "0.044", "0.23", "0.0",
                           "--near", "low1"], 1),
                         (["far", "--position", "3", "0", "0"], 2)):
        argv = ["teach", str(cell_copy), *args]
        if "--near" not in argv:
            argv += ["--near", "high1"]
        assert main(argv) == status, args
        capsys.readouterr()
        assert poses.read_text() == after, args
