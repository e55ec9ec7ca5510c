"""Which pairs a collision checker checks, and with which margin.

A world state's *candidates* are every pair of shapes that can ever touch: each mover (a
robot shape, the held object) against the movers after it and against the environment,
without the pairs never checked (shapes on one joint, a robot's allowed self pairs, the
held object against the jaws that hold it). The allowed contacts of a step then drop
the candidates allowed to touch at any depth and give the others the depth they may
touch by. Pure functions of explicit inputs: the checker calls them when it is built.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Sequence

import numpy as np

from ..model.scene import GRIPPER, AllowedContact
from .reports import Pair

__all__ = ["candidate_pairs", "allowed_depths", "allowed_rows"]


def candidate_pairs(*, names: Sequence[str], joints: Sequence[int], movers: Sequence[int],
                    held: int | None, environment: Sequence[int],
                    contact_links: Collection[str], self_pairs: Collection[tuple[str, ...]],
                    margin_of: Callable[[str], float]
                    ) -> tuple[np.ndarray, dict[Pair, list[int]], np.ndarray]:
    """The pairs to check where no contact is allowed.

    Args:
        names: The link or object name of every geometry.
        joints: The joint that carries every geometry (0: the world).
        movers: The geometries that move (robot shapes, then the held object).
        held: The held object's geometry, or None.
        environment: The environment's geometries.
        contact_links: The tool's links that hold the held object.
        self_pairs: The robot's allowed self pairs (sorted names).
        margin_of: The safety margin [m] of an object or link by name.

    Returns:
        (geometry a, geometry b) rows; the rows of each pair of names (sorted); and each
        pair's safety margin [m] (that of its environment object, else of its first
        body). In the order: for each mover, the movers after it, then the environment.
    """
    rows_of: dict[Pair, list[int]] = {}
    pairs: list[tuple[int, int]] = []
    margins: list[float] = []

    def add(key: Pair, a: int, b: int, margin: float) -> None:
        rows_of.setdefault(key, []).append(len(pairs))
        pairs.append((a, b))
        margins.append(margin)

    for ia, a in enumerate(movers):
        na = names[a]
        for b in movers[ia + 1:]:
            nb = names[b]
            if na == nb or joints[a] == joints[b]:
                continue
            key = (na, nb) if na < nb else (nb, na)
            if b == held:
                if na in contact_links:
                    continue  # the jaws hold it
            elif key in self_pairs:
                continue
            add(key, a, b, margin_of(na))
        if joints[a] == 0:
            continue  # both fixed to the world
        for e in environment:
            ne = names[e]
            add((na, ne) if na <= ne else (ne, na), a, e, margin_of(ne))
    return (np.array(pairs, dtype=np.int64).reshape(-1, 2), rows_of,
            np.array(margins, dtype=float))


def allowed_depths(allowed: Iterable[AllowedContact], contact_links: Collection[str]
                   ) -> dict[Pair, float | None]:
    """The depth [m] each pair of names is allowed to touch by (None: any depth), the
    gripper standing for the tool's contact links; the deepest where contacts repeat."""
    out: dict[Pair, float | None] = {}
    for contact in allowed:
        sides = [sorted(contact_links) if n == GRIPPER else [n] for n in contact.between]
        for a in sides[0]:
            for b in sides[1]:
                key = (a, b) if a <= b else (b, a)
                prev = out.get(key, 0.0)
                if prev is None or contact.max_depth is None:
                    out[key] = None
                else:
                    out[key] = max(prev, contact.max_depth)
    return out


def allowed_rows(n: int, rows_of: dict[Pair, list[int]], depths: dict[Pair, float | None]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The candidates to check, as rows of the ``n`` candidates (``rows_of``: the rows
    of each pair of names), and the depth [m] each is allowed to touch by: the
    candidates without those allowed to touch at any depth."""
    keep = np.ones(n, dtype=bool)
    depth = np.zeros(n)
    for key, d in depths.items():
        at = rows_of.get(key)
        if at is None:
            continue  # never checked
        if d is None:
            keep[at] = False
        else:
            depth[at] = d
    rows = np.flatnonzero(keep)
    return rows, depth[rows]
