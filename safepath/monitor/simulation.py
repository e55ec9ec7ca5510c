"""A closed-loop simulation of the monitor: a robot, a moving obstacle, a sensor.

The robot executes what it was last commanded (a motion, then each replacement from its
``replacement_start`` on), sampled every ``dt``. The obstacle is a sphere moving along
waypoints. A simulated sensor sees it (a point cloud of the side facing the sensor, or
a planar laser scan) every ``period`` with a ``latency``; the monitor decides on every
observation and on a clock tick between them. The true separation at every sample is
measured by :class:`FclSeparation` (python-fcl, the robot's own collision geometry,
independent of the monitor's spheres).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..cell import Cell
from ..model.execution import ControllerModel
from ..model.trajectory import Trajectory
from .monitor import Decision, Monitor
from .observations import Cloud, Scan

__all__ = ["MovingSphere", "FclSeparation", "SimResult", "simulate", "camera_cloud",
           "lidar_scan"]


@dataclass(frozen=True)
class MovingSphere:
    """A sphere moving along straight pieces between timed waypoints.

    Attributes:
        times: Waypoint times [s] (increasing).
        positions: World centres there [m] (n, 3); held before the first and after the
            last.
        radius: Radius [m].
    """

    times: np.ndarray
    positions: np.ndarray
    radius: float

    def at(self, t: float) -> np.ndarray:
        """Centre at time ``t`` [s]."""
        return np.array([np.interp(t, self.times, self.positions[:, k]) for k in range(3)])

    @classmethod
    def approach(cls, start: Sequence[float], toward: Sequence[float], speed: float,
                 t0: float, t_stop: float, *, leave_at: float | None = None,
                 radius: float = 0.06) -> MovingSphere:
        """Moves from ``start`` toward ``toward`` at ``speed`` [m/s] from ``t0`` to
        ``t_stop`` [s] (then stays); with ``leave_at``, goes back to ``start`` at the
        same speed from then."""
        a = np.asarray(start, dtype=float)
        d = np.asarray(toward, dtype=float) - a
        d /= np.linalg.norm(d)
        b = a + d * speed * (t_stop - t0)
        times, pos = [t0, t_stop], [a, b]
        if leave_at is not None:
            times += [leave_at, leave_at + (t_stop - t0)]
            pos += [b, a]
        return cls(np.array(times), np.array(pos), radius)


class FclSeparation:
    """True separation [m] between the robot's moving links (and the held object) and
    a sphere, by python-fcl on the robot's collision geometry."""

    def __init__(self, cell: Cell, held: str | None) -> None:
        import fcl

        from ..verify import fcl_shape

        robot = cell.robot
        self.robot = robot
        self._bodies = []
        for g in robot.collision_model.geometryObjects:
            if int(g.parentJoint) != 0:
                self._bodies.append((int(g.parentJoint), g.placement.homogeneous,
                                     fcl.CollisionObject(fcl_shape(g.geometry))))
        if held is not None and cell.scene.grasp is not None:
            tcp = robot.model.frames[robot.tcp_frame_id]
            T = tcp.placement.homogeneous @ cell.scene.grasp.T_tcp_object
            shape = cell.scene.objects[held].shape.to_coal()
            self._bodies.append((int(tcp.parentJoint), T,
                                 fcl.CollisionObject(fcl_shape(shape))))
        self._data = robot.model.createData()

    def __call__(self, q: np.ndarray, center: np.ndarray, radius: float) -> float:
        import fcl
        import pinocchio as pin

        pin.forwardKinematics(self.robot.model, self._data, q)
        sphere = fcl.CollisionObject(fcl.Sphere(radius), fcl.Transform(np.asarray(center)))
        best = np.inf
        request = fcl.DistanceRequest()
        for joint, T, obj in self._bodies:
            M = self._data.oMi[joint].homogeneous @ T
            obj.setTransform(fcl.Transform(M[:3, :3], M[:3, 3]))
            result = fcl.DistanceResult()
            best = min(best, fcl.distance(obj, sphere, request, result))
        return float(best)


def camera_cloud(obstacle: MovingSphere, t: float, camera: np.ndarray, n: int,
                 rng: np.random.Generator) -> np.ndarray:
    """``n`` points on the side of the sphere facing the camera, in the camera frame."""
    c = obstacle.at(t)
    eye = camera[:3, 3]
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    toward = eye - c
    v[v @ toward < 0] *= -1.0
    world = c + obstacle.radius * v
    return (world - eye) @ camera[:3, :3]


def lidar_scan(obstacle: MovingSphere, t: float, lidar: np.ndarray, beams: int = 360,
               range_max: float = 8.0) -> np.ndarray:
    """Ranges of a planar scan (``beams`` over a full turn) that sees only the sphere
    (``inf``: no return)."""
    c = (obstacle.at(t) - lidar[:3, 3]) @ lidar[:3, :3]
    a = -np.pi + 2 * np.pi * np.arange(beams) / beams
    d = np.column_stack([np.cos(a), np.sin(a), np.zeros(beams)])
    b = d @ c
    disc = b * b - (c @ c - obstacle.radius ** 2)
    r = np.full(beams, np.inf)
    hit = disc >= 0
    r[hit] = b[hit] - np.sqrt(disc[hit])
    r[(r <= 0) | (r > range_max)] = np.inf
    return r


@dataclass
class SimResult:
    """What happened.

    Attributes:
        t: Sample times [s].
        q: Executed joint positions (n, dof) [rad].
        qd: Executed velocities (n, dof) [rad/s].
        obstacle: True obstacle centre at each sample (n, 3) [m].
        motion: Index of the motion executed at each sample.
        held: Object held at each sample (None: nothing).
        decisions: Every decision, in order.
        replacements: Every trajectory commanded after the first (with its start).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    obstacle: np.ndarray
    motion: np.ndarray
    held: list[str | None] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)
    replacements: list[tuple[float, Trajectory]] = field(default_factory=list)


class _Captures:
    """A sensor capturing every ``period`` [s] from 0, each capture delivered ``latency``
    [s] later."""

    def __init__(self, period: float, latency: float) -> None:
        self.period, self.latency = period, latency
        self.next = 0.0
        self.waiting: list[tuple[float, float]] = []  # (delivery, capture)

    def due(self, t: float) -> list[float]:
        """The capture times delivered by ``t`` and not before."""
        while self.next <= t + 1e-12:
            self.waiting.append((self.next + self.latency, self.next))
            self.next += self.period
        due = [c for c in self.waiting if c[0] <= t + 1e-12]
        self.waiting = [c for c in self.waiting if c[0] > t + 1e-12]
        return [capture for _, capture in due]


def _observation(kind: str, obstacle: MovingSphere, capture: float, sensor: str,
                 sensor_pose: np.ndarray, points: int, rng: np.random.Generator
                 ) -> Cloud | Scan:
    """What the sensor captures of the obstacle at ``capture`` [s]."""
    if kind == "cloud":
        return Cloud(capture, sensor, camera_cloud(obstacle, capture, sensor_pose, points,
                                                   rng))
    return Scan(capture, sensor, lidar_scan(obstacle, capture, sensor_pose), -np.pi,
                2 * np.pi / 360, 0.05, 8.0)


def simulate(monitor: Monitor, motions: Sequence[tuple[Trajectory, str | None]],
             obstacle: MovingSphere, *, sensor: str, sensor_pose: np.ndarray,
             kind: str = "cloud", period: float = 1 / 30, latency: float = 0.01,
             points: int = 300, dt: float = 0.004, until: float = 20.0, seed: int = 0,
             on_replan: Callable[[Decision, float],
                                 list[tuple[Trajectory, str | None]] | None] | None = None,
             recorder: Any = None) -> SimResult:
    """Run motions one after the other under the monitor.

    Args:
        monitor: The monitor (its options must know ``sensor``).
        motions: Motions and the object held during each.
        obstacle: The moving obstacle.
        sensor: The sensor's frame id.
        sensor_pose: Its world pose (4x4).
        kind: ``cloud`` (camera) or ``scan`` (planar lidar).
        period: Observation period [s].
        latency: Delay from capture to the monitor [s].
        points: Points per cloud.
        dt: Sample period of the robot [s].
        until: End of the simulation [s].
        seed: Seed of the sensor noise.
        on_replan: Called on a ``replan`` decision with the time; returns the motions
            (with their held objects) that replace the rest (the first followed at once),
            or None.
        recorder: A :class:`~safepath.monitor.ros.MonitorRecorder` that receives the
            observations, decisions, the robot's state (50 Hz) and the true obstacle.
    """
    rng = np.random.default_rng(seed)
    queue = list(motions)
    traj, held = queue.pop(0)
    arm = ControllerModel(traj.q[0], interpolation=monitor.cell.robot.controller.interpolation)

    def send(goal: Trajectory, start: float) -> None:
        """The arm's controller takes a goal stamped ``start`` (at that instant)."""
        arm.take(goal.t - goal.t[0], goal.q, goal.qd, goal.qdd, start=start)
        if recorder is not None:
            recorder.goal(start, goal, start)

    monitor.follow(traj, start=0.0, held=held)
    send(traj, 0.0)
    cmd, motion = traj, 0
    pending: list[tuple[float, Trajectory]] = []
    res = SimResult(np.zeros(0), np.zeros((0, traj.dof)), np.zeros((0, traj.dof)),
                    np.zeros((0, 3)), np.zeros(0, dtype=int))
    ts, qs, qds, obs, mot = [], [], [], [], []
    captures = _Captures(period, latency)
    t = 0.0
    while t <= until:
        for capture in captures.due(t):
            o = _observation(kind, obstacle, capture, sensor, sensor_pose, points, rng)
            d = monitor.observe(o, t)
            res.decisions.append(d)
            if recorder is not None:
                recorder.observation(t, o)
                recorder.decision(d)
            if d.replacement is not None and d.replacement_start is not None:
                pending.append((d.replacement_start, d.replacement))
                res.replacements.append((d.replacement_start, d.replacement))
            if d.kind == "replan" and on_replan is not None:
                new = on_replan(d, t)
                if new:
                    queue = list(new)
                    traj, held = queue.pop(0)
                    monitor.follow(traj, start=t, held=held)
                    send(traj, t)
                    res.replacements.append((t, traj))
                    cmd, motion, pending = traj, motion + 1, []
        for start, rep in [p for p in pending if p[0] <= t + 1e-12]:
            pending.remove((start, rep))
            arm.take(rep.t - rep.t[0], rep.q, rep.qd, rep.qdd, start=start)
            cmd = rep
        q, qd, _, _ = arm.sample(np.array([t]))
        ts.append(t)
        qs.append(q[0])
        qds.append(qd[0])
        obs.append(obstacle.at(t))
        mot.append(motion)
        res.held.append(held)
        if recorder is not None and len(ts) % 5 == 1:
            recorder.joint_state(t, q[0], qd[0])
            recorder.truth(t, obs[-1], obstacle.radius)
        at_end = t >= arm.end - 1e-9 and not pending
        if at_end and cmd.info.get("monitor") != "stop" and monitor.last.scale > 0 and queue:
            nxt, held = queue.pop(0)
            monitor.follow(nxt, start=t, held=held)
            send(nxt, t)
            cmd, motion = nxt, motion + 1
        t = round(t + dt, 9)
    res.t, res.q, res.qd = np.array(ts), np.array(qs), np.array(qds)
    res.obstacle, res.motion = np.array(obs), np.array(mot)
    return res
