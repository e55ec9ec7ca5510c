"""Continuous joints as revolute joints without position limits.

Pinocchio builds a URDF ``continuous`` joint as an unbounded revolute joint of two
coordinates (cos, sin) and one velocity; safepath's joint vectors hold one coordinate per
joint. So a planned continuous joint is rebuilt as a revolute joint about the same axis
whose coordinate is the *unwrapped* angle [rad], any real number, with position limits
-inf .. +inf. The kinematics are the same at every angle (the joint placement, axis,
inertias and frames are copied; joint and frame ids do not change, so the collision and
visual models built for the URDF stay valid); angles a whole turn apart are the same
placement. :attr:`safepath.Robot.continuous` names those joints, and each layer reads it:
the planner takes the short way round, nothing checks a position limit on them.

Only planned joints are rebuilt; a continuous joint that is locked keeps Pinocchio's form
(:mod:`safepath.model._locked` holds it at its value).
"""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
import pinocchio as pin

__all__ = ["CONTINUOUS_KINDS", "unbound_continuous"]

#: Pinocchio's joint models of a URDF ``continuous`` joint (axis along x, y, z, or any).
CONTINUOUS_KINDS = ("JointModelRUBX", "JointModelRUBY", "JointModelRUBZ",
                    "JointModelRevoluteUnboundedUnaligned")


#: What Pinocchio keeps per velocity coordinate (those a version lacks are skipped).
_PER_VELOCITY = ("armature", "damping", "friction", "rotorInertia", "rotorGearRatio",
                 "lowerDryFrictionLimit", "upperDryFrictionLimit", "lowerEffortLimit",
                 "upperEffortLimit", "lowerVelocityLimit", "upperVelocityLimit")


def _revolute_for(model: pin.Model, j: int) -> pin.JointModel:
    """The revolute joint model about the axis of ``model``'s continuous joint ``j``."""
    kind = model.joints[j].shortname()
    if kind == "JointModelRevoluteUnboundedUnaligned":
        # Its axis is not exposed to Python: read it from the motion subspace (angular
        # part, in the joint frame; constant for a revolute joint).
        data = model.createData()
        pin.forwardKinematics(model, data, pin.neutral(model))
        axis = np.asarray(data.joints[j].S, dtype=float).reshape(6)[3:]
        return pin.JointModel(pin.JointModelRevoluteUnaligned(axis / np.linalg.norm(axis)))
    aligned = {"X": pin.JointModelRX, "Y": pin.JointModelRY, "Z": pin.JointModelRZ}
    return pin.JointModel(aligned[kind[-1]]())


def unbound_continuous(model: pin.Model, planned: Collection[str]) -> tuple[pin.Model, list[str]]:
    """``model`` with its planned continuous joints made revolute joints of one unwrapped
    coordinate [rad] without position limits, and the names of those joints.

    Args:
        model: The description as Pinocchio builds it from the URDF.
        planned: The joints safepath plans (only these are rebuilt).

    Returns:
        The model (``model`` itself when no planned joint is continuous) and the names of
        the rebuilt joints, in model order.
    """
    wraps = [j for j in range(1, model.njoints)
             if model.names[j] in planned and model.joints[j].shortname() in CONTINUOUS_KINDS]
    if not wraps:
        return model, []
    out = pin.Model()
    out.name = model.name
    out.gravity = model.gravity
    for j in range(1, model.njoints):
        joint = model.joints[j]
        q = slice(joint.idx_q, joint.idx_q + joint.nq)
        v = slice(joint.idx_v, joint.idx_v + joint.nv)
        if j in wraps:
            built = _revolute_for(model, j)
            lower, upper = np.array([-np.inf]), np.array([np.inf])
        else:
            built = joint
            lower, upper = model.lowerPositionLimit[q], model.upperPositionLimit[q]
        new_id = out.addJoint(model.parents[j], built, model.jointPlacements[j],
                              model.names[j], model.effortLimit[v], model.velocityLimit[v],
                              lower, upper)
        out.inertias[new_id] = model.inertias[j]
    for frame in list(model.frames)[1:]:  # the universe frame is every model's first
        out.addFrame(frame, False)  # inertias are copied above, per joint
    for name in _PER_VELOCITY:  # velocities are indexed alike in both models
        if hasattr(model, name) and np.shape(getattr(model, name)) == (model.nv,):
            setattr(out, name, np.array(getattr(model, name), dtype=float))
    return out, [str(model.names[j]) for j in wraps]
