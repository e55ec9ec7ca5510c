"""What the planner keeps between plans (``safepath.planning._repeats``).

A second plan of the same inputs reuses the first's IK goals, checked lines and checked
splines: the same bits as a plan that computes them again, and never an answer kept for
another world (a line kept free in the bundled cell is refused where a post stands on
it).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from safepath import PlanOptions, plan_cell, plan_route
from safepath.cell import Cell
from safepath.errors import IKError
from safepath.model.scene import SceneObject, Shape, placement
from safepath.planning import _repeats

from .conftest import BUNDLED, route_routes, trajectory_digest


def test_a_second_plan_reuses_and_equals_a_first_plan(bundled_cell: Cell) -> None:
    routes = route_routes(BUNDLED, bundled_cell)
    subset = {name: routes[name] for name in ("phase1", "phase2_safe")}
    _repeats.clear()
    first = plan_cell(bundled_cell, PlanOptions(), routes=subset)
    before = _repeats.counts()
    second = plan_cell(bundled_cell, PlanOptions(), routes=subset)
    after = _repeats.counts()
    # Every IK goal, line and spline of the second plan was kept from the first.
    assert after["hits"] - before["hits"] > 10
    assert after["misses"] == before["misses"]
    assert {n: trajectory_digest(t) for n, t in first.items()} == \
        {n: trajectory_digest(t) for n, t in second.items()}


def test_a_line_kept_in_one_world_is_checked_again_in_another(bundled_cell: Cell) -> None:
    routes = route_routes(BUNDLED, bundled_cell)
    route = routes["phase1"]
    plan_route(bundled_cell, route, PlanOptions())  # keeps its lines
    # A post halfway along the last line (low1 up to high2), in a cell with the same
    # robot: the line is the same input but another world.
    robot = bundled_cell.robot
    low = robot.tcp_position(bundled_cell.pose("low1"))
    high = robot.tcp_position(bundled_cell.pose("high2"))
    post = SceneObject("post", Shape("box", (0.02, 0.02, 0.02)),
                       placement(0.5 * (low + high)))
    scene = replace(bundled_cell.scene,
                    objects={**bundled_cell.scene.objects, "post": post})
    blocked = replace(bundled_cell, scene=scene)
    assert blocked.robot is robot
    with pytest.raises(IKError, match="collides|comes within"):
        plan_route(blocked, route, PlanOptions())


def test_a_blocked_check_is_not_kept(bundled_cell: Cell) -> None:
    from safepath.planning.world import CheckerCache, initial_world

    checker = CheckerCache(bundled_cell, PlanOptions()).checker(initial_world(bundled_cell), ())
    samples = np.zeros((3, len(bundled_cell.robot.joint_names)))
    asked: list[bool] = []

    def check() -> bool:
        asked.append(True)
        return False

    assert not _repeats.spline_free(checker, samples, check)
    assert not _repeats.spline_free(checker, samples, check)
    assert len(asked) == 2
