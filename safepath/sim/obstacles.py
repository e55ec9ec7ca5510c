"""Live obstacles: a moving body in the MuJoCo scene, seen by a simulated laser scanner and
depth camera, with :class:`~safepath.monitor.node.MonitorNodeCore` closed loop.

* **The body** (:class:`MovingBody`): a vertical cylinder (person- or arm-sized) on a
  seeded straight path across the cell: it enters at ``enter`` s, passes the robot's base
  axis at a seeded closest horizontal distance and leaves, at a seeded speed. It is a
  MuJoCo mocap body (it moves as told, nothing pushes it) in the robot's model.
* **The sensors** (:class:`SensorRig`): a planar laser scanner (``sensor_msgs/LaserScan``)
  and a depth camera (``sensor_msgs/PointCloud2``, a pinhole grid of rays), both cast with
  ``mujoco.mj_multiRay`` against the simulated scene at their capture time, with Gaussian
  range noise and a latency (the message is delivered ``latency`` after its stamp). Their
  rays see the moving body only (geom group 3): the arm and the static cell are not in
  their returns, as if the monitor's self and scene filters were perfect (the arm seen by
  a sensor is the monitor's ``self_filter``'s business, not tested here).
* **The loop** (:class:`ObstacleTwin`, a :class:`~safepath.sim.monitor_loop.MonitorTwin`):
  the node core gets every message as the ROS node would (``on_scan``), its decisions
  drive the twin's trajectory controller, its re-plan requests are planned by
  :func:`safepath.monitor.replan.replan` and answered after the planning's own wall time;
  a kill is pressed at a given time or a given lead before a motion's end.
* **Measured**: the true closest approach of the simulated arm to the body (MuJoCo's
  ``mj_geomDistance`` between the arm's collision shapes and the cylinder, every tick),
  overall and while the arm moves; the speed, acceleration and jerk of the motion the
  trajectory controller commanded against the robot's limits, and its goal switches;
  where the arm was at each gripper action; the decisions, and what follows a kill. A run
  fails (:attr:`ObstacleRun.failures`) when the commanded motion exceeds a limit or
  steps at a goal switch, a gripper action happens away from the pose its route plans it
  at (a held object dropped), the controller refuses or aborts a goal, or the kill does
  not hold.
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError
from .monitor_loop import CommandedPeak, MonitorTwin, check_run, configured_core

if TYPE_CHECKING:
    import argparse

    from ..cell import Cell

__all__ = ["MovingBody", "SensorRig", "ObstacleTwin", "ObstacleRun", "run_obstacles",
           "cmd_obstacles"]

#: Geom group of the moving body (the sensors' rays see this group only).
BODY_GROUP = 3
#: Distances arm - body are measured up to this [m] (farther: reported as this).
_DIST_MAX = 10.0
#: The arm moves while a joint's executed speed exceeds this [rad/s].
MOVING_SPEED = 1e-3
#: A commanded speed, acceleration or jerk above its limit by more than this share fails.
LIMIT_SLACK = 1e-6


@dataclass(frozen=True)
class MovingBody:
    """A vertical cylinder moving on a straight line at constant speed.

    Attributes:
        radius: Cylinder radius [m].
        height: Cylinder height [m] (it stands on z = ``base_z``).
        base_z: Height of its bottom [m].
        start: Where its axis is at ``enter`` (x, y) [m].
        velocity: Its horizontal velocity (x, y) [m/s].
        enter: When it starts moving [s] (it waits at ``start`` before).
        leave: When it stops moving [s] (it waits there after).
    """

    radius: float
    height: float
    base_z: float
    start: tuple[float, float]
    velocity: tuple[float, float]
    enter: float
    leave: float

    @classmethod
    def crossing(cls, rng: np.random.Generator, *, radius: float = 0.1, height: float = 0.8,
                 base_z: float = 0.0, pass_distance: tuple[float, float] = (0.22, 0.40),
                 speed: tuple[float, float] = (0.25, 0.6), enter: tuple[float, float]
                 = (0.5, 3.0), reach: float = 1.5) -> MovingBody:
        """A seeded crossing: from ``reach`` m away, past the base axis (z) at a distance
        drawn from ``pass_distance``, to ``reach`` m beyond, at a speed drawn from
        ``speed``, entering at a time drawn from ``enter``."""
        heading = float(rng.uniform(0.0, 2.0 * math.pi))
        d = float(rng.uniform(*pass_distance))
        v = float(rng.uniform(*speed))
        t0 = float(rng.uniform(*enter))
        u = np.array([math.cos(heading), math.sin(heading)])
        n = np.array([-u[1], u[0]])
        start = d * n - reach * u
        return cls(radius, height, base_z, (float(start[0]), float(start[1])),
                   (float(v * u[0]), float(v * u[1])), t0, t0 + 2.0 * reach / v)

    def at(self, t: float) -> np.ndarray:
        """Centre of the cylinder at ``t`` [s] (x, y, z) [m]."""
        tau = min(max(t, self.enter), self.leave) - self.enter
        x = self.start[0] + self.velocity[0] * tau
        y = self.start[1] + self.velocity[1] * tau
        return np.array([x, y, self.base_z + 0.5 * self.height])

    def mjcf(self) -> str:
        """The body as an MJCF mocap body (no contacts: it moves as told)."""
        c = self.at(0.0)
        return (f'<body name="obstacle" mocap="true" pos="{c[0]:.6g} {c[1]:.6g} {c[2]:.6g}">'
                f'<geom name="obstacle" type="cylinder" size="{self.radius:.6g} '
                f'{0.5 * self.height:.6g}" contype="0" conaffinity="0" group="{BODY_GROUP}" '
                f'rgba="0.2 0.5 0.9 0.6"/></body>')


def _pose(position: tuple[float, float, float], x_axis: np.ndarray, z_axis: np.ndarray
          ) -> np.ndarray:
    z = np.asarray(z_axis, dtype=float) / np.linalg.norm(z_axis)
    x = np.asarray(x_axis, dtype=float) - np.dot(x_axis, z) * z
    x /= np.linalg.norm(x)
    T = np.eye(4)  # noqa: N806
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = position
    return T


@dataclass(frozen=True, kw_only=True)
class SensorRig:
    """The simulated laser scanner and depth camera.

    Attributes:
        laser_pose: World pose of the scanner frame (4x4; it scans its x-y plane).
        laser_beams: Beams over ``laser_fov`` [rad].
        laser_fov: Angular field of the scan [rad] (centred on +x).
        laser_rate: Scans per second [Hz].
        laser_latency: Delivery delay after the stamp [s].
        laser_noise: Range noise (standard deviation) [m].
        range_max: Largest range [m].
        camera_pose: World pose of the camera frame (4x4; optical axis +z, x right,
            y down).
        camera_pixels: Rays across and down (width, height).
        camera_fov: Horizontal and vertical fields of view [rad].
        camera_rate: Frames per second [Hz].
        camera_latency: Delivery delay after the stamp [s].
        camera_noise: Depth noise (standard deviation) [m].
    """

    laser_pose: np.ndarray = field(default_factory=lambda: _pose(
        (-0.5, -0.5, 0.3), np.array([1.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])))
    laser_beams: int = 271
    laser_fov: float = math.radians(270.0)
    laser_rate: float = 20.0
    laser_latency: float = 0.02
    laser_noise: float = 0.01
    range_max: float = 6.0
    camera_pose: np.ndarray = field(default_factory=lambda: _pose(
        (0.0, 0.0, 1.8), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])))
    camera_pixels: tuple[int, int] = (48, 36)
    camera_fov: tuple[float, float] = (math.radians(90.0), math.radians(70.0))
    camera_rate: float = 15.0
    camera_latency: float = 0.04
    camera_noise: float = 0.005

    def sensors(self) -> dict[str, np.ndarray]:
        """World poses by frame id (the monitor's ``sensors``)."""
        return {"laser": np.asarray(self.laser_pose, dtype=float),
                "camera": np.asarray(self.camera_pose, dtype=float)}

    def _laser_rays(self) -> tuple[np.ndarray, np.ndarray]:
        a = -0.5 * self.laser_fov + self.laser_fov * np.arange(self.laser_beams) \
            / max(self.laser_beams - 1, 1)
        local = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])
        return a, local

    def _camera_rays(self) -> np.ndarray:
        w, h = self.camera_pixels
        u = np.tan(0.5 * self.camera_fov[0]) * np.linspace(-1.0, 1.0, w)
        v = np.tan(0.5 * self.camera_fov[1]) * np.linspace(-1.0, 1.0, h)
        uu, vv = np.meshgrid(u, v)
        d = np.column_stack([uu.ravel(), vv.ravel(), np.ones(uu.size)])
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def _cast(mujoco: Any, m: Any, d: Any, origin: np.ndarray, dirs: np.ndarray,
          cutoff: float) -> np.ndarray:
    """Distances along unit rays from ``origin`` to the body (inf: no return)."""
    n = dirs.shape[0]
    geomid = np.zeros(n, dtype=np.int32)
    dist = np.zeros(n)
    group = np.zeros(6, dtype=np.uint8)
    group[BODY_GROUP] = 1
    mujoco.mj_multiRay(m, d, np.asarray(origin, dtype=float),
                       np.ascontiguousarray(dirs, dtype=float).ravel(), group, True, -1,
                       geomid, dist, None, n, cutoff)
    return np.where(geomid >= 0, dist, np.inf)


@dataclass
class ObstacleTwin(MonitorTwin):
    """:class:`MonitorTwin` with a moving body, the sensors, re-plans and a kill.

    Args (beyond :class:`MonitorTwin`'s):
        body: The moving body.
        rig: The sensors.
        seed: Seed of the sensors' noise.
    """

    body: MovingBody | None = None
    rig: SensorRig = field(default_factory=SensorRig)
    seed: int = 0

    def __post_init__(self) -> None:
        import mujoco

        if self.body is None:
            raise InputError("expected a MovingBody", key="body")
        self.extra_world = self.body.mjcf()
        super().__post_init__()
        self._mujoco = mujoco
        m = self.twin.model.model
        self._body_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "obstacle")
        self._mocap = int(m.body_mocapid[self._body_id])
        self._body_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "obstacle")
        self._arm_geoms = [g for g in range(m.ngeom)
                           if int(m.geom_bodyid[g]) != 0 and g != self._body_geom]
        self._rng = np.random.default_rng([self.seed, 7])
        self._events: list[tuple[float, int, str, Any]] = []
        self._seq = 0
        self.closest = math.inf
        self.closest_time = math.nan
        self.closest_moving = math.inf
        self.scans = 0
        self.clouds = 0
        self.replans: list[tuple[float, str]] = []
        self.kill_time: float | None = None
        #: Whether an arm goal's success reached the node after the kill was pressed.
        self.motion_end_after_kill = False
        self.motion_goals = 0

    # -- the body and the sensors ------------------------------------------------------
    def _place(self, t: float) -> None:
        assert self.body is not None
        self.twin.data.mocap_pos[self._mocap] = self.body.at(t)
        self._mujoco.mj_kinematics(self.twin.model.model, self.twin.data)

    def _measure(self) -> None:
        """True smallest distance arm - body now (MuJoCo's geometry)."""
        m, d = self.twin.model.model, self.twin.data
        best = math.inf
        for g in self._arm_geoms:
            best = min(best, float(self._mujoco.mj_geomDistance(m, d, g, self._body_geom,
                                                                 _DIST_MAX, None)))
        if best < self.closest:
            self.closest, self.closest_time = best, self.twin.now
        if float(np.max(np.abs(self.twin.qd))) > MOVING_SPEED:
            self.closest_moving = min(self.closest_moving, best)

    def _push(self, when: float, kind: str, payload: Any) -> None:
        self._seq += 1
        heapq.heappush(self._events, (when, self._seq, kind, payload))

    def _laser(self, stamp: float) -> Any:
        from ..monitor.observations import Scan
        from ..monitor.ros import scan_message

        rig = self.rig
        T = rig.laser_pose  # noqa: N806
        a, local = rig._laser_rays()
        r = _cast(self._mujoco, self.twin.model.model, self.twin.data, T[:3, 3],
                  local @ T[:3, :3].T, rig.range_max)
        hit = np.isfinite(r)
        r[hit] += self._rng.normal(0.0, rig.laser_noise, int(hit.sum()))
        r[hit & (r > rig.range_max)] = np.inf
        inc = float(a[1] - a[0]) if a.size > 1 else 0.0
        self.scans += 1
        return scan_message(Scan(stamp, "laser", r, float(a[0]), inc, 0.05, rig.range_max))

    def _camera(self, stamp: float) -> Any:
        from ..monitor.observations import Cloud
        from ..monitor.ros import cloud_message

        rig = self.rig
        T = rig.camera_pose  # noqa: N806
        dirs = rig._camera_rays()
        r = _cast(self._mujoco, self.twin.model.model, self.twin.data, T[:3, 3],
                  dirs @ T[:3, :3].T, rig.range_max)
        hit = np.isfinite(r)
        depth = r[hit] + self._rng.normal(0.0, rig.camera_noise, int(hit.sum()))
        points = dirs[hit] * depth[:, None]
        self.clouds += 1
        return cloud_message(Cloud(stamp, "camera", points.reshape(-1, 3)))

    # -- commands the base loop does not carry out --------------------------------------
    def _dispatch(self, commands: list[Any]) -> None:
        from ..monitor.node import Replan, SendGoal

        for cmd in commands:
            if isinstance(cmd, SendGoal) and cmd.reason == "next motion":
                self.motion_goals += 1
            if isinstance(cmd, Replan):
                self.issued.append(_issued(self.twin.now, "replan", "request"))
                self._replan(cmd)
        super()._dispatch([c for c in commands if not isinstance(c, Replan)])

    def _replan(self, cmd: Any) -> None:
        """Plan around the obstacle now; the answer arrives after the planning's wall
        time (the node plans off its callback thread)."""
        from ..errors import SafepathError
        from ..monitor.replan import replan

        monitor = self.core.monitor
        assert monitor is not None
        t0 = time.perf_counter()
        try:
            traj = replan(monitor.cell, cmd.route, cmd.request, held=cmd.held,
                          margin=cmd.margin)
            answer: tuple[str, Any] = ("ok", traj)
        except SafepathError as exc:
            answer = ("failed", str(exc))
        self._push(self.twin.now + (time.perf_counter() - t0), "replan",
                   (cmd.request, answer))

    # -- the loop ----------------------------------------------------------------------
    def run(self, duration: float, *, kill_at: float | None = None,
            kill_before_end_of: int | None = None, kill_lead: float = 0.005) -> None:
        """Activate the node and run for ``duration`` [s]: the body moves, the sensors
        publish, the node decides.

        A kill is pressed at ``kill_at`` [s], or ``kill_lead`` [s] before the end of the
        ``kill_before_end_of``-th motion (0: the first) as the trajectory controller runs
        it: the end of the goal running it then (its replacements included; a stop's goal
        ends at rest). ``kill_lead`` 0 presses it at that end, to the physics step, before
        the controller's result of that instant reaches the node.

        Raises:
            InputError: ``kill_lead`` not a finite number >= 0 [s], or
                ``kill_before_end_of`` not an integer >= 0.
        """
        if isinstance(kill_lead, bool) or not isinstance(kill_lead, (int, float)) \
                or not math.isfinite(kill_lead) or kill_lead < 0:
            raise InputError(f"expected a finite number >= 0 [s], got {kill_lead!r}",
                             key="kill_lead")
        if kill_before_end_of is not None and (
                isinstance(kill_before_end_of, bool)
                or not isinstance(kill_before_end_of, (int, np.integer))
                or kill_before_end_of < 0):
            raise InputError(f"expected a motion index >= 0, got {kill_before_end_of!r}",
                             key="kill_before_end_of")
        rig = self.rig
        self._place(0.0)
        self._dispatch(self.core.activate(self.twin.now))
        end = self.twin.now + duration
        next_laser, next_camera = 0.0, 0.0
        while self.twin.now < end - 1e-9:
            now = self.twin.now
            nxt = min(now + self.tick, end)
            kill_due = self._kill_due(kill_at, kill_before_end_of, kill_lead)
            due = [next_laser, next_camera, self._events[0][0] if self._events else math.inf]
            if kill_due is not None:
                due.append(kill_due)
            for when in due:
                nxt = min(nxt, max(when, now + self.twin.options.timestep))
            self.twin.data.mocap_pos[self._mocap] = self.body.at(nxt) if self.body else 0
            self._advance(nxt, kill_due)
            now = self.twin.now
            self._place(now)
            self._measure()
            if now >= next_laser - 1e-9:
                self._push(now + rig.laser_latency, "scan", self._laser(now))
                next_laser += 1.0 / rig.laser_rate
            if now >= next_camera - 1e-9:
                self._push(now + rig.camera_latency, "scan", self._camera(now))
                next_camera += 1.0 / rig.camera_rate
            self._deliver(now)
            self._dispatch(self.core.on_tick(now))

    def _kill_due(self, kill_at: float | None, before_end_of: int | None, lead: float
                  ) -> float | None:
        """When the kill is due [s]; None: pressed already, or not yet known (the motion
        it precedes the end of does not run)."""
        if self.kill_time is not None:
            return None
        if kill_at is not None:
            return kill_at
        end = self.goal_end
        if before_end_of is None or end is None or self.motion_goals != before_end_of + 1:
            return None
        return end - lead

    def _press_kill(self) -> None:
        self.kill_time = self.twin.now
        self.issued.append(_issued(self.twin.now, "kill", "pressed"))
        super()._press_kill()

    def _on_result(self, result: Any) -> None:
        from .arm import ArmResult

        if self.kill_time is not None and isinstance(result, ArmResult) and result.success:
            self.motion_end_after_kill = True
        super()._on_result(result)

    def _deliver(self, now: float) -> None:
        """The messages and re-plan answers due by ``now``, to the node core."""
        while self._events and self._events[0][0] <= now + 1e-12:
            _, _, kind, payload = heapq.heappop(self._events)
            if kind == "scan":
                self._dispatch(self.core.on_scan(payload, now))
                continue
            request, (status, value) = payload
            self.replans.append((now, status))
            if status == "ok":
                self._dispatch(self.core.on_replanned(request, value, now))
            else:
                self._dispatch(self.core.on_replan_failed(request, value, now))

    def report(self, *, wall_time: float = math.nan) -> ObstacleRun:
        """What the run so far did, judged (:attr:`ObstacleRun.failures`).

        Args:
            wall_time: The computation time of the run [s] (reported as given).
        """
        assert self.body is not None
        after: tuple[str, ...] = ()
        moved = 0.0
        if self.kill_time is not None:
            # What the core issued after the kill, in the order of events (at the kill's
            # own instant too).
            pressed = next(i for i, c in enumerate(self.issued) if c.kind == "kill")
            after = tuple(f"{c.kind} {c.detail}" for c in self.issued[pressed + 1:]
                          if c.kind != "decision" and c.detail != "stop")
            late = self.positions[self.times >= self.kill_time + 1.0]
            moved = float(np.ptp(late, axis=0).max()) if late.shape[0] else 0.0
        rec = self.twin.recording
        peaks = self.commanded_peaks()
        failures = (_limit_failures(peaks) + _switch_failures(self) + _gripper_failures(self)
                    + _goal_failures(self) + _kill_failures(after, moved))
        offset = max((a.offset for a in self.gripper_actions), default=0.0)
        return ObstacleRun(self.seed, self.body, self.closest, self.closest_time,
                           self.closest_moving, self.decisions(), tuple(self.replans),
                           self.kill_time, after, moved, self.motion_end_after_kill,
                           self.scans, self.clouds,
                           self.twin.now, wall_time, rec.speed_ratio.copy(), *peaks, offset,
                           failures)

    def decisions(self) -> dict[str, int]:
        """How often the decision changed to each kind (a run of the same kind counts
        once)."""
        out: dict[str, int] = {}
        last = None
        for c in self.issued:
            if c.kind == "decision":
                if c.detail != last:
                    out[c.detail] = out.get(c.detail, 0) + 1
                last = c.detail
        return out


def _issued(t: float, kind: str, detail: str) -> Any:
    from .monitor_loop import IssuedCommand

    return IssuedCommand(t, kind, detail)


@dataclass(frozen=True)
class ObstacleRun:
    """What one run of the obstacle twin did.

    Attributes:
        seed: The run's seed.
        body: The moving body.
        closest: True closest approach arm - body [m].
        closest_time: When [s].
        closest_moving: Closest approach while the arm moved (a joint's executed speed
            above :data:`MOVING_SPEED`) [m] (the rest: the body walking past an arm at
            rest); inf when it never moved.
        decisions: How often the decision changed to each kind.
        replans: Re-plans answered (``ok`` / ``failed``).
        kill_time: When the kill was pressed [s] (None: never).
        after_kill: Commands the core issued after the kill (in the order of events)
            other than decisions and a stop goal (must be empty: the kill is latched).
        moved_after_kill: Largest joint travel from 1 s after the kill on [rad].
        motion_end_after_kill: Whether an arm goal's success reached the node after the
            kill (at the kill's own instant too: the kill comes first), i.e. the latch
            was tested through a motion's end.
        scans: Laser scans published.
        clouds: Point clouds published.
        duration: Simulated time [s].
        wall_time: Computation time [s].
        speed_ratio: Largest |executed speed| / limit per joint (the simulated arm).
        commanded_speed: The commanded motion's largest speed / limit (sampled at every
            physics step, :meth:`MonitorTwin.commanded_peaks`).
        commanded_acceleration: Its largest acceleration / limit.
        commanded_jerk: Its largest jerk / limit.
        gripper_offset: Largest distance of the arm from the planned pose at a gripper
            action, over the joints [rad] (0: no action).
        failures: What went wrong, one line each (empty: the run passed): a commanded
            limit exceeded (ratio above 1 + :data:`LIMIT_SLACK`), a goal switch that
            steps the commanded position, speed or acceleration, a gripper action away
            from its pose (a held object dropped, or an object missed), a goal the
            controller rejected or aborted, anything after the kill.
    """

    seed: int
    body: MovingBody
    closest: float
    closest_time: float
    closest_moving: float
    decisions: dict[str, int]
    replans: tuple[tuple[float, str], ...]
    kill_time: float | None
    after_kill: tuple[str, ...]
    moved_after_kill: float
    motion_end_after_kill: bool
    scans: int
    clouds: int
    duration: float
    wall_time: float
    speed_ratio: np.ndarray
    commanded_speed: CommandedPeak
    commanded_acceleration: CommandedPeak
    commanded_jerk: CommandedPeak
    gripper_offset: float
    failures: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Whether the run passed (no failure)."""
        return not self.failures


def run_obstacles(cell: str, seed: int, *, route: str = "phase1", duration: float = 20.0,
                  kill_at: float | None = None, kill_before_end_of: int | None = None,
                  kill_lead: float = 0.005, body: MovingBody | None = None,
                  rig: SensorRig | None = None) -> ObstacleRun:
    """One run of the monitor node's core with a moving body (see the module docstring).

    Args:
        cell: Scene folder.
        seed: Seed of the body's crossing and the sensors' noise.
        route: The route the node runs.
        duration: Simulated time [s].
        kill_at: Time of a kill [s] (None: see ``kill_before_end_of``).
        kill_before_end_of: Kill ``kill_lead`` before the end of this motion (0: the
            first).
        kill_lead: How long before that end [s] (0: at it).
        body: The body (default: a seeded :meth:`MovingBody.crossing`).
        rig: The sensors (default: :class:`SensorRig()`).

    Raises:
        InputError: A bad seed, duration or kill lead.
    """
    from ..monitor import MonitorOptions

    check_run(seed, duration, shortest=0.0)
    rig = rig or SensorRig()
    body = body or MovingBody.crossing(np.random.default_rng([int(seed), 5]))
    core = configured_core(cell, route, MonitorOptions(sensors=rig.sensors()))
    loop = ObstacleTwin(core, body=body, rig=rig, seed=int(seed))
    t0 = time.perf_counter()
    loop.run(duration, kill_at=kill_at, kill_before_end_of=kill_before_end_of,
             kill_lead=kill_lead)
    return loop.report(wall_time=time.perf_counter() - t0)


def _limit_failures(peaks: tuple[CommandedPeak, CommandedPeak, CommandedPeak]
                    ) -> tuple[str, ...]:
    """A commanded speed, acceleration or jerk above its limit."""
    return tuple(f"commanded {name} {p.ratio:.3f} x the limit ({p.joint} at {p.time:.3f} s)"
                 for name, p in zip(("speed", "acceleration", "jerk"), peaks, strict=True)
                 if p.ratio > 1.0 + LIMIT_SLACK)


def _switch_failures(loop: ObstacleTwin) -> tuple[str, ...]:
    """Goal switches that step the commanded position, speed or acceleration (the
    controller took a goal whose first point was not the state it commanded)."""
    reasons = {g.goal_id: g.reason for g in loop.arm_goals}
    return tuple(f"goal {goal_id} ({reasons.get(goal_id, '?')}) taken at {s.time:.3f} s "
                 f"steps {s.position_step:.3g} rad, {s.velocity_step:.3g} rad/s, "
                 f"{s.acceleration_step:.3g} rad/s^2" for goal_id, s in loop.twin.arm.switches
                 if not s.continuous)


def _gripper_failures(loop: ObstacleTwin) -> tuple[str, ...]:
    """Gripper actions away from the pose their route plans them at."""
    out = []
    for a in loop.gripper_actions:
        if a.at_pose:
            continue
        what = "" if a.object is None else \
            f": drops '{a.object}'" if a.action == "open" else f": misses '{a.object}'"
        out.append(f"gripper {a.action} at {a.time:.3f} s {a.offset:.3f} rad from its "
                   f"pose{what}")
    return tuple(out)


def _goal_failures(loop: ObstacleTwin) -> tuple[str, ...]:
    """Arm goals the controller rejected or aborted (a cancelled, replaced goal is
    not a failure)."""
    from .arm import CANCELED, SUCCESSFUL

    return tuple(f"controller: goal {r.goal_id} ended {r.error_code} at {r.time:.3f} s: "
                 f"{r.error_string}" for r in loop.twin.arm.results
                 if r.error_code not in (SUCCESSFUL, CANCELED))


def _kill_failures(after: tuple[str, ...], moved: float) -> tuple[str, ...]:
    """Whatever the latched kill let through."""
    out = []
    if after:
        out.append(f"after the kill: {', '.join(after)}")
    if moved >= 1e-3:
        out.append(f"the arm moved {1000 * moved:.2f} mrad from 1 s after the kill on")
    return tuple(out)


def cmd_obstacles(args: argparse.Namespace, cell: Cell) -> int:
    """``safepath sim CELL --obstacles``: runs of the monitor with a moving body, kills at
    seeded random times and one just before a motion's end. Exits 1 when a run fails
    (:attr:`ObstacleRun.failures`), naming the failures on one line."""
    import os

    from ..monitor import MonitorOptions
    from ..monitor.node import NodeParameters

    duration = min(args.duration, 60.0) if args.duration == 300.0 else args.duration
    runs = max(args.runs, 3)
    rng = np.random.default_rng(args.seed)
    opts = MonitorOptions()
    table = cell.route_table()
    route = NodeParameters(scene=str(cell.folder)).route
    if route not in table:  # the node's default route, else the cell's first
        route = next(iter(table))
    print(f"obstacle twin of {cell.scene.name}: MonitorNodeCore closed loop, route {route}, "
          f"{duration:g} s simulated x {runs} runs (seeds {args.seed}..); a cylinder "
          f"(r 0.10 m, 0.8 m tall) crossing at 0.25-0.6 m/s past the base axis at "
          f"0.22-0.40 m; laser 20 Hz (271 beams, 270 deg, 1 cm noise, 20 ms latency), depth "
          f"camera 15 Hz (48x36 rays, 5 mm noise, 40 ms latency), by mujoco.mj_multiRay; "
          f"monitor: approach speed {opts.approach_speed} m/s, C {opts.min_separation} m")
    print("| seed | closest approach [mm] | at [s] | while moving [mm] | commanded speed / "
          "accel / jerk vs limit | gripper off pose [mrad] | decisions | re-plans | "
          "kill [s] | motion ended after the kill | commands after the kill | "
          "moved after [mrad] | sim/real | result |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    latched = True
    failed: list[str] = []
    for k in range(runs):
        seed = args.seed + k
        kill_at = None
        before_end = None
        if k == 0:
            before_end = 0  # 5 ms before the first motion's end
        else:
            kill_at = float(rng.uniform(1.0, duration))
        r = run_obstacles(str(cell.folder), seed, route=route, duration=duration,
                          kill_at=kill_at, kill_before_end_of=before_end)
        latched = latched and not r.after_kill and r.moved_after_kill < 1e-3
        dec = ", ".join(f"{n} {v}" for n, v in sorted(r.decisions.items()))
        rp = ", ".join(s for _, s in r.replans) or "-"
        kt = "-" if r.kill_time is None else f"{r.kill_time:.3f}" + \
            (" (5 ms before a motion's end)" if before_end is not None else "")
        peaks = " / ".join(f"{p.ratio:.3f}" for p in (r.commanded_speed,
                                                       r.commanded_acceleration,
                                                       r.commanded_jerk))
        moving = "-" if math.isinf(r.closest_moving) else f"{1000 * r.closest_moving:.0f}"
        print(f"| {seed} | {1000 * r.closest:.0f} | {r.closest_time:.2f} | {moving} | "
              f"{peaks} | {1000 * r.gripper_offset:.1f} | {dec} | {rp} | "
              f"{kt} | {'yes' if r.motion_end_after_kill else 'no'} | "
              f"{', '.join(r.after_kill) or 'none'} | {1000 * r.moved_after_kill:.2f} | "
              f"{r.duration / max(r.wall_time, 1e-9):.1f}x | "
              f"{'ok' if r.ok else 'FAILED'} |")
        failed += [f"seed {seed}: {'; '.join(r.failures)}"] if r.failures else []
    load = os.getloadavg()
    print(f"kill latched in every run: {'yes' if latched else 'NO'}; load {load[0]:.2f} "
          f"{load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs")
    if failed:
        print(f"obstacle twin FAILED: {' | '.join(failed)}")
        return 1
    return 0
