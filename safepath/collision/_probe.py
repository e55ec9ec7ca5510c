"""Named views of the sphere layer's buffers, and one pair of placed shapes laid out in them.

The checker's packer (:mod:`safepath.collision._pack`) lays out a whole robot and cell;
:func:`pair_buffers` lays out only what :func:`safepath.collision._gjk.distance_lower_bound`
and ``distance_upper_bound`` read of a pair (its hulls' vertex and edge tables, the two
placed shapes, fresh hints), and :func:`pair_tables` reads a packed checker's pair tables,
so that callers (the tests) name shapes and tables, never buffer offsets.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ._gjk import hull_tables
from ._layout import (
    H_AI,
    H_AP,
    H_DOF,
    H_LAST,
    H_NG,
    H_NP,
    H_PI,
    H_PM,
    H_PW,
    H_V,
    H_W,
    HEADER,
    PIW,
    W_A,
    W_B,
    W_D,
    W_FIXED,
    W_P,
    W_R,
    WI_A,
    WI_B,
    WI_HEADER,
    WI_HINT,
    WI_WARM,
    WS_HULL,
    WS_HULL_END,
    WS_KIND,
)

__all__ = ["Placed", "PairTables", "hull_block", "last_collision", "pair_buffers",
           "pair_tables"]


class Placed(NamedTuple):
    """A shape placed in the world.

    Attributes:
        kind: Its kernel code (the shape table's, or ``_layout.HULL``).
        R: Its world rotation (3, 3).
        p: Its world position (3,) [m].
        dims: Its kernel parameters (3,) [m] (zeros for a hull).
        hull: Its convex hull's points (k, 3) in its own frame [m], or None.
    """

    kind: int
    R: np.ndarray
    p: np.ndarray
    dims: np.ndarray
    hull: np.ndarray | None = None


def hull_block(hulls: Sequence[np.ndarray]
               ) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """The hulls' vertex block (``fb``), the int header and edge tables (``ib``), and each
    hull's vertex rows, from each hull's points (k, 3) [m]."""
    verts, ptrs, idxs, rows = [], [np.zeros(1, dtype=np.int64)], [], []
    nv = ne = 0
    for points in hulls:
        v, ptr, idx = hull_tables(np.asarray(points, dtype=float))
        verts.append(v)
        ptrs.append(ptr[1:] + ne)
        idxs.append(idx + nv)
        rows.append((nv, nv + len(v)))
        nv, ne = nv + len(v), ne + len(idx)
    header = np.zeros(HEADER, dtype=np.int64)
    header[H_V], header[H_AP], header[H_AI] = 0, HEADER, HEADER + nv + 1
    fb = np.concatenate([np.zeros(0), *(v.ravel() for v in verts)])
    return fb, np.concatenate([header, *ptrs, *idxs]), rows


def pair_buffers(a: Placed, b: Placed) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The buffers (``fb``, ``ib``) and scratch (``wf``, ``wi``) of one pair a, b: GJK's
    searches on it read pair 0, with no direction from an earlier search and no hints."""
    hulls = [s.hull for s in (a, b) if s.hull is not None]
    fb, ib, rows = hull_block(hulls)
    wf = np.zeros(W_FIXED + 3)  # the fixed slots, then the pair's last direction
    wi = np.zeros(WI_HEADER + 2, dtype=np.int64)  # the header, then the pair's hints
    found = iter(rows)
    for shape, s, si in ((a, W_A, WI_A), (b, W_B, WI_B)):
        v0, v1 = next(found) if shape.hull is not None else (0, 0)
        wf[s + W_R:s + W_R + 9] = np.asarray(shape.R, dtype=float).ravel()
        wf[s + W_P:s + W_P + 3], wf[s + W_D:s + W_D + 3] = shape.p, shape.dims
        wi[si + WS_KIND], wi[si + WS_HULL], wi[si + WS_HULL_END] = shape.kind, v0, v1
    wi[WI_WARM], wi[WI_HINT], wi[WI_HEADER:] = W_FIXED, WI_HEADER, -1
    return fb, ib, wf, wi


class PairTables(NamedTuple):
    """A packed checker's pair tables (views of its buffers).

    Attributes:
        mover_weights: Per mover and joint, how far a unit joint step moves it (ng, dof)
            [m per unit of the joint].
        pairs: Per pair: mover a, body b, 1 if b is an environment object, 1 if a collision
            can be proven (npairs, 4).
        masks: Per pair and joint: bit 1 if the joint moves a relative to b, bit 2 if it
            moves b relative to a (npairs, dof).
        weights: Per pair and joint, how fast the joint can close the pair (npairs, dof)
            [m per unit of the joint].
    """

    mover_weights: np.ndarray
    pairs: np.ndarray
    masks: np.ndarray
    weights: np.ndarray


def pair_tables(fb: np.ndarray, ib: np.ndarray) -> PairTables:
    """The pair tables of a checker's buffers (``fb``, ``ib``: its layer's ``F``, ``I``)."""
    n, dof, ng = int(ib[H_NP]), int(ib[H_DOF]), int(ib[H_NG])
    return PairTables(fb[ib[H_W]:ib[H_W] + ng * dof].reshape(ng, dof),
                      ib[ib[H_PI]:ib[H_PI] + PIW * n].reshape(n, PIW),
                      ib[ib[H_PM]:ib[H_PM] + n * dof].reshape(n, dof),
                      fb[ib[H_PW]:ib[H_PW] + n * dof].reshape(n, dof))


def last_collision(ib: np.ndarray) -> np.ndarray:
    """The slot of a checker's int buffer (its layer's ``I``) that holds the pair whose
    collision the kernels proved last (-1: none), as a one-element view."""
    return ib[H_LAST:H_LAST + 1]
