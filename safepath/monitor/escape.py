"""Where a re-plan starts: clear of the box it goes around.

The planner refuses a start within the margin of an obstacle, and a robot stopped by a
body that then came close (or parked beside it) rests within ``C + Z_d + margin`` of the
body's points. Two steps make the start clear, in this order:

1. **Cut the box** (:func:`start_box`): the sides of the box facing the robot at rest
   are cut back, each as little as needed (bisection to 0.1 mm on the robot's collision
   geometry), never inside the body's own box (the measured elements' extent), until the
   robot there is ``margin`` + :data:`START_SLACK` clear. One side is tried at a time (the
   smallest cut that suffices); when no single side suffices, the side that helps most
   (by 1 mm at least) goes to the body's box and the others are tried again.
2. **A first stretch away** (:func:`escape_state`): when even the body's own box is
   closer than that, the robot first moves away from it: from the rest state, small joint
   steps (:data:`ESCAPE_STEP`, :data:`_SAME_GRADIENT` of them along each gradient) up the
   gradient of its distance to the box, until it is ``margin`` + :data:`START_SLACK`
   clear. The re-plan plans that stretch with the
   margin it has at rest (less :data:`START_SLACK`), the rest of the way from its end
   with the full margin.

A cut is for the start only. A monitor stops a robot that comes closer to a body at rest
than ``C + Z_d + Z_r`` unless it comes no closer than it is, so a route that leaves the
body and later comes back within the cut-away part of the box is stopped there. When the
box was cut (by the monitor or by :func:`start_box`), the first stretch away therefore
goes on (up the gradient of the distance to the cut box) until the robot is ``margin`` +
:data:`START_SLACK` clear of the *whole* box (the body's box inflated by the request's
``inflation`` on every side), and the rest of the route keeps the margin from that
(:func:`safepath.monitor.replan.replan`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from ..cell import Cell
from ..collision import CollisionChecker
from ..model.scene import SceneObject, Shape

__all__ = ["StartBox", "start_box", "escape_state", "box_clearance", "START_SLACK",
           "ESCAPE_STEP"]

#: The start is kept this much beyond the margin [m].
START_SLACK = 1e-3
#: Joint step of the first stretch away [rad] (a point of the arm moves at most its
#: distance from the joint axes times this).
ESCAPE_STEP = 0.004
#: Most steps of the first stretch away.
_ESCAPE_STEPS = 400
#: The walk gives up when the clearance it walks for has not grown by :data:`_GAIN` [m]
#: in :data:`_STALL` steps.
_GAIN, _STALL = 1e-3, 40
#: Steps taken along one gradient (its central differences are most of a step's work).
_SAME_GRADIENT = 4
#: Within this of the scene, a step of the first stretch away never goes toward it [m].
_NEAR = 0.02
_BOX = "replan_box"
#: A side is cut to the body's box when no single cut suffices only if that adds this
#: much to the clearance at rest [m].
_HELPS = 1e-3
_SIDES = ("-x", "-y", "-z", "+x", "+y", "+z")


@dataclass(frozen=True)
class StartBox:
    """The box to plan around, as :func:`start_box` cut it.

    Attributes:
        lo: Lower corner [m].
        hi: Upper corner [m].
        cut: What was cut, in words ("": nothing).
        clearance: The robot at rest from it [m] (below ``margin`` + START_SLACK: even
            the body's own box is closer; a first stretch away is needed).
    """

    lo: np.ndarray
    hi: np.ndarray
    cut: str
    clearance: float


def box_clearance(cell: Cell, lo: np.ndarray, hi: np.ndarray, *, held: str | None
                  ) -> CollisionChecker:
    """A checker of the robot (and ``held``) against the box (lo, hi) [m] alone: its
    :meth:`~safepath.collision.CollisionChecker.clearance` is the distance to the box."""
    T = np.eye(4)
    T[:3, 3] = (np.asarray(lo) + np.asarray(hi)) / 2
    box = SceneObject(_BOX, Shape("box", tuple(float(v) for v in np.asarray(hi) - lo)), T)
    movable = [o.name for o in cell.scene.objects.values() if o.movable]
    scene = replace(cell.scene, allowed_contacts=(), objects={
        _BOX: box, **{n: cell.scene.objects[n] for n in movable}})
    return CollisionChecker(cell.robot, scene, held=held,
                            resting={n: None for n in movable if n != held})


def start_box(cell: Cell, q: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              body: tuple[np.ndarray, np.ndarray] | None, *, held: str | None,
              margin: float) -> StartBox:
    """The box (lo, hi) [m] with its sides facing the robot at ``q`` cut back (see the
    module doc), never inside ``body`` (its lower and upper corner [m]; None: no side is
    cut)."""
    need = margin + START_SLACK
    faces = np.concatenate([lo, hi]).astype(float)

    def clear(f: np.ndarray) -> float:
        return box_clearance(cell, f[:3], f[3:], held=held).clearance(q)[0]

    now = clear(faces)
    if now >= need or body is None:
        return StartBox(faces[:3], faces[3:], "", now)
    target = np.concatenate(body)
    start = faces.copy()

    def with_face(side: int, value: float) -> float:
        f = faces.copy()
        f[side] = value
        return clear(f)

    for _ in range(6):
        full = {s: with_face(s, target[s]) for s in range(6) if faces[s] != target[s]}
        enough = [s for s, d in full.items() if d >= need]
        if enough:
            cuts = [(s, _least_cut(with_face, s, faces[s], target[s], need)) for s in enough]
            side, face = min(cuts, key=lambda c: abs(c[1] - faces[c[0]]))
            faces[side] = face
            break
        if not full or max(full.values()) <= now + _HELPS:
            break  # (a cut that hardly helps is not made: the start needs a stretch away)
        side = max(full, key=lambda s: full[s])
        faces[side], now = target[side], full[side]
    words = [f"{_SIDES[s]} side cut {1000 * abs(faces[s] - start[s]):.0f} mm "
             f"({1000 * abs(faces[s] - target[s]):.0f} mm beyond the body)"
             for s in range(6) if faces[s] != start[s]]
    cut = f"for a start {1000 * margin:.0f} mm clear: " + ", ".join(words) if words else ""
    return StartBox(faces[:3], faces[3:], cut, clear(faces))


def _least_cut(clearance_with: Callable[[int, float], float], side: int, face: float,
               body: float, need: float) -> float:
    """The face of ``side`` nearest to ``face`` (toward ``body``, where the clearance is
    enough) with a clearance of at least ``need`` [m], to 0.1 mm (bisection)."""
    bad, good = face, body
    while abs(good - bad) > 1e-4:
        mid = (bad + good) / 2
        if clearance_with(side, mid) >= need:
            good = mid
        else:
            bad = mid
    return good


def escape_state(cell: Cell, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
                 held: str | None, resting: Mapping[str, np.ndarray], margin: float,
                 until: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
    """The end of a first stretch away from the box (lo, hi) [m] from ``q`` [rad] (see the
    module doc): a state ``margin`` + START_SLACK clear of it (of the box ``until``, its
    lower and upper corner [m], when given: the walk goes up the gradient of the distance
    to (lo, hi) until that box is that clear), within the joint limits (a joint within a
    step of its limit stops going toward it); None when the walk finds none (a local
    maximum of the distance, no 1 mm of it gained in :data:`_STALL` steps, or
    :data:`_ESCAPE_STEPS` steps).

    Where the robot is within :data:`_NEAR` of the rest of the scene (the objects of
    ``cell``, the movable ones at ``resting``; a vial on its support, jaws around it),
    a step never goes toward it: the part of the step that would is taken out."""
    box = box_clearance(cell, lo, hi, held=held)
    goal = box if until is None else box_clearance(cell, *until, held=held)
    scene = CollisionChecker(cell.robot, cell.scene, held=held, resting=dict(resting))
    robot = cell.robot
    need = margin + START_SLACK
    q = np.asarray(q, dtype=float).copy()
    best, since = -np.inf, 0  # the goal's best clearance, and the steps since it grew
    step = np.zeros(q.size)
    for k in range(_ESCAPE_STEPS):
        if k % _SAME_GRADIENT == 0:  # (the walk's state is judged where it turns)
            now = goal.clearance(q)[0]
            if now >= need:
                return q
            best, since = (now, 0) if now >= best + _GAIN else (best, since + _SAME_GRADIENT)
            if since > _STALL:
                return None
            step = _gradient(box, q)
            if scene.clearance(q)[0] < _NEAR:
                away = _gradient(scene, q)
                toward = float(step @ away)
                if toward < 0.0 and float(away @ away) > 0.0:
                    step = step - toward / float(away @ away) * away
        # A joint within a step of its limit does not go on toward it.
        step[((q >= robot.upper - ESCAPE_STEP) & (step > 0.0))
             | ((q <= robot.lower + ESCAPE_STEP) & (step < 0.0))] = 0.0
        norm = float(np.linalg.norm(step))
        if norm < 1e-9:
            return None
        q = q + ESCAPE_STEP * step / norm
    return q if goal.clearance(q)[0] >= need else None


def _gradient(checker: CollisionChecker, q: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """Central differences of the checker's clearance at ``q`` [m/rad]."""
    grad = np.empty(q.size)
    for j in range(q.size):
        dq = np.zeros(q.size)
        dq[j] = h
        grad[j] = (checker.clearance(q + dq)[0] - checker.clearance(q - dq)[0]) / (2 * h)
    return grad
