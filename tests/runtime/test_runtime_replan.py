"""The runtime planner's request for an extra obstacle: the same answer as in-process."""

from __future__ import annotations

import numpy as np
import pytest

from safepath import Cell, InputError, plan_cell
from safepath.monitor import ReplanRequest
from safepath.monitor.replan import replan, world_at
from safepath.runtime import RuntimePlanner

STEP = "3 move unsafe+0.000,+0.000,+0.060"


def test_replan_in_a_worker_equals_in_process(cell: Cell) -> None:
    planned = plan_cell(cell)
    traj = planned["phase2_unsafe"]
    knots = np.flatnonzero(np.array([traj.steps[s] for s in traj.step_index]) == STEP)
    k_rest, k_box = int(knots[int(0.2 * knots.size)]), int(knots[knots.size // 2])
    t_rest = float(traj.t[k_rest])
    request = ReplanRequest(t_rest, traj.q[k_rest].copy(), t_rest, STEP,
                            cell.robot.tcp_position(traj.q[k_box]), np.full(3, 0.14))
    world = world_at(cell, [planned["phase1"], traj], t_rest)
    here = replan(cell, "phase2_unsafe", request, held=world.held, margin=0.03, world=world)
    with RuntimePlanner(cell.folder, spare=False) as planner:
        with pytest.raises(InputError, match="ReplanRequest"):
            planner.replan("phase2_unsafe", "not a request", held=None, margin=0.03)
        there = planner.replan("phase2_unsafe", request, held=world.held, margin=0.03,
                               world=world).result(timeout=60)
    assert np.array_equal(there.q, here.q) and np.array_equal(there.t, here.t)
    assert there.info["replan"]["way"] == here.info["replan"]["way"]
