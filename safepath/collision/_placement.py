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
from ..model._joint_table import JF_WIDTH, JI_WIDTH
from ._layout import (
    G_POS,
    G_ROT,
    GI_JOINT,
    GI_OUTER,
    GI_OUTER_END,
    GIW,
    GW,
    H_DOF,
    H_G,
    H_GI,
    H_J,
    H_JI,
    H_L,
    H_NJ,
    H_S,
    PS_BOUND,
    PS_RADIUS,
    PSW,
    S_RADIUS,
    SW,
)

#: How the helpers are compiled (see :mod:`safepath.collision._kernels`).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_inlined
def _fk(q, fb, ib, Rw, pw):  # noqa: N803
    """World rotation and position of every joint frame at ``q`` into Rw (nj,3,3), pw (nj,3)."""
    nj, oj, oji = ib[H_NJ], ib[H_J], ib[H_JI]
    joint_frames(q, fb[oj:oj + JF_WIDTH * nj].reshape((nj, JF_WIDTH)),
                 ib[oji:oji + JI_WIDTH * nj].reshape((nj, JI_WIDTH)), Rw, pw)


@_inlined
def _world(fb, s, Rw, pw, j, wf, o):  # noqa: N803
    """World centre of the sphere/point at fb[s:s+3] (frame of joint ``j``) into wf[o:o+3]."""
    x, y, z = fb[s], fb[s + 1], fb[s + 2]
    for r in range(3):
        wf[o + r] = Rw[j, r, 0] * x + Rw[j, r, 1] * y + Rw[j, r, 2] * z + pw[j, r]


@_inlined
def _mover_frame(fb, ib, m, Rw, pw, wf, oR, op):  # noqa: N803
    """World rotation (rows at wf[oR:oR+9]) and position (wf[op:op+3]) of mover ``m``'s
    primitive."""
    og = ib[H_G] + GW * m
    j = ib[ib[H_GI] + GIW * m + GI_JOINT]
    t, R = og + G_POS, og + G_ROT  # noqa: N806
    for r in range(3):
        wf[op + r] = (Rw[j, r, 0] * fb[t] + Rw[j, r, 1] * fb[t + 1] + Rw[j, r, 2] * fb[t + 2]
                      + pw[j, r])
        for c in range(3):
            wf[oR + 3 * r + c] = (Rw[j, r, 0] * fb[R + c] + Rw[j, r, 1] * fb[R + 3 + c]
                                  + Rw[j, r, 2] * fb[R + 6 + c])


@_helper
def _place_spheres(fb, ib, m, Rw, pw, ox, oy, oz, orad, wf, out):  # noqa: N803
    """World centres and radii of mover ``m``'s outer spheres into rows of PSW of ``wf`` from
    ``out`` (x, y, z, r, lower bound of the distance to the sphere (ox, oy, oz, orad));
    returns the count."""
    oS, ogi = ib[H_S], ib[H_GI]
    j = ib[ogi + GIW * m + GI_JOINT]
    n = 0
    for s in range(ib[ogi + GIW * m + GI_OUTER], ib[ogi + GIW * m + GI_OUTER_END]):
        x, y, z = fb[oS + SW * s], fb[oS + SW * s + 1], fb[oS + SW * s + 2]
        wx = Rw[j, 0, 0] * x + Rw[j, 0, 1] * y + Rw[j, 0, 2] * z + pw[j, 0]
        wy = Rw[j, 1, 0] * x + Rw[j, 1, 1] * y + Rw[j, 1, 2] * z + pw[j, 1]
        wz = Rw[j, 2, 0] * x + Rw[j, 2, 1] * y + Rw[j, 2, 2] * z + pw[j, 2]
        r = fb[oS + SW * s + S_RADIUS]
        o = out + PSW * n
        wf[o], wf[o + 1], wf[o + 2], wf[o + PS_RADIUS] = wx, wy, wz, r
        wf[o + PS_BOUND] = math.sqrt((wx - ox) ** 2 + (wy - oy) ** 2 + (wz - oz) ** 2) - r - orad
        n += 1
    return n


@_helper
def _within_limits(q, fb, ib):  # noqa: N803
    dof, ol = ib[H_DOF], ib[H_L]
    for i in range(dof):
        if not (fb[ol + i] <= q[i] <= fb[ol + dof + i]):
            return False
    return True
