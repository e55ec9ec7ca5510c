"""Numpy building blocks of the shape table's geometry (:mod:`safepath.model.shapes`).

Nothing here knows a kind: the grid of cells a sphere fit covers a shape with, the
floating-point slack of a fit, and closed triangle meshes of a box and of a surface of
revolution, which the table's rows assemble into each kind's geometry.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["SLACK", "Spheres", "cell_grid", "box_corners", "box_mesh", "revolve"]

#: Radii are grown (outer spheres) or shrunk (inner spheres) by this much [m]:
#: floating-point slack.
SLACK = 1e-6

#: A sphere fit in a shape's frame: outer centres (n, 3) and radii (n,) [m] of spheres
#: that together enclose the shape, inner centres (m, 3) and radii (m,) [m] of spheres
#: inside it (radii <= 0 are dropped by the fitter).
Spheres = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]

#: The corners of the cube [-1, 1]^3 (x slowest).
_CUBE = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)


def cell_grid(lo: np.ndarray, hi: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres [m] of the cells of a grid over the box [lo, hi] whose edges are at most
    ``cell`` [m], and each cell's half edges [m]."""
    size = hi - lo
    counts = np.maximum(1, np.ceil(size / cell - 1e-9)).astype(int)
    step = size / counts
    axes = [lo[i] + step[i] * (np.arange(counts[i]) + 0.5) for i in range(3)]
    centers = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return centers, step / 2


def box_corners(half: np.ndarray) -> np.ndarray:
    """The 8 corners [m] of the box of half sides ``half`` [m] about the origin."""
    return _CUBE * half


def box_mesh(half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices [m], faces)`` of the box of half sides ``half`` [m]: four vertices per
    side (so a renderer's vertex normals keep its edges sharp), faces turned outwards."""
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3  # e_u x e_v = e_axis
        for sign in (-1.0, 1.0):
            side = np.zeros((4, 3))
            side[:, axis] = sign * half[axis]
            side[:, u], side[:, v] = square[:, 0] * half[u], square[:, 1] * half[v]
            first = 4 * len(vertices)
            quad = [[0, 1, 2], [0, 2, 3]] if sign > 0 else [[0, 2, 1], [0, 3, 2]]
            faces.append(np.array(quad) + first)
            vertices.append(side)
    return np.vstack(vertices), np.vstack(faces).astype(np.int32)


def revolve(pieces: Sequence[np.ndarray], segments: int = 32
            ) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices [m], faces)`` of the surface that profiles swept about the z axis make.

    Args:
        pieces: Smooth parts of the profile, each (k, 2) points (radius, z) [m], going
            round the solid's outline from its bottom to its top (a crease between two
            pieces stays sharp: each piece has its own vertices). A point of radius 0 is a
            pole: one vertex.
        segments: Vertices per ring.

    Returns:
        Vertices on the swept surface and triangles turned outwards (a piece's triangle
        that a pole makes degenerate is dropped).
    """
    phi = 2 * np.pi * np.arange(segments) / segments
    ring = np.column_stack([np.cos(phi), np.sin(phi)])
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    count = 0
    for piece in pieces:
        rows = []  # per profile point: its ring's vertex indices, by angle
        for r, z in piece:
            pole = r == 0
            rows.append(count + (np.zeros(segments, dtype=int) if pole else np.arange(segments)))
            vertices.append(np.array([[0.0, 0.0, z]]) if pole
                            else np.column_stack([r * ring, np.full(segments, z)]))
            count += len(vertices[-1])
        for low, high in zip(rows[:-1], rows[1:], strict=True):
            a, b, c, d = low, np.roll(low, -1), np.roll(high, -1), high
            tris = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
            keep = ((tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2])
                    & (tris[:, 0] != tris[:, 2]))
            faces.append(tris[keep])
    return np.vstack(vertices), np.vstack(faces).astype(np.int32)
