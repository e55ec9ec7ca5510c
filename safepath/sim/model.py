"""A MuJoCo model of a robot, generated from its own description, with position servos.

The MJCF is written in memory from what safepath already holds about the robot, never
from a second copy of its description:

* **bodies and joints** from the Pinocchio model (``robot.model``): one body per joint,
  placed by ``jointPlacements`` (the joint frame in its parent joint's frame), a hinge or
  slide along the joint's axis (:func:`safepath.model.robot.joint_motion`), position limits;
* **inertias** from ``robot.model.inertias`` (mass, centre of mass, rotational inertia
  about it in the joint frame; links joined by fixed joints are already merged there);
* **shapes** from the collision model (``robot.collision_model``: coal boxes,
  cylinders, spheres, capsules, convex hulls), each on its joint's body, and the cell's
  static objects when a scene is given. Shapes carry no mass (``inertiafromgeom`` off);
  they collide with the cell only (never robot with robot), so MuJoCo counts physical
  contacts of the simulated arm with the cell as a second opinion.

**Drives.** Each joint has a position servo, the way the arm's drives follow the
controller's setpoints: a PD law with velocity and acceleration feed-forward and gravity
compensation, its force clamped to the joint's effort limit::

    tau = kp (q_ref - q) + kd (qd_ref - qd) + m qdd_ref + g(q)

with ``kp = m w^2``, ``kd = 2 zeta m w`` (``w = 2 pi bandwidth``, ``m`` the joint's own
inertia, the diagonal of the joint-space inertia matrix at the reference pose). It is
one MuJoCo ``general`` actuator per joint (``gain kp``, ``bias -kp q - kd qd``, control
``q_ref + kd/kp qd_ref + qdd_ref / w^2``) plus MuJoCo's gravity compensation routed
through the actuators (``actuatorgravcomp``), so the clamp bounds the total. The gains
are stated in :class:`ServoGains`; they are a model of a stiff industrial servo, not
the vendor's firmware (see docs/twin.md for what this leaves out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import ConfigError, InputError
from ..model.shapes import SHAPES, from_coal

if TYPE_CHECKING:
    from ..model.robot import Robot
    from ..model.scene import Scene

__all__ = ["ServoGains", "RobotModel", "build_robot_model", "TIMESTEP"]

#: Physics timestep [s] (1 kHz).
TIMESTEP = 0.001


@dataclass(frozen=True, kw_only=True)
class ServoGains:
    """The joints' position servos (see the module docstring).

    Attributes:
        bandwidth: Closed-loop bandwidth of every joint's servo [Hz].
        damping_ratio: Damping ratio of the servo loop.
        feedforward: Velocity and acceleration feed-forward of the setpoint (drives that
            take position, velocity and acceleration, as ros2_control's command
            interfaces carry them); False: position only.
        gravity_compensation: Gravity compensated by the drives.
        armature: Reflected rotor inertia added to every joint [kg m^2] (0: unknown,
            the links alone).
    """

    bandwidth: float = 20.0
    damping_ratio: float = 1.0
    feedforward: bool = True
    gravity_compensation: bool = True
    armature: float = 0.0

    def __post_init__(self) -> None:
        for key, low in (("bandwidth", 0.0), ("damping_ratio", 0.0), ("armature", -1.0)):
            value = getattr(self, key)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) \
                and math.isfinite(value) and (value > low if key != "armature" else value >= 0)
            if not ok:
                bound = ">= 0" if key == "armature" else "> 0"
                raise InputError(f"expected a finite number {bound}, got {value!r}", key=key)

    @property
    def omega(self) -> float:
        """The servo's natural frequency [rad/s]."""
        return 2.0 * math.pi * self.bandwidth


@dataclass(frozen=True)
class RobotModel:
    """A robot's MuJoCo model, its servo gains, and how its joints map to safepath's.

    Attributes:
        model: The ``mujoco.MjModel``.
        joint_names: The planned joints, in safepath's order (``robot.joint_names``).
        qpos_index: For each, its address in ``qpos`` / ``qvel``.
        kp: Position gain per joint [N m/rad or N/m].
        kd: Velocity gain per joint [N m s/rad].
        effort: Effort limit per joint [N m or N].
        gains: The stated servo gains.
        xml: The generated MJCF.
        scene_geoms: Number of the cell's static shapes in the model.
    """

    model: Any = field(repr=False)
    joint_names: tuple[str, ...]
    qpos_index: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    effort: np.ndarray
    gains: ServoGains
    xml: str = field(repr=False)
    scene_geoms: int = 0

    def control(self, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray) -> np.ndarray:
        """The actuators' controls for setpoints (rows of positions [rad], velocities
        [rad/s], accelerations [rad/s^2]) in safepath's joint order."""
        if not self.gains.feedforward:
            return np.asarray(q_ref, dtype=float)
        w = self.gains.omega
        return q_ref + (2.0 * self.gains.damping_ratio / w) * qd_ref + qdd_ref / (w * w)


def _f(values: Any) -> str:
    return " ".join(f"{float(v):.10g}" for v in np.ravel(values))


def _quat_wxyz(R: np.ndarray) -> np.ndarray:  # noqa: N803
    import pinocchio as pin

    q = pin.Quaternion(np.asarray(R, dtype=float))
    return np.array([q.w, q.x, q.y, q.z])


def _geom_xml(name: str, geometry: Any, M: Any, *, robot: bool,  # noqa: N803
              assets: list[str], rgba: str) -> str | None:
    """One ``<geom>`` of a coal shape placed at ``M`` (pinocchio SE3), or None."""
    import coal

    pos, quat = _f(M.translation), _f(_quat_wxyz(M.rotation))
    flags = 'contype="1" conaffinity="0"' if robot else 'contype="0" conaffinity="1"'
    common = f'name={quoteattr(name)} pos="{pos}" quat="{quat}" {flags} rgba="{rgba}"'
    primitive = from_coal(geometry)
    if primitive is not None:
        kind, half = primitive
        return f'<geom type="{kind.mujoco}" size="{_f(half[:kind.mujoco_params])}" {common}/>'
    if isinstance(geometry, coal.ConvexBase):
        points = np.asarray(geometry.points(), dtype=float)
        mesh = f"mesh_{len(assets)}"
        assets.append(f'<mesh name="{mesh}" vertex="{_f(points)}"/>')
        return f'<geom type="mesh" mesh="{mesh}" {common}/>'
    return None


def _scene_xml(scene: Scene) -> list[str]:
    """The cell's static objects as world geoms (movable ones are not simulated)."""
    out = []
    for obj in scene.objects.values():
        if obj.movable:
            continue
        T = obj.T_world_object  # noqa: N806
        pos, quat = _f(T[:3, 3]), _f(_quat_wxyz(T[:3, :3]))
        rgba = _f((*obj.color, 1.0))
        common = (f'name={quoteattr("cell/" + obj.name)} pos="{pos}" quat="{quat}" '
                  f'contype="0" conaffinity="1" rgba="{rgba}"')
        kind = SHAPES[obj.shape.kind]
        out.append(f'<geom type="{kind.mujoco}" size="{_f(kind.mujoco_size(obj.shape.size))}" '
                   f'{common}/>')
    return out


def _body_xml(robot: Robot, j: int, children: dict[int, list[int]], geoms: dict[int, list[str]],
              gains: ServoGains) -> str:
    """The body of joint ``j`` and, nested, its children's."""
    from ..model.robot import joint_motion

    model = robot.model
    M = model.jointPlacements[j]  # noqa: N806
    motion = joint_motion(model, j)
    if motion is None:
        raise ConfigError(f"joint '{model.names[j]}' is neither revolute nor prismatic: the "
                          "twin simulates 1-DoF joints only", key="robot")
    kind, axis = motion
    inertia = model.inertias[j]
    I = np.asarray(inertia.inertia, dtype=float)  # noqa: E741, N806
    mass = max(float(inertia.mass), 1e-6)
    # A link without inertia would make the joint massless: give it a tiny one.
    I = I + np.eye(3) * 1e-9  # noqa: E741, N806
    full = _f([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])
    iq = j - 1
    lo, hi = float(model.lowerPositionLimit[iq]), float(model.upperPositionLimit[iq])
    effort = float(model.effortLimit[iq])
    mj_kind = "hinge" if kind == "revolute" else "slide"
    gravcomp = 'actuatorgravcomp="true"' if gains.gravity_compensation else ""
    lines = [
        f'<body name={quoteattr(model.names[j])} pos="{_f(M.translation)}" '
        f'quat="{_f(_quat_wxyz(M.rotation))}" gravcomp="{1 if gains.gravity_compensation else 0}">',
        f'<inertial pos="{_f(inertia.lever)}" mass="{mass:.10g}" fullinertia="{full}"/>',
        f'<joint name={quoteattr(model.names[j])} type="{mj_kind}" axis="{_f(axis)}" '
        f'{_range(lo, hi)} armature="{gains.armature:.10g}" '
        f'actuatorfrcrange="{-effort:.10g} {effort:.10g}" actuatorfrclimited="true" {gravcomp}/>',
        *geoms.get(j, []),
        *(_body_xml(robot, c, children, geoms, gains) for c in children.get(j, [])),
        "</body>",
    ]
    return "\n".join(lines)


def _check_robot(robot: Robot) -> None:
    model = robot.model
    if model.nq != model.nv or model.nq != len(robot.joint_names):
        raise ConfigError(f"robot '{robot.name}': the twin needs one coordinate per joint "
                          f"(nq {model.nq}, nv {model.nv})", key="robot")
    effort = np.asarray(model.effortLimit, dtype=float)
    if not np.all(np.isfinite(effort) & (effort > 0)):
        bad = [robot.joint_names[k] for k in np.flatnonzero(~(np.isfinite(effort)
                                                              & (effort > 0)))]
        raise ConfigError(f"robot '{robot.name}': joints {bad} have no effort limit > 0 in "
                          "the URDF: the servos need one", key="effort")


def build_robot_model(robot: Robot, scene: Scene | None = None, *,
                      gains: ServoGains | None = None, timestep: float = TIMESTEP,
                      extra_world: str = "") -> RobotModel:
    """The robot (and the cell's static objects) as a MuJoCo model with position servos.

    Args:
        robot: The robot (its Pinocchio model and collision model are used).
        scene: The cell, whose static objects become world geoms; None: the robot alone.
        gains: The servos' gains; default :class:`ServoGains()`.
        timestep: Physics timestep [s] (<= 1 ms).
        extra_world: MJCF of further world bodies (e.g. a moving obstacle, a mocap
            body), inserted in the ``worldbody`` as given.

    Raises:
        ConfigError: A joint that is not 1-DoF revolute or prismatic, or without an
            effort limit.
        InputError: A timestep outside (0, 1 ms].
    """
    import mujoco

    gains = gains or ServoGains()
    if isinstance(timestep, bool) or not isinstance(timestep, (int, float)) \
            or not 0 < timestep <= 0.001:
        raise InputError(f"expected a physics timestep in (0, 0.001] [s], got {timestep!r}",
                         key="timestep")
    _check_robot(robot)
    model = robot.model
    children: dict[int, list[int]] = {}
    for j in range(1, model.njoints):
        children.setdefault(int(model.parents[j]), []).append(j)
    assets: list[str] = []
    geoms: dict[int, list[str]] = {}
    for g in robot.collision_model.geometryObjects:
        xml = _geom_xml("robot/" + g.name, g.geometry, g.placement, robot=True, assets=assets,
                        rgba="0.9 0.6 0.1 1")
        if xml is not None:
            geoms.setdefault(int(g.parentJoint), []).append(xml)
    scene_geoms = _scene_xml(scene) if scene is not None else []
    bodies = "\n".join(_body_xml(robot, c, children, geoms, gains) for c in children.get(0, []))
    actuators = "\n".join(
        f'<general name={quoteattr(name)} joint={quoteattr(name)} gaintype="fixed" '
        f'biastype="affine" gainprm="0" biasprm="0 0 0"/>' for name in robot.joint_names)
    xml = "\n".join([
        f'<mujoco model={quoteattr("safepath/" + robot.name)}>',
        '<compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
        f'<option timestep="{timestep:.10g}" integrator="implicitfast" gravity="0 0 -9.81"/>',
        f"<asset>{''.join(assets)}</asset>",
        "<worldbody>", *geoms.get(0, []), *scene_geoms, bodies, extra_world, "</worldbody>",
        f"<actuator>{actuators}</actuator>",
        "</mujoco>"])
    try:
        mj = mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:  # MuJoCo's compiler errors: ours, never the user's
        raise ConfigError(f"robot '{robot.name}': MuJoCo refused the generated model: {exc}",
                          key="robot") from None
    qpos_index = np.array([mj.jnt_qposadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n)]
                           for n in robot.joint_names], dtype=np.int64)
    effort = np.asarray(model.effortLimit, dtype=float).copy()
    kp, kd = _gains(mj, robot, qpos_index, gains)
    for a in range(mj.nu):
        mj.actuator_gainprm[a, 0] = kp[a]
        mj.actuator_biasprm[a, :3] = (0.0, -kp[a], -kd[a])
        mj.actuator_forcerange[a] = (-effort[a], effort[a])
        mj.actuator_forcelimited[a] = 1
    return RobotModel(mj, tuple(robot.joint_names), qpos_index, kp, kd, effort, gains, xml,
                      len(scene_geoms))


def _range(lower: float, upper: float) -> str:
    """A MuJoCo joint's range attributes: none for a continuous joint (no position limits,
    :attr:`safepath.Robot.continuous`): the hinge turns freely, any number of turns."""
    if np.isinf(lower) and np.isinf(upper):
        return 'limited="false"'
    return f'range="{lower:.10g} {upper:.10g}" limited="true"'


def _gains(mj: Any, robot: Robot, qpos_index: np.ndarray, gains: ServoGains
           ) -> tuple[np.ndarray, np.ndarray]:
    """``kp = m w^2`` and ``kd = 2 zeta m w`` per joint, ``m`` the diagonal of the
    joint-space inertia at the middle of the joint ranges."""
    import mujoco

    data = mujoco.MjData(mj)
    mid = 0.5 * (np.clip(robot.lower, -np.pi, np.pi) + np.clip(robot.upper, -np.pi, np.pi))
    data.qpos[qpos_index] = mid
    mujoco.mj_forward(mj, data)
    M = np.zeros((mj.nv, mj.nv))  # noqa: N806
    try:  # MuJoCo >= 3.4 takes the data; earlier ones its sparse qM
        mujoco.mj_fullM(mj, data, M)
    except TypeError:
        mujoco.mj_fullM(mj, M, data.qM)
    m = np.diag(M)[qpos_index]
    w = gains.omega
    return m * w * w, 2.0 * gains.damping_ratio * m * w
