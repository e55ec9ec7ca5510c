"""Timing and release checks of the chunks of a route (the motion between two stops).

A chunk is first timed blended through its via poses (large blend radii first), and
each timed piece is re-checked by the independent verifier; a blend that is not
collision-free, or fails the re-check, is replaced by a smaller one, then by stops at the
step boundaries, then by stops at every corner of the checked path.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

from ..cell.routes import Route, Step
from ..errors import PlanningError, TimingError, VerificationError
from ..model._knots import interval_index
from ..model.scene import AllowedContact
from ..model.trajectory import GripperEvent, Trajectory
from ..timing import TimedPiece, TimingOptions, spline_path, time_path
from ..verify import VerifyResult
from . import _repeats

if TYPE_CHECKING:
    from ..cell import Cell
    from ..collision import CollisionChecker
    from .options import PlanOptions
    from .world import CheckerCache, WorldState

__all__ = ["TimedPieces", "apart", "assemble", "time_chunk", "time_segments", "verify_piece"]

log = logging.getLogger(__name__)


class TimedPieces:
    """The pieces one planning call has timed, by everything their timing reads: the
    path's points and blended corners, each segment's speed scale and TCP speed limit,
    and the timing options (one robot per call). A route's stop-and-go baseline times a
    lone line step as its chunk did, and routes from the same pose often plan the same
    first steps: a second ask gets the first's piece (the same bits) instead of timing
    it again. Kept for one call only: a plan keeps no results between calls."""

    def __init__(self) -> None:
        self._pieces: dict[tuple[object, ...], TimedPiece] = {}
        #: How many asks got a piece timed before.
        self.reused = 0

    @staticmethod
    def key(waypoints: Sequence[np.ndarray], corners: Sequence[tuple[int, float]],
            scales: Sequence[float], tcp: Sequence[float | None], options: TimingOptions
            ) -> tuple[object, ...]:
        """What the timing of the spline through ``waypoints`` reads."""
        points = np.asarray(waypoints, dtype=float)
        return (points.shape, points.tobytes(), tuple(corners), tuple(scales), tuple(tcp),
                options)

    def get(self, key: tuple[object, ...]) -> TimedPiece | None:
        """The piece timed for ``key``, or None."""
        piece = self._pieces.get(key)
        self.reused += piece is not None
        return piece

    def put(self, key: tuple[object, ...], piece: TimedPiece) -> None:
        """Keep ``piece`` as the timing of ``key``."""
        self._pieces[key] = piece


@dataclass
class Segment:
    step_index: int
    step: Step
    waypoints: list[np.ndarray]
    allowed: tuple[AllowedContact, ...]


def time_chunk(cell: Cell, segments: list[Segment], world: WorldState, options: PlanOptions,
                cache: CheckerCache, labels: list[str], known: float = float("inf"), *,
                timed: TimedPieces | None = None
                ) -> list[tuple[TimedPiece, list[int], VerifyResult]]:
    """Time and verify a chunk: blended through its via points (large blends first, then
    smaller, then passing exactly); if no blend can be timed and passes the independent
    re-check, stop at the step boundaries, then at every corner. A blended spline is not
    checked by the planner's checker before it is timed: the re-check of the timed piece
    (the motion as executed, at the verifier's resolution, under the same margins) is
    what lets it out, and a blend that is not free fails there and gives way to the next
    one as it would have failed the planner's check. ``known``:
    the smallest clearance of the route so far [m] (see ``FclVerifier.verify``); a
    piece's result says inf unless it comes closer. A piece the release check refused is
    refused again without a second check when a later try times to the same piece (a
    smaller blend cut down to the same corners: ``timed`` hands back the same timing)."""
    verify = _Checks(world, cache, labels).verify
    if len(segments) > 1 or len(segments[0].waypoints) > 2:
        for blend in options.timing.blend_radii:
            try:
                piece, seg_steps = time_segments(cell, segments, world, options, cache,
                                                  blend=blend, check=False, timed=timed)
                return [verify(piece, seg_steps, segments, known)]
            except VerificationError as exc:
                log.debug("blend %.3f rad failed the re-check: %s", blend, exc)
            except TimingError as exc:  # e.g. a blend cut down to millimetres: too tight
                log.debug("blend %.3f rad could not be timed: %s", blend, exc)
    out = []
    for seg in segments:
        try:
            piece, seg_steps = time_segments(cell, [seg], world, options, cache, blend=0.0,
                                              timed=timed)
            out.append(verify(piece, seg_steps, [seg], known))
            known = min(known, out[-1][2].min_clearance)
            continue
        except (_NotFree, VerificationError) as exc:
            if seg.step.kind == "line":
                if isinstance(exc, VerificationError):
                    raise
                raise PlanningError("the smoothed line is not collision-free",
                                    step=seg.step.label(seg.step_index)) from None
        # Stop at every corner: each straight segment was checked by the planner.
        for a, b in zip(seg.waypoints[:-1], seg.waypoints[1:], strict=True):
            part = Segment(seg.step_index, seg.step, [a, b], seg.allowed)
            piece, seg_steps = time_segments(cell, [part], world, options, cache, check=False,
                                              timed=timed)
            out.append(verify(piece, seg_steps, [part], known))
            known = min(known, out[-1][2].min_clearance)
    return out


class _Checks:
    """The release checks of one chunk's pieces (:func:`verify_piece` in one world), and
    the pieces they refused with what each was asked (the steps of its knots, their
    allowed contacts, the clearance known): the same piece asked the same is refused as
    before (the check is deterministic), without checking it again. Nothing is kept
    after the chunk, and a piece that passes is never answered from here: every
    released piece was checked."""

    def __init__(self, world: WorldState, cache: CheckerCache, labels: list[str]) -> None:
        self._world, self._cache, self._labels = world, cache, labels
        self._refused: list[tuple[TimedPiece, tuple[object, ...], VerificationError]] = []

    def verify(self, piece: TimedPiece, seg_steps: list[int], segments: list[Segment],
               known: float) -> tuple[TimedPiece, list[int], VerifyResult]:
        """:func:`verify_piece` of ``piece``, or the refusal of the same piece asked the
        same before."""
        asked = (tuple(seg_steps), tuple((s.step_index, s.allowed) for s in segments), known)
        for before, what, refusal in self._refused:
            if before is piece and what == asked:
                raise refusal
        try:
            return verify_piece(piece, seg_steps, segments, self._world, self._cache,
                                self._labels, known)
        except VerificationError as exc:
            self._refused.append((piece, asked, exc))
            raise


def verify_piece(piece: TimedPiece, seg_steps: list[int], segments: list[Segment],
                 world: WorldState, cache: CheckerCache, labels: list[str],
                 known: float = float("inf")) -> tuple[TimedPiece, list[int], VerifyResult]:
    """Re-check a timed piece with the independent verifier, each step under its own
    allowed contacts, in one check (its clearance measured only below ``known`` [m]);
    raise VerificationError on failure."""
    index = np.asarray(seg_steps)[piece.segment]
    steps_of_knots = index.tolist()
    # Consecutive steps with the same allowed contacts are one stage (the same samples
    # and judgement); the stages are checked as one, each from the knot before its
    # first step's first knot (where the stage before ends).
    stages: list[tuple[AllowedContact, ...]] = []
    starts: list[int] = []
    last = -2
    for sidx in sorted(set(steps_of_knots)):
        allowed = next(s for s in segments if s.step_index == sidx).allowed
        if not stages or stages[-1] != allowed or last + 1 != sidx:
            stages.append(allowed)
            starts.append(max(int(np.argmax(index == sidx)) - 1, 0))
        last = sidx
    names = np.asarray(labels, dtype=object)[index].tolist()
    result = cache.stages(world, stages).verify(piece.t, piece.q, starts, steps=names,
                                                known=known)
    return piece, steps_of_knots, result


class _NotFree(Exception):
    pass


#: A waypoint within this [rad] of the one before it, in every joint, repeats it.
_REPEAT = 1e-10


def apart(last: np.ndarray | None, pts: Sequence[np.ndarray]) -> bool:
    """Whether no point of ``pts`` repeats the one before it (``_REPEAT``), ``last``
    before the first (None: nothing before)."""
    P = np.asarray(pts, dtype=float)  # noqa: N806
    if last is not None and np.max(np.abs(P[0] - last)) < _REPEAT:
        return False
    return bool(np.all(np.abs(np.diff(P, axis=0)).max(axis=1) >= _REPEAT))


def time_segments(cell: Cell, segments: list[Segment], world: WorldState,
                   options: PlanOptions, cache: CheckerCache, *, check: bool = True,
                   blend: float = 0.0, timed: TimedPieces | None = None
                   ) -> tuple[TimedPiece, list[int]]:
    """Time the segments as one piece, blended at their via poses (and a planned
    detour's vertices) by ``blend`` [rad]; the spline checked for collisions first
    (``check``, raising _NotFree: the unblended fallbacks, so that a line whose spline
    is not free is named as such), its timing taken from ``timed`` where it was timed
    before. Returns the piece and the step index of each polyline segment."""
    waypoints, corners, seg_of_poly = _polyline(segments, blend)
    seg_steps = [segments[n].step_index for n in seg_of_poly]
    scales = [segments[n].step.speed for n in seg_of_poly]
    tcp = [segments[n].step.tcp_speed for n in seg_of_poly]
    if len(waypoints) < 2:
        q = waypoints[0] if waypoints else segments[0].waypoints[0]
        z = np.zeros((1, q.size))
        return TimedPiece(np.zeros(1), q[None, :], z, z, np.zeros(1), np.zeros(1, dtype=int)), \
            [segments[0].step_index]
    key = TimedPieces.key(waypoints, corners, scales, tcp, options.timing)
    piece = timed.get(key) if timed is not None else None
    checked = check and len(waypoints) > 2
    if piece is not None and not checked:
        return piece, seg_steps
    spacing, blend_kind = options.timing.spacing, options.timing.corner_blend
    path, s_way, _ = _repeats.spline(
        cell.robot, waypoints, (spacing, tuple(corners), blend_kind),
        lambda: spline_path(waypoints, spacing, corners=corners, blend=blend_kind))
    if checked:
        _check_spline(cell, path, s_way, seg_of_poly, segments, world, options, cache)
    if piece is None:
        piece = time_path(cell.robot, path, s_way, scales=scales, tcp_speeds=tcp,
                          options=options.timing,
                          step=segments[0].step.label(segments[0].step_index))
        if timed is not None:
            timed.put(key, piece)
    return piece, seg_steps


def _polyline(segments: list[Segment], blend: float
              ) -> tuple[list[np.ndarray], list[tuple[int, float]], list[int]]:
    """The segments' waypoints as one polyline (repeated points left out), its corners to
    blend (waypoint index, radius [rad]), and the segment of each of its pieces."""
    waypoints: list[np.ndarray] = []
    corners: list[tuple[int, float]] = []
    lengths: list[float] = [
        float(np.sum(np.linalg.norm(np.diff(np.asarray(s.waypoints), axis=0), axis=1)))
        for s in segments] if blend > 0 else []  # (only the corners use them)
    seg_of_poly: list[int] = []
    for n, seg in enumerate(segments):
        if waypoints and n > 0 and blend > 0:
            # A via pose between two steps: blend, within 40 % of either step.
            corners.append((len(waypoints) - 1, float(min(blend, 0.4 * lengths[n - 1],
                                                          0.4 * lengths[n]))))
        pts = seg.waypoints if not waypoints else seg.waypoints[1:]
        detour = seg.step.kind == "move" and blend > 0
        if not detour and len(pts) > 1 and apart(waypoints[-1] if waypoints else None, pts):
            # No point repeats the one before it (the common case: every point is kept).
            seg_of_poly.extend([n] * (len(pts) if waypoints else len(pts) - 1))
            waypoints.extend(pts)
            continue
        for j, p in enumerate(pts):
            if waypoints and np.max(np.abs(p - waypoints[-1])) < _REPEAT:
                continue
            if waypoints:
                seg_of_poly.append(n)
            waypoints.append(p)
            if detour and 0 < j < len(pts) - 1:  # a vertex of a planned detour
                a = float(np.linalg.norm(p - pts[j - 1]))
                b = float(np.linalg.norm(pts[j + 1] - p))
                corners.append((len(waypoints) - 1, min(blend, 0.4 * a, 0.4 * b)))
    return waypoints, corners, seg_of_poly


def _check_spline(cell: Cell, path: object, s_way: np.ndarray, seg_of_poly: Sequence[int],
                  segments: list[Segment], world: WorldState, options: PlanOptions,
                  cache: CheckerCache) -> None:
    """Raise _NotFree unless the spline is valid at the checker's resolution."""
    length = float(s_way[-1])
    n = max(2, int(np.ceil(length / 0.02)) + 1)
    s = np.linspace(0.0, length, n)
    Q = path(s)  # type: ignore[operator]
    step_of = np.asarray(seg_of_poly)[interval_index(s_way, s, len(seg_of_poly))]
    # Consecutive chords of the same step share a checker: check them as one polyline.
    starts = [0, *(np.flatnonzero(step_of[1:] != step_of[:-1]) + 1).tolist(), n]
    for start, k in zip(starts[:-1], starts[1:], strict=True):
        checker = cache.checker(world, segments[int(step_of[start])].allowed)
        chords = Q[start:min(k + 1, n)]
        if not _repeats.spline_free(checker, chords, _path_check(checker, chords)):
            raise _NotFree()
    # The chords between samples are checked; the spline between two samples deviates
    # from its chord by far less than the verifier's resolution, which re-checks the
    # timed result anyway.


def _path_check(checker: CollisionChecker, chords: np.ndarray) -> Callable[[], bool]:
    """Whether ``checker`` finds the polyline ``chords`` free, when called."""
    rows = cast("Sequence[np.ndarray]", chords)  # check_path takes the array as it is
    return lambda: checker.check_path(rows, details=False).valid


def assemble(cell: Cell, route: Route, labels: list[str],
              pieces: list[tuple[TimedPiece, list[int]]], chunk_ends: list[float],
              actions: list) -> Trajectory:
    """Join the timed pieces into one trajectory; a gripper action happens when the
    chunk before it ends (``chunk_ends`` [s]), or at t = 0."""
    t_all: list[np.ndarray] = []
    q_all, qd_all, qdd_all, idx_all = [], [], [], []
    offset = 0.0
    for piece, steps_of_knots in pieces:
        start = 0 if not t_all else 1  # the first knot repeats the previous rest state
        t_all.append(piece.t[start:] + offset)
        q_all.append(piece.q[start:])
        qd_all.append(piece.qd[start:])
        qdd_all.append(piece.qdd[start:])
        idx_all.append(np.asarray(steps_of_knots[start:]))
        offset += float(piece.t[-1])
    t = np.concatenate(t_all)
    events = []
    for after_chunk, i, step in actions:
        when = 0.0 if after_chunk == 0 else chunk_ends[after_chunk - 1]
        obj = step.object or (cell.scene.grasp.object if cell.scene.grasp else None)
        events.append(GripperEvent(when, step.kind, labels[i], obj))  # type: ignore[arg-type]
    return Trajectory(cell.robot.joint_names, t, np.vstack(q_all), np.vstack(qd_all),
                      np.vstack(qdd_all), np.concatenate(idx_all), tuple(labels), tuple(events),
                      cell.robot.name, route.name, limits=cell.robot.motion_limits,
                      interpolation=cell.robot.controller.interpolation)
