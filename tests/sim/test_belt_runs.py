"""The quality-check cell with the belt running while the robot works
(``ControllerOptions(belt_runs_while_working=True)``): the routes with a vial waiting at
the sensor, and a short closed-loop run against the belt stopped during cycles."""

from __future__ import annotations

import pytest

from safepath import Trajectory
from safepath.cell import Cell
from safepath.cells.quality_check.commands import ControllerOptions
from safepath.sim.quality_check import (
    WAITING_VIAL,
    QualityCheckParams,
    run_quality_check,
    waiting_vial_cell,
)

from .conftest import distances_to


def test_routes_keep_the_margin_from_a_vial_waiting_at_the_sensor(
        cell: Cell, routes: dict[str, Trajectory]) -> None:
    dist = distances_to(cell, routes, waiting_vial_cell(cell),
                        lambda name: name == WAITING_VIAL)
    lift = ("phase1", 1)  # the motion carrying the picked vial off the belt
    margin = waiting_vial_cell(cell).scene.margin_for(WAITING_VIAL)
    others = {k: d for k, d in dist.items() if k != lift}
    # every other motion keeps the vial's margin (5 mm) from it, by far: 41 mm measured
    # (forearm_link, arriving at grip; the open jaws straddle it there on purpose)
    assert min(others.values()) >= margin + 0.03, others
    # the lift starts where the picked vial stood: no vial may wait there until it has
    # ended, which is why the controller restarts the belt only after it
    assert dist[lift] < 0


def test_belt_running_handles_more_vials_and_keeps_the_cell_safe(cell_dir) -> None:
    def run(belt: bool):  # noqa: ANN202
        # a long belt (16 s from where vials are put on to the sensor) makes the
        # difference show in a minute: stopped during cycles, the next vial rides it after
        # each cycle; running, during the cycle
        params = QualityCheckParams(duration=60.0, arrival_interval=3.0, belt_length=0.8,
                                    controller=ControllerOptions(belt_runs_while_working=belt))
        return run_quality_check(cell_dir, 0, params)

    stopped, running = run(False), run(True)
    for r in (stopped, running):
        assert r.faults == () and r.unsafe_packaged == 0
        assert r.empty_picks == 0  # no vial picked unless the sensor saw it
        assert r.belt_moving_at_sensor == 0.0
        assert r.clearance.clearance >= r.margin - r.tcp_deviation
    assert running.belt_runs and not stopped.belt_runs
    # the next vial waited at the sensor while the robot worked, and was in the check
    assert running.waiting_motions > 0 and stopped.waiting_motions == 0
    assert running.vials_per_minute > stopped.vials_per_minute
    assert running.robot_idle < stopped.robot_idle
    assert all(len(c.reason) > 0 for c in running.cycles)


@pytest.mark.parametrize("value", [1, "yes", None])
def test_belt_option_must_be_a_bool(value: object) -> None:
    from safepath.errors import InputError

    with pytest.raises(InputError):
        ControllerOptions(belt_runs_while_working=value)  # type: ignore[arg-type]
