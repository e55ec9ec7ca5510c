"""The layout of the sphere layer's two flat buffers, read by its kernels.

All data of one checker travels in two flat buffers, ``fb`` (float64) and ``ib`` (int64),
laid out by :func:`safepath.collision._pack.pack` (one call argument each keeps numba's
dispatch cheap: the single-state API is called millions of times by planners): an int
header of block positions (H_*), the joint table (rows of :mod:`safepath.model._joint_table`,
row j for the model's joint j: H_J its floats, H_JI its ints), the constants (C_*), the
rows of the movers (GW, GIW wide) and of the environment objects, and the shape kinds.
A kernel call's scratch (``wf``, ``wi``) is laid out here too (W_*, WI_*).

Only constants: importing this module compiles nothing (the packer reads it).
The shape kinds' codes are the shape table's (its source keys the builds too).
The kernels read these as compile-time constants; :mod:`safepath._aot` keys its
builds on this file's source too.
"""

from __future__ import annotations

from ..model.shapes import BOX, CAPSULE, CYLINDER, SPHERE

FREE, COLLIDES, UNSURE = 0, 1, 2

# Int header (positions in ib).
H_NJ, H_NG, H_NS, H_NE, H_NP, H_DOF = 0, 1, 2, 3, 4, 5
H_J, H_G, H_S, H_E, H_P, H_W, H_L, H_C = 6, 7, 8, 9, 10, 11, 12, 13
H_JI, H_GI, H_EI, H_PI = 14, 15, 16, 17
H_V = 18  # vertices of hull movers (x, y, z rows, each in its shape's frame)
#: Per pair and joint (ints): bit 1 if the joint moves body a relative to body b (or
#: to the world), bit 2 if it moves b relative to a (joints that carry both: 0).
H_PM = 19
#: Hull edges (ints): per vertex row, where its neighbours start in the H_AI block
#: (rows + 1 entries), and the neighbours' rows.
H_AP, H_AI = 20, 21
#: Radius of a sphere about each environment object's centre that holds it (floats).
H_ER = 22
#: The checker's displacement weights (floats, dof): a joint step dq moves no point of
#: the robot (or held object) more than sum(w |dq|) [m].
H_DW = 23
#: Per pair and joint (floats, pairs x dof): how fast the joint can close the pair [m per
#: unit of the joint]: body a's weight where H_PM has bit 1, plus body b's where it has
#: bit 2 (added in that order, as the masks would), else 0.
H_PW = 24
#: The pair whose collision a kernel proved last (-1: none yet): the one word of the
#: tables the kernels write. A state's evaluation for a segment or a single state tries
#: that pair's proof first (collisions in a planner's checks repeat: the same link and
#: obstacle); what the evaluation returns does not depend on it.
H_LAST = 25
HEADER = 26
# Constants (fb[ib[H_C] + k]); C_RES: the checker's resolution [m].
C_REFINE, C_FREE_EPS, C_PROOF_EPS, C_RES = 0, 1, 2, 3
#: Status of a segment whose start (index 0) or end (index 1) is outside the limits.
OUTSIDE = 3

#: Shape kinds (the shape table's codes, :mod:`safepath.model.shapes`), and the kernels' own:
#: an environment object measured by the box around it (a lower bound), and a mover with no
#: primitive (its spheres decide).
ENV_BOX, ENV_CYLINDER, ENV_SPHERE, ENV_CAPSULE = BOX, CYLINDER, SPHERE, CAPSULE
ENV_BOX_ONLY_OUTER = -2
SPHERES_ONLY = -1
#: A mover's convex hull, measured by GJK on its vertices (H_V).
HULL = -3

# The rows of the tables in the buffers: where each column starts, and the row's width.
#: A mover's floats (H_G): its bounding sphere's centre (3) and radius [m], its
#: primitive's rotation (9, row-major) and position (3) in the joint frame, and its
#: dimensions (3) [m].
G_CENTRE, G_RADIUS, G_ROT, G_POS, G_DIMS, GW = 0, 3, 4, 13, 16, 19
#: A mover's ints (H_GI): its joint, its outer spheres' rows (start, end) and inner
#: spheres' rows (start, end) in the H_S block, its kind, its hull vertices' rows (start,
#: end) in the H_V block.
GI_JOINT, GI_OUTER, GI_OUTER_END, GI_INNER, GI_INNER_END = 0, 1, 2, 3, 4
GI_KIND, GI_HULL, GI_HULL_END, GIW = 5, 6, 7, 8
#: A sphere (H_S): its centre (3) in its mover's joint frame, its radius [m].
S_RADIUS, SW = 3, 4
#: A placed sphere (rows of the WI_BUFA, WI_BUFB blocks of ``wf``): its world centre (3),
#: its radius [m], and a lower bound on its distance to the other body's bounding sphere [m].
PS_RADIUS, PS_BOUND, PSW = 3, 4, 5
#: An environment object's floats (H_E): its world rotation (9, row-major), position (3)
#: and dimensions (3) [m].
E_ROT, E_POS, E_DIMS, EW = 0, 9, 12, 15
#: A pair's ints (H_PI): mover a; mover or environment object b; 1 if b is an environment
#: object; 1 if the pair's margin is >= 0 (a collision can be proven).
PI_A, PI_B, PI_ENV, PI_PROOF, PIW = 0, 1, 2, 3, 4

#: Scratch of one kernel call: the joint frames ``Rw`` (nj, 3, 3) and ``pw`` (nj, 3), one
#: float buffer ``wf`` and one int buffer ``wi``. Helpers take these four arrays, never a
#: tuple of many: a numba call pays the reference counts (and copies the descriptors) of
#: every array it is passed, ~10 ns each, and the per-pair helpers run millions of times a
#: second. ``wf`` starts with fixed slots (W_*: two 3-vectors, the two placed shapes of a
#: pair (W_A, W_B), the separating-axis candidates, GJK's simplex and supports); the
#: per-checker blocks follow, where ``wi``'s header says (WI_*); ``wi`` then holds, after
#: the two placed shapes' ints (WI_A, WI_B), per pair, the hull vertices where GJK's
#: support searches start.
W_TMP, W_TMP2, W_A, W_B = 0, 3, 6, 21
W_AXES, W_S, W_SA, W_SB, W_GV = 36, 108, 120, 123, 126
W_FIXED = 129
#: A placed shape's floats, from its slot in ``wf`` (W_A, W_B): its world rotation (9,
#: row-major), position (3) and dimensions (3) [m].
W_R, W_P, W_D = 0, 9, 12
#: A placed shape's ints, from its slot in ``wi`` (WI_A, WI_B): its kind, its hull
#: vertices' rows (start, end) in the H_V block (a mover's GI_KIND, GI_HULL, GI_HULL_END;
#: an environment object's kind and 0, 0).
WS_KIND, WS_HULL, WS_HULL_END = 0, 1, 2
#: Blocks of ``wf``: world bounding-sphere centres of the movers (ng, 3); two placed sphere
#: sets (ns, PSW) each; per pair, the last direction GJK found (3: the next state's first
#: guess); |u| (dof); per mover and joint, its distance to the joint's axis (DL) and how
#: fast that can grow (CC) (ng, dof); per pair, the polyline walk's ledger: the most
#: clearance budget [m] an evaluated state leaves at the end of the segment being walked
#: (npairs); per pair, the stretch of that segment it is certified along (centre and
#: half-width in units of ``t``; a negative width: none) (npairs, 2); per mover, 1 once
#: its DL row is measured at the state being evaluated, else 0 (ng).
(WI_CW, WI_BUFA, WI_BUFB, WI_WARM, WI_ABSU, WI_DL, WI_CC, WI_BUDGET, WI_CERT, WI_DLOK,
 WI_HINT) = range(11)
WI_A, WI_B = 11, 14
WI_HEADER = 17
