"""Forward kinematics of the planner's numba kernels: the world frame of every joint of a
joint table (:mod:`safepath.model._joint_table`) at a configuration.

One code path for the sphere layer (:mod:`safepath.collision._placement`, the whole
tree) and the inverse kinematics of Cartesian lines (:mod:`safepath.kinematics._ik_kernel`,
the chain to the TCP). The release check keeps its own kinematics
(:mod:`safepath.verify._kernel`) on purpose: it must not share a fault with the planner
it checks.

A moving joint's local placement is its placement times ``exp6(S x)``: the rotation
``exp3(w x)`` (Rodrigues' formula, Pinocchio's Taylor series near 0) and the translation
``t + R_placement (v x)``; the sphere layer's fixed rows (the universe) are their
placement. The operations and their order are the ones the lines' IK has always used, so
its waypoints (which trajectories are made of) keep every bit.

Compiled without numba's reference counting (no allocation, no array returned), like
the sphere layer's helpers that call it. numba's disk cache tracks only the file of the
function it compiles: after editing this file in a source checkout, delete the ``*.nb*``
files of ``safepath/__pycache__``, ``safepath/collision/__pycache__`` and
``safepath/kinematics/__pycache__`` (the kernels compiled ahead of time are keyed on this
file's source).
"""

from __future__ import annotations

import math

from .._aot import njit
from ._joint_table import FIXED, JF_R, JF_T, JF_V, JF_W, JI_KIND, JI_PARENT, JI_Q

__all__ = ["exp3", "joint_frames"]

# Below this angle [rad] exp3's closed form loses precision and a Taylor series is used
# (Pinocchio's threshold: eps ** (1/4)).
_SMALL = 2.220446049250313e-16 ** 0.25

_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_inlined
def exp3(wx, wy, wz):
    """The rotation matrix of the rotation vector ``w`` [rad] (Rodrigues), as 9 floats,
    row-major."""
    t2 = wx * wx + wy * wy + wz * wz
    t = math.sqrt(t2)
    if t < _SMALL:
        a = 1.0 - t2 / 6.0
        b = 0.5 - t2 / 24.0
    else:
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    return (1.0 - b * (wy * wy + wz * wz), b * wx * wy - a * wz, b * wx * wz + a * wy,
            b * wx * wy + a * wz, 1.0 - b * (wx * wx + wz * wz), b * wy * wz - a * wx,
            b * wx * wz - a * wy, b * wy * wz + a * wx, 1.0 - b * (wx * wx + wy * wy))


@_helper
def joint_frames(q, jf, ji, Rw, pw):  # noqa: N803
    """World rotation (Rw (n, 3, 3)) and position (pw (n, 3) [m]) of every joint of the
    table (``jf``, ``ji``) at ``q``."""
    for j in range(jf.shape[0]):
        # The local placement into Rw[j], pw[j].
        if ji[j, JI_KIND] == FIXED:
            for r in range(3):
                for c in range(3):
                    Rw[j, r, c] = jf[j, JF_R + 3 * r + c]
                pw[j, r] = jf[j, JF_T + r]
        else:  # the placement times the joint's motion exp6(S x)
            x = q[ji[j, JI_Q]]
            e00, e01, e02, e10, e11, e12, e20, e21, e22 = exp3(
                jf[j, JF_W] * x, jf[j, JF_W + 1] * x, jf[j, JF_W + 2] * x)
            tx, ty, tz = jf[j, JF_V] * x, jf[j, JF_V + 1] * x, jf[j, JF_V + 2] * x
            for r in range(3):
                m0, m1, m2 = jf[j, JF_R + 3 * r], jf[j, JF_R + 3 * r + 1], jf[j, JF_R + 3 * r + 2]
                Rw[j, r, 0] = m0 * e00 + m1 * e10 + m2 * e20
                Rw[j, r, 1] = m0 * e01 + m1 * e11 + m2 * e21
                Rw[j, r, 2] = m0 * e02 + m1 * e12 + m2 * e22
                pw[j, r] = jf[j, JF_T + r] + m0 * tx + m1 * ty + m2 * tz
        parent = ji[j, JI_PARENT]
        if parent < 0:  # placed in the world
            continue
        # Composed with the parent's world frame, in place (column by column).
        for c in range(3):
            l0, l1, l2 = Rw[j, 0, c], Rw[j, 1, c], Rw[j, 2, c]
            for r in range(3):
                Rw[j, r, c] = (Rw[parent, r, 0] * l0 + Rw[parent, r, 1] * l1
                               + Rw[parent, r, 2] * l2)
        l0, l1, l2 = pw[j, 0], pw[j, 1], pw[j, 2]
        for r in range(3):
            pw[j, r] = (pw[parent, r] + Rw[parent, r, 0] * l0 + Rw[parent, r, 1] * l1
                        + Rw[parent, r, 2] * l2)
