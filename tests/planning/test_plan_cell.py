"""Every route of the bundled cell plans, times and verifies, and the result is sound.

The trajectories are planned once per session (``bundled`` fixture); each test checks
one property on every route, and the last ones re-check the timed result at 1 ms with
the planner's own collision checker built independently from the route description.
"""

from __future__ import annotations

import numpy as np
import pytest

from safepath import CheckOptions, CollisionChecker
from safepath.cell import Cell
from safepath.planning import initial_world

from .conftest import (
    INTERPOLATION_TOL,
    LIMIT_TOL,
    Plans,
    dense_times,
    object_released_at,
    step_worlds,
)

ROUTES = ("phase1", "phase2_safe", "phase2_unsafe")


def test_every_route_is_planned(bundled: Plans) -> None:
    assert set(bundled.trajectories) == set(ROUTES) == set(bundled.routes)
    for name, traj in bundled.trajectories.items():
        assert traj.route == name
        assert traj.robot == bundled.cell.robot.name
        assert traj.joint_names == bundled.cell.robot.joint_names
        assert traj.duration > 1.0


@pytest.mark.parametrize("name", ROUTES)
def test_knots_within_limits(bundled: Plans, name: str) -> None:
    traj, robot = bundled.trajectories[name], bundled.cell.robot
    assert np.all(traj.q >= robot.lower - 1e-9) and np.all(traj.q <= robot.upper + 1e-9)
    v = np.abs(traj.qd) / robot.velocity_limits
    a = np.abs(traj.qdd) / robot.acceleration_limits
    assert v.max() <= 1 + LIMIT_TOL, f"velocity {v.max():.4f} of the limit"
    assert a.max() <= 1 + LIMIT_TOL, f"acceleration {a.max():.4f} of the limit"
    # Each knot also respects the speed fraction of the step it belongs to.
    route = bundled.routes[name]
    speed = np.array([route.steps[k].speed for k in traj.step_index])[:, None]
    assert (v / speed).max() <= 1 + LIMIT_TOL
    assert (a / speed).max() <= 1 + LIMIT_TOL
    # The limits are used, not just respected: the fastest knot is near one.
    assert max(v.max(), a.max()) > 0.9


@pytest.mark.parametrize("name", ROUTES)
def test_verified_clearance_keeps_the_margin(bundled: Plans, name: str) -> None:
    traj = bundled.trajectories[name]
    assert traj.info["min_clearance"] >= bundled.cell.scene.margin
    assert traj.info["closest_pair"] is not None and len(traj.info["closest_pair"]) == 2
    assert 0 < traj.info["planning_time"] <= traj.info["total_time"]


@pytest.mark.parametrize("name", ROUTES)
def test_starts_and_ends_at_taught_poses_at_rest(bundled: Plans, name: str) -> None:
    cell, route, traj = bundled.cell, bundled.routes[name], bundled.trajectories[name]
    np.testing.assert_allclose(traj.q[0], cell.pose(route.start), atol=1e-9)
    last = [s for s in route.steps if s.is_motion][-1]
    assert last.target is not None and last.target.exact_pose is not None
    np.testing.assert_allclose(traj.q[-1], cell.pose(last.target.exact_pose), atol=1e-6)
    assert traj.t[0] == 0.0
    assert not np.any(traj.qd[0]) and not np.any(traj.qd[-1])


@pytest.mark.parametrize("name", ROUTES)
def test_steps_and_events_follow_the_route(bundled: Plans, name: str) -> None:
    cell, route, traj = bundled.cell, bundled.routes[name], bundled.trajectories[name]
    labels = route.labels()
    assert traj.steps == tuple(labels)
    grasped = cell.scene.grasp.object if cell.scene.grasp else None
    expected = [(s.kind, labels[i], s.object or grasped) for i, s in enumerate(route.steps)
                if not s.is_motion]
    assert [(e.action, e.step, e.object) for e in traj.events] == expected
    times = [e.time for e in traj.events]
    assert times == sorted(times)
    # Every motion step owns knots, in route order; gripper steps own none.
    motion = [i for i, s in enumerate(route.steps) if s.is_motion]
    assert sorted(set(traj.step_index.tolist())) == motion
    assert np.all(np.diff(traj.step_index) >= 0)


@pytest.mark.parametrize("name", ROUTES)
def test_gripper_events_happen_at_rest_at_their_pose(bundled: Plans, name: str) -> None:
    cell, route, traj = bundled.cell, bundled.routes[name], bundled.trajectories[name]
    labels = route.labels()
    for event in traj.events:
        k = int(np.argmin(np.abs(traj.t - event.time)))
        assert abs(traj.t[k] - event.time) < 1e-9, "an event falls between knots"
        assert not np.any(traj.qd[k]), f"{event.step}: moving at the event"
        _, qd, _ = traj.sample([event.time])
        assert np.max(np.abs(qd)) < 1e-9
        # The pose of the motion step just before the gripper step.
        i = labels.index(event.step)
        before = [s for s in route.steps[:i] if s.is_motion]
        pose = before[-1].target.exact_pose if before else route.start  # type: ignore[union-attr]
        if pose is not None:
            np.testing.assert_allclose(traj.q[k], cell.pose(pose), atol=1e-6)


@pytest.mark.parametrize("name", ROUTES)
def test_step_durations_sum_to_duration(bundled: Plans, name: str) -> None:
    route, traj = bundled.routes[name], bundled.trajectories[name]
    durations = traj.step_durations()
    assert list(durations) == list(traj.steps)
    assert sum(durations.values()) == pytest.approx(traj.duration, abs=1e-9)
    for step, label in zip(route.steps, traj.steps, strict=True):
        if step.is_motion:
            assert durations[label] > 0.05, label
        else:
            assert durations[label] == 0.0


@pytest.mark.parametrize("name", ROUTES)
def test_blending_beats_stop_and_go(bundled: Plans, name: str) -> None:
    traj = bundled.trajectories[name]
    baseline = traj.info["baseline_duration"]
    assert 0 < traj.duration < baseline


def _worlds(bundled: Plans) -> dict[str, dict[str, np.ndarray]]:
    """Where the movable object rests at the start of each route (independently)."""
    cell = bundled.cell
    start = {k: v for k, v in initial_world(cell).resting.items()}
    released = object_released_at(cell, bundled.trajectories["phase1"])
    return {"phase1": start, "phase2_safe": {"vial": released},
            "phase2_unsafe": {"vial": released}}


@pytest.mark.parametrize("name", ROUTES)
def test_independent_recheck_at_1ms(bundled: Plans, name: str) -> None:
    """Re-sample at 1 ms and check every sample with a checker built from the route:
    the right object held, the right contacts allowed, margins enforced."""
    cell, route, traj = bundled.cell, bundled.routes[name], bundled.trajectories[name]
    grasp = cell.scene.grasp
    assert grasp is not None
    worlds = step_worlds(cell, route)
    resting = dict(_worlds(bundled)[name])
    times = dense_times(traj, 0.001)
    q, qd, _ = traj.sample(times)
    step_of = traj.step_index[np.clip(np.searchsorted(traj.t, times, side="right") - 1, 0,
                                      traj.t.size - 1)]
    # The resting object moves when released: split the samples at the open events.
    opens = [e.time for e in traj.events if e.action == "open"]
    checkers: dict[tuple, CollisionChecker] = {}
    checked_moves = 0
    for n in range(times.size):
        world = worlds[int(step_of[n])]
        released = [t for t in opens if t <= times[n]]
        rest = dict(resting)
        if released and not world.held:
            rest[grasp.object] = object_released_at(cell, traj)
        key = (world.held, world.allowed, len(released))
        if key not in checkers:
            checkers[key] = CollisionChecker(
                cell.robot, cell.scene, held=grasp.object if world.held else None,
                resting=None if world.held else rest, allowed=world.allowed,
                options=CheckOptions(enforce_margin=True))
        if not checkers[key].is_valid(q[n]):
            report = checkers[key].check(q[n])
            pytest.fail(f"{name}: t={times[n]:.3f} s in step '{traj.steps[step_of[n]]}': "
                        f"{report.collisions or report.margin_violations}")
        checked_moves += world.kind == "move"
    assert checked_moves > 500  # every route has moves; they were checked


@pytest.mark.parametrize("name", ROUTES)
def test_dense_samples_stay_within_limits(bundled: Plans, name: str) -> None:
    """Between knots the cubic Hermite interpolation stays within the limits too."""
    traj, robot = bundled.trajectories[name], bundled.cell.robot
    q, qd, _ = traj.sample(dense_times(traj, 0.001))
    assert np.all(q >= robot.lower - 1e-9) and np.all(q <= robot.upper + 1e-9)
    assert (np.abs(qd) / robot.velocity_limits).max() <= 1 + INTERPOLATION_TOL


def test_each_piece_is_verified_in_one_call_each_step_under_its_contacts(
        bundled_cell: Cell, monkeypatch: pytest.MonkeyPatch) -> None:
    """The release check verifies each timed piece in one call: its consecutive steps
    that allow the same contacts are one stage, each stage starts at the last knot of
    the one before, each knot is named by its step; each stage's stretch passes its own
    verifier alone, and the piece's clearance is theirs to within half the
    resolution."""
    from safepath import plan_cell
    from safepath.planning import _chunks
    from safepath.verify import StagedVerifier

    pieces: list[tuple[object, list[int], list[str]]] = []
    calls: list[tuple[StagedVerifier, np.ndarray, np.ndarray, list[int], list[str],
                      float]] = []
    verified, verify = _chunks.verify_piece, StagedVerifier.verify

    def spy_verified(piece: object, seg_steps: list[int], segments: list[object],
                     world: object, cache: object, labels: list[str], *args: object
                     ) -> object:
        pieces.append((piece, seg_steps, labels))
        return verified(piece, seg_steps, segments, world, cache, labels,  # type: ignore[arg-type]
                        *args)

    def spy_verify(self: StagedVerifier, t: np.ndarray, q: np.ndarray, starts: list[int],
                   **kwargs: object) -> object:
        calls.append((self, np.asarray(t), np.asarray(q), list(starts),
                      list(kwargs["steps"]), float(kwargs["known"])))
        return verify(self, t, q, starts, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(_chunks, "verify_piece", spy_verified)
    monkeypatch.setattr(StagedVerifier, "verify", spy_verify)
    plan_cell(bundled_cell)
    monkeypatch.undo()
    assert len(calls) == len(pieces)
    assert any(len(c[0].verifiers) > 1 for c in calls)
    assert any(len(set(c[4])) > len(c[0].verifiers) for c in calls)  # steps merged
    for (staged, t, q, starts, names, known), (piece, seg_steps, labels) in zip(
            calls, pieces, strict=True):
        steps = np.asarray(seg_steps)[piece.segment]  # type: ignore[attr-defined]
        np.testing.assert_array_equal(t, piece.t)  # type: ignore[attr-defined]
        assert names == [labels[k] for k in steps]
        whole = verify(staged, t, q, starts, known=known)
        ends = [*starts[1:], len(t) - 1]
        parts = [v.verify(t[a:b + 1], q[a:b + 1], q[a:b + 1], known=known)
                 for v, a, b in zip(staged.verifiers, starts, ends, strict=True)]
        for k, (a, b) in enumerate(zip(starts, ends, strict=True)):
            # A stage is steps allowing the same contacts, from where the last ended.
            own = set(steps[a + (k > 0):b + 1].tolist())
            assert sorted(own) == list(range(min(own), max(own) + 1))
        best = min(p.min_clearance for p in parts)
        assert abs(whole.min_clearance - best) <= staged.verifiers[0].resolution / 2 or (
            whole.min_clearance == best == float("inf"))


def test_a_checker_and_verifier_made_for_other_contacts_judge_as_new_ones(
        bundled_cell: Cell) -> None:
    """The planner makes the checker and verifier of a world state's other allowed
    contacts from the first one (``with_allowed``): the same pairs, margins, layer
    tables and answers as ones made from scratch."""
    from safepath import plan_cell
    from safepath.planning.options import PlanOptions
    from safepath.planning.world import CheckerCache
    from safepath.verify import FclVerifier

    plan_cell(bundled_cell)
    options = PlanOptions().check
    made, verifiers = CheckerCache(bundled_cell, PlanOptions()).made()
    worlds = [state for state, _ in made]
    derived = [key for key in made if worlds.count(key[0]) > 1]
    assert derived and any(allowed for _, allowed in derived)
    rng = np.random.default_rng(5)
    robot = bundled_cell.robot
    states = rng.uniform(robot.lower, robot.upper, (200, robot.dof))
    for key in derived:
        checker = made[key]
        fresh = CollisionChecker(robot, bundled_cell.scene, held=checker.held,
                                 resting=checker.resting, allowed=key[1], options=options)
        assert checker.pairs == fresh.pairs
        np.testing.assert_array_equal(checker.layer_source().security,
                                      fresh.layer_source().security)
        assert checker.layer is not None and fresh.layer is not None
        np.testing.assert_array_equal(checker.layer.F, fresh.layer.F)
        np.testing.assert_array_equal(checker.layer.I, fresh.layer.I)
        assert [checker.is_valid(q) for q in states] == [fresh.is_valid(q) for q in states]
        assert [checker.exact_collides(q) for q in states[:40]] == [
            fresh.exact_collides(q) for q in states[:40]]
        verifier = verifiers[key]
        new = FclVerifier(robot, bundled_cell.scene, held=checker.held,
                          resting=dict(checker.resting), allowed=key[1],
                          resolution=options.resolution, margin=options.margin,
                          enforce_margin=options.enforce_margin)
        # The same pairs, what each must keep and which count for the clearance ...
        assert verifier.pairs == new.pairs
        # ... and the same layer: its pairs' motion weights and, in the same order, bounds.
        np.testing.assert_array_equal(verifier.pair_weights, new.pair_weights)
        for q in states[:10]:
            np.testing.assert_array_equal(verifier.bounds_at(q).bounds,
                                          new.bounds_at(q).bounds)


def test_routes_given_as_a_list_are_a_typed_error(bundled_cell: Cell) -> None:
    """plan_cell(routes=...) takes a mapping of names to Routes: a list of names is a
    ConfigError naming the argument (it was a bare TypeError deep in route ordering)."""
    from safepath import ConfigError, plan_cell

    with pytest.raises(ConfigError, match="mapping of route names") as info:
        plan_cell(bundled_cell, routes=["phase1"])  # type: ignore[arg-type]
    assert info.value.key == "routes"


def test_a_blend_that_cannot_be_timed_is_passed_through_exactly(
        bundled_cell: Cell, monkeypatch: pytest.MonkeyPatch) -> None:
    """A blend TOPP-RA cannot time (a radius cut down to millimetres by a short segment
    was one, on a fresh Panda set) is given up like one that collides: the next, smaller
    one is tried, then passing through exactly. It used to fail the whole plan."""
    from safepath import PlanOptions, plan_cell
    from safepath.errors import TimingError
    from safepath.planning import _chunks

    from .conftest import BUNDLED, route_routes

    time_segments = _chunks.time_segments
    blends: list[float] = []

    def untimeable_blends(*args: object, blend: float = 0.0, **kwargs: object) -> object:
        blends.append(blend)
        if blend > 0.0:
            raise TimingError("TOPP-RA found no feasible timing (test)")
        return time_segments(*args, blend=blend, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(_chunks, "time_segments", untimeable_blends)
    routes = route_routes(BUNDLED, bundled_cell)
    traj = plan_cell(bundled_cell, PlanOptions(), routes={"phase1": routes["phase1"]})["phase1"]
    assert traj.duration > 0.0 and traj.info["min_clearance"] > 0.0  # released: re-checked
    assert {0.6, 0.3, 0.1} <= set(blends) and 0.0 in blends
