"""The sphere layer's records, read and written by name: the one place its kernels
turn a mover, a sphere, an environment object, a pair or a scratch slot into positions
in the flat buffers.

The buffers (``fb``, ``ib``: one checker, packed by :mod:`safepath.collision._pack`) and a
kernel call's scratch (``wf``, ``wi``) are laid out as :mod:`safepath.collision._layout`
says; that module owns the numbers, this one the arithmetic on them. The kernels
(:mod:`safepath.collision._placement`, ``_pair_tests``, ``_gjk``, ``_kernels``,
``_bounds``) call these accessors and import no offset: ``mover_radius(fb, ib, m)``, not
``fb[ib[H_G] + GW * m + G_RADIUS]``. A record of several numbers comes back as a tuple
(a rotation as a :class:`Rotation`, read by field name, as the release check's records
are in :mod:`safepath.verify._records`).

Every accessor is inlined into its caller (numba's ``inline="always"``): the same loads
and stores as the hand-written offsets, so the same floats, and no call in the hot loops.
They are compiled without numba's reference counting, like every helper of the layer (see
:mod:`safepath.collision._kernels`); the few that return views of the buffers may do so
only because they are inlined. :func:`workspace`, which allocates a call's scratch, is
compiled with it.

numba's disk cache tracks only the file of the function it compiles: the kernels that
inline these keep their cached code when only this file changes. After editing it in a
source checkout, delete ``safepath/collision/__pycache__/*.nb*`` (the kernels compiled
ahead of time are keyed on this file's source too).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._aot import njit
from ..model._joint_table import JF_W, JF_WIDTH, JI_KIND, JI_PARENT, JI_Q, JI_WIDTH, PRISMATIC
from ._layout import (
    C_FREE_EPS,
    C_PROOF_EPS,
    C_REFINE,
    C_RES,
    E_DIMS,
    E_POS,
    E_ROT,
    EW,
    G_CENTRE,
    G_DIMS,
    G_POS,
    G_RADIUS,
    G_ROT,
    GI_HULL,
    GI_HULL_END,
    GI_INNER,
    GI_INNER_END,
    GI_JOINT,
    GI_KIND,
    GI_OUTER,
    GI_OUTER_END,
    GIW,
    GW,
    H_AI,
    H_AP,
    H_C,
    H_DOF,
    H_DW,
    H_E,
    H_EI,
    H_ER,
    H_G,
    H_GI,
    H_J,
    H_JI,
    H_L,
    H_LAST,
    H_NG,
    H_NJ,
    H_NP,
    H_NS,
    H_P,
    H_PI,
    H_PM,
    H_PW,
    H_S,
    H_V,
    H_W,
    PI_A,
    PI_B,
    PI_ENV,
    PI_PROOF,
    PIW,
    PS_BOUND,
    PS_RADIUS,
    PSW,
    S_RADIUS,
    SW,
    W_A,
    W_AXES,
    W_B,
    W_D,
    W_FIXED,
    W_GV,
    W_P,
    W_R,
    W_S,
    W_TMP,
    WI_A,
    WI_ABSU,
    WI_B,
    WI_BUDGET,
    WI_BUFA,
    WI_BUFB,
    WI_CC,
    WI_CERT,
    WI_CW,
    WI_DL,
    WI_DLOK,
    WI_HEADER,
    WI_HINT,
    WI_WARM,
    WS_HULL,
    WS_HULL_END,
    WS_KIND,
)

#: How the accessors are compiled (see the module doc).
_read = njit(cache=True, nogil=True, _nrt=False, inline="always")

#: The two shapes of a pair placed in the scratch (GJK's and the separating axes' A and B),
#: and the two sets of placed spheres.
A, B = 0, 1


class Rotation(NamedTuple):
    """A rotation (row-major), read by name: column j is the rotated frame's axis j."""

    r00: float
    r01: float
    r02: float
    r10: float
    r11: float
    r12: float
    r20: float
    r21: float
    r22: float


@_read
def _rotation(x, o):
    """The rotation stored row-major at x[o:o+9]."""
    return Rotation(x[o], x[o + 1], x[o + 2], x[o + 3], x[o + 4], x[o + 5], x[o + 6],
                    x[o + 7], x[o + 8])


@_read
def _vector(x, o):
    """The 3-vector at x[o:o+3]."""
    return x[o], x[o + 1], x[o + 2]


# -- the checker (fb, ib) ----------------------------------------------------------------
@_read
def n_joints(ib):
    """Rows of the joint table."""
    return ib[H_NJ]


@_read
def n_movers(ib):
    """Moving bodies (the robot's geometries, then the held object's)."""
    return ib[H_NG]


@_read
def n_spheres(ib):
    """Spheres of all movers (outer and inner)."""
    return ib[H_NS]


@_read
def n_pairs(ib):
    """Checked pairs."""
    return ib[H_NP]


@_read
def dof(ib):
    """Joint coordinates (the length of ``q``)."""
    return ib[H_DOF]


@_read
def limits(fb, ib, v):
    """Lower and upper limit of coordinate ``v`` [rad] or [m]."""
    return fb[ib[H_L] + v], fb[ib[H_L] + ib[H_DOF] + v]


@_read
def refine_below(fb, ib):
    """A pair whose bounding-sphere budget is at most this [m] is measured finer when a
    radius is wanted."""
    return fb[ib[H_C] + C_REFINE]


@_read
def free_eps(fb, ib):
    """What a pair must clear beyond its margin to be proven free [m]."""
    return fb[ib[H_C] + C_FREE_EPS]


@_read
def proof_eps(fb, ib):
    """How far inside its margin a pair must be to be proven colliding [m]."""
    return fb[ib[H_C] + C_PROOF_EPS]


@_read
def resolution(fb, ib):
    """The checker's resolution [m]."""
    return fb[ib[H_C] + C_RES]


@_read
def displacement_weight(fb, ib, v):
    """How far [m] a unit step of coordinate ``v`` can move a point of the robot."""
    return fb[ib[H_DW] + v]


@_read
def joint_table(fb, ib):
    """The joint table's float and int rows (nj x JF_WIDTH, nj x JI_WIDTH): views."""
    nj, oj, oji = ib[H_NJ], ib[H_J], ib[H_JI]
    return (fb[oj:oj + JF_WIDTH * nj].reshape((nj, JF_WIDTH)),
            ib[oji:oji + JI_WIDTH * nj].reshape((nj, JI_WIDTH)))


@_read
def joint_parent(ib, j):
    """Joint ``j``'s parent row (0: the universe, -1: the world)."""
    return ib[ib[H_JI] + JI_WIDTH * j + JI_PARENT]


@_read
def joint_coordinate(ib, j):
    """Joint ``j``'s coordinate in ``q``."""
    return ib[ib[H_JI] + JI_WIDTH * j + JI_Q]


@_read
def joint_is_prismatic(ib, j):
    """Whether joint ``j`` slides (else it turns, or is fixed)."""
    return ib[ib[H_JI] + JI_WIDTH * j + JI_KIND] == PRISMATIC


@_read
def joint_axis(fb, ib, j):
    """Joint ``j``'s rotation axis in its own frame (its screw's angular part)."""
    return _vector(fb, ib[H_J] + JF_WIDTH * j + JF_W)


# Movers.
@_read
def mover_joint(ib, m):
    """The joint that carries mover ``m``."""
    return ib[ib[H_GI] + GIW * m + GI_JOINT]


@_read
def mover_kind(ib, m):
    """Mover ``m``'s shape kind (a shape table code, SPHERES_ONLY or HULL)."""
    return ib[ib[H_GI] + GIW * m + GI_KIND]


@_read
def outer_spheres(ib, m):
    """The rows (start, end) of mover ``m``'s outer spheres (they cover it)."""
    row = ib[H_GI] + GIW * m
    return ib[row + GI_OUTER], ib[row + GI_OUTER_END]


@_read
def inner_spheres(ib, m):
    """The rows (start, end) of mover ``m``'s inner spheres (inside it)."""
    row = ib[H_GI] + GIW * m
    return ib[row + GI_INNER], ib[row + GI_INNER_END]


@_read
def mover_hull(ib, m):
    """The rows (start, end) of mover ``m``'s hull vertices (none: equal)."""
    row = ib[H_GI] + GIW * m
    return ib[row + GI_HULL], ib[row + GI_HULL_END]


@_read
def mover_centre(fb, ib, m):
    """Mover ``m``'s bounding sphere's centre in its joint frame [m]."""
    return _vector(fb, ib[H_G] + GW * m + G_CENTRE)


@_read
def mover_radius(fb, ib, m):
    """Mover ``m``'s bounding sphere's radius [m]."""
    return fb[ib[H_G] + GW * m + G_RADIUS]


@_read
def mover_rotation(fb, ib, m):
    """Mover ``m``'s primitive's rotation in its joint frame."""
    return _rotation(fb, ib[H_G] + GW * m + G_ROT)


@_read
def mover_position(fb, ib, m):
    """Mover ``m``'s primitive's position in its joint frame [m]."""
    return _vector(fb, ib[H_G] + GW * m + G_POS)


@_read
def mover_dims(fb, ib, m):
    """Mover ``m``'s primitive's dimensions [m] (the kernel parameters of its kind)."""
    return _vector(fb, ib[H_G] + GW * m + G_DIMS)


@_read
def mover_weight(fb, ib, m, v):
    """How far [m] a unit step of coordinate ``v`` can move a point of mover ``m``."""
    return fb[ib[H_W] + m * ib[H_DOF] + v]


@_read
def sphere_centre(fb, ib, s):
    """Sphere ``s``'s centre in its mover's joint frame [m]."""
    return _vector(fb, ib[H_S] + SW * s)


@_read
def sphere_radius(fb, ib, s):
    """Sphere ``s``'s radius [m]."""
    return fb[ib[H_S] + SW * s + S_RADIUS]


# Environment objects.
@_read
def env_kind(ib, e):
    """Environment object ``e``'s shape kind (a shape table code or ENV_BOX_ONLY_OUTER)."""
    return ib[ib[H_EI] + e]


@_read
def env_rotation(fb, ib, e):
    """Environment object ``e``'s rotation in the world."""
    return _rotation(fb, ib[H_E] + EW * e + E_ROT)


@_read
def env_position(fb, ib, e):
    """Environment object ``e``'s position in the world [m]."""
    return _vector(fb, ib[H_E] + EW * e + E_POS)


@_read
def env_dims(fb, ib, e):
    """Environment object ``e``'s dimensions [m] (the kernel parameters of its kind)."""
    return _vector(fb, ib[H_E] + EW * e + E_DIMS)


@_read
def env_reach(fb, ib, e):
    """Radius [m] of a sphere about environment object ``e``'s position that holds it."""
    return fb[ib[H_ER] + e]


# Pairs.
@_read
def pair(ib, k):
    """Pair ``k``: (mover a, mover or environment object b, 1 if b is an environment
    object, 1 if a collision can be proven)."""
    row = ib[H_PI] + PIW * k
    return ib[row + PI_A], ib[row + PI_B], ib[row + PI_ENV], ib[row + PI_PROOF]


@_read
def last_collision(ib):
    """The pair whose collision a kernel proved last (-1: none yet)."""
    return ib[H_LAST]


@_read
def set_last_collision(ib, k):
    """Remember pair ``k`` as the one whose collision was proved last."""
    ib[H_LAST] = k


@_read
def pair_margin(fb, ib, k):
    """Pair ``k``'s security margin [m] (negative: an allowed contact depth)."""
    return fb[ib[H_P] + k]


@_read
def pair_moves(ib, k, v):
    """Whether coordinate ``v`` moves pair ``k``'s body a relative to b (bit 1) and b
    relative to a (bit 2)."""
    return ib[ib[H_PM] + k * ib[H_DOF] + v]


@_read
def pair_weight(fb, ib, k, v):
    """How fast [m per unit of coordinate ``v``] that coordinate can close pair ``k``."""
    return fb[ib[H_PW] + k * ib[H_DOF] + v]


# Hulls.
@_read
def hull_vertex(fb, ib, g):
    """Hull vertex row ``g``, in its shape's frame [m]."""
    return _vector(fb, ib[H_V] + 3 * g)


@_read
def hull_edges(ib, g):
    """Where the neighbours of vertex row ``g`` are listed (start, end)."""
    oap = ib[H_AP]
    return ib[oap + g], ib[oap + g + 1]


@_read
def hull_neighbour(ib, e):
    """The vertex row listed at ``e`` (see :func:`hull_edges`)."""
    return ib[ib[H_AI] + e]


# -- a call's scratch (wf, wi) -------------------------------------------------------------
@njit(cache=True, nogil=True)
def workspace(ib):
    """Fresh scratch (Rw, pw, wf, wi) for the checker packed in ``ib``."""
    nj, ng, ns, npairs, nq = ib[H_NJ], ib[H_NG], ib[H_NS], ib[H_NP], ib[H_DOF]
    wi = np.empty(WI_HEADER + 2 * npairs, dtype=np.int64)
    sizes = (3 * ng, PSW * ns, PSW * ns, 3 * npairs, nq, ng * nq, ng * nq, npairs,
             2 * npairs, ng)
    o = W_FIXED
    for i in range(10):
        wi[i] = o
        o += sizes[i]
    wi[WI_HINT] = WI_HEADER
    wi[WI_HEADER:] = -1
    wf = np.empty(o)  # written before read, but for these blocks:
    wf[wi[WI_WARM]:wi[WI_WARM] + 3 * npairs] = 0.0  # no direction yet
    wf[wi[WI_DL]:wi[WI_BUDGET]] = 0.0  # DL, CC of joints that do not move a mover
    return np.empty((nj, 3, 3)), np.empty((nj, 3)), wf, wi


# The movers' bounding spheres in the world.
@_read
def bound_centre(wf, wi, m):
    """Mover ``m``'s bounding sphere's world centre at the placed state [m]."""
    return _vector(wf, wi[WI_CW] + 3 * m)


@_read
def set_bound_centre(wf, wi, m, x, y, z):
    """Write mover ``m``'s bounding sphere's world centre [m]."""
    o = wi[WI_CW] + 3 * m
    wf[o], wf[o + 1], wf[o + 2] = x, y, z


# The two placed shapes of a pair (A, B).
@_read
def _slot(s):
    """Where placed shape ``s`` (A or B) starts in ``wf``."""
    return W_A + (W_B - W_A) * s


@_read
def _int_slot(s):
    """Where placed shape ``s`` (A or B) starts in ``wi``."""
    return WI_A + (WI_B - WI_A) * s


@_read
def placed_rotation(wf, s):
    """Placed shape ``s``'s world rotation."""
    return _rotation(wf, _slot(s) + W_R)


@_read
def placed_rotation_start(s):
    """Where placed shape ``s``'s world rotation (row-major) starts in ``wf``: for the
    shape table's geometry (:mod:`safepath.model._primitives`), which reads a rotation
    from an array."""
    return _slot(s) + W_R


@_read
def placed_axis(wf, s, c):
    """Placed shape ``s``'s axis ``c`` in the world (its rotation's column ``c``)."""
    o = _slot(s) + W_R + c
    return wf[o], wf[o + 3], wf[o + 6]


@_read
def placed_position(wf, s):
    """Placed shape ``s``'s world position [m]."""
    return _vector(wf, _slot(s) + W_P)


@_read
def placed_dims(wf, s):
    """Placed shape ``s``'s dimensions [m] (the kernel parameters of its kind)."""
    return _vector(wf, _slot(s) + W_D)


@_read
def placed_kind(wi, s):
    """Placed shape ``s``'s kind."""
    return wi[_int_slot(s) + WS_KIND]


@_read
def placed_hull(wi, s):
    """Placed shape ``s``'s hull vertex rows (start, end; none: 0, 0)."""
    o = _int_slot(s)
    return wi[o + WS_HULL], wi[o + WS_HULL_END]


@_read
def place(wf, wi, s, R, x, y, z, d0, d1, d2, kind, h0, h1):  # noqa: N803
    """Write placed shape ``s``: its world rotation ``R`` (a :class:`Rotation`) and
    position (x, y, z) [m], its dimensions [m], kind and hull vertex rows."""
    o = _slot(s)
    r = o + W_R
    wf[r], wf[r + 1], wf[r + 2] = R.r00, R.r01, R.r02
    wf[r + 3], wf[r + 4], wf[r + 5] = R.r10, R.r11, R.r12
    wf[r + 6], wf[r + 7], wf[r + 8] = R.r20, R.r21, R.r22
    wf[o + W_P], wf[o + W_P + 1], wf[o + W_P + 2] = x, y, z
    wf[o + W_D], wf[o + W_D + 1], wf[o + W_D + 2] = d0, d1, d2
    i = _int_slot(s)
    wi[i + WS_KIND], wi[i + WS_HULL], wi[i + WS_HULL_END] = kind, h0, h1


# The separating-axis candidates.
@_read
def axis(wf, i):
    """Candidate axis ``i`` (a unit vector)."""
    return _vector(wf, W_AXES + 3 * i)


@_read
def set_axis(wf, i, x, y, z):
    """Write candidate axis ``i``."""
    o = W_AXES + 3 * i
    wf[o], wf[o + 1], wf[o + 2] = x, y, z


# GJK's state.
@_read
def simplex(wf):
    """GJK's simplex (4 x 3), its search direction (3) and a spare 3-vector: views."""
    return wf[W_S:W_S + 12].reshape((4, 3)), wf[W_GV:W_GV + 3], wf[W_TMP:W_TMP + 3]


@_read
def pair_warm(wf, wi, k):
    """Pair ``k``'s last GJK direction (3; zero: none): a view."""
    o = wi[WI_WARM] + 3 * k
    return wf[o:o + 3]


@_read
def pair_hints(wi, k):
    """Pair ``k``'s hull vertices where the support searches of A and B start (2): a
    view."""
    o = wi[WI_HINT] + 2 * k
    return wi[o:o + 2]


# Placed spheres: two sets (A, B), rows of PSW.
@_read
def _sphere_row(wi, which, i):
    """Where sphere ``i`` of placed set ``which`` (A or B) starts in ``wf``."""
    return wi[WI_BUFA + (WI_BUFB - WI_BUFA) * which] + PSW * i


@_read
def placed_sphere(wf, wi, which, i):
    """Sphere ``i`` of placed set ``which``: its world centre and radius [m]."""
    o = _sphere_row(wi, which, i)
    return wf[o], wf[o + 1], wf[o + 2], wf[o + PS_RADIUS]


@_read
def placed_sphere_bound(wf, wi, which, i):
    """Sphere ``i`` of placed set ``which``: a lower bound on its distance to the other
    body's bounding sphere [m]."""
    return wf[_sphere_row(wi, which, i) + PS_BOUND]


@_read
def set_placed_sphere(wf, wi, which, i, x, y, z, r, bound):
    """Write sphere ``i`` of placed set ``which`` (see :func:`placed_sphere`,
    :func:`placed_sphere_bound`)."""
    o = _sphere_row(wi, which, i)
    wf[o], wf[o + 1], wf[o + 2], wf[o + PS_RADIUS] = x, y, z, r
    wf[o + PS_BOUND] = bound


# Along a segment: |u|, the axis distances and their growth, the ledger, the certificates.
@_read
def abs_u(wf, wi, v):
    """|u_v|: the segment direction's coordinate ``v``, unsigned."""
    return wf[wi[WI_ABSU] + v]


@_read
def set_abs_u(wf, wi, v, x):
    """Write |u_v|."""
    wf[wi[WI_ABSU] + v] = x


@_read
def axis_distance(ib, wf, wi, m, v):
    """How fast [m per unit of coordinate ``v``] mover ``m``'s points move when ``v``
    alone moves, at the evaluated state (DL)."""
    return wf[wi[WI_DL] + m * ib[H_DOF] + v]


@_read
def set_axis_distance(ib, wf, wi, m, v, x):
    """Write DL[m, v] (see :func:`axis_distance`)."""
    wf[wi[WI_DL] + m * ib[H_DOF] + v] = x


@_read
def axis_growth(ib, wf, wi, m, v):
    """How fast DL[m, v] can grow per unit of ``t`` along the segment (CC)."""
    return wf[wi[WI_CC] + m * ib[H_DOF] + v]


@_read
def set_axis_growth(ib, wf, wi, m, v, x):
    """Write CC[m, v] (see :func:`axis_growth`)."""
    wf[wi[WI_CC] + m * ib[H_DOF] + v] = x


@_read
def axes_measured(wf, wi, m):
    """Whether mover ``m``'s DL row is measured at the evaluated state."""
    return wf[wi[WI_DLOK] + m] != 0.0


@_read
def set_axes_measured(wf, wi, m):
    """Mark mover ``m``'s DL row as measured."""
    wf[wi[WI_DLOK] + m] = 1.0


@_read
def forget_axes(ib, wf, wi):
    """Mark every mover's DL row as not measured (a new state)."""
    wf[wi[WI_DLOK]:wi[WI_DLOK] + ib[H_NG]] = 0.0


@_read
def ledger(wf, wi, k):
    """Pair ``k``'s ledger entry: the most clearance budget [m] an evaluated state
    leaves at the end of the segment being walked."""
    return wf[wi[WI_BUDGET] + k]


@_read
def set_ledger(wf, wi, k, x):
    """Write pair ``k``'s ledger entry [m]."""
    wf[wi[WI_BUDGET] + k] = x


@_read
def clear_ledger(ib, wf, wi):
    """No budget for any pair (before the first segment)."""
    wf[wi[WI_BUDGET]:wi[WI_BUDGET] + ib[H_NP]] = -1.0


@_read
def certified(wf, wi, k):
    """The stretch pair ``k`` is certified along: centre and half-width in units of
    ``t`` (a negative width: none)."""
    o = wi[WI_CERT] + 2 * k
    return wf[o], wf[o + 1]


@_read
def set_certified(wf, wi, k, centre, width):
    """Write pair ``k``'s certified stretch (see :func:`certified`)."""
    o = wi[WI_CERT] + 2 * k
    wf[o] = centre
    wf[o + 1] = width
