"""A body parked in the robot's way: when it counts as at rest, the box a re-plan goes
around, and how it stays watched once the re-plan has taken it in.

* **The body** (:func:`blocking_body`): the observed elements linked to the blocking one
  (the closest to the path) by chains of elements at most ``link`` apart; its box is
  their extent (each element's radius included).
* **The rest rule** (:class:`RestHistory`): the body's box and centroid are recorded at
  every new observation while the robot is stopped by it. It is *at rest* when, over the
  observations of the last ``window`` seconds (the history covering the whole window,
  at least :data:`MIN_SAMPLES` of them), the least-squares velocity of its centroid
  (norm) and of each side of its box are at most ``speed`` [m/s], and every side of the
  latest box and of at least :data:`REST_SHARE` of the window's boxes lies within
  :data:`REPLAN_MOVED` of the window's median (a step at the end of the window, or a
  body moving to and fro, is not averaged away).
* **The box** (:func:`shrink_box`): the body's box inflated by ``C + Z_d``; each side
  whose inflation reaches into the robot's enclosing spheres at its rest state is cut
  back to the spheres (the face touches them), never inside the body's own box.
* **The watch** (:class:`ParkedBody`): once re-planned around, the body's elements (those
  within :data:`REPLAN_MOVED` of its box as measured at rest, the *zone*) are left out of
  the separation test, and every observation checks that it stays: it has *moved* when
  no element is in the zone any more, or an element outside the zone lies in the
  absorbed box or within ``link`` of an element of the zone (the body grew, shifted or
  something joined it). A body that moved is dropped: it is an obstacle like any other
  again, and the separation rule stops or slows the robot.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["REPLAN_MOVED", "MIN_SAMPLES", "REST_SHARE", "Rest", "RestHistory", "ParkedBody",
           "blocking_body", "extent", "shrink_box"]

#: A body (or a box) has moved once a side of its box moved more than this [m] (beyond
#: the jitter of noisy points on the box's edges).
REPLAN_MOVED = 0.03
#: The rest rule needs at least this many observations in its window.
MIN_SAMPLES = 3
#: Share of the window's boxes that must lie within REPLAN_MOVED of its median.
REST_SHARE = 0.8

_SIDES = ("-x", "-y", "-z", "+x", "+y", "+z")


def extent(elements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box (lo, hi) [m] holding ``elements`` (n >= 1, 4: x, y, z, radius)."""
    return ((elements[:, :3] - elements[:, 3:]).min(axis=0),
            (elements[:, :3] + elements[:, 3:]).max(axis=0))


def blocking_body(elements: np.ndarray, closest: np.ndarray, link: float) -> np.ndarray:
    """The elements linked to the one nearest ``closest`` (x, y, z, ...) [m]: elements
    share a body when their grid cells (edge ``link / 2`` plus the largest element
    radius [m]) touch, face, edge or corner, directly or through a chain of such cells
    (elements closer than half ``link`` always share one; farther than about 1.7 ``link``
    never directly)."""
    if len(elements) == 0:
        return np.asarray(closest, dtype=float)[None, :4].copy()
    points = elements[:, :3]
    seed = int(np.argmin(np.linalg.norm(points - np.asarray(closest)[:3], axis=1)))
    edge = link / 2 + float(elements[:, 3].max())
    return elements[_cells_linked(points, edge, seed)]


#: The offsets of a grid cell's 26 neighbours (face, edge and corner) and of itself.
_NEIGHBOURS = np.stack(np.meshgrid(*([np.arange(-1, 2)] * 3), indexing="ij"),
                       axis=-1).reshape(-1, 3)
#: Largest cell key (:func:`_cells_linked`) computed directly from the cells' coordinates.
_KEY_RANGE = 1 << 62
#: The cells' neighbours are looked up in a table of every key of their box where it has
#: at most this many keys per element (else by bisection among the occupied keys).
_TABLE = 64


def _cells_linked(points: np.ndarray, edge: float, seed: int) -> np.ndarray:
    """Indices of ``points`` (increasing) whose grid cells (edge [m]) are linked to the
    seed's by chains of touching cells (face, edge or corner).

    A stop decision records the body that blocks the robot (:func:`blocking_body`)
    before the stop leaves the monitor, so the search is compiled
    (``_kernels.linked_cells``): every cell gets one integer key, in a box one cell wider
    than the occupied one on every side, so that a neighbour's key is the cell's plus a
    fixed step (looked up in a table of the box's keys where the box is small). Where
    that box's keys would not fit an int64, each axis's coordinates are first packed (a
    gap of more than one cell shrinks to one empty cell: which cells touch is
    unchanged)."""
    from ._kernels import linked_cells

    cells = np.floor(points / edge).astype(np.int64)
    size = cells.max(axis=0) - cells.min(axis=0) + 3
    if float(np.prod(size.astype(float))) >= _KEY_RANGE:
        cells = np.column_stack([_packed(cells[:, k]) for k in range(3)])
        size = cells.max(axis=0) - cells.min(axis=0) + 3
    stride = np.array([size[1] * size[2], size[2], 1], dtype=np.int64)
    key = (cells - (cells.min(axis=0) - 1)) @ stride
    span = int(np.prod(size))
    linked = np.empty(len(points), dtype=bool)
    linked_cells(key, _NEIGHBOURS @ stride, int(seed), span if span <= _TABLE * len(points)
                 else 0, linked)
    return np.flatnonzero(linked)


def _packed(coordinate: np.ndarray) -> np.ndarray:
    """Integer coordinates with every gap of more than one between neighbouring values
    shrunk to two (the same values differ by at most one as before)."""
    values, at = np.unique(coordinate, return_inverse=True)
    packed = np.concatenate([[0], np.cumsum(np.minimum(np.diff(values), 2))])
    return packed[at.reshape(-1)]


@dataclass(frozen=True)
class Rest:
    """What the rest rule found.

    Attributes:
        at_rest: Whether the body counts as at rest.
        speed: Its measured speed [m/s] (largest of the centroid's and the box sides'
            least-squares velocities over the window; inf: not measured).
        jump: How far the latest box's sides lie from the window's median [m].
        share: Share of the window's boxes whose sides all lie within
            :data:`REPLAN_MOVED` of the median.
        seen: How long the history covers [s].
        why: Why not, in words ("" when at rest).
        lo: Box of the body over the window [m]: the union of its boxes (at rest, of
            those within :data:`REPLAN_MOVED` of their median).
        hi: Its upper corner [m].
    """

    at_rest: bool
    speed: float
    jump: float
    share: float
    seen: float
    why: str
    lo: np.ndarray
    hi: np.ndarray


class RestHistory:
    """The blocking body's box and centroid at each new observation (see the module doc).

    Args:
        window: How long the body must be seen at rest [s].
        speed: Largest velocity of a body at rest [m/s].
    """

    def __init__(self, window: float, speed: float) -> None:
        self.window = window
        self.speed = speed
        self._samples: deque[tuple[float, np.ndarray]] = deque()

    def clear(self) -> None:
        """Forget the history (the robot is no longer stopped by the body)."""
        self._samples.clear()

    def add(self, stamp: float, body: np.ndarray) -> None:
        """Record the body's elements (n >= 1, 4) [m] observed at ``stamp`` [s]; a stamp
        not newer than the last one is ignored (a tick without a new observation)."""
        if self._samples and stamp <= self._samples[-1][0]:
            return
        lo, hi = extent(body)
        self._samples.append((stamp, np.concatenate([lo, hi, body[:, :3].mean(axis=0)])))
        while self._samples[0][0] < stamp - 2.0 * self.window:
            self._samples.popleft()

    def judge(self) -> Rest:
        """Whether the body is at rest now (the rule in the module doc)."""
        if not self._samples:
            nothing = np.full(3, np.nan)
            return Rest(False, float("inf"), 0.0, 0.0, 0.0, "no body observed", nothing,
                        nothing)
        last = self._samples[-1][0]
        seen = last - self._samples[0][0]
        used = [(t, y) for t, y in self._samples if t >= last - self.window - 1e-9]
        Y = np.array([y for _, y in used])  # noqa: N806
        lo, hi = Y[:, :3].min(axis=0), Y[:, 3:6].max(axis=0)
        if seen < self.window - 1e-9 or len(used) < MIN_SAMPLES:
            return Rest(False, float("inf"), 0.0, 0.0, seen, f"seen for {seen:.2f} s of the "
                        f"{self.window:g} s at rest the re-plan needs", lo, hi)
        t = np.array([t for t, _ in used])
        t = t - t.mean()
        slope = t @ (Y - Y.mean(axis=0)) / float(t @ t)
        speed = max(float(np.linalg.norm(slope[6:])), float(np.abs(slope[:6]).max()))
        off = np.abs(Y[:, :6] - np.median(Y[:, :6], axis=0)).max(axis=1)
        jump, share = float(off[-1]), float(np.mean(off <= REPLAN_MOVED))
        if speed > self.speed:
            why = (f"the body moves ({speed:.3f} m/s > {self.speed:g} m/s over the last "
                   f"{self.window:g} s)")
        elif jump > REPLAN_MOVED or share < REST_SHARE:
            latest = "among them" if jump > REPLAN_MOVED else "not"
            why = (f"the body moves: {100 * (1 - share):.0f} % of its boxes over the last "
                   f"{self.window:g} s (the latest {latest}) lie more than "
                   f"{1000 * REPLAN_MOVED:.0f} mm from their median")
        else:  # at rest: its box is the union of the boxes near the median
            why = ""
            near = Y[off <= REPLAN_MOVED]
            lo, hi = near[:, :3].min(axis=0), near[:, 3:6].max(axis=0)
        return Rest(not why, speed, jump, share, seen, why, lo, hi)


def shrink_box(lo: np.ndarray, hi: np.ndarray, body_lo: np.ndarray, body_hi: np.ndarray,
               centers: np.ndarray, radii: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, str]:
    """The box (lo, hi) [m] cut back where it reaches into the spheres (centres (K, 3),
    radii (K,)) [m]: for each sphere it meets, deepest first, the one side whose cut
    (to the sphere's surface) is the smallest, never inside the body's box (body_lo,
    body_hi).

    Returns:
        The new corners, and what was cut, in words ("" when nothing was).
    """
    lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
    lo0, hi0 = lo.copy(), hi.copy()

    def gap(c: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.maximum(np.maximum(lo - c, c - hi), 0.0), axis=-1)

    depth = radii - gap(centers)
    unresolved = 0
    for k in np.argsort(-depth):
        if depth[k] <= 0:
            break
        c, r = centers[k], float(radii[k])
        if gap(c) >= r:
            continue
        best = _best_cut(c, r, lo, hi, body_lo, body_hi)
        if best is None:
            unresolved += 1
            continue
        side, face = best
        if side >= 3:
            hi[side - 3] = face
        else:
            lo[side] = face
    words = _cuts_in_words(lo0, hi0, lo, hi, body_lo, body_hi)
    if unresolved:
        words.append(f"{unresolved} of the arm's spheres reach into the body's own box: "
                     "no side can be cut without cutting the body")
    return lo, hi, "; ".join(words)


def _best_cut(c: np.ndarray, r: float, lo: np.ndarray, hi: np.ndarray, body_lo: np.ndarray,
              body_hi: np.ndarray) -> tuple[int, float] | None:
    """The side (0-2: -x, -y, -z; 3-5: +x, +y, +z) and new face [m] of the smallest cut
    that puts the sphere (centre ``c``, radius ``r``) outside the box, never inside the
    body's box; None when no side can."""
    best: tuple[float, int, float] | None = None  # (cut, side, new face)
    for i in range(3):
        face = c[i] - r  # below the sphere: the +i side comes down to it
        if body_hi[i] <= face < hi[i] and (best is None or hi[i] - face < best[0]):
            best = (hi[i] - face, 3 + i, face)
        face = c[i] + r  # above it: the -i side goes up to it
        if lo[i] < face <= body_lo[i] and (best is None or face - lo[i] < best[0]):
            best = (face - lo[i], i, face)
    return None if best is None else (best[1], best[2])


def _cuts_in_words(lo0: np.ndarray, hi0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                   body_lo: np.ndarray, body_hi: np.ndarray) -> list[str]:
    words = []
    for s, name in enumerate(_SIDES):
        i = s % 3
        cut = (lo[i] - lo0[i]) if s < 3 else (hi0[i] - hi[i])
        if cut > 0:
            beyond = (body_lo[i] - lo[i]) if s < 3 else (hi[i] - body_hi[i])
            words.append(f"{name} side cut {1000 * cut:.0f} mm to the arm's spheres "
                         f"({1000 * beyond:.0f} mm beyond the body)")
    return words


@dataclass(eq=False)  # one body is itself only (its fields are arrays)
class ParkedBody:
    """A body re-planned around: its absorbed box and its box as measured at rest.

    Attributes:
        box_lo: Absorbed box, lower corner [m].
        box_hi: Upper corner [m].
        body_lo: The body's box at rest, lower corner [m] (its zone reaches
            :data:`REPLAN_MOVED` beyond); None: an empty box (any element in it has
            moved in).
        body_hi: Upper corner [m]; None with ``body_lo``.
        link: Elements this close to the zone's belong to the body [m].
    """

    box_lo: np.ndarray
    box_hi: np.ndarray
    body_lo: np.ndarray | None
    body_hi: np.ndarray | None
    link: float

    def watch(self, elements: np.ndarray) -> tuple[np.ndarray, str]:
        """Which of ``elements`` (n, 4) [m] are the body (a mask), and how it moved ("":
        it stays; see the module doc)."""
        P, r = elements[:, :3], elements[:, 3:]  # noqa: N806
        box = np.all((P + r >= self.box_lo) & (P - r <= self.box_hi), axis=1)
        if self.body_lo is None or self.body_hi is None:
            moved = f"{int(box.sum())} element(s) entered its box" if box.any() else ""
            return np.zeros(len(P), dtype=bool), moved
        zlo, zhi = self.body_lo - REPLAN_MOVED, self.body_hi + REPLAN_MOVED
        in_zone = np.all((P >= zlo + r) & (P <= zhi - r), axis=1)
        if not in_zone.any():
            return in_zone, "no element left where the body was"
        outside = ~in_zone
        in_box = outside & box
        if in_box.any():
            return in_zone, (f"{int(in_box.sum())} element(s) in its box beyond "
                             f"{1000 * REPLAN_MOVED:.0f} mm of the body")
        reach = self.link + 2.0 * float(elements[:, 3].max())
        near = outside & np.all((P >= zlo - reach) & (P <= zhi + reach), axis=1)
        if near.any():
            from scipy.spatial import cKDTree

            d, _ = cKDTree(P[in_zone]).query(P[near], distance_upper_bound=reach)
            linked = int(np.isfinite(d).sum())
            if linked:
                return in_zone, (f"{linked} element(s) beyond {1000 * REPLAN_MOVED:.0f} mm "
                                 f"of its box at rest, linked to it")
        return in_zone, ""
