"""The release check's numba kernel: its own forward kinematics and the walk along the
grid.

Part of the verifier's independent geometry (:mod:`safepath.verify`; the distance
bounds it walks with are :mod:`safepath.verify._distance`): it shares no code with the
planner's kernels (:mod:`safepath.collision`), on purpose. Imported lazily by
``_bounds`` (numba takes a while to import); compiled once and cached on disk. Plain
loops, no ``np.dot`` or ``@``.

What the walk reads comes in small records read by field name (``typing.NamedTuple``,
which numba compiles to plain structs; defined in :mod:`safepath.verify._records`): the
grid (``Samples``), the joints and bodies (``Kinematics``), the pose cache (``Poses``),
the pairs (``Pairs``), the shapes (``World``), what the walks learn (``Memory``), the
margins (``Params``) and the buffers (``Scratch``); a pose in locals is a ``Pose``, a
placed shape a :class:`~safepath.verify._distance.Placed`. The walk is
split into named steps (``_threshold``, ``_shapes``, ``_bound``, ``_set_shares``,
``_reach``, ...), each inlined into it (``inline="always"``): the same operations, so
the same floats, and no call in the hot loop.

The walk is compiled without numba's reference counting (``_nrt=False``): it allocates
nothing, its scratch and output buffers come from the caller, and a reference count on
every array it touches cost ~8 % of its time. :func:`certify` is the entry point that
calls it and builds its records from the plain tuples the caller passes (an
ahead-of-time build compiles entry points with reference counting, their callees as
they are declared; its guards take plain tuples). The walk returns when its output
buffers are full, with the place to resume from.

numba's disk cache tracks only the file of the function it compiles: the walk keeps its
cached code when only :mod:`safepath.verify._distance` changes. After editing that in a
source checkout, delete ``safepath/verify/__pycache__/*.nb*`` (the kernels compiled
ahead of time are keyed on both files' sources).
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit
from ._distance import (
    CENTRE,
    KIND,
    PAR,
    RADIUS,
    Hulls,
    Placed,
    axis_bound,
    gap,
    gjk_bound,
    sphere_bound,
)
from ._records import (
    APPROX,
    KEPT,
    PRISMATIC,
    Kinematics,
    Memory,
    Pairs,
    Params,
    Pose,
    Poses,
    Samples,
    Scratch,
    World,
)

#: How every function here but the entry points is compiled (see the module doc).
_kernel = njit(cache=True, _nrt=False)
#: How the walk's steps are compiled: inlined into the walk (numba's ``inline="always"``),
#: as its closures were, so that splitting it into steps changes no operation (and no
#: time: a call would copy the records and the placed shapes onto the stack).
_step = njit(cache=True, _nrt=False, inline="always")

@njit(cache=True)
def grid(q: np.ndarray, weights: np.ndarray, resolution: float
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cut the knots ``q`` (knots x dof) so that no body moves more than ``resolution``
    [m] between two samples, the bodies' motion weights being ``weights`` (bodies x
    dof): a knot interval whose weighted step reaches n resolutions gets n samples.

    Returns:
        (knot of every sample, fraction of its interval, |dq| into every knot (0 at the
        first), its accumulated sum): see ``_bounds.Grid``.
    """
    knots, dof = q.shape
    step = np.empty((knots, dof))
    cum = np.empty((knots, dof))
    cuts = np.ones(knots, dtype=np.int64)
    total = 1
    for v in range(dof):
        step[0, v] = 0.0
        cum[0, v] = 0.0
    for k in range(1, knots):
        for v in range(dof):
            step[k, v] = abs(q[k, v] - q[k - 1, v])
            cum[k, v] = cum[k - 1, v] + step[k, v]
        most = 0.0
        for b in range(weights.shape[0]):
            moved = 0.0
            for v in range(dof):
                moved += step[k, v] * weights[b, v]
            most = max(most, moved)
        cuts[k] = max(int(math.ceil(most / resolution)), 1)
        total += cuts[k]
    knot_of = np.empty(total, dtype=np.int64)
    frac = np.empty(total)
    knot_of[0], frac[0] = 0, 1.0
    s = 1
    for k in range(1, knots):
        for i in range(1, cuts[k] + 1):
            knot_of[s], frac[s] = k, i / cuts[k]
            s += 1
    return knot_of, frac, step, cum


@_kernel
def _basis(x: float, y: float, z: float) -> int:
    """0, 1 or 2 if (x, y, z) is the unit x, y or z axis, else -1."""
    if y == 0.0 and z == 0.0 and x == 1.0:
        return 0
    if x == 0.0 and z == 0.0 and y == 1.0:
        return 1
    if x == 0.0 and y == 0.0 and z == 1.0:
        return 2
    return -1


@_kernel
def _joint_motion(kind: int, value: float, x: float, y: float, z: float) -> Pose:
    """A joint's own motion: a rotation about the unit axis (x, y, z) by ``value`` [rad]
    (Rodrigues), or a shift along it by ``value`` [m] (prismatic)."""
    if kind == PRISMATIC:
        return Pose(1.0, 0.0, 0.0, x * value, 0.0, 1.0, 0.0, y * value,
                    0.0, 0.0, 1.0, z * value)
    co, si = math.cos(value), math.sin(value)
    t = 1.0 - co
    return Pose(co + t * x * x, t * x * y - si * z, t * x * z + si * y, 0.0,
                t * x * y + si * z, co + t * y * y, t * y * z - si * x, 0.0,
                t * x * z - si * y, t * y * z + si * x, co + t * z * z, 0.0)


@_kernel
def _turned(p0: float, p1: float, p2: float, along: int, co: float, si: float
            ) -> tuple[float, float, float]:
    """A row (p0, p1, p2) of a joint's placement times its turn about its own axis
    ``along`` (0, 1 or 2) by the angle of cosine ``co`` and sine ``si``: the other two
    columns turn into each other."""
    if along == 0:
        return p0, p1 * co + p2 * si, p2 * co - p1 * si
    if along == 1:
        return p0 * co - p2 * si, p1, p2 * co + p0 * si
    return p0 * co + p1 * si, p1 * co - p0 * si, p2


@_kernel
def _row_times(a0: float, a1: float, a2: float, a3: float, M: Pose
               ) -> tuple[float, float, float, float]:
    """A row (a0, a1, a2, a3) of a pose times the pose ``M``."""
    return (a0 * M.r00 + a1 * M.r10 + a2 * M.r20, a0 * M.r01 + a1 * M.r11 + a2 * M.r21,
            a0 * M.r02 + a1 * M.r12 + a2 * M.r22, a0 * M.t0 + a1 * M.t1 + a2 * M.t2 + a3)


@_step
def _times(T: np.ndarray, M: Pose) -> Pose:
    """The pose ``T`` (a 3 x 4 array) times the pose ``M`` (:func:`_times_pose`)."""
    return _times_pose(_pose_of(T), M)


@_step
def _pose_of(T: np.ndarray) -> Pose:
    """The pose ``T`` (a 3 x 4 array), read into locals."""
    return Pose(T[0, 0], T[0, 1], T[0, 2], T[0, 3], T[1, 0], T[1, 1], T[1, 2], T[1, 3],
                T[2, 0], T[2, 1], T[2, 2], T[2, 3])


@_step
def _store(T: np.ndarray, M: Pose) -> None:
    """Write the pose ``M`` into ``T`` (a 3 x 4 array)."""
    T[0, 0], T[0, 1], T[0, 2], T[0, 3] = M.r00, M.r01, M.r02, M.t0
    T[1, 0], T[1, 1], T[1, 2], T[1, 3] = M.r10, M.r11, M.r12, M.t1
    T[2, 0], T[2, 1], T[2, 2], T[2, 3] = M.r20, M.r21, M.r22, M.t2


@njit(cache=True)
def certify(todo: np.ndarray, first: np.ndarray, stop: np.ndarray, theta: np.ndarray,
            grid: tuple, kin: tuple, cache: tuple, pairs: tuple, world: tuple, memory: tuple,
            params: tuple, scratch: tuple, t0: int, s0: int) -> tuple[int, int, int]:
    """Walk every pair in ``todo`` along its stretch of the grid with the lower bound
    (see :func:`_walk`, which it calls).

    The tuples are the walk's records in their fields' order (:class:`Kinematics`,
    :class:`Poses`, :class:`Pairs`, :class:`Memory`, :class:`Params`, :class:`Scratch`;
    ``world``: the shape table, the environment's poses and the :class:`Hulls` tables;
    ``grid``: the accumulated joint motion and its steps, the same for the upstream
    turning, the knots, the knot and fraction of every sample): the ahead-of-time
    guards take plain tuples.

    The joints' accumulated motion and upstream turning are interpolated to every sample
    here, once per walk: a step's search reads them for every joint at every probe
    (three probes per step, on average), and did the same interpolation each time."""
    cum, step, cum_turn, step_turn, qk, knot_of, frac = grid
    at, at_turn = _accumulated(cum, step, knot_of, frac), _accumulated(cum_turn, step_turn,
                                                                       knot_of, frac)
    shapes, env_pose, hulls = world
    return _walk(todo, first, stop, theta,  # type: ignore[no-any-return]
                 Samples(at, at_turn, qk, knot_of, frac), Kinematics(*kin), Poses(*cache),
                 Pairs(*pairs), World(shapes, env_pose, Hulls(*hulls)), Memory(*memory),
                 Params(*params), Scratch(*scratch), t0, s0)


@njit(cache=True)
def _accumulated(cum: np.ndarray, step: np.ndarray, knot_of: np.ndarray, frac: np.ndarray
                 ) -> np.ndarray:
    """The accumulated sum ``cum`` (knots x dof) of the steps ``step`` into every knot,
    at every sample (samples x dof; zero at the first knot's): the same expression the
    walk evaluated at each probe, so the same numbers."""
    out = np.empty((knot_of.size, cum.shape[1]))
    for s in range(knot_of.size):
        k = knot_of[s]
        for v in range(cum.shape[1]):
            out[s, v] = 0.0 if k == 0 else cum[k - 1, v] + frac[s] * step[k, v]
    return out


@njit(cache=True)
def body_poses(states: np.ndarray, kin: tuple, m: int, out: np.ndarray) -> None:
    """Moving body ``m``'s geometry frame in the world at each joint state of ``states``
    (states x dof [rad] or [m]), into ``out`` (states x 3 x 4): the states off the grid
    that the check between samples measures, placed with the walk's operations
    (:func:`_placed_motion` joint after joint from the base, then the body's placement):
    at a state of the grid, the joint poses are the walk's, bit for bit.

    ``kin`` is the :class:`Kinematics` record's fields in order (the ahead-of-time
    guards take plain tuples)."""
    k = Kinematics(*kin)
    chain = np.empty(k.parent.size, dtype=np.int64)
    count, j = 0, k.m_joint[m]
    while j > 0:
        chain[count] = j
        count += 1
        j = k.parent[j]
    P = _pose_of(k.m_place[m])
    for i in range(states.shape[0]):
        T = P
        if count:
            T = _placed_motion(k, chain[count - 1], states[i, k.iq[chain[count - 1]]])
            for c in range(count - 2, -1, -1):
                T = _times_pose(T, _placed_motion(k, chain[c], states[i, k.iq[chain[c]]]))
            T = _times_pose(T, P)
        _store(out[i], T)


@_step
def _times_pose(A: Pose, M: Pose) -> Pose:
    """The pose ``A`` times the pose ``M`` (both in locals)."""
    r00, r01, r02, t0 = _row_times(A.r00, A.r01, A.r02, A.t0, M)
    r10, r11, r12, t1 = _row_times(A.r10, A.r11, A.r12, A.t1, M)
    r20, r21, r22, t2 = _row_times(A.r20, A.r21, A.r22, A.t2, M)
    return Pose(r00, r01, r02, t0, r10, r11, r12, t1, r20, r21, r22, t2)


# -- the walk's steps: forward kinematics ----------------------------------------------------
@_step
def _joint_value(g: Samples, col: int, s: int) -> float:
    """Position of velocity index ``col`` at sample ``s`` [rad] or [m]."""
    knot = g.knot_of[s]
    return g.qk[0, col] if knot == 0 else (  # type: ignore[no-any-return]
        g.qk[knot - 1, col] + g.frac[s] * (g.qk[knot, col] - g.qk[knot - 1, col]))


@_step
def _placed_motion(kin: Kinematics, k: int, value: float) -> Pose:
    """Joint k's placement times its own motion at ``value`` (a rotation about its axis
    or a shift along it)."""
    x, y, z = kin.axis[k, 0], kin.axis[k, 1], kin.axis[k, 2]
    P = kin.place[k]
    along = _basis(x, y, z) if kin.kind[k] != PRISMATIC else -1
    if along < 0:
        return _times(P, _joint_motion(kin.kind[k], value, x, y, z))  # type: ignore[no-any-return]
    # The usual joints: a turn about the joint's own x, y or z (the general case, with
    # the zeros left out).
    co, si = math.cos(value), math.sin(value)
    m00, m01, m02 = _turned(P[0, 0], P[0, 1], P[0, 2], along, co, si)
    m10, m11, m12 = _turned(P[1, 0], P[1, 1], P[1, 2], along, co, si)
    m20, m21, m22 = _turned(P[2, 0], P[2, 1], P[2, 2], along, co, si)
    return Pose(m00, m01, m02, P[0, 3], m10, m11, m12, P[1, 3], m20, m21, m22, P[2, 3])


@_step
def _joint_poses(g: Samples, kin: Kinematics, poses: Poses, chain: np.ndarray, s: int,
                 j: int) -> None:
    """poses.pose[s, j] (and its missing ancestors) = parent's pose * placement * the
    joint's own motion. The placement times the motion is kept in locals, and the
    parent's pose read before the joint's is written: through arrays, every write to
    the pose could overwrite what the next product reads, and would be read back."""
    count, k = 0, j
    while k > 0 and not poses.done[s, k]:
        chain[count] = k
        count += 1
        k = kin.parent[k]
    for c in range(count - 1, -1, -1):
        k = chain[c]
        M = _placed_motion(kin, k, _joint_value(g, kin.iq[k], s))
        p = kin.parent[k]
        _store(poses.pose[s, k], M if p == 0 else _times(poses.pose[s, p], M))
        poses.done[s, k] = True


# -- the walk's steps: the pair's shapes -----------------------------------------------------
@_step
def _placed(shapes: np.ndarray, k: int, T: Pose) -> Placed:
    """Shape k (a row of the shape table) with its geometry frame at ``T``."""
    c0, c1, c2 = shapes[k, CENTRE], shapes[k, CENTRE + 1], shapes[k, CENTRE + 2]
    return Placed(shapes[k, KIND], shapes[k, PAR], shapes[k, PAR + 1], shapes[k, PAR + 2],
                  shapes[k, RADIUS],
                  T.t0 + T.r00 * c0 + T.r01 * c1 + T.r02 * c2,
                  T.t1 + T.r10 * c0 + T.r11 * c1 + T.r12 * c2,
                  T.t2 + T.r20 * c0 + T.r21 * c1 + T.r22 * c2,
                  T.r00, T.r01, T.r02, T.r10, T.r11, T.r12, T.r20, T.r21, T.r22)


@_step
def _placed_body(g: Samples, kin: Kinematics, poses: Poses, chain: np.ndarray,
                 shapes: np.ndarray, s: int, m: int) -> Placed:
    """Body m's shape at sample s: its geometry frame is its joint's pose times its
    placement in the joint frame."""
    j = kin.m_joint[m]
    if j > 0 and not poses.done[s, j]:
        _joint_poses(g, kin, poses, chain, s, j)
    P = _pose_of(kin.m_place[m])
    return _placed(shapes, m, P if j == 0 else _times(poses.pose[s, j], P))  # type: ignore[no-any-return]


@_step
def _shapes(g: Samples, kin: Kinematics, poses: Poses, chain: np.ndarray, world: World,
            pairs: Pairs, p: int, s: int) -> tuple[Placed, Placed]:
    """Pair p's two shapes at sample s (an environment object's rows follow the
    bodies' in the shape table)."""
    a, b = pairs.a[p], pairs.b[p]
    Sa = _placed_body(g, kin, poses, chain, world.shapes, s, a)
    if pairs.env[p]:
        return Sa, _placed(world.shapes, kin.m_joint.size + b, _pose_of(world.env_pose[b]))
    return Sa, _placed_body(g, kin, poses, chain, world.shapes, s, b)


# -- the walk's steps: the bound at a sample ---------------------------------------------------
@_step
def _threshold(theta: np.ndarray, pairs: Pairs, memory: Memory, params: Params, p: int
               ) -> float:
    """Pair p's threshold [m]: its own, or for a clearance pair the ceiling minus
    ``drop`` if that is higher (see :class:`Params`)."""
    if pairs.tracked[p] and params.drop >= 0.0:
        return max(theta[p], memory.ceiling[0] - params.drop)  # type: ignore[no-any-return]
    return theta[p]  # type: ignore[no-any-return]


@_step
def _full_bound(Sa: Placed, Sb: Placed, hulls: Hulls, memory: Memory, params: Params,
                scratch: Scratch, tracked: bool, p: int, s: int, th: float
                ) -> tuple[float, float, float, float]:
    """The axis bound, refined with GJK below th + fine (a clearance pair's GJK upper
    bound lowers the ceiling), and its axis."""
    full, f0, f1, f2 = axis_bound(Sa, Sb, hulls)
    memory.stats[1] += 1
    if full <= th + params.fine:
        full, upper, f0, f1, f2 = gjk_bound(Sa, Sb, hulls, full, f0, f1, f2,
                                            memory.axes[p, KEPT] != 0.0, scratch.W,
                                            scratch.e, scratch.idx)
        memory.stats[2] += 1
        if tracked and upper < memory.ceiling[0]:
            memory.ceiling[0], memory.ceiling[1], memory.ceiling[2] = upper, p, s
    return full, f0, f1, f2


@_step
def _bound(Sa: Placed, Sb: Placed, hulls: Hulls, memory: Memory, params: Params,
           scratch: Scratch, tracked: bool, p: int, s: int, th: float
           ) -> tuple[float, float, float, float]:
    """Pair p's lower bound at sample s [m] and its axis n: the cheap bounds first, the
    finer ones only where those are not enough. Each is a gap along an axis, kept for
    the step."""
    bound, n0, n1, n2 = sphere_bound(Sa, Sb)
    memory.stats[0] += 1
    if not bound <= th + params.coarse:  # (a NaN bound is not refined, as before)
        return bound, n0, n1, n2
    axes = memory.axes
    if axes[p, KEPT] != 0.0:
        warm = gap(Sa, Sb, hulls, axes[p, 0], axes[p, 1], axes[p, 2])
        if warm > bound:
            bound, n0, n1, n2 = warm, axes[p, 0], axes[p, 1], axes[p, 2]
    # The kept axis is trusted while its gap has not fallen far below the last full
    # bound; else (or without one) the full bound is computed.
    if bound - th < params.keep * (memory.last[p] - th) or axes[p, KEPT] == 0.0:
        full, f0, f1, f2 = _full_bound(Sa, Sb, hulls, memory, params, scratch, tracked, p,
                                       s, th)
        if full >= bound:
            bound, n0, n1, n2 = full, f0, f1, f2
        axes[p, 0], axes[p, 1], axes[p, 2], axes[p, KEPT] = n0, n1, n2, 1.0
        memory.last[p] = bound
    return bound, n0, n1, n2


# -- the walk's steps: how far the bound certifies -------------------------------------------
@_step
def _world_axis(kin: Kinematics, J: np.ndarray, j: int) -> tuple[float, float, float]:
    """Joint j's axis in the world, its pose being ``J`` (3 x 4)."""
    along = _basis(kin.axis[j, 0], kin.axis[j, 1], kin.axis[j, 2])
    if along >= 0:  # the pose's own axis: its column
        return J[0, along], J[1, along], J[2, along]
    a0, a1, a2 = kin.axis[j, 0], kin.axis[j, 1], kin.axis[j, 2]
    return (J[0, 0] * a0 + J[0, 1] * a1 + J[0, 2] * a2,
            J[1, 0] * a0 + J[1, 1] * a1 + J[1, 2] * a2,
            J[2, 0] * a0 + J[2, 1] * a1 + J[2, 2] * a2)


@_step
def _set_shares(kin: Kinematics, poses: Poses, pairs: Pairs, scratch: Scratch, p: int,
                s: int, n0: float, n1: float, n2: float, Sa: Placed, Sb: Placed) -> None:
    """For every joint that moves pair p, at sample s: |n x u| (revolute) or |n . u|
    (prismatic), u being the joint's axis in the world (see :func:`_gap_change`), and
    how far the points of the body it moves lie from its axis (``scratch.reach``: the
    body's bounding sphere's centre's distance plus its radius; a prismatic joint: its
    weight)."""
    share, reach = scratch.share, scratch.reach
    for v in range(pairs.weights.shape[1]):
        if pairs.weights[p, v] == 0.0:
            continue
        j = kin.joint_of[v]
        J = poses.pose[s, j]
        u0, u1, u2 = _world_axis(kin, J, j)
        if kin.kind[j] == PRISMATIC:
            share[v] = abs(n0 * u0 + n1 * u1 + n2 * u2)
            reach[v] = pairs.weights[p, v]
            continue
        c0, c1, c2 = n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0
        share[v] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        S = Sb if pairs.moves_b[p, v] else Sa
        d0, d1, d2 = S.cx - J[0, 3], S.cy - J[1, 3], S.cz - J[2, 3]
        c0, c1, c2 = d1 * u2 - d2 * u1, d2 * u0 - d0 * u2, d0 * u1 - d1 * u0
        reach[v] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) + S.radius


@_step
def _gap_change(g: Samples, pairs: Pairs, scratch: Scratch, p: int, s: int, i: int
                ) -> float:
    """Bound on how much pair p's gap along its axis n can change from sample s to
    i [m]. A revolute joint turning by dq moves a point at r from its axis by at
    most r dq, perpendicular to the axis u, so along n by at most r dq |n x u|;
    while the joints upstream turn by a, u turns by at most a, so |n x u| stays
    below its value at s plus a (and below 1). A prismatic joint moves points
    along u: |n . u| instead. Between two bodies, joints that move
    both leave their distance alone (their weight is zero; taking n in the frame
    they move keeps the argument, and the turning counted is only more).

    r is at most the joint's weight for the body it moves, and at most the body's
    reach from the axis at s (``scratch.reach``) plus what the joints between the two
    have moved its points since (each by its weight times its motion: they change
    the body's distance to the axis, the joints upstream move both alike). Those
    joints come after it in velocity order (a joint's children follow it), so one
    pass from the last joint adds them up, per body."""
    acc = grown_a = grown_b = 0.0
    share, reach = scratch.share, scratch.reach
    w_p, b_p, at_i, at_s = pairs.weights[p], pairs.moves_b[p], g.at[i], g.at[s]
    turn_i, turn_s = g.at_turn[i], g.at_turn[s]
    for v in range(g.qk.shape[1] - 1, -1, -1):
        w = w_p[v]
        if w == 0.0:
            continue
        moved = at_i[v] - at_s[v]
        turned = turn_i[v] - turn_s[v]
        if b_p[v]:
            r = min(w, reach[v] + grown_b)
            grown_b += w * moved
        else:
            r = min(w, reach[v] + grown_a)
            grown_a += w * moved
        acc += r * min(1.0, share[v] + turned) * moved
    return acc


@_step
def _next_probe(s: int, lo: int, hi: int, m_lo: float, m_hi: float, target: float,
                count: int) -> int:
    """The next sample :func:`_reach` probes: extrapolated from the motion seen so far
    (overshooting a little) until the target is bracketed, then every third probe
    halves the bracket and the others interpolate in it."""
    if m_hi == np.inf:
        slope = m_lo / (lo - s)
        ahead = 2 * (lo - s) if slope <= 0.0 else int(1.1 * (target - m_lo) / slope) + 1
        return min(lo + max(ahead, 1), hi - 1)
    if count % 3 == 0:
        return (lo + hi) // 2
    share = (target - m_lo) / (m_hi - m_lo)
    return min(max(lo + int(share * (hi - lo)), lo + 1), hi - 1)


@_step
def _reach(g: Samples, pairs: Pairs, scratch: Scratch, p: int, s: int, end: int,
           target: float, rate: float) -> tuple[int, float]:
    """A sample after s up to which pair p's gap cannot have changed by target [m]
    (the first at which it can, ``end`` (the end of the stretch walked) if none
    before, or one close before it: see APPROX), and the motion per sample seen on
    the way [m] (the next call's first guess; 0: none). The bound never decreases
    along the grid and grows about linearly: the first probe is where ``rate`` (the
    last call's) says the target is reached (without one, the next sample), the next
    ones as :func:`_next_probe` says; once the bracket is within a 1/APPROX share of
    the step, the sample after its low end is returned. Invariant: motion(lo) <
    target; motion(hi) >= target, or hi is ``end`` and its motion unknown (inf)."""
    lo, hi, m_lo, m_hi, count = s, end, 0.0, np.inf, 0
    probe = s + 1 if rate <= 0.0 else min(max(s + int(target / rate), s + 1), end - 1)
    while hi - lo > 1:
        m = _gap_change(g, pairs, scratch, p, s, probe)
        if m >= target:
            hi, m_hi = probe, m
        else:
            lo, m_lo = probe, m
        count += 1
        if hi - lo <= 1:
            break
        if m_hi != np.inf and (hi - lo) * APPROX <= lo - s:
            return lo + 1, m_lo / (lo - s)
        probe = _next_probe(s, lo, hi, m_lo, m_hi, target, count)
    if m_hi != np.inf:
        return hi, m_hi / (hi - s)
    return hi, (m_lo / (lo - s) if lo > s else 0.0)


@_kernel
def _walk(todo: np.ndarray, first: np.ndarray, stop: np.ndarray, theta: np.ndarray,
          g: Samples, kin: Kinematics, poses: Poses, pairs: Pairs, world: World,
          memory: Memory, params: Params, scratch: Scratch, t0: int, s0: int
          ) -> tuple[int, int, int]:
    """Walk every pair in ``todo`` along its stretch of the grid with the lower bound.

    At a sample whose bound exceeds the pair's threshold, the samples until the bound
    on how much the pair's gap (along the bound's axis) can have changed reaches the
    excess are certified; a sample whose bound does not exceed it is returned, for FCL,
    and the walk goes on at the next sample. Its steps, in order: the threshold
    (:func:`_threshold`), the pair's shapes (:func:`_shapes`, computing the joint poses
    they need), the bound (:func:`_bound`), and, above the threshold, how far it
    certifies (:func:`_set_shares`, :func:`_reach`).

    Args:
        todo: Pairs to walk, in this order (a pair may come more than once, for
            stretches apart).
        first, stop: The stretch of the grid each entry of ``todo`` walks: samples
            ``first`` to ``stop`` - 1.
        theta: Threshold of every pair [m].
        g: The grid (:class:`Samples`).
        kin: The joints and bodies (:class:`Kinematics`).
        poses: The joint poses by sample (:class:`Poses`; filled here).
        pairs: The pairs (:class:`Pairs`).
        world: The shapes (:class:`World`).
        memory: What the walks of this grid learnt (:class:`Memory`; updated).
        params: The bounds' margins (:class:`Params`).
        scratch: Scratch and output buffers (:class:`Scratch`).
        t0, s0: Where to start: the walk of ``todo[t0]`` at sample ``s0`` (0,
            ``first[0]``: from the beginning; else where the last call stopped).

    Returns:
        The number of uncertified (pair, sample) couples written to the outputs (entry
        by entry, samples ascending), and where to resume: (``todo.size``, 0) when the
        walk is done, else the place after the last couple written (the outputs were
        full). A walk resumed there goes on exactly as if it had not stopped.
    """
    scratch.share[:] = 1.0
    cap = scratch.out_p.size
    count = 0
    for t in range(t0, todo.size):
        p, end = todo[t], stop[t]
        s = s0 if t == t0 else first[t]
        rate = 0.0
        while s < end:
            th = _threshold(theta, pairs, memory, params, p)
            Sa, Sb = _shapes(g, kin, poses, scratch.chain, world, pairs, p, s)
            bound, n0, n1, n2 = _bound(Sa, Sb, world.hulls, memory, params, scratch,
                                       pairs.tracked[p], p, s, th)
            if bound > th:
                _set_shares(kin, poses, pairs, scratch, p, s, n0, n1, n2, Sa, Sb)
                s, rate = _reach(g, pairs, scratch, p, s, end, bound - th, rate)
                continue
            scratch.out_p[count] = p
            scratch.out_s[count] = s
            scratch.out_b[count] = bound
            count += 1
            s += 1
            if count == cap:
                return count, t, s
    return count, todo.size, 0
