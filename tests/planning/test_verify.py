"""The independent FCL verifier catches what it must: collisions and margin violations.

A timed trajectory that goes straight through the detour cell's post (timed with the
library's own spline and TOPPRA, but never collision-checked) must be rejected with
the pair, the time and the step; a safe trajectory checked against a margin larger
than its clearance must be rejected only when margins are enforced.
"""

from __future__ import annotations

import numpy as np
import pytest

from safepath import CheckOptions, VerificationError
from safepath.cell import Cell
from safepath.planning import FclVerifier, initial_world
from safepath.planning.timing import TimedPiece, spline_path, time_path

from .conftest import Plans

STEP = "2 move high2"


def _straight(cell: Cell, a: str, b: str) -> TimedPiece:
    """The straight joint move a -> b, timed rest to rest, not collision-checked."""
    path, s_way, _ = spline_path([cell.pose(a), cell.pose(b)], 0.06)
    return time_path(cell.robot, path, s_way, scales=[1.0], tcp_speeds=[None])


def _verifier(cell: Cell, **kwargs: object) -> FclVerifier:
    world = initial_world(cell)
    return FclVerifier(cell.robot, cell.scene, held="vial", resting=dict(world.resting),
                       **kwargs)  # type: ignore[arg-type]


def test_a_trajectory_through_the_post_is_rejected(detour_cell: Cell) -> None:
    piece = _straight(detour_cell, "high1", "high2")
    verifier = _verifier(detour_cell)
    with pytest.raises(VerificationError) as info:
        verifier.verify(piece.t, piece.q, piece.qd, steps=[STEP] * len(piece.t))
    err = info.value
    assert err.step == STEP
    assert 0.0 < err.time < float(piece.t[-1])
    assert err.pairs and all("obstacle" in pair for pair in err.pairs)
    assert "obstacle" in str(err) and STEP in str(err) and f"t={err.time:.3f}" in str(err)
    # The rejected state does collide (or breaks the margin) for the planner's checker.
    checker = detour_cell.checker(held=True, options=CheckOptions(enforce_margin=True))
    assert not checker.is_valid(np.asarray(err.q))
    # Before the reported time the motion was accepted: the failure is the first one.
    first = int(np.searchsorted(piece.t, err.time))
    early = _verifier(detour_cell).verify(piece.t[:max(first - 5, 2)],
                                          piece.q[:max(first - 5, 2)],
                                          piece.qd[:max(first - 5, 2)])
    assert early.min_clearance >= 0.0


def test_the_same_motion_is_accepted_without_the_post(bundled_cell: Cell) -> None:
    piece = _straight(bundled_cell, "high1", "high2")
    result = _verifier(bundled_cell).verify(piece.t, piece.q, piece.qd)
    assert result.min_clearance >= bundled_cell.scene.margin
    assert 0 < result.checked <= result.samples
    assert result.closest_pair is not None


def _move_of_phase1(bundled: Plans) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    traj = bundled.trajectories["phase1"]
    sel = traj.step_index == traj.steps.index(STEP)
    return traj.t[sel], traj.q[sel], traj.qd[sel]


def test_a_margin_violation_is_caught_only_when_enforced(bundled: Plans) -> None:
    cell = bundled.cell
    t, q, qd = _move_of_phase1(bundled)
    relaxed = _verifier(cell, margin=0.2, enforce_margin=False).verify(t, q, qd)
    assert relaxed.min_clearance < 0.2  # the margin is not kept ...
    with pytest.raises(VerificationError) as info:  # ... and that is caught when enforced
        _verifier(cell, margin=0.2, enforce_margin=True).verify(t, q, qd,
                                                                 steps=[STEP] * len(t))
    assert info.value.step == STEP and info.value.pairs
    # With the scene's margins the planned move passes, and its clearance is the same.
    strict = _verifier(cell, enforce_margin=True).verify(t, q, qd)
    assert strict.min_clearance >= cell.scene.margin
    assert strict.min_clearance == pytest.approx(relaxed.min_clearance, abs=2e-3)


def test_verifier_and_checker_agree_on_clearance(bundled: Plans) -> None:
    """FCL (verifier) and coal (checker) measure the same closest distance, within 1 mm."""
    cell = bundled.cell
    t, q, qd = _move_of_phase1(bundled)
    result = _verifier(cell, enforce_margin=True).verify(t, q, qd)
    checker = cell.checker(held=True)
    coal_min = min(checker.clearance(qk)[0] for qk in q[::5])
    assert result.min_clearance == pytest.approx(coal_min, abs=1e-3)
