"""Kernels of the sphere layer: kinematics and placement.

The world frames of the checker's joints (the planner's one forward kinematics,
:func:`safepath.model._fk_kernel.joint_frames`, over the joint table in the buffers), and the
world placement of a mover's spheres and primitive frame (the rows
:mod:`safepath.collision._layout` describes), for :mod:`safepath.collision._pair_tests`
and :mod:`safepath.collision._kernels`. Compiled without numba's reference counting, like
every helper of the layer (see :mod:`safepath.collision._kernels`): no allocation, no
array returned.

numba's disk cache tracks only the file of the function it compiles: the kernels of
:mod:`safepath.collision._kernels` that call (and inline) these helpers keep their cached
code when only this file changes. After editing it in a source checkout, delete
``safepath/collision/__pycache__/*.nb*`` (an installed copy compiles afresh; the kernels
compiled ahead of time are keyed on every kernel module's source).
"""

from __future__ import annotations

import math

from .._aot import njit
from ..model._fk_kernel import joint_frames
from ._records import (
    Rotation,
    dof,
    joint_table,
    limits,
    mover_joint,
    mover_position,
    mover_rotation,
    outer_spheres,
    set_placed_sphere,
    sphere_centre,
    sphere_radius,
)

#: How the helpers are compiled (see :mod:`safepath.collision._kernels`).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_inlined
def _fk(q, fb, ib, Rw, pw):  # noqa: N803
    """World rotation and position of every joint frame at ``q`` into Rw (nj,3,3), pw (nj,3)."""
    jf, ji = joint_table(fb, ib)
    joint_frames(q, jf, ji, Rw, pw)


@_inlined
def _to_world(Rw, pw, j, x, y, z):  # noqa: N803
    """The world point of (x, y, z) [m] in the frame of joint ``j``."""
    return (Rw[j, 0, 0] * x + Rw[j, 0, 1] * y + Rw[j, 0, 2] * z + pw[j, 0],
            Rw[j, 1, 0] * x + Rw[j, 1, 1] * y + Rw[j, 1, 2] * z + pw[j, 1],
            Rw[j, 2, 0] * x + Rw[j, 2, 1] * y + Rw[j, 2, 2] * z + pw[j, 2])


@_inlined
def _sphere_world(fb, ib, s, Rw, pw, j):  # noqa: N803
    """World centre [m] of sphere ``s``, carried by joint ``j``."""
    x, y, z = sphere_centre(fb, ib, s)
    return _to_world(Rw, pw, j, x, y, z)


@_inlined
def _mover_frame(fb, ib, m, Rw, pw):  # noqa: N803
    """World rotation (a Rotation) and position (x, y, z) [m] of mover ``m``'s primitive."""
    j = mover_joint(ib, m)
    x, y, z = mover_position(fb, ib, m)
    M = mover_rotation(fb, ib, m)  # noqa: N806
    R = Rotation(  # noqa: N806
        Rw[j, 0, 0] * M.r00 + Rw[j, 0, 1] * M.r10 + Rw[j, 0, 2] * M.r20,
        Rw[j, 0, 0] * M.r01 + Rw[j, 0, 1] * M.r11 + Rw[j, 0, 2] * M.r21,
        Rw[j, 0, 0] * M.r02 + Rw[j, 0, 1] * M.r12 + Rw[j, 0, 2] * M.r22,
        Rw[j, 1, 0] * M.r00 + Rw[j, 1, 1] * M.r10 + Rw[j, 1, 2] * M.r20,
        Rw[j, 1, 0] * M.r01 + Rw[j, 1, 1] * M.r11 + Rw[j, 1, 2] * M.r21,
        Rw[j, 1, 0] * M.r02 + Rw[j, 1, 1] * M.r12 + Rw[j, 1, 2] * M.r22,
        Rw[j, 2, 0] * M.r00 + Rw[j, 2, 1] * M.r10 + Rw[j, 2, 2] * M.r20,
        Rw[j, 2, 0] * M.r01 + Rw[j, 2, 1] * M.r11 + Rw[j, 2, 2] * M.r21,
        Rw[j, 2, 0] * M.r02 + Rw[j, 2, 1] * M.r12 + Rw[j, 2, 2] * M.r22)
    px, py, pz = _to_world(Rw, pw, j, x, y, z)
    return R, px, py, pz


@_helper
def _place_spheres(fb, ib, m, Rw, pw, ox, oy, oz, orad, wf, wi, which):  # noqa: N803
    """World centres and radii of mover ``m``'s outer spheres into placed sphere set
    ``which`` (with each a lower bound of its distance to the sphere (ox, oy, oz,
    orad)); returns the count."""
    j = mover_joint(ib, m)
    first, end = outer_spheres(ib, m)
    for s in range(first, end):
        wx, wy, wz = _sphere_world(fb, ib, s, Rw, pw, j)
        r = sphere_radius(fb, ib, s)
        bound = math.sqrt((wx - ox) ** 2 + (wy - oy) ** 2 + (wz - oz) ** 2) - r - orad
        set_placed_sphere(wf, wi, which, s - first, wx, wy, wz, r, bound)
    return end - first


@_helper
def _within_limits(q, fb, ib):  # noqa: N803
    for i in range(dof(ib)):
        lo, hi = limits(fb, ib, i)
        if not (lo <= q[i] <= hi):
            return False
    return True
