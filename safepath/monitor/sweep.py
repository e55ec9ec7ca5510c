"""The robot along a path, as spheres that enclose it, ready for separation queries.

A :class:`PathSweep` samples the states of a path so that no point of the robot (or of
the object it holds) moves more than ``spacing`` between two consecutive samples, and
places at every sample the outer spheres of :mod:`safepath.collision.spheres` (which *enclose*
every link: a distance to them is a lower bound of the distance to the real robot).
Between two samples every point of the robot stays within ``spacing`` of where it was
at one of them, so the separation at any state in between is at least the smaller of
the two samples' lower bounds minus ``spacing / 2``.

Only bodies that move are included (links on a moving joint, the held object): the
separation monitor protects against the robot's motion; the fixed base is part of the
static cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..collision.spheres import fit_spheres
from ..model.robot import Robot
from ..model.scene import Scene

__all__ = ["PathSweep", "RobotSpheres"]


@dataclass(frozen=True)
class RobotSpheres:
    """The moving bodies of a robot as spheres in their joints' frames.

    Attributes:
        names: Body names (links' geometry names, then the held object).
        joints: Joint carrying each body.
        body_start: Sphere range of each body (n_bodies + 1,).
        centers: Sphere centres in their joint's frame [m] (K, 3).
        radii: Radii [m] (K,).
        bounding: Per body, a sphere holding its spheres, in the joint frame (n, 4) [m].
        weights: Per body and joint, how far [m] a point of the body can lie from the
            joint's axis: it moves at most sum_j w_j |dq_j| for a joint change dq.
    """

    names: tuple[str, ...]
    joints: np.ndarray
    body_start: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    bounding: np.ndarray
    weights: np.ndarray

    @classmethod
    def build(cls, robot: Robot, scene: Scene | None = None, held: str | None = None, *,
              cell: float = 0.04) -> RobotSpheres:
        """Fit spheres to every moving link (and ``held``, at the scene's grasp).

        Args:
            robot: The robot.
            scene: The scene whose grasp places the held object.
            held: Name of the held object, or None.
            cell: Cell edge of the sphere fit [m] (smaller: tighter, more spheres).
        """
        bodies: list[tuple[str, int, np.ndarray, object]] = []
        for g in robot.collision_model.geometryObjects:
            if int(g.parentJoint) == 0:
                continue
            bodies.append((g.name, int(g.parentJoint), g.placement.homogeneous, g.geometry))
        if held is not None:
            if scene is None or scene.grasp is None or held not in scene.objects:
                from ..errors import ConfigError

                raise ConfigError(f"cannot place held object '{held}': the scene has no "
                                  "such object or no grasp", key="held")
            tcp = robot.model.frames[robot.tcp_frame_id]
            T = tcp.placement.homogeneous @ scene.grasp.T_tcp_object
            bodies.append((held, int(tcp.parentJoint), T, scene.objects[held].shape.to_coal()))
        centers, radii, starts, bounding, joints = [], [], [0], [], []
        for _, joint, T, geometry in bodies:
            fit = fit_spheres(geometry, cell=cell).transformed(T)
            centers.append(fit.outer_centers)
            radii.append(fit.outer_radii)
            starts.append(starts[-1] + len(fit.outer_radii))
            c, r = fit.bounding
            bounding.append([*c, r])
            joints.append(joint)
        J = np.array(joints, dtype=np.int64)
        B = np.array(bounding, dtype=float).reshape(-1, 4)
        return cls(tuple(b[0] for b in bodies), J, np.array(starts, dtype=np.int64),
                   np.vstack(centers), np.concatenate(radii), B,
                   _weights(robot.model, J, B))

    def place(self, robot: Robot, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # noqa: N803
        """World sphere centres (n, K, 3) and body bounding spheres (n, bodies, 4) at
        the states ``Q`` (n, dof)."""
        model = robot.model
        data = model.createData()
        body_of = np.repeat(np.arange(self.joints.size), np.diff(self.body_start))
        joint_of = self.joints[body_of]
        C = np.empty((len(Q), self.radii.size, 3))
        Bd = np.empty((len(Q), self.joints.size, 4))
        Bd[:, :, 3] = self.bounding[:, 3]
        for i, q in enumerate(Q):
            pin.forwardKinematics(model, data, q)
            R = np.array([data.oMi[j].rotation for j in range(model.njoints)])
            p = np.array([data.oMi[j].translation for j in range(model.njoints)])
            C[i] = np.einsum("kab,kb->ka", R[joint_of], self.centers) + p[joint_of]
            Bd[i, :, :3] = (np.einsum("kab,kb->ka", R[self.joints], self.bounding[:, :3])
                            + p[self.joints])
        return C, Bd

    def travel(self, dq: np.ndarray) -> np.ndarray:
        """Upper bound [m] on how far any point of any body moves for joint changes
        ``dq`` (n, dof) taken as straight joint segments."""
        return np.max(np.abs(dq) @ self.weights.T, axis=-1)


def _weights(model: pin.Model, joints: np.ndarray, bounding: np.ndarray) -> np.ndarray:
    """Per body and joint, the largest distance of the body's points from the joint's
    origin (revolute) or 1 (prismatic); 0 for joints that do not carry it."""
    W = np.zeros((joints.size, model.nv))
    for b, j0 in enumerate(joints):
        reach = float(np.linalg.norm(bounding[b, :3])) + float(bounding[b, 3])
        j = int(j0)
        while j > 0:
            prismatic = "Prismatic" in model.joints[j].shortname() or \
                model.joints[j].shortname().startswith("JointModelP")
            iv = model.joints[j].idx_v
            W[b, iv] = 1.0 if prismatic else reach
            reach += float(np.linalg.norm(model.jointPlacements[j].translation))
            if prismatic:
                reach += max(abs(float(model.lowerPositionLimit[iv])),
                             abs(float(model.upperPositionLimit[iv])))
            j = model.parents[j]
    return W


@dataclass(frozen=True)
class PathSweep:
    """Sampled states of a path with the robot's spheres placed at each.

    Attributes:
        tau: Path parameter (the verified trajectory's time) of each sample [s].
        knot: Index of the path knot of each sample.
        centers: World sphere centres per sample (n, K, 3) [m].
        bounding: World body bounding spheres per sample (n, bodies, 4) [m].
        spheres: The robot's spheres.
        spacing: Largest motion of any robot point between two samples [m].
        path_t: Path parameter of every knot of the path [s].
        travel: Per knot, a bound on how far any robot point has moved along the path
            since its start [m] (running sum of the knot steps' bounds).
    """

    tau: np.ndarray
    knot: np.ndarray
    centers: np.ndarray
    bounding: np.ndarray
    spheres: RobotSpheres
    spacing: float
    path_t: np.ndarray
    travel: np.ndarray

    @classmethod
    def build(cls, robot: Robot, spheres: RobotSpheres, tau: np.ndarray, q: np.ndarray, *,
              spacing: float) -> PathSweep:
        """Sample the knots ``q`` (at path parameters ``tau``) every ``spacing`` [m] of
        robot motion (first and last knot always), and place the spheres."""
        step = spheres.travel(np.diff(q, axis=0)) if len(q) > 1 else np.zeros(0)
        keep = [0]
        acc = 0.0
        for k, d in enumerate(step):
            if acc + d > spacing and k > keep[-1]:
                keep.append(k)
                acc = 0.0
            acc += d
        if keep[-1] != len(q) - 1:
            keep.append(len(q) - 1)
        idx = np.array(keep, dtype=np.int64)
        # The real largest motion between kept samples (one knot step may exceed spacing).
        csum = np.concatenate([[0.0], np.cumsum(step)])
        real = float(np.max(np.diff(csum[idx]))) if idx.size > 1 else 0.0
        C, Bd = spheres.place(robot, q[idx])
        tau = np.asarray(tau, dtype=float)
        return cls(tau[idx], idx, C, Bd, spheres, max(real, 0.0), tau, csum)

    def travel_between(self, tau_a: float, tau_b: float) -> float:
        """Bound on how far any robot point moves along the path from ``tau_a`` to
        ``tau_b`` [m] (whole knot steps around them counted)."""
        last = self.travel.size - 1
        a = min(max(int(np.searchsorted(self.path_t, tau_a, side="right")) - 1, 0), last)
        b = min(max(int(np.searchsorted(self.path_t, tau_b, side="left")), 0), last)
        return float(max(self.travel[b] - self.travel[a], 0.0))

    def index_at(self, tau: float) -> int:
        """The last sample at or before path parameter ``tau``."""
        k = int(np.searchsorted(self.tau, tau, side="right")) - 1
        return min(max(k, 0), self.tau.size - 1)
