"""The release check's numba kernel: its own forward kinematics and the walk along the
grid.

Part of the verifier's independent geometry (:mod:`safepath.verify`; the distance
bounds it walks with are :mod:`safepath.verify._distance`): it shares no code with the
planner's kernels (:mod:`safepath.collision`), on purpose. Imported lazily by
``_bounds`` (numba takes a while to import); compiled once and cached on disk. Plain
loops, no ``np.dot`` or ``@``; the array work of the walk sits in closures inside
:func:`certify`: a numba helper that takes arrays pays their reference counting on every
call.

The walk is compiled without numba's reference counting (``_nrt=False``): it allocates
nothing, its scratch and output buffers come from the caller, and a reference count on
every array it touches cost ~8 % of its time. :func:`certify` is the entry point that
calls it (an ahead-of-time build compiles entry points with reference counting, their
callees as they are declared). The walk returns when its output buffers are full, with
the place to resume from.

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
    axis_bound,
    gap,
    gjk_bound,
    sphere_bound,
)

#: How every function here but the entry points is compiled (see the module doc).
_kernel = njit(cache=True, _nrt=False)

#: A step's search for the first sample its bound does not certify stops once it has that
#: sample within a 1/APPROX share of the step (the step then ends at the last sample it
#: knows certified): pinning it down to the sample costs more motion probes than the
#: few extra bounds save.
APPROX = 3
REVOLUTE, PRISMATIC = 1, 2


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
def _motion(kind: int, value: float, x: float, y: float, z: float
            ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """A joint's own rotation (row-major): about the unit axis (x, y, z) by ``value``
    [rad] (Rodrigues), or none for a prismatic joint."""
    if kind == PRISMATIC:
        return 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    co, si = math.cos(value), math.sin(value)
    t = 1.0 - co
    return (co + t * x * x, t * x * y - si * z, t * x * z + si * y,
            t * x * y + si * z, co + t * y * y, t * y * z - si * x,
            t * x * z - si * y, t * y * z + si * x, co + t * z * z)


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
def _placed_row(p0: float, p1: float, p2: float, p3: float, r00: float, r01: float,
                r02: float, r10: float, r11: float, r12: float, r20: float, r21: float,
                r22: float, t0: float, t1: float, t2: float
                ) -> tuple[float, float, float, float]:
    """A row (p0, p1, p2, p3) of a joint's placement times its motion (rotation r,
    row-major, and shift t)."""
    return (p0 * r00 + p1 * r10 + p2 * r20, p0 * r01 + p1 * r11 + p2 * r21,
            p0 * r02 + p1 * r12 + p2 * r22, p0 * t0 + p1 * t1 + p2 * t2 + p3)


@_kernel
def _pose_row(a0: float, a1: float, a2: float, a3: float, m00: float, m01: float,
              m02: float, m03: float, m10: float, m11: float, m12: float, m13: float,
              m20: float, m21: float, m22: float, m23: float
              ) -> tuple[float, float, float, float]:
    """A row (a0, a1, a2, a3) of a pose times the pose m (3 x 4, row-major)."""
    return (a0 * m00 + a1 * m10 + a2 * m20, a0 * m01 + a1 * m11 + a2 * m21,
            a0 * m02 + a1 * m12 + a2 * m22, a0 * m03 + a1 * m13 + a2 * m23 + a3)


@njit(cache=True)
def certify(todo: np.ndarray, first: np.ndarray, stop: np.ndarray, theta: np.ndarray,
            grid: tuple, kin: tuple, cache: tuple, pairs: tuple, world: tuple, memory: tuple,
            params: tuple, scratch: tuple, t0: int, s0: int) -> tuple[int, int, int]:
    """Walk every pair in ``todo`` along its stretch of the grid with the lower bound
    (see :func:`_walk`, which it calls).

    The joints' accumulated motion and upstream turning are interpolated to every sample
    here, once per walk: a step's search reads them for every joint at every probe
    (three probes per step, on average), and did the same interpolation each time."""
    cum, step, cum_turn, step_turn, qk, knot_of, frac = grid
    at, at_turn = _accumulated(cum, step, knot_of, frac), _accumulated(cum_turn, step_turn,
                                                                       knot_of, frac)
    return _walk(todo, first, stop, theta,  # type: ignore[no-any-return]
                 (at, at_turn, qk, knot_of, frac), kin, cache, pairs, world, memory, params,
                 scratch, t0, s0)


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


@_kernel
def _walk(todo: np.ndarray, first: np.ndarray, stop: np.ndarray, theta: np.ndarray,
          grid: tuple, kin: tuple, cache: tuple, pairs: tuple, world: tuple, memory: tuple,
          params: tuple, scratch: tuple, t0: int, s0: int) -> tuple[int, int, int]:
    """Walk every pair in ``todo`` along its stretch of the grid with the lower bound.

    At a sample whose bound exceeds the pair's threshold, the samples until the bound
    on how much the pair's gap (along the bound's axis) can have changed reaches the
    excess are certified; a sample whose bound does not exceed it is returned, for FCL,
    and the walk goes on at the next sample.

    Args:
        todo: Pairs to walk, in this order (a pair may come more than once, for
            stretches apart).
        first, stop: The stretch of the grid each entry of ``todo`` walks: samples
            ``first`` to ``stop`` - 1.
        theta: Threshold of every pair [m].
        grid: (accumulated joint motion |dq| at every sample (samples x dof), the
            same for the turning of the revolute joints upstream of each joint, knot
            positions [rad], knot of every sample, fraction of its interval). Samples
            move linearly between knots.
        kin: (parent, placement (3 x 4), kind, axis, q index) of every joint; (joint,
            placement in it (3 x 4)) of every body; the joint of every velocity index.
        cache: (joint done, joint pose) by sample.
        pairs: (body a, body or environment object b, b is environment, motion weights,
            counts for the clearance) of every pair, and per pair and velocity index
            whether the joint moves body b (else a, or neither: weight 0).
        world: (shape table: the bodies' rows, then the environment objects'; world
            pose of every environment object (3 x 4); the hull tables: vertices,
            neighbour starts, neighbour rows, climbs' starts (see :func:`support`)).
        memory: Per pair, the axis that separated it best at its last full evaluation
            and 1 if there is one, and its last full bound [m]; the bounds evaluated
            (all, with the axes, with GJK); the ceiling (smallest GJK upper bound of a
            clearance pair [m], its pair, its sample). Updated.
        params: (coarse: use the bounding spheres alone above theta + coarse [m];
            fine: refine with GJK below theta + fine [m]; keep: trust a kept axis while
            its gap keeps this share of the last full bound's excess; drop: if not
            negative, a clearance pair's threshold is the ceiling minus drop [m], if
            higher than its own).

        scratch: (chain (joints, int), share, reach_ (dof each), GJK's W (4 x 3), e
            (3 x 3) and idx (4, int); the outputs: pair (int), sample (int) and bound of
            every uncertified couple, as long as the room they have).
        t0, s0: Where to start: the walk of ``todo[t0]`` at sample ``s0`` (0,
            ``first[0]``: from the beginning; else where the last call stopped).

    Returns:
        The number of uncertified (pair, sample) couples written to the outputs (entry
        by entry, samples ascending), and where to resume: (``todo.size``, 0) when the
        walk is done, else the place after the last couple written (the outputs were
        full). A walk resumed there goes on exactly as if it had not stopped.
    """
    at, at_turn, qk, knot_of, frac = grid
    parent, place, kind, axis, iq, m_joint, m_place, joint_of = kin
    jdone, jpose = cache
    pair_a, pair_b, pair_env, weights, tracked, moves_b = pairs
    shp, env_pose, hulls = world
    axes, last, stats, ceiling = memory
    coarse, fine, keep, drop = params
    movers = m_joint.size
    nv = qk.shape[1]
    chain, share, reach_, W, e, idx, out_p, out_s, out_b = scratch
    share[:] = 1.0

    def joint_pose(s: int, j: int) -> None:
        """jpose[s, j] (and its missing ancestors) = parent's pose * placement * the
        joint's own motion (a rotation about its axis or a shift along it). The
        placement times the motion is kept in locals, and the parent's pose read
        before the joint's is written: through arrays, every write to the pose could
        overwrite what the next product reads, and would be read back."""
        count, k = 0, j
        while k > 0 and not jdone[s, k]:
            chain[count] = k
            count += 1
            k = parent[k]
        knot = knot_of[s]
        for c in range(count - 1, -1, -1):
            k = chain[c]
            col = iq[k]
            value = qk[0, col] if knot == 0 else (
                qk[knot - 1, col] + frac[s] * (qk[knot, col] - qk[knot - 1, col]))
            x, y, z = axis[k, 0], axis[k, 1], axis[k, 2]
            p = parent[k]
            along = _basis(x, y, z) if kind[k] != PRISMATIC else -1
            if along >= 0:
                # The usual joints: a turn about the joint's own x, y or z (the general
                # case below, with the zeros left out).
                co, si = math.cos(value), math.sin(value)
                m00, m01, m02 = _turned(place[k, 0, 0], place[k, 0, 1], place[k, 0, 2],
                                        along, co, si)
                m10, m11, m12 = _turned(place[k, 1, 0], place[k, 1, 1], place[k, 1, 2],
                                        along, co, si)
                m20, m21, m22 = _turned(place[k, 2, 0], place[k, 2, 1], place[k, 2, 2],
                                        along, co, si)
                m03, m13, m23 = place[k, 0, 3], place[k, 1, 3], place[k, 2, 3]
            else:
                r00, r01, r02, r10, r11, r12, r20, r21, r22 = _motion(kind[k], value, x, y, z)
                t0, t1, t2 = (x * value, y * value, z * value) if kind[k] == PRISMATIC \
                    else (0.0, 0.0, 0.0)
                m00, m01, m02, m03 = _placed_row(place[k, 0, 0], place[k, 0, 1], place[k, 0, 2],
                                                 place[k, 0, 3], r00, r01, r02, r10, r11, r12,
                                                 r20, r21, r22, t0, t1, t2)
                m10, m11, m12, m13 = _placed_row(place[k, 1, 0], place[k, 1, 1], place[k, 1, 2],
                                                 place[k, 1, 3], r00, r01, r02, r10, r11, r12,
                                                 r20, r21, r22, t0, t1, t2)
                m20, m21, m22, m23 = _placed_row(place[k, 2, 0], place[k, 2, 1], place[k, 2, 2],
                                                 place[k, 2, 3], r00, r01, r02, r10, r11, r12,
                                                 r20, r21, r22, t0, t1, t2)
            if p == 0:
                jpose[s, k, 0, 0], jpose[s, k, 0, 1], jpose[s, k, 0, 2] = m00, m01, m02
                jpose[s, k, 1, 0], jpose[s, k, 1, 1], jpose[s, k, 1, 2] = m10, m11, m12
                jpose[s, k, 2, 0], jpose[s, k, 2, 1], jpose[s, k, 2, 2] = m20, m21, m22
                jpose[s, k, 0, 3], jpose[s, k, 1, 3], jpose[s, k, 2, 3] = m03, m13, m23
            else:
                r0 = _pose_row(jpose[s, p, 0, 0], jpose[s, p, 0, 1], jpose[s, p, 0, 2],
                               jpose[s, p, 0, 3], m00, m01, m02, m03, m10, m11, m12, m13,
                               m20, m21, m22, m23)
                r1 = _pose_row(jpose[s, p, 1, 0], jpose[s, p, 1, 1], jpose[s, p, 1, 2],
                               jpose[s, p, 1, 3], m00, m01, m02, m03, m10, m11, m12, m13,
                               m20, m21, m22, m23)
                r2 = _pose_row(jpose[s, p, 2, 0], jpose[s, p, 2, 1], jpose[s, p, 2, 2],
                               jpose[s, p, 2, 3], m00, m01, m02, m03, m10, m11, m12, m13,
                               m20, m21, m22, m23)
                jpose[s, k, 0, 0], jpose[s, k, 0, 1], jpose[s, k, 0, 2], jpose[s, k, 0, 3] = r0
                jpose[s, k, 1, 0], jpose[s, k, 1, 1], jpose[s, k, 1, 2], jpose[s, k, 1, 3] = r1
                jpose[s, k, 2, 0], jpose[s, k, 2, 1], jpose[s, k, 2, 2], jpose[s, k, 2, 3] = r2
            jdone[s, k] = True

    def placed_body(k: int, s: int, m: int) -> tuple:
        """Shape k placed as body m at sample s: its geometry frame is its joint's pose
        times its placement in the joint frame."""
        j = m_joint[m]
        if j > 0 and not jdone[s, j]:
            joint_pose(s, j)
        p00, p01, p02, p03 = m_place[m, 0, 0], m_place[m, 0, 1], m_place[m, 0, 2], m_place[m, 0, 3]
        p10, p11, p12, p13 = m_place[m, 1, 0], m_place[m, 1, 1], m_place[m, 1, 2], m_place[m, 1, 3]
        p20, p21, p22, p23 = m_place[m, 2, 0], m_place[m, 2, 1], m_place[m, 2, 2], m_place[m, 2, 3]
        if j == 0:
            t0, t1, t2 = (p00, p01, p02, p03), (p10, p11, p12, p13), (p20, p21, p22, p23)
        else:
            t0 = _pose_row(jpose[s, j, 0, 0], jpose[s, j, 0, 1], jpose[s, j, 0, 2],
                           jpose[s, j, 0, 3], p00, p01, p02, p03, p10, p11, p12, p13, p20,
                           p21, p22, p23)
            t1 = _pose_row(jpose[s, j, 1, 0], jpose[s, j, 1, 1], jpose[s, j, 1, 2],
                           jpose[s, j, 1, 3], p00, p01, p02, p03, p10, p11, p12, p13, p20,
                           p21, p22, p23)
            t2 = _pose_row(jpose[s, j, 2, 0], jpose[s, j, 2, 1], jpose[s, j, 2, 2],
                           jpose[s, j, 2, 3], p00, p01, p02, p03, p10, p11, p12, p13, p20,
                           p21, p22, p23)
        c0, c1, c2 = shp[k, CENTRE], shp[k, CENTRE + 1], shp[k, CENTRE + 2]
        return (shp[k, KIND], shp[k, PAR], shp[k, PAR + 1], shp[k, PAR + 2], shp[k, RADIUS],
                t0[3] + t0[0] * c0 + t0[1] * c1 + t0[2] * c2,
                t1[3] + t1[0] * c0 + t1[1] * c1 + t1[2] * c2,
                t2[3] + t2[0] * c0 + t2[1] * c1 + t2[2] * c2,
                t0[0], t0[1], t0[2], t1[0], t1[1], t1[2], t2[0], t2[1], t2[2])

    def placed_env(k: int, b: int) -> tuple:
        """Shape k placed as environment object b."""
        c0, c1, c2 = shp[k, CENTRE], shp[k, CENTRE + 1], shp[k, CENTRE + 2]
        return (shp[k, KIND], shp[k, PAR], shp[k, PAR + 1], shp[k, PAR + 2], shp[k, RADIUS],
                env_pose[b, 0, 3] + env_pose[b, 0, 0] * c0 + env_pose[b, 0, 1] * c1
                + env_pose[b, 0, 2] * c2,
                env_pose[b, 1, 3] + env_pose[b, 1, 0] * c0 + env_pose[b, 1, 1] * c1
                + env_pose[b, 1, 2] * c2,
                env_pose[b, 2, 3] + env_pose[b, 2, 0] * c0 + env_pose[b, 2, 1] * c1
                + env_pose[b, 2, 2] * c2,
                env_pose[b, 0, 0], env_pose[b, 0, 1], env_pose[b, 0, 2],
                env_pose[b, 1, 0], env_pose[b, 1, 1], env_pose[b, 1, 2],
                env_pose[b, 2, 0], env_pose[b, 2, 1], env_pose[b, 2, 2])

    def shapes(p: int, s: int) -> tuple:
        """Pair p's two shapes at sample s."""
        a, b = pair_a[p], pair_b[p]
        if pair_env[p]:
            return placed_body(a, s, a), placed_env(movers + b, b)
        return placed_body(a, s, a), placed_body(b, s, b)

    def set_shares(p: int, s: int, n0: float, n1: float, n2: float, Sa: tuple, Sb: tuple
                   ) -> None:
        """For every joint that moves pair p, at sample s: |n x u| (revolute) or |n . u|
        (prismatic), u being the joint's axis in the world (see ``motion``), and how far
        the points of the body it moves lie from its axis (``reach_``: the body's
        bounding sphere's centre's distance plus its radius; a prismatic joint: its
        weight)."""
        for v in range(nv):
            if weights[p, v] == 0.0:
                continue
            j = joint_of[v]
            along = _basis(axis[j, 0], axis[j, 1], axis[j, 2])
            if along >= 0:  # the pose's own axis: its column
                u0, u1, u2 = jpose[s, j, 0, along], jpose[s, j, 1, along], jpose[s, j, 2, along]
            else:
                u0 = (jpose[s, j, 0, 0] * axis[j, 0] + jpose[s, j, 0, 1] * axis[j, 1]
                      + jpose[s, j, 0, 2] * axis[j, 2])
                u1 = (jpose[s, j, 1, 0] * axis[j, 0] + jpose[s, j, 1, 1] * axis[j, 1]
                      + jpose[s, j, 1, 2] * axis[j, 2])
                u2 = (jpose[s, j, 2, 0] * axis[j, 0] + jpose[s, j, 2, 1] * axis[j, 1]
                      + jpose[s, j, 2, 2] * axis[j, 2])
            if kind[j] == PRISMATIC:
                share[v] = abs(n0 * u0 + n1 * u1 + n2 * u2)
                reach_[v] = weights[p, v]
            else:
                c0, c1, c2 = n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0
                share[v] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
                S = Sb if moves_b[p, v] else Sa
                d0, d1, d2 = (S[5] - jpose[s, j, 0, 3], S[6] - jpose[s, j, 1, 3],
                              S[7] - jpose[s, j, 2, 3])
                c0, c1, c2 = d1 * u2 - d2 * u1, d2 * u0 - d0 * u2, d0 * u1 - d1 * u0
                reach_[v] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) + S[4]

    def motion(p: int, s: int, i: int) -> float:
        """Bound on how much pair p's gap along its axis n can change from sample s to
        i [m]. A revolute joint turning by dq moves a point at r from its axis by at
        most r dq, perpendicular to the axis u, so along n by at most r dq |n x u|;
        while the joints upstream turn by a, u turns by at most a, so |n x u| stays
        below its value at s plus a (and below 1). A prismatic joint moves points
        along u: |n . u| instead. Between two bodies, joints that move
        both leave their distance alone (their weight is zero; taking n in the frame
        they move keeps the argument, and the turning counted is only more).

        r is at most the joint's weight for the body it moves, and at most the body's
        reach from the axis at s (``reach_``) plus what the joints between the two
        have moved its points since (each by its weight times its motion: they change
        the body's distance to the axis, the joints upstream move both alike). Those
        joints come after it in velocity order (a joint's children follow it), so one
        pass from the last joint adds them up, per body."""
        acc = grown_a = grown_b = 0.0
        w_p, b_p, at_i, at_s = weights[p], moves_b[p], at[i], at[s]
        turn_i, turn_s = at_turn[i], at_turn[s]
        for v in range(nv - 1, -1, -1):
            w = w_p[v]
            if w == 0.0:
                continue
            moved = at_i[v] - at_s[v]
            turned = turn_i[v] - turn_s[v]
            if b_p[v]:
                r = min(w, reach_[v] + grown_b)
                grown_b += w * moved
            else:
                r = min(w, reach_[v] + grown_a)
                grown_a += w * moved
            acc += r * min(1.0, share[v] + turned) * moved
        return acc

    def reach(p: int, s: int, end: int, target: float, rate: float) -> tuple[int, float]:
        """A sample after s up to which pair p's gap cannot have changed by target [m]
        (the first at which it can, ``end`` (the end of the stretch walked) if none
        before, or one close before it: see APPROX), and the motion per sample seen on
        the way [m] (the next call's first guess; 0: none). The bound never decreases
        along the grid and grows about linearly: the first probe is where ``rate`` (the
        last call's) says the target is reached (without one, the next sample), each
        next one interpolated from what the last ones found (extrapolated, overshooting
        a little, until the target is bracketed), every third one halves the bracket;
        once the bracket is within a 1/APPROX share of the step, the sample after its
        low end is returned. Invariant: motion(lo) < target; motion(hi) >= target, or
        hi is ``end`` and its motion unknown (inf)."""
        lo, hi, m_lo, m_hi, count = s, end, 0.0, np.inf, 0
        probe = s + 1 if rate <= 0.0 else min(max(s + int(target / rate), s + 1), end - 1)
        while hi - lo > 1:
            m = motion(p, s, probe)
            if m >= target:
                hi, m_hi = probe, m
            else:
                lo, m_lo = probe, m
            count += 1
            if hi - lo <= 1:
                break
            if m_hi != np.inf and (hi - lo) * APPROX <= lo - s:
                return lo + 1, m_lo / (lo - s)
            if m_hi == np.inf:
                slope = m_lo / (lo - s)
                ahead = 2 * (lo - s) if slope <= 0.0 else int(1.1 * (target - m_lo) / slope) + 1
                probe = min(lo + max(ahead, 1), hi - 1)
            elif count % 3 == 0:
                probe = (lo + hi) // 2
            else:
                share_ = (target - m_lo) / (m_hi - m_lo)
                probe = min(max(lo + int(share_ * (hi - lo)), lo + 1), hi - 1)
        if m_hi != np.inf:
            return hi, m_hi / (hi - s)
        return hi, (m_lo / (lo - s) if lo > s else 0.0)

    cap = out_p.size
    count = 0
    for t in range(t0, todo.size):
        p, end = todo[t], stop[t]
        s = s0 if t == t0 else first[t]
        rate = 0.0
        while s < end:
            th = max(theta[p], ceiling[0] - drop) if tracked[p] and drop >= 0.0 else theta[p]
            Sa, Sb = shapes(p, s)
            # The cheap bounds first, the finer ones only where those are not enough.
            # Each is a gap along an axis n, kept for the step.
            bound, n0, n1, n2 = sphere_bound(Sa, Sb)
            stats[0] += 1
            if bound <= th + coarse:
                if axes[p, 3] != 0.0:
                    warm = gap(Sa, Sb, hulls, axes[p, 0], axes[p, 1], axes[p, 2])
                    if warm > bound:
                        bound, n0, n1, n2 = warm, axes[p, 0], axes[p, 1], axes[p, 2]
                # The kept axis is trusted while its gap has not fallen far below the
                # last full bound; else (or without one) the full bound is computed.
                if bound - th < keep * (last[p] - th) or axes[p, 3] == 0.0:
                    full, f0, f1, f2 = axis_bound(Sa, Sb, hulls)
                    stats[1] += 1
                    if full <= th + fine:
                        full, upper, f0, f1, f2 = gjk_bound(Sa, Sb, hulls, full, f0, f1,
                                                            f2, axes[p, 3] != 0.0, W, e,
                                                            idx)
                        stats[2] += 1
                        if tracked[p] and upper < ceiling[0]:
                            ceiling[0], ceiling[1], ceiling[2] = upper, p, s
                    if full >= bound:
                        bound, n0, n1, n2 = full, f0, f1, f2
                    axes[p, 0], axes[p, 1], axes[p, 2], axes[p, 3] = n0, n1, n2, 1.0
                    last[p] = bound
            if bound > th:
                set_shares(p, s, n0, n1, n2, Sa, Sb)
                s, rate = reach(p, s, end, bound - th, rate)
                continue
            out_p[count] = p
            out_s[count] = s
            out_b[count] = bound
            count += 1
            s += 1
            if count == cap:
                return count, t, s
    return count, todo.size, 0
