"""Forward kinematics of the planner's numba kernels: the world frame of every joint of a
joint table (:mod:`safepath.model._joint_table`) at a configuration.

One code path for the sphere layer (:mod:`safepath.collision._placement`, the whole
tree), the inverse kinematics of Cartesian lines (:mod:`safepath.kinematics._ik_kernel`,
the chain to the TCP) and the TCP's positions and speeds along a path
(:func:`tcp_motion`, behind :meth:`safepath.Robot.tcp_speeds`: timing's TCP speed
limits). The release check keeps its own kinematics
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

__all__ = ["exp3", "frame_origin", "joint_frames", "joint_motion", "tcp_motion"]

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


@_inlined
def frame_origin(Rw, pw, k, frame_f):  # noqa: N803
    """World position [m] of a frame placed at ``frame_f`` (rotation 0-8 row-major,
    translation 9-11) in the last of ``k`` joint frames (in the world when ``k`` is 0)."""
    if k == 0:
        return frame_f[9], frame_f[10], frame_f[11]
    e = k - 1
    return ((pw[e, 0] + Rw[e, 0, 0] * frame_f[9] + Rw[e, 0, 1] * frame_f[10]
             + Rw[e, 0, 2] * frame_f[11]),
            (pw[e, 1] + Rw[e, 1, 0] * frame_f[9] + Rw[e, 1, 1] * frame_f[10]
             + Rw[e, 1, 2] * frame_f[11]),
            (pw[e, 2] + Rw[e, 2, 0] * frame_f[9] + Rw[e, 2, 1] * frame_f[10]
             + Rw[e, 2, 2] * frame_f[11]))


@_inlined
def joint_motion(jf, Rw, pw, j, px, py, pz):  # noqa: N803
    """Per unit speed of the table's joint ``j`` (a screw, placed at ``Rw[j]``, ``pw[j]``):
    the velocity of the point ``p`` and the angular velocity, in world axes
    (``vx, vy, vz, wx, wy, wz``)."""
    ax, ay, az = jf[j, JF_W], jf[j, JF_W + 1], jf[j, JF_W + 2]
    wx = Rw[j, 0, 0] * ax + Rw[j, 0, 1] * ay + Rw[j, 0, 2] * az
    wy = Rw[j, 1, 0] * ax + Rw[j, 1, 1] * ay + Rw[j, 1, 2] * az
    wz = Rw[j, 2, 0] * ax + Rw[j, 2, 1] * ay + Rw[j, 2, 2] * az
    lx, ly, lz = jf[j, JF_V], jf[j, JF_V + 1], jf[j, JF_V + 2]
    vx = Rw[j, 0, 0] * lx + Rw[j, 0, 1] * ly + Rw[j, 0, 2] * lz
    vy = Rw[j, 1, 0] * lx + Rw[j, 1, 1] * ly + Rw[j, 1, 2] * lz
    vz = Rw[j, 2, 0] * lx + Rw[j, 2, 1] * ly + Rw[j, 2, 2] * lz
    # The point's velocity: v + w x (p - p_joint).
    dx, dy, dz = px - pw[j, 0], py - pw[j, 1], pz - pw[j, 2]
    vx += wy * dz - wz * dy
    vy += wz * dx - wx * dz
    vz += wx * dy - wy * dx
    return vx, vy, vz, wx, wy, wz


@njit(cache=True, nogil=True)
def tcp_motion(jf, ji, frame_f, q_path, qd_path, speed, Rw, pw, q, p_out, v_out):  # noqa: N803
    """The TCP's world position (p_out (n, 3) [m]) at each row of ``q_path`` (n, nq) and,
    if ``speed``, the norm of its linear velocity at the velocities ``qd_path`` (v_out
    (n,) [m/s]), over a chain table (``jf``, ``ji``: the joints from the root to the TCP's
    parent joint, each the parent of the next) and the TCP's placement in its last joint
    (``frame_f``: rotation 0-8 row-major, translation 9-11). ``Rw`` (k, 3, 3), ``pw``
    (k, 3) and ``q`` (nq,) are scratch."""
    k = jf.shape[0]
    for i in range(q_path.shape[0]):
        for c in range(q.size):
            q[c] = q_path[i, c]
        joint_frames(q, jf, ji, Rw, pw)
        px, py, pz = frame_origin(Rw, pw, k, frame_f)
        p_out[i, 0], p_out[i, 1], p_out[i, 2] = px, py, pz
        if not speed:
            continue
        vx = vy = vz = 0.0
        for j in range(k):
            x = qd_path[i, ji[j, JI_Q]]
            mx, my, mz, _, _, _ = joint_motion(jf, Rw, pw, j, px, py, pz)
            vx += x * mx
            vy += x * my
            vz += x * mz
        v_out[i] = math.sqrt(vx * vx + vy * vy + vz * vz)
