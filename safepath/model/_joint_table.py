"""The joint table: a kinematic tree as the planner's numba kernels read it.

One row per joint, parents before children, in two arrays: floats ``(n, JF_WIDTH)`` and
ints ``(n, JI_WIDTH)``, their columns named below. A joint's local placement at its
coordinate ``x`` is its placement in the parent joint's frame times ``exp6(S x)``, ``S``
its motion subspace: a screw whose angular part is a unit vector or zero and whose linear
part is parallel to it (revolute, prismatic and helical joints). Written by the sphere
layer (:mod:`safepath.collision._pack`, every joint of the model, the universe first) and
by Cartesian lines (:mod:`safepath.planning.cartesian`, the chain to the TCP); read by
:func:`safepath.model._fk_kernel.joint_frames`.

Only constants and a builder: importing this module compiles nothing, and the kernels
read the constants as compile-time constants (:mod:`safepath._aot` keys its builds on
this file's source).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

__all__ = ["JF_R", "JF_T", "JF_V", "JF_W", "JF_WIDTH", "JI_PARENT", "JI_KIND", "JI_Q",
           "JI_WIDTH", "FIXED", "REVOLUTE", "PRISMATIC", "HELICAL", "WORLD", "Chain",
           "chain_joints", "frame_chain", "joint_table", "not_a_screw"]

# Float columns.
#: The placement's rotation in the parent joint's frame, row-major (9 columns).
JF_R = 0
#: The placement's translation in the parent joint's frame [m] (3 columns).
JF_T = 9
#: The screw's linear part [m per unit of the coordinate] (3 columns).
JF_V = 12
#: The screw's angular part [rad per unit of the coordinate] (3 columns).
JF_W = 15
JF_WIDTH = 18

# Int columns.
#: The parent joint's row; WORLD for a joint placed in the world frame.
JI_PARENT = 0
#: The kind of joint (FIXED, REVOLUTE, PRISMATIC, HELICAL).
JI_KIND = 1
#: The index of its coordinate in ``q`` (0 for a fixed joint).
JI_Q = 2
JI_WIDTH = 3

WORLD = -1
FIXED, REVOLUTE, PRISMATIC, HELICAL = 0, 1, 2, 3


def joint_table(model: pin.Model, joints: Sequence[int], parents: Sequence[int]
                ) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``model``'s joints ``joints`` (pinocchio indices, each a revolute,
    prismatic or helical joint; 0, the universe, is a fixed row at the origin), whose
    parents are the rows ``parents`` (WORLD: the world frame).

    Returns:
        The float table (n, JF_WIDTH) and the int table (n, JI_WIDTH).
    """
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    jf = np.zeros((len(joints), JF_WIDTH))
    ji = np.zeros((len(joints), JI_WIDTH), dtype=np.int64)
    for row, (j, parent) in enumerate(zip(joints, parents, strict=True)):
        ji[row, JI_PARENT] = parent
        if j == 0:
            jf[row, JF_R:JF_R + 9] = np.eye(3).ravel()
            ji[row, JI_KIND] = FIXED
            continue
        placement = model.jointPlacements[j]
        S = np.asarray(data.joints[j].S, dtype=float).reshape(6)
        jf[row, JF_R:JF_R + 9] = placement.rotation.reshape(9)
        jf[row, JF_T:JF_T + 3] = placement.translation
        jf[row, JF_V:JF_V + 3] = S[:3]
        jf[row, JF_W:JF_W + 3] = S[3:]
        angular, linear = np.linalg.norm(S[3:]) > 0.5, np.linalg.norm(S[:3]) > 0.0
        ji[row, JI_KIND] = (HELICAL if angular and linear else REVOLUTE if angular
                            else PRISMATIC)
        ji[row, JI_Q] = model.joints[j].idx_q
    return jf, ji


@dataclass(frozen=True)
class Chain:
    """The kinematic chain from the root to a frame, as the kernels read it.

    Attributes:
        joint_f: The float table of the joints from the root to the frame's parent joint,
            in order, each the parent of the next (n, JF_WIDTH).
        joint_i: Their int table (n, JI_WIDTH).
        frame_f: The frame's placement in the last joint: rotation (0-8, row-major),
            translation (9-11) [m].
    """

    joint_f: np.ndarray
    joint_i: np.ndarray
    frame_f: np.ndarray


def chain_joints(model: pin.Model, frame_id: int) -> list[int]:
    """The joints (pinocchio indices) from the root to frame ``frame_id``'s parent joint."""
    return [j for j in model.supports[model.frames[frame_id].parentJoint] if j != 0]


def not_a_screw(model: pin.Model, joints: Sequence[int], q_test: np.ndarray) -> int | None:
    """The first of ``joints`` that does not move as a screw of constant axis (revolute,
    prismatic or helical: the joint table's kinds), judged at the configuration
    ``q_test`` (inside the limits, finite, away from 0); None when all do."""
    data = model.createData()
    pin.forwardKinematics(model, data, q_test)
    for j in joints:
        S = np.asarray(data.joints[j].S, dtype=float).reshape(6)
        x = float(q_test[model.idx_qs[j]])
        moved = pin.exp6(pin.Motion(S * x))
        angular = float(np.linalg.norm(S[3:]))
        if (not (abs(angular - 1.0) < 1e-12 or angular == 0.0)
                or np.linalg.norm(np.cross(S[:3], S[3:])) > 1e-12
                or not data.joints[j].M.isApprox(moved, 1e-12)):
            return j
    return None


def frame_chain(model: pin.Model, frame_id: int, q_test: np.ndarray) -> Chain | None:
    """The chain from the root to frame ``frame_id``; None when one of its joints is not a
    screw (:func:`not_a_screw`, judged at ``q_test``)."""
    joints = chain_joints(model, frame_id)
    if not_a_screw(model, joints, q_test) is not None:
        return None
    joint_f, joint_i = joint_table(model, joints, [WORLD, *range(len(joints) - 1)])
    frame = model.frames[frame_id]
    return Chain(joint_f, joint_i,
                 np.concatenate([frame.placement.rotation.reshape(9), frame.placement.translation]))
