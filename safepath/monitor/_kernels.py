"""Numba kernels of the monitor: separation lower bounds and path-velocity profiles.

Imported lazily: the kernels compiled ahead of time (:mod:`safepath._aot`), else the first
import compiles them (or loads numba's on-disk cache).

Separation
    Observed elements are spheres (a point is a sphere of radius 0). They are bucketed
    into cubic cells and cells into blocks of 4x4x4 cells, each with a sphere that holds
    its contents. The robot at every sampled path state is a set of spheres that enclose
    its links (grouped per body, each group with a bounding sphere). For a run of states
    the kernel returns the running minimum ("prefix minimum") of the lower bound
    ``|p - c| - r_p - r_s`` over every element and every robot sphere: a state is only
    refined where it could lower the minimum found so far, so open space costs one
    comparison per block and body.

Profiles
    A path is the knots of a verified trajectory, parametrised by its own time ``tau``
    (``Q'(tau)`` its velocities, ``Q''(tau)`` its accelerations). A new timing
    ``tau(t)`` with speed ``r = dtau/dt`` in [0, 1] gives joint velocities ``Q' r`` and
    accelerations ``Q'' r^2 + Q' dr/dt``. With ``x = r^2`` and ``u = dr/dt`` constant
    between knots (``x_{i+1} = x_i + 2 (tau_{i+1} - tau_i) u_i``, TOPP-RA's discretisation),
    the limits at knot ``i`` are ``|Q'_i u_i + Q''_i x_i| <= a_max`` and
    ``|Q'_i| sqrt(x_i) <= v_max``. Because the verified timing (``x = 1``, ``u = 0``)
    keeps every limit, any ``x <= 1`` with ``u = 0`` does too: a greedy forward pass never
    gets stuck, and needs no backward pass.
"""

from __future__ import annotations

import math

import numpy as np

from .._aot import njit
from ..model._primitives import signed_distance

#: Cells per block edge.
BLOCK = 4
_OFF = 1 << 20

#: The kernels' steps: inlined into the kernel that calls them (the same operations).
_inlined = njit(cache=True, nogil=True, inline="always")


@njit(cache=True, nogil=True)
def bucket(E, h):  # noqa: N803
    """Sort elements ``E`` (n, 4: x, y, z, radius) into cells of edge ``h`` [m] and blocks.

    Returns:
        (sorted elements, cell spheres (nc, 4), cell starts (nc + 1), block spheres
        (nb, 4), block starts into cells (nb + 1)).
    """
    keys = _cell_keys(E, h)
    order = np.argsort(keys)
    S = E[order]
    cstart, bstart, nc, nb = _runs(keys[order])
    cells = _cell_spheres(S, cstart, nc)
    blocks = _block_spheres(cells, bstart, nb)
    return S, cells, cstart[:nc + 1].copy(), blocks, bstart[:nb + 1].copy()


@_inlined
def _cell_keys(E, h):  # noqa: N803
    """Each element's key: its block's key times 64 plus its cell's place in the block."""
    n = E.shape[0]
    keys = np.empty(n, dtype=np.int64)
    for i in range(n):
        ix = int(math.floor(E[i, 0] / h)) + _OFF
        iy = int(math.floor(E[i, 1] / h)) + _OFF
        iz = int(math.floor(E[i, 2] / h)) + _OFF
        bkey = ((ix // BLOCK) * (1 << 20) + (iy // BLOCK)) * (1 << 20) + (iz // BLOCK)
        keys[i] = bkey * 64 + ((ix % BLOCK) * 16 + (iy % BLOCK) * 4 + iz % BLOCK)
    return keys


@_inlined
def _runs(ks):
    """Cells as runs of equal sorted keys ``ks``, blocks as runs of equal ``key // 64``:
    (cell starts, block starts into cells, cell count, block count); each start array
    ends with the total at index count."""
    n = ks.size
    cstart = np.empty(n + 1, dtype=np.int64)
    bstart = np.empty(n + 1, dtype=np.int64)
    nc = 0
    nb = 0
    for i in range(n):
        if i == 0 or ks[i] != ks[i - 1]:
            if i == 0 or ks[i] // 64 != ks[i - 1] // 64:
                bstart[nb] = nc
                nb += 1
            cstart[nc] = i
            nc += 1
    cstart[nc] = n
    bstart[nb] = nc
    return cstart, bstart, nc, nb


@_inlined
def _cell_spheres(S, cstart, nc):  # noqa: N803
    """A sphere (nc, 4) about each cell's elements: centred on the box of their centres."""
    cells = np.empty((nc, 4))
    for c in range(nc):
        a, b = cstart[c], cstart[c + 1]
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for i in range(a, b):
            for d in range(3):
                lo[d] = min(lo[d], S[i, d])
                hi[d] = max(hi[d], S[i, d])
        for d in range(3):
            cells[c, d] = 0.5 * (lo[d] + hi[d])
        cells[c, 3] = _radius_about(S, a, b, cells, c)
    return cells


@_inlined
def _block_spheres(cells, bstart, nb):
    """A sphere (nb, 4) about each block's cell spheres: centred on the box that holds
    them."""
    blocks = np.empty((nb, 4))
    for k in range(nb):
        a, b = bstart[k], bstart[k + 1]
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for c in range(a, b):
            for d in range(3):
                lo[d] = min(lo[d], cells[c, d] - cells[c, 3])
                hi[d] = max(hi[d], cells[c, d] + cells[c, 3])
        for d in range(3):
            blocks[k, d] = 0.5 * (lo[d] + hi[d])
        blocks[k, 3] = _radius_about(cells, a, b, blocks, k)
    return blocks


@_inlined
def _radius_about(P, a, b, X, k):  # noqa: N803
    """Radius [m] of the sphere centred at ``X[k, :3]`` that holds the spheres ``P[a:b]``,
    padded by a relative and an absolute 1e-12 against rounding."""
    r = 0.0
    for i in range(a, b):
        dx = P[i, 0] - X[k, 0]
        dy = P[i, 1] - X[k, 1]
        dz = P[i, 2] - X[k, 2]
        r = max(r, math.sqrt(dx * dx + dy * dy + dz * dz) + P[i, 3])
    return r * (1.0 + 1e-12) + 1e-12


@njit(cache=True, nogil=True, inline="always")
def _gap(ax, ay, az, ar, B, k):  # noqa: N803
    dx = ax - B[k, 0]
    dy = ay - B[k, 1]
    dz = az - B[k, 2]
    return math.sqrt(dx * dx + dy * dy + dz * dz) - ar - B[k, 3]


@njit(cache=True, nogil=True)
def _refine(C, R, s, a, b, S, cells, cstart, c, best, who):  # noqa: N803
    """Exact element-sphere bounds of cell ``c`` against spheres ``a..b-1`` at state ``s``."""
    for sp in range(a, b):
        r = R[sp]
        if r < 0.0:
            continue
        cx, cy, cz = C[s, sp, 0], C[s, sp, 1], C[s, sp, 2]
        if _gap(cx, cy, cz, r, cells, c) >= best:
            continue
        for e in range(cstart[c], cstart[c + 1]):
            d = _gap(cx, cy, cz, r, S, e)
            if d < best:
                best = d
                who = e
    return best, who


@njit(cache=True, nogil=True)
def prefix_separation(C, R, body_start, Bd, s0, s1, S, cells, cstart, blocks, bstart,  # noqa: N803
                      cap, out, arg):
    """Running minimum over states ``s0..s1-1`` of the separation lower bound [m].

    Per state, the (body, cell) pair with the smallest lower bound is refined first, so
    that the minimum found prunes the ordered pass over blocks, cells and spheres that
    follows.

    Args:
        C: Robot sphere centres per state (n_states, K, 3).
        R: Robot sphere radii (K,); a negative radius disables a sphere.
        body_start: Sphere range of each body (n_bodies + 1,).
        Bd: Bounding sphere of each body per state (n_states, n_bodies, 4).
        S, cells, cstart, blocks, bstart: Elements as :func:`bucket` returns them.
        cap: Distances at or beyond this are not refined (reported as ``cap``) [m].
        out: Receives the running minimum for each state of the range (s1 - s0,).
        arg: Receives the element that gives it (-1 if none closer than ``cap``).
    """
    best = cap
    who = -1
    for s in range(s0, s1):
        m_min, c_min = _closest_pair(Bd, s, body_start.size - 1, cells, blocks, bstart, best)
        if m_min >= 0:  # else nothing can beat the minimum at this state
            best, who = _refine(C, R, s, body_start[m_min], body_start[m_min + 1], S,
                                cells, cstart, c_min, best, who)
            best, who = _refine_state(C, R, body_start, Bd, s, S, cells, cstart, blocks,
                                      bstart, best, who)
        out[s - s0] = best
        arg[s - s0] = who


@_inlined
def _closest_pair(Bd, s, nbodies, cells, blocks, bstart, bound):  # noqa: N803
    """The (body, cell) of state ``s`` (bodies ``0..nbodies-1``) whose bounding spheres'
    lower bound is smallest and below ``bound``; (-1, -1) if none is."""
    g_min = bound
    m_min = -1
    c_min = -1
    for m in range(nbodies):
        bx, by, bz, br = Bd[s, m, 0], Bd[s, m, 1], Bd[s, m, 2], Bd[s, m, 3]
        if br < 0.0:
            continue
        for k in range(blocks.shape[0]):
            if _gap(bx, by, bz, br, blocks, k) >= g_min:
                continue
            for c in range(bstart[k], bstart[k + 1]):
                g = _gap(bx, by, bz, br, cells, c)
                if g < g_min:
                    g_min = g
                    m_min = m
                    c_min = c
    return m_min, c_min


@_inlined
def _refine_state(C, R, body_start, Bd, s, S, cells, cstart, blocks, bstart, best, who):  # noqa: N803
    """The ordered pass at state ``s``: every (body, cell) pair whose bounding spheres
    could beat ``best`` is refined; returns the new (best, who)."""
    for m in range(body_start.size - 1):
        bx, by, bz, br = Bd[s, m, 0], Bd[s, m, 1], Bd[s, m, 2], Bd[s, m, 3]
        if br < 0.0:
            continue
        for k in range(blocks.shape[0]):
            if _gap(bx, by, bz, br, blocks, k) >= best:
                continue
            for c in range(bstart[k], bstart[k + 1]):
                if _gap(bx, by, bz, br, cells, c) < best:
                    best, who = _refine(C, R, s, body_start[m], body_start[m + 1], S,
                                        cells, cstart, c, best, who)
    return best, who


@njit(cache=True, nogil=True)
def near_robot(C, R, body_start, Bd, s0, s1, E, within, out):  # noqa: N803
    """Whether each element of ``E`` comes within ``within`` [m] of the robot's spheres at
    any state ``s0..s1-1`` (``out``, bool per element)."""
    nbodies = body_start.size - 1
    for i in range(E.shape[0]):
        x, y, z, re = E[i, 0], E[i, 1], E[i, 2], E[i, 3]
        hit = False
        for s in range(s0, s1):
            for m in range(nbodies):
                if Bd[s, m, 3] < 0.0 or _gap(x, y, z, re, Bd[s], m) > within:
                    continue
                for sp in range(body_start[m], body_start[m + 1]):
                    if R[sp] < 0.0:
                        continue
                    dx = x - C[s, sp, 0]
                    dy = y - C[s, sp, 1]
                    dz = z - C[s, sp, 2]
                    if math.sqrt(dx * dx + dy * dy + dz * dz) - R[sp] - re <= within:
                        hit = True
                        break
                if hit:
                    break
            if hit:
                break
        out[i] = hit


@njit(cache=True, nogil=True)
def scene_distance(P, kind, T, dims, reach, within, out):  # noqa: N803
    """Smallest signed distance [m] from each point of ``P`` (n, 3) to the scene's
    primitives (kinds: the shape table's codes; ``T`` (k, 4, 4) their
    placements, ``dims`` (k, 3) half sizes / radius, half length, ``reach`` (k,) the
    radius of a sphere about each that holds it) into ``out``; objects farther than
    ``within`` are not measured exactly (their bounding-sphere distance is used)."""
    for i in range(P.shape[0]):
        best = np.inf
        for o in range(kind.size):
            dx = P[i, 0] - T[o, 0, 3]
            dy = P[i, 1] - T[o, 1, 3]
            dz = P[i, 2] - T[o, 2, 3]
            far = math.sqrt(dx * dx + dy * dy + dz * dz) - reach[o]
            if far > within:
                best = min(best, far)
                continue
            x = T[o, 0, 0] * dx + T[o, 1, 0] * dy + T[o, 2, 0] * dz
            y = T[o, 0, 1] * dx + T[o, 1, 1] * dy + T[o, 2, 1] * dz
            z = T[o, 0, 2] * dx + T[o, 1, 2] * dy + T[o, 2, 2] * dz
            d = signed_distance(kind[o], dims[o, 0], dims[o, 1], dims[o, 2], x, y, z)
            best = min(best, d)
        out[i] = best


@njit(cache=True, nogil=True, inline="always")
def _u_range(qd, qdd, x, amax, i):
    """Feasible path accelerations ``u`` at knot ``i`` with squared speed ``x``."""
    lo = -np.inf
    hi = np.inf
    for j in range(amax.size):
        a = qd[i, j]
        b = qdd[i, j] * x
        c = amax[j]
        if abs(a) > 1e-12:
            u1 = (-c - b) / a
            u2 = (c - b) / a
            if a < 0.0:
                u1, u2 = u2, u1
            lo = max(lo, u1)
            hi = min(hi, u2)
    # x <= 1 keeps u = 0 feasible; rounding must not exclude it.
    return min(lo, 0.0), max(hi, 0.0)


@njit(cache=True, nogil=True)
def march(tau, qd, qdd, amax, x0, x_target, t_stop, out_x, out_u, out_t):  # noqa: N803
    """A greedy path-velocity profile over knots ``tau`` (n,) from squared speed ``x0``.

    Goes toward ``x_target`` (in [0, 1]) as fast as the acceleration limits allow, and
    from time ``t_stop`` [s] on brakes as hard as they allow, until at rest (at a knot)
    or at the last knot.

    Returns:
        (knots used m, index of the knot where braking began or -1, at rest at the end).
        ``out_x[:m]``, ``out_u[:m]``, ``out_t[:m]`` hold x, u (on the interval after the
        knot; 0 for the last) and time from the start [s].
    """
    n = tau.size
    x = min(max(x0, 0.0), 1.0)
    t = 0.0
    braking = -1
    for i in range(n):
        out_x[i] = x
        out_t[i] = t
        if i == n - 1:
            out_u[i] = 0.0
            return n, braking, True
        if braking < 0 and t >= t_stop:
            braking = i
        if braking >= 0 and x <= 0.0:
            out_u[i] = 0.0
            return i + 1, braking, True
        d2 = 2.0 * (tau[i + 1] - tau[i])
        lo, hi = _u_range(qd, qdd, x, amax, i)
        if braking >= 0:
            u = lo
        else:
            u = min(max((x_target - x) / d2, lo), hi)
        nxt = x + d2 * u
        if nxt <= 0.0:  # comes to rest at the next knot (a milder u, still feasible)
            nxt = 0.0
            u = -x / d2
        elif nxt > 1.0:  # rounding: never faster than the verified timing
            nxt = 1.0
            u = (nxt - x) / d2
        if x + nxt <= 0.0:  # at rest and staying there
            out_u[i] = 0.0
            return i + 1, braking, True
        out_u[i] = u
        t += d2 / (math.sqrt(x) + math.sqrt(nxt))
        x = nxt
    return n, braking, True


@njit(cache=True, nogil=True)
def linked_cells(key, steps, seed, span, linked):
    """Which elements lie in grid cells linked to element ``seed``'s by chains of
    neighbouring cells: ``key`` (n,) is each element's cell key, ``steps`` the key
    differences of a cell's neighbours (a neighbour's key is the cell's plus one of
    them); ``linked`` (n,) is set. The occupied cells are the runs of the sorted keys;
    the seed's cell grows through them by a depth-first search. A neighbour is looked up
    in a table of every key when the keys lie in ``[0, span)`` (``span`` > 0), else by
    bisection among the occupied keys."""
    n = key.size
    order = np.argsort(key)
    occupied = np.empty(n, dtype=np.int64)
    cell_of = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        k = key[order[i]]
        if m == 0 or k != occupied[m - 1]:
            occupied[m] = k
            m += 1
        cell_of[order[i]] = m - 1
    table = np.full(max(span, 0), -1, dtype=np.int64)
    for c in range(m if span > 0 else 0):
        table[occupied[c]] = c
    reached = np.zeros(m, dtype=np.bool_)
    stack = np.empty(m, dtype=np.int64)
    stack[0] = cell_of[seed]
    reached[stack[0]] = True
    top = 1
    while top > 0:
        top -= 1
        c = stack[top]
        for s in range(steps.size):
            found = _occupied_at(occupied, m, table, span, occupied[c] + steps[s])
            if found >= 0 and not reached[found]:
                reached[found] = True
                stack[top] = found
                top += 1
    for i in range(n):
        linked[i] = reached[cell_of[i]]


@_inlined
def _occupied_at(occupied, m, table, span, want):
    """The index of key ``want`` among the ``m`` sorted ``occupied`` keys, or -1: read
    from ``table`` when ``span`` > 0, else by bisection."""
    if span > 0:
        return table[want] if 0 <= want < span else -1
    lo, hi = 0, m
    while lo < hi:  # the first occupied key >= want
        mid = (lo + hi) // 2
        if occupied[mid] < want:
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < m and occupied[lo] == want else -1
