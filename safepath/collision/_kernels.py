"""Numba kernels of the sphere layer (see :mod:`safepath.collision.layer`): a state's
evaluation, its certificates along segments, and the entry points.

Imported lazily: the first import compiles (or loads from numba's on-disk cache).
All data of one checker travels in two flat buffers, ``fb`` (float64) and ``ib`` (int64),
laid out as :mod:`safepath.collision._layout` says, by
:func:`safepath.collision._pack.pack` (one call argument each keeps numba's dispatch
cheap: the single-state API is called millions of times by planners), and every kernel
reads them, and its scratch, through the named accessors of
:mod:`safepath.collision._records` (no kernel indexes them by hand). The kernels are
split by step: kinematics and placement (:mod:`safepath.collision._placement`), the tests
of one pair (:mod:`safepath.collision._pair_tests`, GJK in :mod:`safepath.collision._gjk`)
and, here, a state's evaluation over all pairs and the certification of segments and
polylines.

Status codes: FREE (certainly valid), COLLIDES (certainly in collision or outside the
limits), UNSURE (ask the exact checker).

Reference counts: only the entry points (``classify``, ``classify_many``,
``certify_polyline``, ``certify_segment`` and the scratch they allocate,
``_records.workspace``) are compiled with numba's reference counting; every helper below
them (here and in the modules named above) is compiled without it (``_nrt=False``): they
allocate nothing and return no arrays (but the views an inlined accessor hands over), and
the counts numba keeps on every array a helper is passed or slices took ~20 % of a
planner's time on the Panda (``perf``: NRT_incref / NRT_decref). Such a helper must keep
to that: no array allocation, no array returned, no array-to-array slice assignment.

numba's disk cache tracks only the file of the function it compiles: after editing a
helper module in a source checkout, delete ``safepath/collision/__pycache__/*.nb*``.
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit
from ._layout import COLLIDES, FREE, OUTSIDE, UNSURE
from ._pair_tests import _env_sdist3, _pair_bound, _pair_collides, _proof_without_gjk
from ._placement import _fk, _to_world, _within_limits
from ._records import (
    abs_u,
    axes_measured,
    axis_distance,
    axis_growth,
    bound_centre,
    certified,
    clear_ledger,
    displacement_weight,
    dof,
    env_position,
    env_reach,
    forget_axes,
    free_eps,
    joint_axis,
    joint_coordinate,
    joint_is_prismatic,
    joint_parent,
    last_collision,
    ledger,
    mover_centre,
    mover_joint,
    mover_radius,
    mover_weight,
    n_movers,
    n_pairs,
    pair,
    pair_margin,
    pair_moves,
    pair_weight,
    proof_eps,
    refine_below,
    resolution,
    set_abs_u,
    set_axes_measured,
    set_axis_distance,
    set_axis_growth,
    set_bound_centre,
    set_certified,
    set_last_collision,
    set_ledger,
    workspace,
)

#: How the helpers are compiled (see the module doc).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@_helper
def _evaluate(q, fb, ib, Rw, pw, wf, wi, rates, want_radius, need, t, first):  # noqa: N803
    """(status, radius) of one state inside the limits. With ``want_radius``, ``q`` is
    the state at ``t`` of a segment walked along ``u`` and radius is such that every
    state ``q + t' u`` with ``|t'| < radius`` is certainly valid (see ``_state_radius``);
    else the radius is 0. With ``first``, the pair whose collision was proved last is
    tried first (``_last_collides``; not in a batch of states, whose later states would
    see other GJK hints in the scratch)."""
    _fk(q, fb, ib, Rw, pw)
    _place_bounds(fb, ib, Rw, pw, wf, wi)
    if first and _last_collides(want_radius, need, t, fb, ib, Rw, pw, wf, wi):
        return COLLIDES, 0.0
    if not want_radius:
        return _state_status(fb, ib, Rw, pw, wf, wi), 0.0
    return _state_radius(fb, ib, Rw, pw, wf, wi, rates, need, t)


@_inlined
def _state_status(fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """FREE, COLLIDES or UNSURE of the state placed in Rw, pw and the bounding centres:
    every pair's bound (bounding spheres first, finer only when they do not clear the
    margin)."""
    unsure = False
    for k in range(n_pairs(ib)):
        budget, _ = _pair_budget(k, True, 0.0, 0.0, fb, ib, Rw, pw, wf, wi)
        if budget <= 0.0:
            if _proven(k, fb, ib, Rw, pw, wf, wi):
                return COLLIDES
            unsure = True
    return UNSURE if unsure else FREE


@_helper
def _state_radius(fb, ib, Rw, pw, wf, wi, rates, need, t):  # noqa: N803
    """(status, radius) of the state at ``t`` of a segment walked along ``u`` (placed in
    Rw, pw and the bounding centres): FREE with a radius such that every state within it
    of ``t`` is certainly valid, ``rates[k]`` bounding how fast pair ``k`` can close per
    unit ``t`` (and the scratch's |u| filled by ``_pair_rates``, CC by ``_axis_growth``),
    or some radius of at least ``need`` when that is all the caller can use; COLLIDES or
    UNSURE.

    The radius is the least of the pairs' (``_certify_pair``, which updates the stretch
    each is certified along, ``_records.certified``); a pair is not evaluated when the
    stretch an earlier state of the segment certified for it reaches ``need`` either side
    of ``t`` (its radius is ``need``). Pairs whose closing-rate radius reaches ``need``
    skip the finer local radius. Last, when the pair that binds the radius had its budget
    from its bounding spheres alone, its finer bound (``_pair_bound``) is measured and the
    pair certified again: the radius can only grow, to the next pair's at most."""
    forget_axes(ib, wf, wi)  # the axis distances (DL) are measured when first needed
    refine = refine_below(fb, ib)
    best = (1e300, 1e300, -1)  # the radius, the next pair's, the binding pair if coarse
    unsure = False
    for k in range(n_pairs(ib)):
        if _held(k, t, wf, wi) > need:  # certified for every state the caller can use
            best = _take(best, need, -1)
            continue
        budget, refined = _pair_budget(k, False, refine, refine, fb, ib, Rw, pw, wf, wi)
        if budget <= 0.0:
            if _proven(k, fb, ib, Rw, pw, wf, wi):
                return COLLIDES, 0.0
            unsure = True
        else:
            h = _certify_pair(k, budget, t, need, rates, fb, ib, Rw, pw, wf, wi)
            best = _take(best, h, -1 if refined else k)
    if unsure:
        return UNSURE, 0.0
    radius, second, k = best
    if k < 0 or radius >= need:
        return FREE, radius
    # The binding pair, measured until its budget would certify all the caller can use.
    budget, _ = _pair_budget(k, False, 1e300, need * rates[k], fb, ib, Rw, pw, wf, wi)
    h = _certify_pair(k, budget, t, need, rates, fb, ib, Rw, pw, wf, wi)
    return FREE, min(h, second)


@_inlined
def _pair_budget(k, broad, refine, enough, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """(budget, refined): a lower bound [m] on how far pair ``k`` lies beyond its margin
    and ``free_eps`` at the state placed (<= 0: not proven free), from its bounding
    spheres (``_coarse_distance``; with ``broad``, 1e300 when they lie apart), or, when
    that is at most ``refine``, from its finer bound too (``refined``; searched until it
    shows ``enough`` [m] beyond the margin)."""
    sm = max(pair_margin(fb, ib, k), 0.0)
    eps = free_eps(fb, ib)
    a, b, is_env, _ = pair(ib, k)
    apart, coarse = _coarse_distance(a, b, is_env, sm, eps, broad, fb, ib, wf, wi)
    if apart:
        return 1e300, False
    budget = coarse - sm - eps
    if budget > refine:
        return budget, False
    return max(coarse, _pair_bound(k, fb, ib, Rw, pw, wf, wi, enough + eps)) - sm - eps, True


@_inlined
def _proven(k, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """Whether pair ``k`` is proven closer than its margin at the state placed
    (``_pair_collides``); such a pair is remembered (``_records.last_collision``)."""
    if _pair_collides(k, fb, ib, proof_eps(fb, ib), Rw, pw, wf, wi):
        set_last_collision(ib, k)
        return True
    return False


@_inlined
def _held(k, t, wf, wi):
    """How far (in units of ``t``) the stretch pair ``k`` is certified along
    (``_records.certified``) reaches either side of ``t``: every state closer than that
    is free of pair ``k`` (<= 0: the stretch does not hold ``t``)."""
    c, w = certified(wf, wi, k)
    return min(t - (c - w), (c + w) - t)


@_inlined
def _take(best, h, k):
    """``best`` (the radius, the next pair's radius, the binding pair when a finer bound
    may raise its radius, else -1) with pair ``k``'s radius ``h`` taken in (``k``: -1
    when no finer bound can raise it)."""
    radius, second, kb = best
    if h < radius:
        return h, radius, k
    if h < second:
        return radius, h, kb
    return best


@_inlined
def _last_collides(want_radius, need, t, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """Whether the pair whose collision was proved last is proven to collide at the state
    placed in Rw, pw (and the bounding centres) without GJK: a certain COLLIDES, which
    the walk over every pair returns too (that pair's lower bounds cannot clear its
    margin, and its proof does not depend on what the walk did before). A pair the
    segment's walk has certified ``t`` in (``_held``) is not tried: it is free there."""
    k = last_collision(ib)
    if k < 0 or k >= n_pairs(ib) or (want_radius and _held(k, t, wf, wi) > 0.0):
        return False
    sm = max(pair_margin(fb, ib, k), 0.0)
    a, b, is_env, _ = pair(ib, k)
    apart, _ = _coarse_distance(a, b, is_env, sm, free_eps(fb, ib), True, fb, ib, wf, wi)
    return not apart and _proof_without_gjk(k, fb, ib, proof_eps(fb, ib), Rw, pw, wf, wi)


@_inlined
def _place_bounds(fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """World centres of the movers' bounding spheres at the state of Rw, pw into the
    scratch (``_records.bound_centre``)."""
    for m in range(n_movers(ib)):
        x, y, z = mover_centre(fb, ib, m)
        wx, wy, wz = _to_world(Rw, pw, mover_joint(ib, m), x, y, z)
        set_bound_centre(wf, wi, m, wx, wy, wz)


@_inlined
def _coarse_distance(a, b, is_env, sm, eps, broad, fb, ib, wf, wi):
    """(apart, distance): a lower bound [m] on the distance of mover ``a`` and environment
    object (``is_env``) or mover ``b`` from a's bounding sphere (to the object, or to b's
    bounding sphere; their centres placed by the caller). With ``broad`` (no radius
    wanted), apart (and no distance) when the bounding spheres lie farther apart than the
    margin ``sm`` and ``eps`` (free_eps): free, without measuring the object."""
    cax, cay, caz = bound_centre(wf, wi, a)
    ra = mover_radius(fb, ib, a)
    if is_env == 1:
        if broad:
            ex, ey, ez = env_position(fb, ib, b)
            dx = cax - ex
            dy = cay - ey
            dz = caz - ez
            reach = ra + env_reach(fb, ib, b) + sm + eps
            if dx * dx + dy * dy + dz * dz > reach * reach:
                return True, 0.0
        return False, _env_sdist3(fb, ib, b, cax, cay, caz) - ra
    cbx, cby, cbz = bound_centre(wf, wi, b)
    dd = (cax - cbx) ** 2 + (cay - cby) ** 2 + (caz - cbz) ** 2
    rr = ra + mover_radius(fb, ib, b)
    if broad and dd > (rr + sm + eps) ** 2:
        return True, 0.0
    return False, math.sqrt(dd) - rr


@_inlined
def _certify_pair(k, budget, t, need, rates, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """Pair ``k``, free at the state at ``t`` with ``budget`` [m] to spare: its ledger
    entry (what the budget leaves at the segment's end, if more) and the stretch it is
    certified along; returns that stretch's radius (in units of ``t``; 1e300: the segment
    does not move the pair)."""
    left = budget - rates[k] * (1.0 - t)  # at the segment's end
    if left > ledger(wf, wi, k):
        set_ledger(wf, wi, k, left)
    h = 1e300  # a pair the segment does not move stays free along all of it
    if rates[k] > 0.0:
        h = budget / rates[k]
        if h < need:
            h = max(h, _finer_radius(k, budget, fb, ib, Rw, pw, wf, wi))
    set_certified(wf, wi, k, t, h * (1.0 - 1e-12))
    return h


@_inlined
def _finer_radius(k, budget, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """Pair ``k``'s radius from its bodies' distances to the joint axes (see
    ``_local_radius``), measuring each body's (DL) first if this state has not yet."""
    a, b, is_env, _ = pair(ib, k)
    if not axes_measured(wf, wi, a):
        _axis_distances(a, fb, ib, Rw, pw, wf, wi)
        set_axes_measured(wf, wi, a)
    if is_env == 0 and not axes_measured(wf, wi, b):
        _axis_distances(b, fb, ib, Rw, pw, wf, wi)
        set_axes_measured(wf, wi, b)
    return _local_radius(k, a, b, budget, ib, wf, wi)


@_inlined
def _axis_distances(m, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """DL[m, v] (``_records.axis_distance``): how fast [m per unit of joint v] mover
    ``m``'s points move when joint ``v`` alone moves, at the state placed in Rw, pw and
    the bounding centres: the distance of its bounding sphere from the joint's axis plus
    its radius (revolute), 1 (prismatic)."""
    r_m = mover_radius(fb, ib, m)
    cx_m, cy_m, cz_m = bound_centre(wf, wi, m)
    j = mover_joint(ib, m)
    while j > 0:
        v = joint_coordinate(ib, j)
        if joint_is_prismatic(ib, j):
            set_axis_distance(ib, wf, wi, m, v, 1.0)
        else:
            ax, ay, az = joint_axis(fb, ib, j)
            ux = Rw[j, 0, 0] * ax + Rw[j, 0, 1] * ay + Rw[j, 0, 2] * az
            uy = Rw[j, 1, 0] * ax + Rw[j, 1, 1] * ay + Rw[j, 1, 2] * az
            uz = Rw[j, 2, 0] * ax + Rw[j, 2, 1] * ay + Rw[j, 2, 2] * az
            dx = cx_m - pw[j, 0]
            dy = cy_m - pw[j, 1]
            dz = cz_m - pw[j, 2]
            cx, cy, cz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
            set_axis_distance(ib, wf, wi, m, v, math.sqrt(cx * cx + cy * cy + cz * cz) + r_m)
        j = joint_parent(ib, j)


@_inlined
def _local_radius(k, a, b, budget, ib, wf, wi):  # noqa: N803
    """A radius (in units of ``t``) within which pair ``k`` cannot close by ``budget`` [m],
    from the bodies' distances to the joint axes at this state (DL, see
    ``_axis_distances``), which grow along the segment by at most CC per unit of ``t``
    (``_axis_growth``): the closing speed is at most A + B |t|, so the radius solves
    A h + B h^2 / 2 = budget."""
    A = B = 0.0
    for v in range(dof(ib)):
        au = abs_u(wf, wi, v)
        if au == 0.0:
            continue
        mask = pair_moves(ib, k, v)
        if mask & 1:
            A += au * axis_distance(ib, wf, wi, a, v)
            B += au * axis_growth(ib, wf, wi, a, v)
        if mask & 2:
            A += au * axis_distance(ib, wf, wi, b, v)
            B += au * axis_growth(ib, wf, wi, b, v)
    if A <= 0.0:
        return 0.0
    if B <= 1e-12 * A:
        return budget / A
    return (math.sqrt(A * A + 2.0 * B * budget) - A) / B


@njit(cache=True, nogil=True)
def classify(q, fb, ib):  # noqa: N803
    """Status of one state: FREE, COLLIDES (or outside the limits) or UNSURE."""
    if not _within_limits(q, fb, ib):
        return COLLIDES
    Rw, pw, wf, wi = workspace(ib)
    status, _ = _evaluate(q, fb, ib, Rw, pw, wf, wi, wf, False, 0.0, 0.0, True)
    return status


@njit(cache=True, nogil=True)
def classify_many(Q, fb, ib, out):  # noqa: N803
    """Status of every row of ``Q`` into ``out``."""
    Rw, pw, wf, wi = workspace(ib)
    for i in range(Q.shape[0]):
        if not _within_limits(Q[i], fb, ib):
            out[i] = COLLIDES
            continue
        out[i], _ = _evaluate(Q[i], fb, ib, Rw, pw, wf, wi, wf, False, 0.0, 0.0, False)


@_helper
def _pair_rates(u, fb, ib, wf, wi, rates):  # noqa: N803
    """Per pair, a bound on how fast its two bodies approach per unit of ``t`` along
    the joint-space direction ``u`` [m] (joints that carry both bodies leave their
    distance alone: their weight is 0). Also the scratch's |u| (``_records.abs_u``)."""
    nq = dof(ib)
    for v in range(nq):
        set_abs_u(wf, wi, v, abs(u[v]))
    for k in range(n_pairs(ib)):
        r = 0.0
        for v in range(nq):
            r += pair_weight(fb, ib, k, v) * abs_u(wf, wi, v)
        rates[k] = r


@_helper
def _axis_growth(fb, ib, wf, wi):  # noqa: N803
    """Per mover and joint, CC (``_records.axis_growth``): how fast the mover's distance
    to that joint's axis can grow per unit of ``t`` along the direction whose |u| is in
    the scratch (the joints between the two move it, at most by their weights). Only an
    evaluation with a radius reads it."""
    for m in range(n_movers(ib)):
        acc = 0.0
        j = mover_joint(ib, m)
        while j > 0:
            v = joint_coordinate(ib, j)
            set_axis_growth(ib, wf, wi, m, v, 0.0 if joint_is_prismatic(ib, j) else acc)
            acc += mover_weight(fb, ib, m, v) * abs_u(wf, wi, v)
            j = joint_parent(ib, j)


@njit(cache=True, nogil=True)
def certify_polyline(P, n, lo, hi, fb, ib, unsure_seg, unsure_idx, max_unsure):  # noqa: N803
    """Certify the grid states of a joint polyline.

    Segment ``k`` of ``P`` (rows) is cut into ``n[k]`` equal steps; its grid states
    ``lo[k]..hi[k]`` (0 = ``P[k]``, ``n[k]`` = ``P[k+1]``) must be valid. States are
    visited coarse to fine (middle first); a state the spheres prove free certifies
    its neighbours within its clearance radius, a state they cannot decide is written
    to ``unsure_seg/unsure_idx`` for the exact checker. Every endpoint must lie inside
    the limits (the caller checks them; the limit box is convex).

    Returns:
        (status, segment, index, evaluated, unsure): COLLIDES with the colliding grid
        state; UNSURE when ``max_unsure`` undecided states were found (the walk stopped:
        the exact checker should look at those first, a collision is often among them);
        else FREE (no state left but the unsure ones).
    """
    npairs, nq = n_pairs(ib), dof(ib)
    Rw, pw, wf, wi = workspace(ib)
    rates = np.empty(npairs)
    u = np.empty(nq)
    qs = np.empty(nq)
    n_unsure = 0
    evaluated = 0
    # The ledger (``_records.ledger``): per pair, the most clearance budget [m] left at
    # the start of the segment by any state evaluated before it (its budget less what
    # the path since may have closed: the pair's rate times the path walked, segment by
    # segment), none (<= 0) yet. A pair within its budget over a whole segment is not
    # evaluated there; a segment within every pair's is certified without an evaluation
    # (short chords of a sampled curve).
    clear_ledger(ib, wf, wi)
    # FIFO of disjoint, non-empty index ranges still to cover (coarse to fine), made once
    # for the longest segment: a segment's live ranges and the two it adds fit in it.
    room = 3
    for k in range(P.shape[0] - 1):
        room = max(room, hi[k] - lo[k] + 3)
    qlo = np.empty(room, dtype=np.int64)
    qhi = np.empty(room, dtype=np.int64)
    for k in range(P.shape[0] - 1):
        for j in range(nq):
            u[j] = P[k + 1, j] - P[k, j]
        _pair_rates(u, fb, ib, wf, wi, rates)
        # No state of this segment to check, or every pair's budget lasts along it.
        if hi[k] < lo[k] or _ledger_lasts(ib, wf, wi, rates):
            _spend_ledger(ib, wf, wi, rates)
            continue
        _open_segment(ib, wf, wi, rates)
        _axis_growth(fb, ib, wf, wi)  # for this segment's evaluations
        nk = n[k]
        head, tail = 0, 1
        qlo[0], qhi[0] = lo[k], hi[k]
        while head < tail:
            a, b = qlo[head], qhi[head]
            head += 1
            mid = (a + b) // 2
            t = mid / nk
            for j in range(nq):
                qs[j] = P[k, j] + t * u[j]
            # A radius covering the rest of [a, b] is all this walk can use.
            need = (max(mid - a, b - mid) + 0.5) / nk
            status, radius = _evaluate(qs, fb, ib, Rw, pw, wf, wi, rates, True, need, t, True)
            evaluated += 1
            if status == COLLIDES:
                return COLLIDES, k, mid, evaluated, n_unsure
            m = 0
            if status == FREE:
                m = _certified_steps(radius, nk)
            else:
                unsure_seg[n_unsure] = k
                unsure_idx[n_unsure] = mid
                n_unsure += 1
                if n_unsure >= max_unsure:
                    return UNSURE, k, mid, evaluated, n_unsure
            head, tail = _queue_rest(qlo, qhi, head, tail, a, b, mid, m)
    return FREE, -1, -1, evaluated, n_unsure


@_inlined
def _ledger_lasts(ib, wf, wi, rates):
    """Whether every pair's ledger entry outlasts a segment along which it can close by
    ``rates`` [m]."""
    for p in range(n_pairs(ib)):
        if ledger(wf, wi, p) - rates[p] <= 0.0:
            return False
    return True


@_inlined
def _spend_ledger(ib, wf, wi, rates):
    """The ledger at the end of a segment certified as a whole: each entry less what the
    segment may close (``rates``)."""
    for p in range(n_pairs(ib)):
        set_ledger(wf, wi, p, ledger(wf, wi, p) - rates[p])


@_inlined
def _open_segment(ib, wf, wi, rates):
    """Start a segment's walk: each pair certified from its start as far as its ledger's
    budget lasts (``_records.certified``); the ledger becomes what that budget leaves at the
    segment's end (the evaluations raise it)."""
    for p in range(n_pairs(ib)):
        left = ledger(wf, wi, p)
        width = -1.0
        if left > 0.0:
            width = 1e300 if rates[p] == 0.0 else left / rates[p] * (1.0 - 1e-12)
        set_certified(wf, wi, p, 0.0, width)
        set_ledger(wf, wi, p, left - rates[p])


@_inlined
def _certified_steps(radius, nk):
    """How many grid steps either side of a free state its ``radius`` (in units of ``t``,
    ``nk`` steps per unit) certifies: grid states with |i - mid| / nk < radius."""
    reach = radius * nk * (1.0 - 1e-12)
    return nk if reach >= nk else max(int(math.ceil(reach)) - 1, 0)


@_inlined
def _queue_rest(qlo, qhi, head, tail, a, b, mid, m):
    """Queue what range [a, b] leaves to cover once ``mid`` and the ``m`` states either
    side of it are decided (moving the live ranges to the front of the FIFO first when
    its end is near); returns the new (head, tail)."""
    if tail + 2 > qlo.shape[0]:
        live = tail - head
        for i in range(live):  # forwards: the ranges move down
            qlo[i], qhi[i] = qlo[head + i], qhi[head + i]
        head, tail = 0, live
    if a <= mid - m - 1:
        qlo[tail], qhi[tail] = a, mid - m - 1
        tail += 1
    if mid + m + 1 <= b:
        qlo[tail], qhi[tail] = mid + m + 1, b
        tail += 1
    return head, tail


@njit(cache=True, nogil=True)
def certify_segment(q0, q1, fb, ib, skip_start, skip_end, unsure_idx):  # noqa: N803
    """One straight segment, as :func:`certify_polyline` walks it, with what its caller
    would otherwise do in Python around it (the planners' edge check: ~60 % of its time
    went there): the limits at both ends, the grid count from the displacement weights
    and the resolution, states 0 (unless ``skip_start``) to n (n - 1 with ``skip_end``).
    The walk stops once it has left ``len(unsure_idx)`` states undecided, their grid
    indices written there in the order found.

    Returns:
        (status, index, evaluated, unsure, n): OUTSIDE with index 0 (start) or 1 (end);
        COLLIDES with the colliding grid index; UNSURE or FREE as certify_polyline, with
        ``unsure`` undecided states found (FREE: all of them; UNSURE: the walk stopped).
    """
    if not _within_limits(q0, fb, ib):
        return OUTSIDE, 0, 0, 0, 0
    if not _within_limits(q1, fb, ib):
        return OUTSIDE, 1, 0, 0, 0
    nq = dof(ib)
    bound = 0.0
    for j in range(nq):
        bound += displacement_weight(fb, ib, j) * abs(q1[j] - q0[j])
    n = max(1, int(math.ceil(bound / resolution(fb, ib))))
    P = np.empty((2, nq))
    for j in range(nq):
        P[0, j], P[1, j] = q0[j], q1[j]
    counts = np.full(1, n, dtype=np.int64)
    lo = np.full(1, 1 if skip_start else 0, dtype=np.int64)
    hi = np.full(1, n - 1 if skip_end else n, dtype=np.int64)
    seg = np.empty(max(unsure_idx.shape[0], 1), dtype=np.int64)
    status, _, i, evaluated, unsure = certify_polyline(P, counts, lo, hi, fb, ib, seg,
                                                       unsure_idx, unsure_idx.shape[0])
    return status, i, evaluated, unsure, n
