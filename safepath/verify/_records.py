"""The records the release check's walk reads (:mod:`safepath.verify._kernel`), by
field name: ``typing.NamedTuple`` classes, which numba compiles to plain structs.

Part of the verifier's independent geometry (:mod:`safepath.verify`): nothing here is
shared with the planner's kernels. The kernels compiled ahead of time are keyed on this
file's source too (:mod:`safepath._aot.table`); numba's disk cache is not: after editing
it in a source checkout, delete ``safepath/verify/__pycache__/*.nb*``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._distance import Hulls

__all__ = ["APPROX", "REVOLUTE", "PRISMATIC", "KEPT", "Pose", "Samples", "Kinematics",
           "Poses", "Pairs", "World", "Memory", "Params", "Scratch"]

#: A step's search for the first sample its bound does not certify stops once it has that
#: sample within a 1/APPROX share of the step (the step then ends at the last sample it
#: knows certified): pinning it down to the sample costs more motion probes than the
#: few extra bounds save.
APPROX = 3
REVOLUTE, PRISMATIC = 1, 2
#: Column of the memory's axes table (the axis in columns 0 to 2) that is 1 when the pair
#: has an axis kept.
KEPT = 3


class Pose(NamedTuple):
    """A pose (3 x 4) in locals, read by name: its rotation (row-major) and its
    translation [m]."""

    r00: float
    r01: float
    r02: float
    t0: float
    r10: float
    r11: float
    r12: float
    t1: float
    r20: float
    r21: float
    r22: float
    t2: float


class Samples(NamedTuple):
    """The grid as the walk reads it; samples move linearly between knots.

    Attributes:
        at: Accumulated joint motion |dq| at every sample (samples x dof).
        at_turn: The same for the turning of the revolute joints upstream of each joint.
        qk: Knot positions (knots x dof) [rad] or [m].
        knot_of: Knot of every sample.
        frac: Fraction of its knot interval of every sample.
    """

    at: np.ndarray
    at_turn: np.ndarray
    qk: np.ndarray
    knot_of: np.ndarray
    frac: np.ndarray


class Kinematics(NamedTuple):
    """The joints and the moving bodies (``_bounds.joint_tables`` and the layer).

    Attributes:
        parent: Parent of every joint (0: the universe).
        place: Placement of every joint in its parent's frame (joints x 3 x 4).
        kind: REVOLUTE or PRISMATIC, per joint.
        axis: Unit axis of every joint in its own frame (joints x 3).
        iq: Velocity index of every joint.
        m_joint: Joint of every moving body.
        m_place: Geometry frame of every moving body in its joint frame (bodies x 3 x 4).
        joint_of: Joint of every velocity index.
    """

    parent: np.ndarray
    place: np.ndarray
    kind: np.ndarray
    axis: np.ndarray
    iq: np.ndarray
    m_joint: np.ndarray
    m_place: np.ndarray
    joint_of: np.ndarray


class Poses(NamedTuple):
    """The joint poses computed so far, by sample (``_bounds.PoseCache``).

    Attributes:
        done: Whether each is computed (samples x joints).
        pose: Each joint's pose in the world (samples x joints x 3 x 4).
    """

    done: np.ndarray
    pose: np.ndarray


class Pairs(NamedTuple):
    """The checked pairs.

    Attributes:
        a: Body a of every pair.
        b: Body or environment object b of every pair.
        env: Whether b is an environment object.
        weights: Motion weights (pairs x dof) [m/rad] or [m/m].
        tracked: Whether the pair counts for the clearance.
        moves_b: Per pair and velocity index, whether the joint moves body b (else a, or
            neither: weight 0).
    """

    a: np.ndarray
    b: np.ndarray
    env: np.ndarray
    weights: np.ndarray
    tracked: np.ndarray
    moves_b: np.ndarray


class World(NamedTuple):
    """The shapes.

    Attributes:
        shapes: The shape table: the bodies' rows, then the environment objects' (see
            :mod:`safepath.verify._distance`).
        env_pose: World pose of every environment object (objects x 3 x 4).
        hulls: The hull tables.
    """

    shapes: np.ndarray
    env_pose: np.ndarray
    hulls: Hulls


class Memory(NamedTuple):
    """What the walks along one grid learn (``_bounds.WalkMemory``; updated).

    Attributes:
        axes: Per pair, the axis that separated it best at its last full evaluation,
            and in column KEPT 1 if there is one (pairs x 4).
        last: Per pair, its last full bound [m].
        stats: The bounds evaluated: all, with the axes, with GJK.
        ceiling: The smallest GJK upper bound of a clearance pair [m], its pair, its
            sample.
    """

    axes: np.ndarray
    last: np.ndarray
    stats: np.ndarray
    ceiling: np.ndarray


class Params(NamedTuple):
    """The bounds' margins.

    Attributes:
        coarse: Use the bounding spheres alone above theta + coarse [m].
        fine: Refine with GJK below theta + fine [m].
        keep: Trust a kept axis while its gap keeps this share of the last full
            bound's excess.
        drop: If not negative, a clearance pair's threshold is the ceiling minus drop
            [m], if higher than its own.
    """

    coarse: float
    fine: float
    keep: float
    drop: float


class Scratch(NamedTuple):
    """The walk's scratch and output buffers (the caller's; outputs as long as the room
    they have).

    Attributes:
        chain: Joints whose pose is missing (joints).
        share: Per velocity index, |n x u| or |n . u| at the step's start (dof).
        reach: Per velocity index, how far the moved body reaches from the axis [m].
        W, e, idx: GJK's simplex (4 x 3), its edges (3 x 3) and vertex indices (4).
        out_p, out_s, out_b: Pair, sample and bound [m] of every uncertified couple.
    """

    chain: np.ndarray
    share: np.ndarray
    reach: np.ndarray
    W: np.ndarray
    e: np.ndarray
    idx: np.ndarray
    out_p: np.ndarray
    out_s: np.ndarray
    out_b: np.ndarray
