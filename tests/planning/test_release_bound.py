"""The release criterion between samples (issue 35, point 4): a motion is released only
with a certified clearance bound >= 0 against every object, at every instant of the
motion a controller executes, between the verifier's samples too.

Real python-fcl and real geometry throughout: a turning arm whose 1 mm ball passes a
1 mm ball in the cell at a chosen gap halfway between two of the verifier's samples
(distances checked here in closed form, on the executed quintic join of
``tests/quintic_join.py``), and the Panda problem set of the peer benchmark (objects with
margin 0), whose motions came out released with a negative bound before.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin
import pytest
from quintic_join import quintic_state

import safepath
from safepath import PlannerOptions, PlanOptions, UnprovenClearance
from safepath.model.robot import Robot
from safepath.model.scene import Scene, SceneObject, Shape
from safepath.timing import TimedPiece, spline_path, time_path
from safepath.verify import FclVerifier

ROOT = Path(__file__).resolve().parents[2]
PEERS = ROOT / "benchmarks" / "peers"
#: The arm's reach to its ball's centre and the two balls' radius [m].
REACH, BALL = 0.6, 0.0005
STEP = "0 move past"


def _turning_arm() -> Robot:
    """One joint turning about z, carrying a ball of radius BALL at REACH from the axis."""
    model = pin.Model()
    geometry = pin.GeometryModel()
    turn = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "turn")
    model.lowerPositionLimit[:], model.upperPositionLimit[:] = -np.pi, np.pi
    frame = model.addFrame(pin.Frame("hand", turn, pin.SE3.Identity(), pin.FrameType.BODY))
    geometry.addGeometryObject(pin.GeometryObject(
        "hand_0", turn, frame, pin.SE3(np.eye(3), np.array([REACH, 0.0, 0.0])),
        coal.Sphere(BALL)))
    return Robot(name="turn", model=model, collision_model=geometry, visual_model=None,
                 velocity_limits=np.ones(1), acceleration_limits=np.ones(1),
                 tcp_frame="hand")


def _cell_ball(gap: float, angle: float) -> Scene:
    """A scene of one ball (radius BALL, margin 0) beyond the arm's ball: ``gap`` [m]
    between the two when the arm is turned to ``angle`` [rad]."""
    T = np.eye(4)
    T[:3, 3] = (REACH + 2 * BALL + gap) * np.array([np.cos(angle), np.sin(angle), 0.0])
    return Scene("ball", "turn", {"ball": SceneObject("ball", Shape("sphere", (BALL,)), T)},
                 margin=0.0)


def _distance(gap: float, angle: float, q: np.ndarray) -> np.ndarray:
    """The two balls' distance [m] at the arm's angles ``q``, in closed form."""
    centre = REACH + 2 * BALL + gap
    between = np.sqrt(REACH ** 2 + centre ** 2 - 2 * REACH * centre * np.cos(q - angle))
    return between - 2 * BALL


@pytest.fixture(scope="module")
def sweep() -> tuple[Robot, TimedPiece, float, float]:
    """The arm turning half a radian rest to rest, timed at its limits (knots ~4 ms
    apart), and the angle halfway between two consecutive samples of the verifier's grid
    in the middle of the motion, with the arc between them [m]."""
    robot = _turning_arm()
    path, s_way, _ = spline_path([np.array([0.0]), np.array([0.5])], 0.06)
    piece = time_path(robot, path, s_way, scales=[1.0], tcp_speeds=[None])
    grid = FclVerifier(robot, _cell_ball(0.01, 0.25), margin=0.0).grid(piece.q)
    s = grid.samples // 2
    a, b = float(grid.state(piece.q, s)[0]), float(grid.state(piece.q, s + 1)[0])
    return robot, piece, (a + b) / 2, (b - a) * REACH


def _executed(piece: TimedPiece, rate: float = 20_000.0) -> np.ndarray:
    """The arm's angle on the executed quintic join, ``rate`` samples a second."""
    times = np.arange(0.0, float(piece.t[-1]), 1.0 / rate)
    return np.array([quintic_state(piece.t, piece.q, piece.qd, piece.qdd, at)[0][0]
                     for at in times])


@pytest.mark.parametrize("gap_mm", [-0.1, -0.02, 0.03, 0.1, 0.3])
def test_a_pass_between_two_samples_is_released_only_if_proven_apart(
        sweep: tuple[Robot, TimedPiece, float, float], gap_mm: float) -> None:
    """The balls meet (or not) halfway between two samples: every sample of the grid is
    clear in every case, so a check of the samples alone releases them all (it did);
    the release criterion refuses the contacts, naming the pair and a negative bound,
    and releases the passes it proves apart with a bound no higher than the executed
    motion's clearance."""
    robot, piece, angle, arc = sweep
    gap = gap_mm / 1000
    verifier = FclVerifier(robot, _cell_ball(gap, angle), margin=0.0)
    grid = verifier.grid(piece.q)
    samples = np.array([grid.state(piece.q, s)[0] for s in range(grid.samples)])
    assert 1e-3 < arc <= verifier.resolution
    assert _distance(gap, angle, samples).min() > 0.0  # every sample clear
    executed = _distance(gap, angle, _executed(piece)).min()
    assert executed == pytest.approx(gap, abs=2e-6)  # the join passes the gap itself
    assert _distance(gap, angle, samples).min() - verifier.resolution < 0.0  # the grid
    # alone cannot prove any of them apart
    steps = [STEP] * len(piece.t)
    if gap < 0:
        with pytest.raises(UnprovenClearance) as info:
            verifier.verify(piece.t, piece.q, piece.qd, steps=steps)
        err = info.value
        assert err.pair == ("hand", "ball") and err.pairs == [("hand", "ball")]
        assert err.bound < 0.0 and err.step == STEP
        assert "hand / ball" in str(err) and "certified clearance bound" in str(err)
        k = int(np.searchsorted(piece.t, err.time))
        assert abs(float(piece.q[min(k, len(piece.t) - 1), 0]) - angle) < 2 * arc / REACH
    else:
        result = verifier.verify(piece.t, piece.q, piece.qd, steps=steps)
        assert 0.0 <= result.clearance_bound <= executed
        assert result.min_clearance > executed  # the samples alone saw more


def _cell_balls(placed: dict[str, tuple[float, float]]) -> Scene:
    """A scene of balls (radius BALL, margin 0), each ``name: (gap [m], angle [rad])``
    beyond the arm's ball as :func:`_cell_ball` places one."""
    objects = {}
    for name, (gap, angle) in placed.items():
        T = np.eye(4)
        T[:3, 3] = (REACH + 2 * BALL + gap) * np.array([np.cos(angle), np.sin(angle), 0.0])
        objects[name] = SceneObject(name, Shape("sphere", (BALL,)), T)
    return Scene("balls", "turn", objects, margin=0.0)


@pytest.mark.parametrize("late_gap_mm", [-0.05, 0.05])
def test_of_several_passes_between_samples_the_one_not_proven_apart_is_named(
        sweep: tuple[Robot, TimedPiece, float, float], late_gap_mm: float) -> None:
    """Three balls, each passed halfway between two samples: two early ones 0.05 and
    0.1 mm apart, and a later one that the motion touches or passes 0.05 mm apart. The
    finer check bounds every interval next to every ball at once: the touch is refused,
    naming that ball and where it is passed (the closest approaches before it proven
    apart); without it, the motion is released with a bound no higher than its closest
    pass."""
    robot, piece, late, _ = sweep
    grid = FclVerifier(robot, _cell_ball(0.01, late), margin=0.0).grid(piece.q)
    angles = [float(np.mean([grid.state(piece.q, s)[0] for s in (k, k + 1)]))
              for k in (grid.samples // 5, grid.samples // 3)]
    placed = {"early": (0.05e-3, angles[0]), "middle": (0.1e-3, angles[1]),
              "late": (late_gap_mm / 1000, late)}
    verifier = FclVerifier(robot, _cell_balls(placed), margin=0.0)
    executed = _executed(piece)
    closest = {name: _distance(gap, angle, executed).min()
               for name, (gap, angle) in placed.items()}
    assert closest["early"] > 0.0 and closest["middle"] > 0.0
    if late_gap_mm < 0:
        with pytest.raises(UnprovenClearance) as info:
            verifier.verify(piece.t, piece.q, piece.qd)
        assert info.value.pair == ("hand", "late") and info.value.bound < 0.0
        k = int(np.searchsorted(piece.t, info.value.time))
        assert abs(float(piece.q[min(k, len(piece.t) - 1), 0]) - late) < 0.01
        return
    result = verifier.verify(piece.t, piece.q, piece.qd)
    assert 0.0 <= result.clearance_bound <= min(closest.values())


def test_the_finer_checks_bound_is_its_formula_on_the_intervals_around_the_pass(
        sweep: tuple[Robot, TimedPiece, float, float]) -> None:
    """A pass 1.2 mm from the ball, while the arm speeds up: closer than the grid's figure
    proves, far enough for every interval's bound from its two ends to be positive. The
    bound is the least, over the grid's intervals, of ``max((d_a + d_b - m) / 2,
    max(d_a, d_b) - m)`` minus the stray, with the distances in closed form, the ball's
    arc ``m`` between the samples and the stray of the knot interval each lies on (or
    half the resolution, if smaller)."""
    robot, piece, _, _ = sweep
    grid = FclVerifier(robot, _cell_ball(0.01, 0.0), margin=0.0).grid(piece.q)
    theta = np.array([grid.state(piece.q, s)[0] for s in range(grid.samples)])
    # Passed while the arm speeds up: the arcs between samples differ, so each interval
    # must be bounded with its own ends' distances.
    s = int(np.argmax(np.diff(theta) * REACH > 1e-3))
    angle = float(theta[s] + theta[s + 1]) / 2
    verifier = FclVerifier(robot, _cell_ball(1.2e-3, angle), margin=0.0)
    result = verifier.verify(piece.t, piece.q, piece.qd)
    d = _distance(1.2e-3, angle, theta)
    arc = (REACH + BALL) * np.abs(np.diff(theta))
    knot = grid.knot_of[1:]
    h = piece.t[knot] - piece.t[np.maximum(knot - 1, 0)]
    bounds = (np.maximum((d[:-1] + d[1:] - arc) / 2, np.maximum(d[:-1], d[1:]) - arc)
              - (REACH + BALL) * 1.0 * h * h / 8)
    assert result.min_clearance - verifier.resolution < 0.0  # the figure proves nothing
    assert 0.0 < bounds.min() < verifier.resolution / 2
    assert result.clearance_bound == pytest.approx(bounds.min(), abs=1e-9)


def test_the_bound_is_the_grid_figure_where_that_proves_it(
        sweep: tuple[Robot, TimedPiece, float, float]) -> None:
    """Far from the ball, the bound is the smallest clearance minus the resolution and
    the join's stray (amax h^2 / 8 times the reach), and below the executed clearance."""
    robot, piece, angle, _ = sweep
    verifier = FclVerifier(robot, _cell_ball(0.02, angle), margin=0.0)
    result = verifier.verify(piece.t, piece.q, piece.qd)
    h = float(np.max(np.diff(piece.t)))
    stray = (REACH + BALL) * 1.0 * h * h / 8
    assert result.clearance_bound == pytest.approx(
        result.min_clearance - verifier.resolution - stray, abs=1e-9)
    assert 0.0 < result.clearance_bound < _distance(0.02, angle, _executed(piece)).min()


def _peer_problems() -> Any:
    """The peer benchmark's problem module (``benchmarks/peers/problems.py``)."""
    spec = importlib.util.spec_from_file_location("peer_problems", PEERS / "problems.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _panda_cell(tmp: Path, problems: dict | None = None
                ) -> tuple[safepath.Cell, dict, list]:
    """The peer benchmark's Panda problem set (the committed one unless ``problems``)
    as a cell (margin 0), its routes and problems."""
    module = _peer_problems()
    if problems is None:
        problems = json.loads((PEERS / "panda_problems.json").read_text())
    cell = safepath.load_cell(module.write_panda_cell(problems, tmp / "panda"))
    routes = safepath.load_routes(cell.folder, poses=list(cell.poses),
                                  objects=list(cell.scene.objects))
    return cell, routes, problems["problems"]


#: Problems (and seeds) of the Panda set released with a negative bound before
#: (-1.11, -1.66 and -1.83 mm, next to the pillar and the crossbar).
NEGATIVE_BEFORE = ("p04", "p07", "p17")


def test_panda_motions_near_objects_of_margin_0_are_released_with_a_proven_bound(
        tmp_path: Path) -> None:
    """Each motion comes within the resolution of an object (the grid's figure is
    negative: by the old criterion it was released so); now it is released with a
    certified bound >= 0 that the executed motion keeps (coal, 1 kHz), or refused."""
    cell, routes, problems = _panda_cell(tmp_path)
    checker = cell.checker()
    released = 0
    for problem in (p for p in problems if p["id"] in NEGATIVE_BEFORE):
        options = PlanOptions(planner=PlannerOptions(seed=int(problem["seed"])))
        try:
            traj = safepath.plan_route(cell, routes[problem["id"]], options)
        except UnprovenClearance as exc:
            assert exc.bound < 0.0 and exc.pair[1] in cell.scene.objects
            continue
        info = traj.info
        assert info["min_clearance"] - info["resolution"] - info["knot_deviation"] < 0.0
        assert info["clearance_bound"] >= 0.0
        q, _, _ = traj.sample(np.arange(0.0, traj.duration, 0.001))
        assert min(checker.check(qk).clearance for qk in q) >= info["clearance_bound"]
        released += 1
    assert released >= 2


def test_a_blend_that_times_to_a_refused_piece_is_refused_without_a_second_check(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Problem p23 of the Panda set drawn with seed 97001: smaller blends time to pieces
    a larger blend timed already, which the release check refused (contact between two
    samples not ruled out). Each piece is checked once; the route is still planned, as
    before (stops at the corners), every released piece checked."""
    from safepath.planning import _chunks

    problems = _peer_problems().generate_panda_problems(seed=97001)
    cell, routes, listed = _panda_cell(tmp_path, problems)
    timed: list[object] = []
    checked: list[tuple[object, bool]] = []
    time_segments, verify_piece = _chunks.time_segments, _chunks.verify_piece

    def timing(*args: Any, **kwargs: Any) -> Any:
        piece, steps = time_segments(*args, **kwargs)
        timed.append(piece)
        return piece, steps

    def checking(piece: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            out = verify_piece(piece, *args, **kwargs)
        except safepath.VerificationError:
            checked.append((piece, False))
            raise
        checked.append((piece, True))
        return out

    monkeypatch.setattr(_chunks, "time_segments", timing)
    monkeypatch.setattr(_chunks, "verify_piece", checking)
    problem = listed[23]
    traj = safepath.plan_route(cell, routes[problem["id"]],
                               PlanOptions(planner=PlannerOptions(seed=int(problem["seed"]))))
    repeats = [p for k, p in enumerate(timed) if any(p is e for e in timed[:k])]
    assert repeats, "no try timed to an earlier piece: the case is gone"
    pieces = [p for p, _ in checked]
    assert all(sum(p is e for e in pieces) == 1 for p in pieces), "a piece checked twice"
    assert all(any(r is p and not ok for p, ok in checked) for r in repeats)
    released = [p for p, ok in checked if ok]
    assert released and traj.info["clearance_bound"] >= 0.0


def test_a_blend_into_an_object_is_refused_by_the_release_check_and_a_smaller_one_released(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Problem p05 of the Panda set drawn with seed 97001: its detour's corners rounded by
    0.6 rad bring the hand into the crossbar. The planner's checker is not asked about a
    blended spline; the release check of the timed piece refuses it (a sample in
    contact), the 0.3 rad blend is timed, checked and released, and the motion as
    executed keeps the bound released with (coal, 1 kHz)."""
    from safepath.planning import _chunks

    problems = _peer_problems().generate_panda_problems(seed=97001)
    cell, routes, listed = _panda_cell(tmp_path, problems)
    blends: list[float] = []
    checked: list[tuple[float, bool, str]] = []
    refused: list[Any] = []
    splines: list[object] = []
    time_segments, verify_piece = _chunks.time_segments, _chunks.verify_piece
    check_path = safepath.CollisionChecker.check_path

    def timing(*args: Any, blend: float = 0.0, **kwargs: Any) -> Any:
        blends.append(blend)
        return time_segments(*args, blend=blend, **kwargs)

    def checking(piece: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            out = verify_piece(piece, *args, **kwargs)
        except safepath.VerificationError as exc:
            checked.append((blends[-1], False, str(exc)))
            refused.append(piece)
            raise
        checked.append((blends[-1], True, ""))
        return out

    def path_check(self: Any, path: Any, *args: Any, **kwargs: Any) -> Any:
        splines.append(path)  # a move plans by segments: only a spline check asks this
        return check_path(self, path, *args, **kwargs)

    monkeypatch.setattr(_chunks, "time_segments", timing)
    monkeypatch.setattr(_chunks, "verify_piece", checking)
    monkeypatch.setattr(safepath.CollisionChecker, "check_path", path_check)
    problem = listed[5]
    traj = safepath.plan_route(cell, routes[problem["id"]],
                               PlanOptions(planner=PlannerOptions(seed=int(problem["seed"]))))
    assert not splines  # no blended spline checked by the planner's checker
    assert checked[0][:2] == (0.6, False) and "in collision" in checked[0][2]
    assert "crossbar" in checked[0][2]
    assert checked[-1][:2] == (0.3, True) and len(checked) == 2
    # The refused blend's knots touch the crossbar as the planner's checker sees it too.
    checker = cell.checker()
    assert any("crossbar" in {a, b} for qk in refused[0].q
               for a, b in checker.check(qk).collisions)
    assert traj.info["clearance_bound"] >= 0.0
    q, _, _ = traj.sample(np.arange(0.0, traj.duration, 0.001))
    assert min(checker.check(qk).clearance for qk in q) >= traj.info["clearance_bound"]
