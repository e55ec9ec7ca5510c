"""The quality-check cell with vials queued on the belt behind the one at the sensor: the
routes keep the vial's margin from a vial queued at the cell's minimum spacing, and the
twin's executed clearance includes the queued vials where they stand."""

from __future__ import annotations

from safepath import Trajectory
from safepath.cell import Cell
from safepath.collision import CheckOptions, CollisionChecker
from safepath.sim.quality_check import (
    QUEUED_VIAL,
    QualityCheckParams,
    queued_vials_cell,
    run_quality_check,
)

from .conftest import distances_to

#: The cell's minimum spacing of vials on the belt, centre to centre [m]
#: (scenes/quality_check_cell/README.md), which the twin puts vials on with.
SPACING = QualityCheckParams().vial_spacing


def test_routes_keep_the_margin_from_vials_queued_at_the_minimum_spacing(
        cell: Cell, routes: dict[str, Trajectory]) -> None:
    dist = distances_to(cell, routes, queued_vials_cell(cell, (SPACING, 2 * SPACING)),
                        lambda name: name.startswith(QUEUED_VIAL))
    # the pick's lift rises straight up before it moves along the belt, the return comes
    # down straight onto the grip pose: 10.7 mm measured (the open jaws, on the vertical
    # lines), against -5.6 mm (the held vial hit) when the lift went straight to high1
    assert min(dist.values()) >= cell.scene.margin, dist


def test_touching_vials_are_hit_by_the_open_jaws_at_grip(cell: Cell) -> None:
    # why the cell needs vials 35 mm apart: the jaws straddle the picked vial along the
    # belt, so no route reaches grip clear of a vial touching it (16 mm)
    vial = cell.scene.objects[cell.scene.grasp.object]  # type: ignore[union-attr]
    diameter = 2 * vial.shape.size[0]
    allowed = tuple(cell.scene.contacts_at("grip"))

    def at_grip(spacing: float) -> float:
        qcell = queued_vials_cell(cell, (spacing,))
        checker = CollisionChecker(qcell.robot, qcell.scene, allowed=allowed,
                                   options=CheckOptions())
        return min(d for pair, d in checker.distances(cell.poses["grip"])
                   if f"{QUEUED_VIAL}_1" in pair)

    assert at_grip(diameter) < 0
    assert at_grip(SPACING) >= cell.scene.margin


def test_twin_checks_the_queued_vials(cell_dir) -> None:
    # vials put on as soon as there is room: the next one stands the minimum spacing
    # (within half a millimetre) behind the picked one. The old lift, straight to high1,
    # hit it (-5.6 mm, the held vial); the lift straight up keeps 10.8 mm.
    params = QualityCheckParams(duration=40.0, arrival_interval=0.02)
    run = run_quality_check(cell_dir, 0, params)
    assert run.faults == () and len(run.cycles) >= 1
    assert run.queued_motions > 0  # the queued vials were in the check
    assert run.clearance.clearance >= run.margin - run.tcp_deviation, run.clearance
