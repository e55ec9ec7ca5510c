"""Which joints of a robot description safepath plans, which it locks, and which robots
it refuses.

safepath plans for fixed-base arms of revolute, continuous and prismatic joints (a
continuous joint is planned as a revolute joint without position limits, see
:mod:`safepath.description._continuous`). A description that is something else is refused with
:class:`RobotNotSupported` naming the joints at fault, never reduced silently to the
joints that fit:

* a floating base (a ``floating`` or ``planar`` URDF joint, or example-robot-data's
  free-flyer root: legged robots, humanoids, drones) is not an arm;
* any other joint of more than one DoF (spherical, ...) is refused.

Gripper joints are recognised by name (:data:`GRIPPER_WORDS`), with the joints that
mimic them and those they carry: they are *locked* (see :mod:`safepath.model._locked`), never
planned. A robot described by a ``robot.yaml`` lists its planned and locked joints itself.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import pinocchio as pin

from ..errors import RobotNotSupported
from ._continuous import CONTINUOUS_KINDS

__all__ = ["GRIPPER_WORDS", "refuse_non_arm", "gripper_joints", "tip_frame"]

#: Words (any case) that make a joint a gripper's: ``panda_finger_joint1``, z1's
#: ``jointGripper``, the SO-100's ``gripper``, a ``jaw`` or ``claw``.
GRIPPER_WORDS = ("finger", "gripper", "jaw", "claw", "thumb", "knuckle")
_GRIPPER = re.compile("|".join(GRIPPER_WORDS), re.IGNORECASE)



def refuse_non_arm(model: pin.Model, *, robot: str, path: Path | None = None,
                   planned: Collection[str] | None = None, hint: str = "") -> None:
    """Refuse a description that is not a fixed-base arm of 1-DoF joints (continuous
    joints count as 1-DoF: :func:`~safepath.description._continuous.unbound_continuous`
    makes them so).

    Args:
        model: The description as Pinocchio builds it (every joint movable).
        robot: The robot's name, for the message.
        path: The file, for the message.
        planned: The joints to be planned (None: every joint); only these are checked
            for multi-DoF joints (a locked one says its own error).
        hint: What the user can do instead, appended to a floating-base refusal.

    Raises:
        RobotNotSupported: A floating base or a joint of several DoF.
    """
    floating = [str(model.names[j]) for j in range(1, model.njoints)
                if model.parents[j] == 0 and model.joints[j].nq > 1
                and model.joints[j].shortname() not in CONTINUOUS_KINDS]
    if floating:
        roots = ", ".join(f"'{n}' ({model.joints[model.getJointId(n)].shortname()})"
                          for n in floating)
        raise RobotNotSupported(
            f"'{robot}' is not a fixed-base arm: it has a floating base ({roots}); safepath "
            f"plans for arms fixed to their base{hint}", robot=robot, joints=floating,
            path=path, key="joints")
    names = [str(model.names[j]) for j in range(1, model.njoints)
             if planned is None or model.names[j] in planned]
    kinds = {n: model.joints[model.getJointId(n)].shortname() for n in names}
    multi = [n for n in names if kinds[n] not in CONTINUOUS_KINDS
             and (model.joints[model.getJointId(n)].nq != 1
                  or model.joints[model.getJointId(n)].nv != 1)]
    if multi:
        raise RobotNotSupported(
            f"'{robot}' has joints of several DoF {[f'{n} ({kinds[n]})' for n in multi]}: "
            "safepath plans for revolute and prismatic joints", robot=robot, joints=multi,
            path=path, key="joints")


def gripper_joints(model: pin.Model, mimics: Mapping[str, tuple[str, float, float]]
                   ) -> list[str]:
    """The joints of a gripper: named so (:data:`GRIPPER_WORDS`), mimicking one, or carried
    by one (a finger's tip joint), in model order."""
    named = {model.getJointId(n) for n in model.names[1:] if _GRIPPER.search(n)}
    named |= {model.getJointId(n) for n, (driver, _, _) in mimics.items()
              if model.existJointName(n) and _GRIPPER.search(driver)}
    out = []
    for j in range(1, model.njoints):
        k = j
        while k > 0 and k not in named:
            k = model.parents[k]
        if k > 0:
            out.append(str(model.names[j]))
    return out


def tip_frame(model: pin.Model, arm: Sequence[str], *, robot: str,
              path: Path | None = None) -> str:
    """The frame a TCP is guessed at, for a description that names none: the last body of
    the chain of ``arm`` joints (the URDF's tip link, before any gripper joint).

    Raises:
        RobotNotSupported: No joint to plan, or the joints branch (two arms, a hand's
            fingers): the TCP must then be named (``tcp_frame=``).
    """
    ids = [model.getJointId(n) for n in arm]
    if not ids:
        raise RobotNotSupported(f"'{robot}' has no joint to plan (every joint is a "
                                "gripper's or fixed)", robot=robot, path=path, key="joints")
    for previous, j in zip([0, *ids], ids, strict=False):
        if model.parents[j] != previous:
            raise RobotNotSupported(
                f"'{robot}' is not one chain ({model.names[j]} does not follow "
                f"{model.names[previous] if previous else 'the base'}): name its TCP frame "
                "with load_robot(..., tcp_frame=...)", robot=robot,
                joints=[str(model.names[j])], path=path, key="tcp_frame")
    last = ids[-1]
    bodies = [f for f in model.frames
              if f.parentJoint == last and f.type == pin.FrameType.BODY]
    if not bodies:  # pragma: no cover - a joint always has its child link
        return str(model.names[last])
    return str(bodies[-1].name)
