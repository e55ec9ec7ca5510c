"""Numba kernels of the sphere layer (see :mod:`safepath.collision.layer`): a state's
evaluation, its certificates along segments, and the entry points.

Imported lazily: the first import compiles (or loads from numba's on-disk cache).
All data of one checker travels in two flat buffers, ``fb`` (float64) and ``ib`` (int64),
laid out as :mod:`safepath.collision._layout` says, by
:func:`safepath.collision._pack.pack` (one call argument each keeps numba's dispatch
cheap: the single-state API is called millions of times by planners). The kernels are
split by step: kinematics and placement (:mod:`safepath.collision._placement`), the tests
of one pair (:mod:`safepath.collision._pair_tests`, GJK in :mod:`safepath.collision._gjk`)
and, here, a state's evaluation over all pairs and the certification of segments and
polylines.

Status codes: FREE (certainly valid), COLLIDES (certainly in collision or outside the
limits), UNSURE (ask the exact checker).

Reference counts: only the entry points (``classify``, ``classify_many``,
``certify_polyline``, ``certify_segment`` and the ``_workspace`` they allocate) are
compiled with numba's reference counting; every helper below them (here and in the
modules named above) is compiled without it (``_nrt=False``): they allocate nothing and
return no arrays, and the counts numba keeps on every array a helper is passed or slices
took ~20 % of a planner's time on the Panda (``perf``: NRT_incref / NRT_decref). Such a
helper must keep to that: no array allocation, no array returned, no array-to-array slice
assignment.

numba's disk cache tracks only the file of the function it compiles: after editing a
helper module in a source checkout, delete ``safepath/collision/__pycache__/*.nb*``.
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit
from ..model._joint_table import JF_W, JF_WIDTH, JI_KIND, JI_PARENT, JI_Q, JI_WIDTH, PRISMATIC
from ._layout import (
    C_FREE_EPS,
    C_PROOF_EPS,
    C_REFINE,
    C_RES,
    COLLIDES,
    E_POS,
    EW,
    FREE,
    G_CENTRE,
    G_RADIUS,
    GI_JOINT,
    GIW,
    GW,
    H_C,
    H_DOF,
    H_DW,
    H_E,
    H_ER,
    H_G,
    H_GI,
    H_J,
    H_JI,
    H_NG,
    H_NJ,
    H_NP,
    H_NS,
    H_P,
    H_PI,
    H_PM,
    H_PW,
    H_W,
    OUTSIDE,
    PI_A,
    PI_B,
    PI_ENV,
    PIW,
    PSW,
    UNSURE,
    W_FIXED,
    WI_ABSU,
    WI_BUDGET,
    WI_CC,
    WI_CERT,
    WI_CW,
    WI_DL,
    WI_DLOK,
    WI_HEADER,
    WI_HINT,
    WI_WARM,
)
from ._pair_tests import _env_sdist3, _pair_bound, _pair_collides
from ._placement import _fk, _within_limits

#: How the helpers are compiled (see the module doc).
_helper = njit(cache=True, nogil=True, _nrt=False)
_inlined = njit(cache=True, nogil=True, _nrt=False, inline="always")


@njit(cache=True, nogil=True)
def _workspace(ib):
    """Fresh scratch (Rw, pw, wf, wi) for the checker packed in ``ib``."""
    nj, ng, ns, npairs, dof = ib[H_NJ], ib[H_NG], ib[H_NS], ib[H_NP], ib[H_DOF]
    wi = np.empty(WI_HEADER + 2 * npairs, dtype=np.int64)
    sizes = (3 * ng, PSW * ns, PSW * ns, 3 * npairs, dof, ng * dof, ng * dof, npairs,
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


@_helper
def _evaluate(q, fb, ib, Rw, pw, wf, wi, rates, want_radius, need, t):  # noqa: N803
    """(status, radius) of one state inside the limits. With ``want_radius``, ``q`` is
    the state at ``t`` of a segment walked along ``u`` and radius is the largest ``h``
    such that every state ``q + t' u`` with ``|t'| < h`` is certainly valid,
    ``rates[k]`` bounding how fast pair ``k`` can close per unit ``t`` (and wf's
    WI_ABSU block filled by ``_pair_rates``, WI_CC by ``_axis_growth``), or some radius
    of at least ``need`` when that is all the caller can use: pairs whose closing-rate
    radius reaches ``need`` skip the finer local radius, and a pair is not evaluated at
    all when the stretch an earlier state of the segment certified for it (wf's WI_CERT
    block, which this updates) covers ``need`` either side of ``t``."""
    _fk(q, fb, ib, Rw, pw)
    oc = ib[H_C]
    free_eps, proof_eps = fb[oc + C_FREE_EPS], fb[oc + C_PROOF_EPS]
    refine = fb[oc + C_REFINE] if want_radius else 0.0
    _place_bounds(fb, ib, Rw, pw, wf, wi)
    if want_radius:  # the axis distances (DL) are measured when a pair first needs them
        wf[wi[WI_DLOK]:wi[WI_DLOK] + ib[H_NG]] = 0.0
    unsure = False
    radius = 1e300
    og, op_, of_, ocw = ib[H_G], ib[H_PI], ib[H_P], wi[WI_CW]
    for k in range(ib[H_NP]):
        if want_radius and _covered(k, t, need, wf, wi):
            # Free for every state within ``need`` of this one: its bound is no limit.
            if need < radius:
                radius = need
            continue
        sm = max(fb[of_ + k], 0.0)
        pair = op_ + PIW * k
        a, b, is_env = ib[pair + PI_A], ib[pair + PI_B], ib[pair + PI_ENV]
        apart, coarse = _coarse_distance(a, b, is_env, sm, free_eps, not want_radius, fb, ib,
                                         wf, og, ocw)
        if apart:
            continue
        budget = coarse - sm - free_eps
        if budget <= refine:
            budget = max(coarse, _pair_bound(k, fb, ib, Rw, pw, wf, wi,
                                             refine + free_eps)) - sm - free_eps
        if budget <= 0.0:
            if _pair_collides(k, fb, ib, proof_eps, Rw, pw, wf, wi):
                return COLLIDES, 0.0
            unsure = True
        elif want_radius:
            h = _certify_pair(k, budget, t, need, rates, fb, ib, Rw, pw, wf, wi)
            if h < radius:
                radius = h
    if unsure:
        return UNSURE, 0.0
    return FREE, radius


@_inlined
def _place_bounds(fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """World centres of the movers' bounding spheres at the state of Rw, pw into wf's
    WI_CW block."""
    og, ogi, ocw = ib[H_G], ib[H_GI], wi[WI_CW]
    for m in range(ib[H_NG]):
        j = ib[ogi + GIW * m + GI_JOINT]
        c = og + GW * m + G_CENTRE
        x, y, z = fb[c], fb[c + 1], fb[c + 2]
        for r in range(3):
            wf[ocw + 3 * m + r] = (Rw[j, r, 0] * x + Rw[j, r, 1] * y + Rw[j, r, 2] * z
                                   + pw[j, r])


@_inlined
def _covered(k, t, need, wf, wi):
    """Whether the stretch pair ``k`` is certified along (wf's WI_CERT block) covers every
    state within ``need`` of ``t``."""
    ocert = wi[WI_CERT]
    c, w = wf[ocert + 2 * k], wf[ocert + 2 * k + 1]
    return t - need > c - w and t + need < c + w


@_inlined
def _coarse_distance(a, b, is_env, sm, free_eps, broad, fb, ib, wf, og, ocw):
    """(apart, distance): a lower bound [m] on the distance of mover ``a`` and environment
    object (``is_env``) or mover ``b`` from a's bounding sphere (to the object, or to b's
    bounding sphere; centres in wf from ``ocw``, rows of the movers from ``og``). With
    ``broad`` (no radius wanted), apart (and no distance) when the bounding spheres lie
    farther apart than the margin ``sm`` and ``free_eps``: free, without measuring the
    object. The offsets are the caller's, read once per state: this runs for every pair
    of every state."""
    cax, cay, caz = wf[ocw + 3 * a], wf[ocw + 3 * a + 1], wf[ocw + 3 * a + 2]
    if is_env == 1:
        if broad:
            e_pos = ib[H_E] + EW * b + E_POS
            dx = cax - fb[e_pos]
            dy = cay - fb[e_pos + 1]
            dz = caz - fb[e_pos + 2]
            reach = fb[og + GW * a + G_RADIUS] + fb[ib[H_ER] + b] + sm + free_eps
            if dx * dx + dy * dy + dz * dz > reach * reach:
                return True, 0.0
        return False, _env_sdist3(fb, ib, b, cax, cay, caz) - fb[og + GW * a + G_RADIUS]
    dd = ((cax - wf[ocw + 3 * b]) ** 2 + (cay - wf[ocw + 3 * b + 1]) ** 2
          + (caz - wf[ocw + 3 * b + 2]) ** 2)
    rr = fb[og + GW * a + G_RADIUS] + fb[og + GW * b + G_RADIUS]
    if broad and dd > (rr + sm + free_eps) ** 2:
        return True, 0.0
    return False, math.sqrt(dd) - rr


@_inlined
def _certify_pair(k, budget, t, need, rates, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """Pair ``k``, free at the state at ``t`` with ``budget`` [m] to spare: its ledger
    entry (wf's WI_BUDGET block: what the budget leaves at the segment's end, if more) and
    the stretch it is certified along (WI_CERT); returns that stretch's radius (in units
    of ``t``; 1e300: the segment does not move the pair)."""
    obud, ocert = wi[WI_BUDGET], wi[WI_CERT]
    left = budget - rates[k] * (1.0 - t)  # at the segment's end
    if left > wf[obud + k]:
        wf[obud + k] = left
    h = 1e300  # a pair the segment does not move stays free along all of it
    if rates[k] > 0.0:
        h = budget / rates[k]
        if h < need:
            h = max(h, _finer_radius(k, budget, fb, ib, Rw, pw, wf, wi))
    wf[ocert + 2 * k] = t
    wf[ocert + 2 * k + 1] = h * (1.0 - 1e-12)
    return h


@_inlined
def _finer_radius(k, budget, fb, ib, Rw, pw, wf, wi):  # noqa: N803
    """Pair ``k``'s radius from its bodies' distances to the joint axes (see
    ``_local_radius``), measuring each body's (DL) first if this state has not yet."""
    pair = ib[H_PI] + PIW * k
    a, b = ib[pair + PI_A], ib[pair + PI_B]
    ocw, odl, odlok = wi[WI_CW], wi[WI_DL], wi[WI_DLOK]
    if wf[odlok + a] == 0.0:
        _axis_distances(a, fb, ib, Rw, pw, wf, ocw, odl)
        wf[odlok + a] = 1.0
    if ib[pair + PI_ENV] == 0 and wf[odlok + b] == 0.0:
        _axis_distances(b, fb, ib, Rw, pw, wf, ocw, odl)
        wf[odlok + b] = 1.0
    return _local_radius(k, a, b, budget, ib, wf, odl, wi[WI_CC], wi[WI_ABSU])


@_inlined
def _axis_distances(m, fb, ib, Rw, pw, wf, ocw, odl):  # noqa: N803
    """DL[m, v] (wf from ``odl``, rows of dof): how fast [m per unit of joint v] mover
    ``m``'s points move when joint ``v`` alone moves, at the state placed in Rw, pw and
    the bounding centres (wf from ``ocw``): the distance of its bounding sphere from the
    joint's axis plus its radius (revolute), 1 (prismatic)."""
    oj, oji, og, ogi = ib[H_J], ib[H_JI], ib[H_G], ib[H_GI]
    dof = ib[H_DOF]
    r_m = fb[og + GW * m + G_RADIUS]
    j = ib[ogi + GIW * m + GI_JOINT]
    while j > 0:
        v = ib[oji + JI_WIDTH * j + JI_Q]
        if ib[oji + JI_WIDTH * j + JI_KIND] == PRISMATIC:
            wf[odl + m * dof + v] = 1.0
        else:
            axis = oj + JF_WIDTH * j + JF_W
            ax, ay, az = fb[axis], fb[axis + 1], fb[axis + 2]
            ux = Rw[j, 0, 0] * ax + Rw[j, 0, 1] * ay + Rw[j, 0, 2] * az
            uy = Rw[j, 1, 0] * ax + Rw[j, 1, 1] * ay + Rw[j, 1, 2] * az
            uz = Rw[j, 2, 0] * ax + Rw[j, 2, 1] * ay + Rw[j, 2, 2] * az
            dx = wf[ocw + 3 * m] - pw[j, 0]
            dy = wf[ocw + 3 * m + 1] - pw[j, 1]
            dz = wf[ocw + 3 * m + 2] - pw[j, 2]
            cx, cy, cz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
            wf[odl + m * dof + v] = math.sqrt(cx * cx + cy * cy + cz * cz) + r_m
        j = ib[oji + JI_WIDTH * j + JI_PARENT]


@_inlined
def _local_radius(k, a, b, budget, ib, wf, odl, occ, oabs):  # noqa: N803
    """A radius (in units of ``t``) within which pair ``k`` cannot close by ``budget`` [m],
    from the bodies' distances to the joint axes at this state (DL, see
    ``_axis_distances``), which grow along the segment by at most CC per unit of ``t``
    (wf from ``odl``, ``occ``; |u| from ``oabs``): the closing speed is at most
    A + B |t|, so the radius solves A h + B h^2 / 2 = budget."""
    dof, opm = ib[H_DOF], ib[H_PM] + k * ib[H_DOF]
    A = B = 0.0
    for v in range(dof):
        au = wf[oabs + v]
        if au == 0.0:
            continue
        mask = ib[opm + v]
        if mask & 1:
            A += au * wf[odl + a * dof + v]
            B += au * wf[occ + a * dof + v]
        if mask & 2:
            A += au * wf[odl + b * dof + v]
            B += au * wf[occ + b * dof + v]
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
    Rw, pw, wf, wi = _workspace(ib)
    status, _ = _evaluate(q, fb, ib, Rw, pw, wf, wi, wf, False, 0.0, 0.0)
    return status


@njit(cache=True, nogil=True)
def classify_many(Q, fb, ib, out):  # noqa: N803
    """Status of every row of ``Q`` into ``out``."""
    Rw, pw, wf, wi = _workspace(ib)
    for i in range(Q.shape[0]):
        if not _within_limits(Q[i], fb, ib):
            out[i] = COLLIDES
            continue
        out[i], _ = _evaluate(Q[i], fb, ib, Rw, pw, wf, wi, wf, False, 0.0, 0.0)


@_helper
def _pair_rates(u, fb, ib, wf, wi, rates):  # noqa: N803
    """Per pair, a bound on how fast its two bodies approach per unit of ``t`` along
    the joint-space direction ``u`` [m] (joints that carry both bodies leave their
    distance alone: their H_PW weight is 0). Also wf's WI_ABSU block = |u|."""
    dof, opw = ib[H_DOF], ib[H_PW]
    oabs = wi[WI_ABSU]
    for v in range(dof):
        wf[oabs + v] = abs(u[v])
    for k in range(ib[H_NP]):
        row = opw + k * dof
        r = 0.0
        for v in range(dof):
            r += fb[row + v] * wf[oabs + v]
        rates[k] = r


@_helper
def _axis_growth(fb, ib, wf, wi):  # noqa: N803
    """Per mover and joint, wf's WI_CC block: how fast the mover's distance to that
    joint's axis can grow per unit of ``t`` along the direction whose |u| is in the
    WI_ABSU block (the joints between the two move it, at most by their weights).
    Only an evaluation with a radius reads it."""
    dof, ow, oji, ogi = ib[H_DOF], ib[H_W], ib[H_JI], ib[H_GI]
    oabs, occ = wi[WI_ABSU], wi[WI_CC]
    for m in range(ib[H_NG]):
        acc = 0.0
        j = ib[ogi + GIW * m + GI_JOINT]
        while j > 0:
            v = ib[oji + JI_WIDTH * j + JI_Q]
            wf[occ + m * dof + v] = (0.0 if ib[oji + JI_WIDTH * j + JI_KIND] == PRISMATIC
                                     else acc)
            acc += fb[ow + m * dof + v] * wf[oabs + v]
            j = ib[oji + JI_WIDTH * j + JI_PARENT]


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
    npairs, dof = ib[H_NP], ib[H_DOF]
    Rw, pw, wf, wi = _workspace(ib)
    rates = np.empty(npairs)
    u = np.empty(dof)
    qs = np.empty(dof)
    n_unsure = 0
    evaluated = 0
    # The ledger (wf's WI_BUDGET block): per pair, the most clearance budget [m] left at
    # the start of the segment by any state evaluated before it (its budget less what
    # the path since may have closed: the pair's rate times the path walked, segment by
    # segment), none (<= 0) yet. A pair within its budget over a whole segment is not
    # evaluated there; a segment within every pair's is certified without an evaluation
    # (short chords of a sampled curve).
    wf[wi[WI_BUDGET]:wi[WI_BUDGET] + npairs] = -1.0
    # FIFO of disjoint, non-empty index ranges still to cover (coarse to fine), made once
    # for the longest segment: a segment's live ranges and the two it adds fit in it.
    room = 3
    for k in range(P.shape[0] - 1):
        room = max(room, hi[k] - lo[k] + 3)
    qlo = np.empty(room, dtype=np.int64)
    qhi = np.empty(room, dtype=np.int64)
    for k in range(P.shape[0] - 1):
        for j in range(dof):
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
            for j in range(dof):
                qs[j] = P[k, j] + t * u[j]
            # A radius covering the rest of [a, b] is all this walk can use.
            need = (max(mid - a, b - mid) + 0.5) / nk
            status, radius = _evaluate(qs, fb, ib, Rw, pw, wf, wi, rates, True, need, t)
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
    """Whether every pair's ledger entry (wf's WI_BUDGET block) outlasts a segment along
    which it can close by ``rates`` [m]."""
    obud = wi[WI_BUDGET]
    for p in range(ib[H_NP]):
        if wf[obud + p] - rates[p] <= 0.0:
            return False
    return True


@_inlined
def _spend_ledger(ib, wf, wi, rates):
    """The ledger at the end of a segment certified as a whole: each entry less what the
    segment may close (``rates``)."""
    obud = wi[WI_BUDGET]
    for p in range(ib[H_NP]):
        wf[obud + p] -= rates[p]


@_inlined
def _open_segment(ib, wf, wi, rates):
    """Start a segment's walk: each pair certified from its start as far as its ledger's
    budget lasts (wf's WI_CERT block); the ledger becomes what that budget leaves at the
    segment's end (the evaluations raise it)."""
    obud, ocert = wi[WI_BUDGET], wi[WI_CERT]
    for p in range(ib[H_NP]):
        left = wf[obud + p]
        width = -1.0
        if left > 0.0:
            width = 1e300 if rates[p] == 0.0 else left / rates[p] * (1.0 - 1e-12)
        wf[ocert + 2 * p] = 0.0
        wf[ocert + 2 * p + 1] = width
        wf[obud + p] = left - rates[p]


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
    dof, odw = ib[H_DOF], ib[H_DW]
    bound = 0.0
    for j in range(dof):
        bound += fb[odw + j] * abs(q1[j] - q0[j])
    n = max(1, int(math.ceil(bound / fb[ib[H_C] + C_RES])))
    P = np.empty((2, dof))
    for j in range(dof):
        P[0, j], P[1, j] = q0[j], q1[j]
    counts = np.full(1, n, dtype=np.int64)
    lo = np.full(1, 1 if skip_start else 0, dtype=np.int64)
    hi = np.full(1, n - 1 if skip_end else n, dtype=np.int64)
    seg = np.empty(max(unsure_idx.shape[0], 1), dtype=np.int64)
    status, _, i, evaluated, unsure = certify_polyline(P, counts, lo, hi, fb, ib, seg,
                                                       unsure_idx, unsure_idx.shape[0])
    return status, i, evaluated, unsure, n
