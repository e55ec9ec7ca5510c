"""Robots: kinematics, collision geometry, limits, TCP and tool.

:class:`Robot` is built by :func:`safepath.load_robot` (:mod:`safepath.description.robot_folder`)
from a robot folder or an ``example-robot-data`` name, or directly from Pinocchio models.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pinocchio as pin

from ..errors import ConfigError, FrameNotFound, PoseError
from ..files._io import brief
from ..files.derived import Derived, DerivedValues
from ._joint_table import Chain, frame_chain
from ._locked import LockedJoint
from .controller_spec import ControllerSpec
from .limits import MotionLimits, limit_vector
from .tool import ToolSpec, check_tool

__all__ = ["Robot", "ToolSpec", "adjacent_link_pairs", "frame_id", "joint_motion",
           "is_prismatic"]

#: Time in which a joint may go from rest to its full acceleration [s], for robots whose
#: vendor publishes no jerk limits: ``jerk = acceleration / JERK_RAMP_TIME``. 50 ms is a
#: 20 Hz acceleration bandwidth, well inside what servo and stepper drives follow (see
#: ``robots/ned3pro/README.md``).
JERK_RAMP_TIME = 0.05


def derived_jerk_limits(acceleration_limits: Sequence[float] | np.ndarray) -> np.ndarray:
    """Jerk limits [rad/s^3] derived from acceleration limits [rad/s^2] when no vendor
    publishes any: full acceleration reached in :data:`JERK_RAMP_TIME`."""
    return np.asarray(acceleration_limits, dtype=float) / JERK_RAMP_TIME


def joint_vector(q: Any, joint_names: Sequence[str], lower: np.ndarray, upper: np.ndarray,
                 *, name: str = "q", path: Path | None = None,
                 check_limits: bool = True) -> np.ndarray:
    """Validate a joint vector against a robot's joints: right length, finite, inside
    ``lower`` .. ``upper`` (:meth:`Robot.as_joint_vector`; the runtime planner checks
    a pose update with it before any worker is free).

    Raises:
        PoseError: Naming the pose and the offending joint.
    """
    try:
        arr = np.asarray(q, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise PoseError(f"not a vector of numbers: {brief(q)}", path=path, key=name) from None
    if arr.shape != (len(joint_names),):
        raise PoseError(f"expected {len(joint_names)} joint values, got {arr.size}", path=path,
                        key=name)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise PoseError(f"{joint_names[bad[0]]} is not finite ({arr[bad[0]]})",
                        path=path, key=name)
    if check_limits:
        violation = limit_violation(arr, joint_names, lower, upper)
        if violation:
            raise PoseError(violation, path=path, key=name)
    return arr


def limit_violation(q: np.ndarray, joint_names: Sequence[str], lower: np.ndarray,
                    upper: np.ndarray) -> str | None:
    """Describe the first joint of ``q`` outside ``lower`` .. ``upper``, or None."""
    for i, name in enumerate(joint_names):
        if not (lower[i] <= q[i] <= upper[i]):
            value = f"{q[i]:.5f}" if abs(q[i]) < 1e6 else f"{q[i]:.6g}"
            return (f"{name} = {value} rad is outside its limits "
                    f"[{lower[i]:.5f}, {upper[i]:.5f}]")
    return None


class Robot:
    """A serial arm: Pinocchio model, collision geometry, limits and TCP.

    Joint vectors are numpy arrays in the order of :attr:`joint_names` [rad].

    Collision checkers and verifiers share what they build from the robot's shapes alone
    (see :attr:`derived`). To change a shape, give the robot a new collision model
    (``robot.collision_model = ...``) rather than changing one in place; moving a
    geometry, changing the limits or replacing a model is seen.
    """

    def __init__(
        self,
        *,
        name: str,
        model: pin.Model,
        collision_model: pin.GeometryModel,
        visual_model: pin.GeometryModel | None,
        velocity_limits: Sequence[float] | np.ndarray,
        acceleration_limits: Sequence[float] | np.ndarray,
        tcp_frame: str,
        jerk_limits: Sequence[float] | np.ndarray | None = None,
        tool: ToolSpec | None = None,
        allowed_self_pairs: Sequence[tuple[str, str]] = (),
        source: Path | None = None,
        urdf_path: Path | None = None,
        allowed_collisions_path: Path | None = None,
        controller: ControllerSpec | None = None,
        locked_joints: Sequence[LockedJoint] = (),
    ) -> None:
        self.name = name
        self.model = model
        self.collision_model = collision_model
        self.visual_model = visual_model
        self.source = source
        self.urdf_path = urdf_path
        #: Where the robot folder keeps its allowed self-collision pairs (None: no folder).
        self.allowed_collisions_path = allowed_collisions_path
        self.joint_names: tuple[str, ...] = tuple(model.names[1:])
        self.lower = np.array(model.lowerPositionLimit, dtype=float)
        self.upper = np.array(model.upperPositionLimit, dtype=float)
        self._revolute = _revolute_joints(model)
        if model.nq != model.nv or model.nq != len(self.joint_names):
            raise ConfigError("only arms of revolute/prismatic 1-DoF joints are supported",
                              path=source, key="urdf")
        vel = limit_vector(velocity_limits, "velocity_limits", source, dof=self.dof)
        acc = limit_vector(acceleration_limits, "acceleration_limits", source, dof=self.dof)
        # Jerk limits [rad/s^3]: the robot folder's ``jerk_limits`` (vendor numbers where
        # published), else :func:`derived_jerk_limits` of the acceleration limits.
        jerk = (derived_jerk_limits(acc) if jerk_limits is None
                else limit_vector(jerk_limits, "jerk_limits", source, dof=self.dof))
        self._motion = MotionLimits(vel, acc, jerk)
        if not model.existFrame(tcp_frame):
            raise FrameNotFound(tcp_frame, [f.name for f in model.frames], path=source,
                                key="tcp_frame")
        self.tcp_frame = tcp_frame
        self.tcp_frame_id = frame_id(model, tcp_frame)
        self.tool = None if tool is None else check_tool(tool, model, path=source)
        self.allowed_self_pairs = frozenset(tuple(sorted(p)) for p in allowed_self_pairs)
        if controller is not None:
            controller.check_joints(self.joint_names)
        #: Its ROS 2 trajectory controller (from the robot folder's ``controller.yaml``, or
        #: derived from the joint names): what :mod:`safepath.ros` addresses.
        self.controller = controller or ControllerSpec.derived(self.joint_names)
        #: How :func:`safepath.load_robot` loads this robot again (a folder or a name), or
        #: None for a robot built in Python. A robot pickles as this reference, its locked
        #: joints and its attributes a user may change (``robot_folder.CARRIED``: limits,
        #: TCP frame, tool, controller...): worker processes load it themselves and apply
        #: them. Changes made to ``model`` itself do not travel. One without a reference
        #: does not pickle.
        self.reference: str | None = None
        #: Joints held still during motions (fingers, ...): their value, or None where the
        #: collision geometry covers their whole travel. See :func:`safepath.load_robot`.
        self.locked_joints: tuple[LockedJoint, ...] = tuple(locked_joints)
        self._local = threading.local()  # one pinocchio Data per thread
        self._derived = DerivedValues()  # shared by its copies with another tool
        self._chain: tuple[tuple[Any, ...], Chain | None] | None = None  # tcp_chain's

    # -- basic facts -------------------------------------------------------------------
    @property
    def dof(self) -> int:
        """Number of joints."""
        return int(self.model.nq)

    @property
    def motion_limits(self) -> MotionLimits:
        """Its joint velocity, acceleration and jerk limits, one read-only record (what a
        trajectory timed for it carries, :attr:`safepath.Trajectory.limits`). Replaced
        whole, never changed in place: ``robot.motion_limits = MotionLimits(...)``, or
        one of :attr:`velocity_limits`, :attr:`acceleration_limits`, :attr:`jerk_limits`
        assigned a new array.

        Raises:
            ConfigError: Not a :class:`MotionLimits` of this robot's joints.
        """
        return self._motion

    @motion_limits.setter
    def motion_limits(self, value: MotionLimits) -> None:
        if not isinstance(value, MotionLimits) or value.dof != self.dof:
            raise ConfigError(f"expected MotionLimits of {self.dof} joints, got {value!r}",
                              key="motion_limits")
        self._motion = value

    @property
    def velocity_limits(self) -> np.ndarray:
        """Joint velocity limits [rad/s or m/s] (read-only; assign a new array)."""
        return self._motion.velocity

    @velocity_limits.setter
    def velocity_limits(self, value: Sequence[float] | np.ndarray) -> None:
        self._motion = replace(self._motion,
                               velocity=limit_vector(value, "velocity_limits", dof=self.dof))

    @property
    def acceleration_limits(self) -> np.ndarray:
        """Joint acceleration limits [rad/s^2 or m/s^2] (read-only; assign a new array)."""
        return self._motion.acceleration

    @acceleration_limits.setter
    def acceleration_limits(self, value: Sequence[float] | np.ndarray) -> None:
        self._motion = replace(self._motion, acceleration=limit_vector(
            value, "acceleration_limits", dof=self.dof))

    @property
    def jerk_limits(self) -> np.ndarray:
        """Joint jerk limits [rad/s^3 or m/s^3] (read-only; assign a new array)."""
        return self._motion.jerk

    @jerk_limits.setter
    def jerk_limits(self, value: Sequence[float] | np.ndarray) -> None:
        self._motion = replace(self._motion,
                               jerk=limit_vector(value, "jerk_limits", dof=self.dof))

    @property
    def continuous(self) -> tuple[bool, ...]:
        """Per joint (in :attr:`joint_names` order), whether it is continuous: a revolute
        joint without position limits (:attr:`lower` -inf, :attr:`upper` +inf: a URDF
        ``continuous`` joint, see :mod:`safepath.description._continuous`). Its coordinate is an
        unwrapped angle [rad]: values a whole turn apart are the same placement, and a
        motion moves it continuously (never by a jump of a turn). Giving such a joint
        finite limits (``robot.lower[j] = ...``) makes it a bounded revolute joint."""
        return tuple(bool(r and self.lower[j] == -np.inf and self.upper[j] == np.inf)
                     for j, r in enumerate(self._revolute))

    @property
    def link_names(self) -> tuple[str, ...]:
        """Names of the links that carry collision geometry, in model order."""
        seen: dict[str, None] = {}
        for geom in self.collision_model.geometryObjects:
            seen[self.model.frames[geom.parentFrame].name] = None
        return tuple(seen)

    @property
    def derived(self) -> Derived:
        """What is computed from this robot alone and kept for it (sphere fits placed on
        their joints, hulls, reach per joint, the verifier's shapes), made again when its
        models are replaced, a geometry moves or a limit changes: see
        :mod:`safepath.files.derived` (``held()`` lists it, ``forget()`` drops it)."""
        return Derived(self, self._derived)

    def geometry_link(self, geom_index: int) -> str:
        """Link (frame) name that carries collision geometry ``geom_index``."""
        geom = self.collision_model.geometryObjects[geom_index]
        return str(self.model.frames[geom.parentFrame].name)

    def with_tool(self, tool: ToolSpec | None) -> Robot:
        """A copy of this robot holding ``tool`` (the models and the shared parts made from
        its shapes are the same objects: nothing is loaded again).

        Raises:
            FrameNotFound: A contact link the robot does not have.
        """
        other = Robot.__new__(Robot)  # not copy.copy: a robot pickles as its reference
        other.__dict__.update(self.__dict__)
        other.tool = None if tool is None else check_tool(tool, self.model, path=self.source)
        return other

    def __repr__(self) -> str:
        locked = [j.name for j in self.locked_joints if j.follows is None]
        held = f", locked={locked}" if locked else ""
        return f"Robot({self.name!r}, dof={self.dof}, tcp={self.tcp_frame!r}{held})"

    # -- poses ---------------------------------------------------------------------------
    def as_joint_vector(self, q: Any, *, name: str = "q", path: Path | None = None,
                        check_limits: bool = True) -> np.ndarray:
        """Validate a joint vector: right length, finite, inside the limits.

        Raises:
            PoseError: Naming the pose and the offending joint.
        """
        return joint_vector(q, self.joint_names, self.lower, self.upper, name=name,
                            path=path, check_limits=check_limits)

    def within_limits(self, q: np.ndarray, tol: float = 0.0) -> bool:
        """Whether every joint lies inside its position limits (± ``tol`` [rad])."""
        lower, upper = (self.lower - tol, self.upper + tol) if tol else (self.lower, self.upper)
        return bool((q >= lower).all() and (q <= upper).all())

    def limit_violation(self, q: np.ndarray) -> str | None:
        """Describe the first joint outside its limits, or None."""
        return limit_violation(q, self.joint_names, self.lower, self.upper)

    def nearest_turn(self, q: np.ndarray, q_near: np.ndarray) -> np.ndarray:
        """``q`` [rad] with each continuous joint (:attr:`continuous`) moved by whole turns
        to the value nearest ``q_near`` (within pi): the same placement, reached from
        ``q_near`` the short way round. Other joints are as in ``q``."""
        out = np.array(q, dtype=float)
        for j in np.flatnonzero(self.continuous):
            out[j] -= 2.0 * np.pi * np.round((out[j] - q_near[j]) / (2.0 * np.pi))
        return out

    def frame_pose(self, q: np.ndarray, frame: str | None = None) -> pin.SE3:
        """Pose of ``frame`` (default: the TCP) in the world frame at ``q``."""
        fid = self.tcp_frame_id if frame is None else self._frame_id(frame)
        data = self._data()
        pin.forwardKinematics(self.model, data, q)
        return pin.updateFramePlacement(self.model, data, fid).copy()

    def tcp_position(self, q: np.ndarray) -> np.ndarray:
        """TCP position in the world frame [m]."""
        return np.array(self.frame_pose(q).translation)

    def tcp_positions(self, q_path: np.ndarray) -> np.ndarray:
        """TCP positions in the world frame [m] (n, 3) at the joint positions ``q_path``
        (n, dof): :meth:`tcp_position` of each row, in one compiled pass over the chain
        to the TCP (:meth:`tcp_chain`; Pinocchio row by row where it has none)."""
        return self._tcp_motion(q_path, None)[0]

    def tcp_speeds(self, q_path: np.ndarray, qd_path: np.ndarray) -> np.ndarray:
        """Speeds of the TCP [m/s] (n,) at the joint positions ``q_path`` and velocities
        ``qd_path`` (n, dof): the norm of its linear velocity in the world frame."""
        return self._tcp_motion(q_path, qd_path)[1]

    def tcp_chain(self) -> Chain | None:
        """The chain from the root to the TCP as the planner's kernels read it (a joint
        table, :mod:`safepath.model._joint_table`), kept per TCP frame; None when a joint on
        it is not a revolute, prismatic or helical joint."""
        # Kept by identity of the model (not in :attr:`derived`, whose currency check
        # reads every collision geometry's placement: 30 us, more than the TCP's speeds
        # along a path take).
        key = (self.model, int(self.tcp_frame_id), self.lower.tobytes(), self.upper.tobytes())
        kept = self._chain
        if kept is None or kept[0][0] is not key[0] or kept[0][1:] != key[1:]:
            kept = self._chain = (key, frame_chain(self.model, key[1], self.chain_test_q()))
        return kept[1]

    def chain_test_q(self) -> np.ndarray:
        """A configuration inside the limits, finite and away from 0, at which the chain's
        joints are told apart (:func:`~safepath.model._joint_table.not_a_screw`)."""
        return np.clip(np.full(self.model.nq, 0.7), self.lower, self.upper)

    def _tcp_motion(self, q_path: np.ndarray, qd_path: np.ndarray | None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """TCP positions (n, 3) [m] and, with ``qd_path``, speeds (n,) [m/s]."""
        q_path = np.ascontiguousarray(q_path, dtype=np.float64).reshape(-1, self.model.nq)
        n = q_path.shape[0]
        speed = qd_path is not None
        qd = (np.ascontiguousarray(qd_path, dtype=np.float64).reshape(n, self.model.nv)
              if speed else q_path[:0])
        chain = self.tcp_chain()
        p_out, v_out = np.empty((n, 3)), np.empty(n if speed else 0)
        if chain is not None:
            from . import _fk_kernel

            k = chain.joint_f.shape[0]
            _fk_kernel.tcp_motion(chain.joint_f, chain.joint_i, chain.frame_f, q_path, qd,
                                  speed, np.empty((k, 3, 3)), np.empty((k, 3)),
                                  np.empty(self.model.nq), p_out, v_out)
            return p_out, v_out
        model, data, fid = self.model, self._data(), self.tcp_frame_id
        world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        for k, q in enumerate(q_path):
            if speed:
                pin.forwardKinematics(model, data, q, qd[k])
                v_out[k] = np.linalg.norm(pin.getFrameVelocity(model, data, fid, world).linear)
            else:
                pin.forwardKinematics(model, data, q)
            p_out[k] = pin.updateFramePlacement(model, data, fid).translation
        return p_out, v_out

    def _data(self) -> pin.Data:
        """This thread's pinocchio data of the model."""
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        return data

    def _frame_id(self, frame: str) -> int:
        if not self.model.existFrame(frame):
            raise FrameNotFound(frame, [f.name for f in self.model.frames])
        return frame_id(self.model, frame)


def _revolute_joints(model: pin.Model) -> tuple[bool, ...]:
    """Per joint of ``model``: whether it is a 1-DoF revolute joint."""
    out = []
    for j in range(1, model.njoints):
        motion = joint_motion(model, j)
        out.append(motion is not None and motion[0] == "revolute")
    return tuple(out)


def frame_id(model: pin.Model, name: str) -> int:
    """The id of frame ``name`` of ``model`` (which has it): the link's own frame when a
    fixed joint bears the same name (URDFs may name both alike; Pinocchio then refuses
    to choose)."""
    ids = [i for i, f in enumerate(model.frames) if f.name == name]
    if len(ids) > 1:
        bodies = [i for i in ids if model.frames[i].type == pin.FrameType.BODY]
        ids = bodies or ids
    return ids[0]


JointKind = Literal["revolute", "prismatic"]
_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def joint_motion(model: pin.Model, j: int) -> tuple[JointKind, tuple[float, float, float]] | None:
    """How joint ``j`` of ``model`` moves its child: the one place that reads joint types.

    Returns:
        ``("revolute" | "prismatic", axis)`` for a 1-DoF revolute or prismatic joint (axis
        in the joint frame; unit length for Pinocchio's aligned joints, as given in the
        URDF for unaligned ones), or None for any other joint (helical, spherical, ...).
    """
    joint = model.joints[j]
    name = joint.shortname()
    if joint.nq != 1 or joint.nv != 1:
        return None
    kinds: tuple[tuple[str, JointKind], ...] = (("JointModelR", "revolute"),
                                               ("JointModelP", "prismatic"))
    for prefix, kind in kinds:
        if name[:-1] == prefix and name[-1] in _AXES:
            return kind, _AXES[name[-1]]
    if name in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        axis = np.asarray(joint.extract().axis, dtype=float)
        unaligned: JointKind = "revolute" if "Revolute" in name else "prismatic"
        return unaligned, (float(axis[0]), float(axis[1]), float(axis[2]))
    return None


def is_prismatic(model: pin.Model, j: int) -> bool:
    """Whether joint ``j`` of ``model`` slides (1-DoF prismatic, any axis)."""
    motion = joint_motion(model, j)
    return motion is not None and motion[0] == "prismatic"


def adjacent_link_pairs(model: pin.Model, geom: pin.GeometryModel) -> list[tuple[str, str]]:
    """Link pairs that touch at the joint between them: never self-checked.

    Two links are adjacent when their geometry hangs on the same joint (links joined by
    fixed joints) or on a joint and its parent, as MoveIt's setup assistant counts them;
    a joint that carries no geometry is looked through (its child is adjacent to the
    nearest ancestor that carries geometry).
    """
    links: dict[str, int] = {}
    for g in geom.geometryObjects:
        links[model.frames[g.parentFrame].name] = g.parentJoint
    carrying = set(links.values())

    def shown_parent(j: int) -> int:
        j = model.parents[j]
        while j > 0 and j not in carrying:
            j = model.parents[j]
        return j

    out = []
    names = sorted(links)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            ja, jb = links[a], links[b]
            if ja == jb or (ja > 0 and shown_parent(ja) == jb) \
                    or (jb > 0 and shown_parent(jb) == ja):
                out.append((a, b))
    return out
