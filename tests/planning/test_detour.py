"""A post on the direct high1 -> high2 sweep: OMPL must find a detour, and it is safe.

The detour cell (``tests/data/detour_cell``) is the bundled cell plus one box post
standing on the table between the two poses.
"""

from __future__ import annotations

import numpy as np

from safepath import CheckOptions, CollisionChecker, PlannerOptions, PlanOptions
from safepath.cell import Cell
from safepath.model.trajectory import Trajectory
from safepath.planning import plan_cell, plan_joint_path

from .conftest import DETOUR, Plans, dense_times, route_routes

MOVE = "3 move high2"


def _held_checker(cell: Cell) -> CollisionChecker:
    return cell.checker(held=True, options=CheckOptions(enforce_margin=True))


def test_the_taught_poses_stay_valid(detour_cell: Cell) -> None:
    for held in (False, True):
        checker = detour_cell.checker(held=held, options=CheckOptions(enforce_margin=True))
        for name in ("high1", "high2"):
            report = checker.check(detour_cell.pose(name))
            assert report.margin_ok, (name, held, report)
            # The post is not what limits the poses' clearance.
            distances = dict(checker.distances(detour_cell.pose(name)))
            to_post = min(d for pair, d in distances.items() if "obstacle" in pair)
            assert to_post > 0.05


def test_the_direct_segment_collides_with_the_post(detour_cell: Cell) -> None:
    q1, q2 = detour_cell.pose("high1"), detour_cell.pose("high2")
    for held in (False, True):
        checker = detour_cell.checker(held=held, options=CheckOptions(enforce_margin=True))
        report = checker.check_segment(q1, q2)
        assert not report.valid
        assert report.fraction is not None and 0 < report.fraction < 1
        assert report.collisions and all("obstacle" in pair for pair in report.collisions)
        if held:
            assert ("vial", "obstacle") in report.collisions


def test_ompl_finds_a_valid_polyline(detour_cell: Cell) -> None:
    checker = _held_checker(detour_cell)
    q1, q2 = detour_cell.pose("high1"), detour_cell.pose("high2")
    path = plan_joint_path(checker, q1, q2, options=PlannerOptions(seed=5), step="detour")
    assert len(path) >= 3  # not the direct segment
    np.testing.assert_array_equal(path[0], q1)
    np.testing.assert_array_equal(path[-1], q2)
    assert checker.check_path(path).valid


def test_phase1_plans_around_the_post(detour_cell: Cell, detour_phase1: Trajectory) -> None:
    traj = detour_phase1
    assert traj.info["min_clearance"] >= detour_cell.scene.margin
    k = traj.steps.index(MOVE)
    q = traj.q[traj.step_index == k]
    q1, q2 = detour_cell.pose("high1"), detour_cell.pose("high2")
    # Distance of each knot of the move from the straight joint segment [rad].
    d = q2 - q1
    s = np.clip((q - q1) @ d / (d @ d), 0.0, 1.0)
    off = np.linalg.norm(q - (q1 + s[:, None] * d), axis=1)
    assert off.max() > 0.1, f"the move stays within {off.max():.3f} rad of the segment"


def test_phase1_detour_is_free_at_1ms(detour_cell: Cell, detour_phase1: Trajectory) -> None:
    traj = detour_phase1
    checker = _held_checker(detour_cell)
    times = dense_times(traj, 0.001)
    k = traj.steps.index(MOVE)
    step_of = traj.step_index[np.clip(np.searchsorted(traj.t, times, side="right") - 1, 0,
                                      traj.t.size - 1)]
    q, _, _ = traj.sample(times[step_of == k])
    assert len(q) > 100
    bad = [i for i in range(len(q)) if not checker.is_valid(q[i])]
    assert not bad, f"{len(bad)} samples of the detour collide or break a margin"


def test_the_detour_costs_time_but_keeps_the_route(detour_cell: Cell,
                                                   detour_phase1: Trajectory,
                                                   bundled: Plans) -> None:
    direct = bundled.trajectories["phase1"]
    assert detour_phase1.steps == direct.steps
    assert [(e.action, e.step) for e in detour_phase1.events] == \
        [(e.action, e.step) for e in direct.events]
    assert detour_phase1.duration > direct.duration
    np.testing.assert_allclose(detour_phase1.q[-1], detour_cell.pose("high2"), atol=1e-6)


def test_phase1_with_baseline_plans_with_seed_8(detour_cell: Cell) -> None:
    routes = route_routes(DETOUR, detour_cell)
    options = PlanOptions(planner=PlannerOptions(seed=8), baseline=True)
    traj = plan_cell(detour_cell, options, routes={"phase1": routes["phase1"]})["phase1"]
    assert traj.info["baseline_duration"] > 0
    assert traj.info["min_clearance"] >= detour_cell.scene.margin


def test_shortcut_options_reach_the_shortcutter(detour_cell: Cell) -> None:
    """The shortcutter's options are kept when the planner seeds each step (they were
    once rebuilt positionally), and a shortcut that gains under ``shortcut_min_gain`` is
    not taken: with a gain threshold of 99 % only the greedy vertex removal shortens."""
    import pytest

    from safepath.errors import ConfigError

    q1, q2 = detour_cell.pose("high1"), detour_cell.pose("high2")
    checker = _held_checker(detour_cell)

    def length(path: list) -> float:
        return float(np.sum(np.linalg.norm(np.diff(np.asarray(path), axis=0), axis=1)))

    lazy = PlannerOptions(seed=3, shortcut_min_gain=0.99)
    keen = PlannerOptions(seed=3, shortcut_min_gain=0.0)
    greedy_only = PlannerOptions(seed=3, shortcut_iterations=0)
    paths = {name: plan_joint_path(checker, q1, q2, options=o)
             for name, o in (("lazy", lazy), ("keen", keen), ("greedy", greedy_only))}
    assert length(paths["lazy"]) == pytest.approx(length(paths["greedy"]))
    assert length(paths["keen"]) < length(paths["greedy"])
    for path in paths.values():
        assert checker.check_path(path).valid
    with pytest.raises(ConfigError, match="shortcut_min_gain"):
        PlannerOptions(shortcut_min_gain=1.0)


def test_the_planner_passes_every_planner_option_on(detour_cell: Cell,
                                                    monkeypatch: object) -> None:
    """Each move is planned with the caller's options, only the seed advanced per step."""
    import dataclasses

    from safepath.planning import route_planner as planner

    seen: list[PlannerOptions] = []
    real = planner.plan_joint_path

    def spy(*args: object, options: PlannerOptions, **kwargs: object) -> object:
        seen.append(options)
        return real(*args, options=options, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(planner, "plan_joint_path", spy)  # type: ignore[attr-defined]
    mine = PlannerOptions(seed=7, time_limit=3.5, shortcut_iterations=17,
                          shortcut_min_gain=0.2)
    phase1 = route_routes(DETOUR, detour_cell)["phase1"]
    plan_cell(detour_cell, PlanOptions(planner=mine), routes={"phase1": phase1})
    assert seen
    for options in seen:
        assert options.seed >= mine.seed
        assert dataclasses.replace(options, seed=mine.seed) == mine
