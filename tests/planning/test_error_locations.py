"""Planning errors say where and why (issue 28, confusing points): in a cell of several
routes, an error names the route and the routes file as well as the step; a planner
that had no time says so instead of "no collision-free path found"."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from safepath import (
    Cell,
    IKError,
    PlannerOptions,
    PlannerTimeout,
    PlanningError,
    load_cell,
    plan_cell,
    plan_route,
)
from safepath.planning import plan_joint_path

DETOUR = Path(__file__).resolve().parents[1] / "data" / "detour_cell"
#: A TCP pose about 2.6 m beyond the Ned3 Pro's reach (its TCP reaches ~0.45 m).
FAR = {"position": [3.0, 0.0, 0.2], "orientation": [0.0, 1.0, 0.0, 0.0]}


def _far_target(folder: Path, route: str, step: int) -> Path:
    """Make step ``step`` of ``route`` a line to :data:`FAR`; the routes file."""
    routes = folder / "routes.yaml"
    data = yaml.safe_load(routes.read_text())
    data["routes"][route]["steps"][step] = {"line": FAR}
    routes.write_text(yaml.safe_dump(data, sort_keys=False))
    return routes


def test_plan_cell_names_route_and_file_of_a_failing_step(cell_copy: Path) -> None:
    routes = _far_target(cell_copy, "phase1", 1)  # after the 'close: vial'
    with pytest.raises(IKError) as info:  # the same type as before: only located
        plan_cell(load_cell(cell_copy))
    error = info.value
    assert error.route == "phase1"
    assert error.path == routes
    assert error.step is not None and "line" in error.step
    assert str(error).startswith(f"{routes}, route 'phase1', step '{error.step}': no "
                                 "inverse-kinematics solution")


def test_plan_route_names_route_and_file(cell_copy: Path) -> None:
    cell = load_cell(cell_copy)
    # phase2_safe follows phase1: from the scene's world the vial is not at low1, so
    # its 'close: vial' fails (a gripper step's error, also located).
    with pytest.raises(PlanningError, match="from the gripper") as info:
        plan_route(cell, cell.route_table()["phase2_safe"])
    assert info.value.route == "phase2_safe"
    assert info.value.path == cell_copy / "routes.yaml"
    assert f"route 'phase2_safe', step '{info.value.step}'" in str(info.value)


def test_a_route_built_in_python_names_no_file(cell: Cell) -> None:
    table = cell.route_table()
    route = table["phase2_safe"]
    python_cell = Cell(cell.robot, cell.scene, dict(cell.poses), routes=table)
    with pytest.raises(PlanningError) as info:
        plan_route(python_cell, route)
    assert info.value.route == "phase2_safe" and info.value.path is None
    assert str(info.value).startswith("route 'phase2_safe', step ")


def test_no_time_to_plan_is_a_timeout() -> None:
    cell = load_cell(DETOUR)  # a post on the direct high1 -> high2 sweep: OMPL must plan
    checker = cell.checker()
    q_start, q_goal = cell.pose("high1"), cell.pose("high2")
    assert not checker.segment_is_valid(q_start, q_goal)
    with pytest.raises(PlannerTimeout, match="ran out of time") as info:
        plan_joint_path(checker, q_start, q_goal, options=PlannerOptions(time_limit=1e-4),
                        step="3 move high2")
    assert "time_limit of 0.0001 s" in str(info.value)
    assert info.value.step == "3 move high2"
