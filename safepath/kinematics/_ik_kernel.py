"""Numba kernels of Cartesian lines: the arm's kinematics and damped-least-squares IK.

The same algorithm as :func:`safepath.kinematics.solve_ik` (the frame error as
``log6`` in the TCP frame, its Jacobian ``Jlog6``, the damping, clipping to the limits,
the acceptance test and the iteration count), without one Python call per operation:
a whole line is one call. Imported lazily by :mod:`~safepath.planning.cartesian`, so
``import safepath`` does not import numba; the first call compiles, or loads from
numba's on-disk cache (``cache=True``, in ``__pycache__`` next to this file).

The chain (``safepath.planning.cartesian.line_chain``) is a joint table
(:mod:`safepath.model._joint_table`: ``joint_f``, ``joint_i``) of the joints from the root to
the TCP's parent joint, in order, each the parent of the next; its joint frames come from
the planner's one forward kinematics (:func:`safepath.model._fk_kernel.joint_frames`).
``frame_f`` holds the TCP placement in the last joint (rotation 0-8 row-major,
translation 9-11). Results agree with Pinocchio to rounding
(tests/planning/test_cartesian.py compares them).

Written for short compile times: scalar loops, no array expressions or slices.
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit
from ..model._fk_kernel import exp3, frame_origin, joint_frames, joint_motion
from ..model._joint_table import JI_Q

__all__ = ["OK", "NO_SOLUTION", "JUMP", "tcp_pose", "tcp_jacobian", "log6", "jlog6",
           "solve", "line_path"]

#: Status codes of :func:`line_path`.
OK, NO_SOLUTION, JUMP = 0, 1, 2

# Below these angles [rad] log6's and Jlog6's closed forms lose precision and Taylor
# series are used (Pinocchio's thresholds: eps ** (1/3) and eps ** (1/4)).
_SMALL2 = 2.220446049250313e-16 ** (1.0 / 3.0)
_SMALL3 = 2.220446049250313e-16 ** 0.25


@njit(cache=True, nogil=True)
def _fk(joint_f, joint_i, frame_f, q, Rw, pw, R, p):  # noqa: N803
    """World pose of every chain joint (Rw (k,3,3), pw (k,3)) and of the TCP (R, p)."""
    k = joint_f.shape[0]
    joint_frames(q, joint_f, joint_i, Rw, pw)
    for r in range(3):
        for c in range(3):
            R[r, c] = frame_f[3 * r + c] if k == 0 else (
                Rw[k - 1, r, 0] * frame_f[c] + Rw[k - 1, r, 1] * frame_f[3 + c]
                + Rw[k - 1, r, 2] * frame_f[6 + c])
    p[0], p[1], p[2] = frame_origin(Rw, pw, k, frame_f)


@njit(cache=True, nogil=True)
def _jacobian(joint_f, joint_i, Rw, pw, R, p, J):  # noqa: N803
    """TCP Jacobian in the TCP frame (Pinocchio's LOCAL: rows 0-2 the velocity of the
    TCP origin, rows 3-5 the angular velocity, both in TCP axes) into J (6, nq)."""
    for r in range(6):
        for c in range(J.shape[1]):
            J[r, c] = 0.0
    for j in range(joint_f.shape[0]):
        col = joint_i[j, JI_Q]
        # The velocity of the TCP origin and the angular velocity, world axes.
        vx, vy, vz, wx, wy, wz = joint_motion(joint_f, Rw, pw, j, p[0], p[1], p[2])
        for r in range(3):  # in TCP axes: R^T
            J[r, col] = R[0, r] * vx + R[1, r] * vy + R[2, r] * vz
            J[3 + r, col] = R[0, r] * wx + R[1, r] * wy + R[2, r] * wz


@njit(cache=True, nogil=True)
def _log6(R, p, w, out):  # noqa: N803
    """log6 of the pose (R, p) into out (6,) = (linear, angular), log3(R) into w;
    returns the rotation angle in [0, pi] [rad]."""
    ax = 0.5 * (R[2, 1] - R[1, 2])  # sin(angle) * axis
    ay = 0.5 * (R[0, 2] - R[2, 0])
    az = 0.5 * (R[1, 0] - R[0, 1])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    s = math.sqrt(ax * ax + ay * ay + az * az)
    t = math.atan2(s, c)
    if c > -0.9:  # angle below ~154 deg: the antisymmetric part gives the axis
        k = 1.0 + s * s / 6.0 if s < _SMALL2 else t / s
        w[0], w[1], w[2] = k * ax, k * ay, k * az
    else:  # near pi: the axis from the symmetric part, (1 - c) u u^T, its sign from a
        one_c = 1.0 - c
        d0, d1, d2 = R[0, 0] - c, R[1, 1] - c, R[2, 2] - c
        if d0 >= d1 and d0 >= d2:
            u0 = math.sqrt(max(d0 / one_c, 0.0))
            u1 = 0.5 * (R[0, 1] + R[1, 0]) / (one_c * u0)
            u2 = 0.5 * (R[0, 2] + R[2, 0]) / (one_c * u0)
        elif d1 >= d2:
            u1 = math.sqrt(max(d1 / one_c, 0.0))
            u0 = 0.5 * (R[0, 1] + R[1, 0]) / (one_c * u1)
            u2 = 0.5 * (R[1, 2] + R[2, 1]) / (one_c * u1)
        else:
            u2 = math.sqrt(max(d2 / one_c, 0.0))
            u0 = 0.5 * (R[0, 2] + R[2, 0]) / (one_c * u2)
            u1 = 0.5 * (R[1, 2] + R[2, 1]) / (one_c * u2)
        sign = -1.0 if u0 * ax + u1 * ay + u2 * az < 0.0 else 1.0
        n = sign * math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        w[0], w[1], w[2] = t * u0 / n, t * u1 / n, t * u2 / n
    t2 = t * t
    if t < _SMALL2:
        alpha = 1.0 - t2 / 12.0 - t2 * t2 / 720.0
        beta = 1.0 / 12.0 + t2 / 720.0
    else:
        st, ct = math.sin(t), math.cos(t)
        alpha = t * st / (2.0 * (1.0 - ct))
        beta = 1.0 / t2 - st / (2.0 * t * (1.0 - ct))
    wp = w[0] * p[0] + w[1] * p[1] + w[2] * p[2]
    out[0] = alpha * p[0] - 0.5 * (w[1] * p[2] - w[2] * p[1]) + beta * wp * w[0]
    out[1] = alpha * p[1] - 0.5 * (w[2] * p[0] - w[0] * p[2]) + beta * wp * w[1]
    out[2] = alpha * p[2] - 0.5 * (w[0] * p[1] - w[1] * p[0]) + beta * wp * w[2]
    out[3], out[4], out[5] = w[0], w[1], w[2]
    return t


@njit(cache=True, nogil=True)
def _jlog6(p, t, w, out, A, C):  # noqa: N803
    """Jacobian of log6 at a pose (R, p) into out (6, 6), given w = log3(R) and its
    angle t [rad]; A and C (3, 3) are work space."""
    t2 = t * t
    if t < _SMALL3:
        alpha = 1.0 / 12.0 + t2 / 720.0
        diag = 0.5 * (2.0 - t2 / 6.0)
        beta_dot = 1.0 / 360.0
    else:
        st, ct = math.sin(t), math.cos(t)
        inv = 1.0 / (2.0 * (1.0 - ct))
        alpha = 1.0 / t2 - st / t * inv
        diag = 0.5 * t * st / (1.0 - ct)
        beta_dot = -2.0 / (t2 * t2) + (1.0 + st / t) / t2 * inv
    wp = w[0] * p[0] + w[1] * p[1] + w[2] * p[2]
    for r in range(3):
        # A = Jlog3 = alpha w w^T + diag I + [w/2]x; C: the left factor of the top right
        # block, (beta_dot wp w - (t2 beta_dot + 2 beta) p) w^T + beta w p^T + wp beta I
        # + [p/2]x, with beta = alpha.
        v = beta_dot * wp * w[r] - (t2 * beta_dot + 2.0 * alpha) * p[r]
        for c in range(3):
            A[r, c] = alpha * w[r] * w[c]
            C[r, c] = v * w[c] + alpha * w[r] * p[c]
        A[r, r] += diag
        C[r, r] += wp * alpha
    A[0, 1] -= 0.5 * w[2]
    A[1, 0] += 0.5 * w[2]
    A[0, 2] += 0.5 * w[1]
    A[2, 0] -= 0.5 * w[1]
    A[1, 2] -= 0.5 * w[0]
    A[2, 1] += 0.5 * w[0]
    C[0, 1] -= 0.5 * p[2]
    C[1, 0] += 0.5 * p[2]
    C[0, 2] += 0.5 * p[1]
    C[2, 0] -= 0.5 * p[1]
    C[1, 2] -= 0.5 * p[0]
    C[2, 1] += 0.5 * p[0]
    for r in range(3):
        for c in range(3):
            out[r, c] = A[r, c]
            out[3 + r, 3 + c] = A[r, c]
            out[3 + r, c] = 0.0
            out[r, 3 + c] = C[r, 0] * A[0, c] + C[r, 1] * A[1, c] + C[r, 2] * A[2, c]


@njit(cache=True, nogil=True)
def _cholesky_solve(A, b, x):  # noqa: N803
    """Solve A x = b for a symmetric positive definite A (6, 6), overwritten by its
    Cholesky factor."""
    n = A.shape[0]
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= A[j, k] * A[j, k]
        d = math.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / d
    for i in range(n):  # L y = b
        s = b[i]
        for k in range(i):
            s -= A[i, k] * x[k]
        x[i] = s / A[i, i]
    for i in range(n - 1, -1, -1):  # L^T x = y
        s = x[i]
        for k in range(i + 1, n):
            s -= A[k, i] * x[k]
        x[i] = s / A[i, i]


@njit(cache=True, nogil=True)
def _error_pose(R, p, R_target, p_target, Re, pe):  # noqa: N803
    """The error pose (Re, pe) = TCP^-1 target of the TCP (R, p) and the target
    (R_target, p_target), in the TCP frame; returns the position error [m]."""
    dx, dy, dz = p_target[0] - p[0], p_target[1] - p[1], p_target[2] - p[2]
    for r in range(3):
        pe[r] = R[0, r] * dx + R[1, r] * dy + R[2, r] * dz
        for c in range(3):
            Re[r, c] = (R[0, r] * R_target[0, c] + R[1, r] * R_target[1, c]
                        + R[2, r] * R_target[2, c])
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True, nogil=True)
def _damped_step(J, Jl, err, damping, lower, upper, q, Jt, A, x):  # noqa: N803
    """One damped least-squares step on the 6-D error ``err``, with the Jacobians of the
    frame (J) and of log6 (Jl): q += Jt^T (Jt Jt^T + damping I)^-1 err with Jt = Jl J,
    each joint then clipped to its limits (Jt, A, x: workspaces)."""
    nq = q.shape[0]
    for r in range(6):  # Jt = Jlog6 J; A = Jt Jt^T + damping I
        for c in range(nq):
            s = 0.0
            for m in range(6):
                s += Jl[r, m] * J[m, c]
            Jt[r, c] = s
    for r in range(6):
        for c in range(r + 1):
            s = 0.0
            for m in range(nq):
                s += Jt[r, m] * Jt[c, m]
            A[r, c] = s
            A[c, r] = s
        A[r, r] += damping
    _cholesky_solve(A, err, x)
    for c in range(nq):
        s = 0.0
        for r in range(6):
            s += Jt[r, c] * x[r]
        q[c] = min(max(q[c] + s, lower[c]), upper[c])


@njit(cache=True, nogil=True)
def solve(joint_f, joint_i, frame_f, R_target, p_target, q, lower, upper, params,  # noqa: N803
          max_iterations):
    """Damped least squares from ``q`` (updated in place) towards the TCP pose
    (R_target, p_target); ``params`` = (position tolerance [m], orientation tolerance
    [rad], largest joint step [rad] (unused here), damping). Returns the number of
    Jacobian steps taken, or -1 when ``max_iterations`` checks found no solution."""
    nq, k = q.shape[0], joint_f.shape[0]
    Rw, pw = np.empty((k, 3, 3)), np.empty((k, 3))
    R, p, E = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
    Re, pe, w, err = np.empty((3, 3)), np.empty(3), np.empty(3), np.empty(6)
    J, Jl, Jt = np.empty((6, nq)), np.empty((6, 6)), np.empty((6, nq))
    A, x = np.empty((6, 6)), np.empty(6)
    for it in range(max_iterations):
        _fk(joint_f, joint_i, frame_f, q, Rw, pw, R, p)
        position_error = _error_pose(R, p, R_target, p_target, Re, pe)
        t = _log6(Re, pe, w, err)
        if (position_error < params[0]
                and math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) < params[1]):
            return it
        _jacobian(joint_f, joint_i, Rw, pw, R, p, J)
        _jlog6(pe, t, w, Jl, Re, E)
        _damped_step(J, Jl, err, params[3], lower, upper, q, Jt, A, x)
    return -1


@njit(cache=True, nogil=True)
def line_path(joint_f, joint_i, frame_f, R0, w_line, p0, p1, lower, upper, params,  # noqa: N803
              max_iterations, path):
    """IK waypoints of the straight TCP line into ``path`` (n + 1, nq), whose row 0
    holds the start. Waypoint k (s = k/n) targets the position (1 - s) p0 + s p1 and
    the rotation R0 exp3(s w_line); it is seeded with the previous waypoints' motion
    continued (quadratically once there are three), and no joint may move more than
    params[2] [rad] from the previous waypoint.

    Returns (status, k, iterations, jump): OK (k = n), NO_SOLUTION or JUMP at waypoint
    k; the Jacobian steps taken in all; the failing jump [rad] (JUMP only).
    """
    n, nq = path.shape[0] - 1, path.shape[1]
    R_target, p_target, q = np.empty((3, 3)), np.empty(3), np.empty(nq)
    iterations = 0
    for k in range(1, n + 1):
        s = k / n
        e = exp3(s * w_line[0], s * w_line[1], s * w_line[2])
        for r in range(3):
            for c in range(3):
                R_target[r, c] = R0[r, 0] * e[c] + R0[r, 1] * e[3 + c] + R0[r, 2] * e[6 + c]
            p_target[r] = (1.0 - s) * p0[r] + s * p1[r]
        for c in range(nq):
            if k == 1:
                v = path[0, c]
            elif k == 2:
                v = 2.0 * path[1, c] - path[0, c]
            else:
                v = 3.0 * path[k - 1, c] - 3.0 * path[k - 2, c] + path[k - 3, c]
            q[c] = min(max(v, lower[c]), upper[c])
        steps = solve(joint_f, joint_i, frame_f, R_target, p_target, q, lower, upper, params,
                      max_iterations)
        if steps < 0:
            return NO_SOLUTION, k, iterations, 0.0
        iterations += steps
        jump = 0.0
        for c in range(nq):
            jump = max(jump, abs(q[c] - path[k - 1, c]))
        if jump > params[2]:
            return JUMP, k, iterations, jump
        for c in range(nq):
            path[k, c] = q[c]
    return OK, n, iterations, 0.0


@njit(cache=True, nogil=True)
def tcp_pose(joint_f, joint_i, frame_f, q, R, p):  # noqa: N803
    """TCP pose in the world frame at ``q`` into R (3, 3) and p (3,) (for tests)."""
    k = joint_f.shape[0]
    _fk(joint_f, joint_i, frame_f, q, np.empty((k, 3, 3)), np.empty((k, 3)), R, p)


@njit(cache=True, nogil=True)
def tcp_jacobian(joint_f, joint_i, frame_f, q, J):  # noqa: N803
    """TCP Jacobian in the TCP frame at ``q`` into J (6, nq) (for tests)."""
    k = joint_f.shape[0]
    Rw, pw, R, p = np.empty((k, 3, 3)), np.empty((k, 3)), np.empty((3, 3)), np.empty(3)
    _fk(joint_f, joint_i, frame_f, q, Rw, pw, R, p)
    _jacobian(joint_f, joint_i, Rw, pw, R, p, J)


@njit(cache=True, nogil=True)
def log6(R, p, out):  # noqa: N803
    """log6 of the pose (R, p) into out (6,) = (linear, angular) (for tests)."""
    _log6(R, p, np.empty(3), out)


@njit(cache=True, nogil=True)
def jlog6(R, p, out):  # noqa: N803
    """Jacobian of log6 at the pose (R, p) into out (6, 6) (for tests)."""
    w = np.empty(3)
    t = _log6(R, p, w, np.empty(6))
    _jlog6(p, t, w, out, np.empty((3, 3)), np.empty((3, 3)))
