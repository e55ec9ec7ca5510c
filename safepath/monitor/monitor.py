"""The separation monitor: observations in, a decision out every time.

A :class:`Monitor` follows one verified motion (a trajectory without gripper events
inside; see :func:`safepath.ros.split_at_gripper_events`) and, for every observation
(:meth:`Monitor.observe`), every clock tick (:meth:`Monitor.tick`) and the kill switch
(:meth:`Monitor.kill`), returns a :class:`Decision`:

* ``continue``: full speed (the verified timing) is safe;
* ``slow``: a lower speed scale is safe, full speed is not (ISO/TS 15066 speed and
  separation monitoring; the test is in :mod:`safepath.monitor.separation`);
* ``stop``: no scale is safe, a sensor fell silent, or the kill switch latched: brake
  along the same path as hard as the acceleration limits allow;
* ``resume``: after the area stayed clear for ``hold_time``, speed up again;
* ``replan``: stopped by an obstacle for ``replan_after``: plan around it
  (:func:`safepath.monitor.replan`), then :meth:`Monitor.follow` the new motion.

A change of speed comes with a *replacement*: the rest of the path re-timed
(:mod:`safepath.monitor.profile`) as a trajectory starting at the state the robot is in
when the controller acts (``command_latency`` after the decision), every knot within the
velocity and acceleration limits, for a ``FollowJointTrajectory`` goal
(:func:`safepath.ros.follow_joint_trajectory_goal`).

Time: every time is on the monitor's clock [s] (ROS time in a node), the clock of the
observations' stamps. Stamps later than ``now + future_tolerance`` are refused; a stamp
older than the last one of its sensor is ignored (``out_of_order``); an observation older
than ``stale_after`` is ignored (``stale``) and does not count as the sensor speaking.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from ..cell import Cell
from ..errors import InputError, TimingError
from ..trajectory import Trajectory
from .elements import OBSTACLES, scene_arrays, to_elements
from .observations import Counts, ObservationError
from .options import MonitorOptions
from .profile import MonitoredPath, Timing
from .separation import Assessment, assess
from .sweep import PathSweep, RobotSpheres

__all__ = ["Monitor", "Decision", "ReplanRequest"]

log = logging.getLogger(__name__)

DecisionKind = Literal["continue", "slow", "stop", "resume", "replan"]

#: A re-plan that found no way is asked again once a side of the obstacle's box moved
#: more than this [m] (beyond the jitter of noisy points on the box's edges).
REPLAN_MOVED = 0.03


@dataclass(frozen=True)
class ReplanRequest:
    """What a re-plan needs: where the robot rests and what blocks it.

    Attributes:
        time: Monitor time of the request [s].
        q: The joint state the robot rests at [rad].
        tau: Where on the followed trajectory it rests [s of that trajectory].
        step: The route step it rests in.
        obstacle_center: Centre of a world box holding the blocking elements [m].
        obstacle_size: Its edge lengths [m] (inflated by C + Z_d on every side).
    """

    time: float
    q: np.ndarray
    tau: float
    step: str
    obstacle_center: np.ndarray
    obstacle_size: np.ndarray


@dataclass(frozen=True)
class Decision:
    """One decision of the monitor.

    Attributes:
        time: Monitor time [s].
        kind: ``continue``, ``slow``, ``stop``, ``resume`` or ``replan``.
        reason: Why, in words.
        scale: Speed scale commanded, in [0, 1] (0: stopping or stopped).
        separation_now: Separation lower bound robot-observations now [m].
        separation_path: Over the look-ahead horizon of the path [m].
        protective_distance: ``S_p`` the decision was tested against [m].
        separation_kept: ``D``, the separation over the swept path it keeps [m].
        stopping_time: ``T_s`` of braking now [s].
        stopping_distance: Largest travel of a robot point while braking now [m].
        replacement: The re-timed rest of the path, if the speed changes.
        replacement_start: Monitor time at which the replacement's t = 0 applies [s].
        replan: The re-plan request of a ``replan`` decision.
        counts: What became of the readings of the observation decided on.
        closest: Closest observed element (x, y, z, radius) [m], or None.
        latched: Whether the kill switch is latched.
        elapsed: Computation time of the decision [s].
    """

    time: float
    kind: DecisionKind
    reason: str
    scale: float
    separation_now: float = float("inf")
    separation_path: float = float("inf")
    protective_distance: float = 0.0
    separation_kept: float = float("inf")
    stopping_time: float = 0.0
    stopping_distance: float = 0.0
    replacement: Trajectory | None = field(default=None, repr=False)
    replacement_start: float | None = None
    replan: ReplanRequest | None = None
    counts: Counts = field(default_factory=Counts)
    closest: np.ndarray | None = field(default=None, repr=False)
    latched: bool = False
    elapsed: float = 0.0


@dataclass
class _Source:
    stamp: float
    elements: np.ndarray
    counts: Counts


class Monitor:
    """Speed and separation monitoring of a robot following verified motions.

    Args:
        cell: The robot and its static scene (elements inside it are the scene's).
        options: Protective-distance parameters, sensors, timings.
    """

    def __init__(self, cell: Cell, options: MonitorOptions | None = None) -> None:
        self.cell = cell
        self.options = options or MonitorOptions()
        self._spheres: dict[str | None, RobotSpheres] = {}
        self._sources: dict[str, _Source] = {}
        self._scene = scene_arrays(cell)
        self._path: MonitoredPath | None = None
        self._sweep: PathSweep | None = None
        self._timings: list[Timing] = []
        self._scale = 1.0
        self._latched = False
        self._clear_since: float | None = None
        self._blocked_since: float | None = None
        self._replan_sent = False
        self._replan_failed: tuple[ReplanRequest, str] | None = None
        self._last_stamp: dict[str, float] = {}
        self.last: Decision = Decision(0.0, "continue", "not started", 1.0)
        self.stats = {"out_of_order": 0, "stale": 0, "malformed": 0}
        self._self_filtered = 0

    # -- motion ----------------------------------------------------------------------
    def follow(self, traj: Trajectory, *, start: float, held: str | None = None,
               scale: float = 1.0) -> None:
        """Follow a verified motion that starts (at rest, or at its first state) at
        monitor time ``start`` [s].

        Args:
            traj: The motion (no gripper event strictly inside it).
            start: Monitor time of its first knot [s].
            held: Object the gripper holds during it (part of the robot), or None.
            scale: Speed scale to start with (1: its verified timing).

        Raises:
            InputError: A gripper event inside the motion, or a robot mismatch.
        """
        if tuple(traj.joint_names) != tuple(self.cell.robot.joint_names):
            raise InputError("joint names differ from the cell's robot", key="traj")
        for e in traj.events:
            if traj.t[0] + 1e-9 < e.time < traj.t[-1] - 1e-9:
                raise InputError(f"gripper event '{e.action}' at t={e.time:.3f} s inside "
                                 "the motion: follow each motion between events",
                                 key="traj.events")
        if held not in self._spheres:
            self._spheres[held] = RobotSpheres.build(self.cell.robot, self.cell.scene, held,
                                                     cell=self.options.sphere_cell)
        self._path = MonitoredPath(traj, self.cell.robot)
        self._sweep = PathSweep.build(self.cell.robot, self._spheres[held], traj.t, traj.q,
                                      spacing=self.options.sweep_spacing)
        # A motion starts at rest (Q' = 0 there), so its first speed scale is immaterial.
        timing = self._path.march(start, float(traj.t[0]), scale, scale, np.inf)
        self._timings = [timing]
        self._scale = scale
        self._blocked_since = None
        self._replan_sent = False
        self._replan_failed = None

    def state_at(self, time: float) -> tuple[float, float]:
        """Path parameter [s] and speed scale ``r`` commanded at monitor time ``time``."""
        if not self._timings:
            return 0.0, 0.0
        timing = self._timings[0]
        for t in self._timings:
            if t.start <= time:
                timing = t
        return timing.state_at(time)

    def _timing_at(self, time: float) -> Timing | None:
        """The profile followed at monitor time ``time`` (None: no motion)."""
        timing = self._timings[0] if self._timings else None
        for t in self._timings:
            if t.start <= time:
                timing = t
        return timing

    # -- inputs ----------------------------------------------------------------------
    def observe(self, observation: Any, now: float) -> Decision:
        """Take an observation (a :class:`Scan`, :class:`Cloud`, :class:`Obstacles`, or a
        ``sensor_msgs`` LaserScan / PointCloud2 message) and decide.

        Raises:
            ObservationError: A malformed message, an unknown frame or a stamp from the
                future; nothing changes (the last decision stands).
        """
        try:
            source, stamp, elements, counts = to_elements(observation, now, self.options,
                                                          self._scene)
        except ObservationError:
            self.stats["malformed"] += 1
            raise
        last = self._last_stamp.get(source)
        if last is not None and stamp < last:
            self.stats["out_of_order"] += 1
            return self.tick(now)
        if source != OBSTACLES and now - stamp > self.options.stale_after:
            self.stats["stale"] += 1
            return self.tick(now)
        self._last_stamp[source] = stamp
        self._sources[source] = _Source(stamp, elements, counts)
        return self._decide(now, counts)

    def tick(self, now: float) -> Decision:
        """Decide without a new observation (call it regularly: silence stops)."""
        return self._decide(now, Counts())

    def kill(self, now: float) -> Decision:
        """Kill switch: brake to rest at once along the path; latched until
        :meth:`reset`."""
        self._latched = True
        return self._decide(now, Counts())

    def add_static_box(self, center: np.ndarray, size: np.ndarray) -> None:
        """Take a box into the static scene (after re-planning around an obstacle that
        stays): elements within it (and the scene filter) are ignored from now on;
        whatever leaves it is monitored again.

        Args:
            center: World centre [m].
            size: Edge lengths [m].
        """
        kinds, Ts, dims = self._scene
        T = np.eye(4)
        T[:3, 3] = center
        self._scene = (np.append(kinds, 0), np.concatenate([Ts, T[None]]),
                       np.vstack([dims, np.asarray(size, dtype=float) / 2]))

    def replan_failed(self, request: ReplanRequest, reason: str) -> None:
        """A re-plan found no way (``reason``: the planner's why). The robot stays
        stopped; its stop decisions say why, and a new request is made as soon as the
        obstacle's box has moved (by more than :data:`REPLAN_MOVED` on any side) while
        the robot is still blocked.

        Args:
            request: The request that failed.
            reason: Why, in words (e.g. the ``PlanningError``'s message).
        """
        self._replan_failed = (request, str(reason))

    def reset(self) -> None:
        """Release the kill switch; motion resumes by the hold-time rule."""
        self._latched = False
        self._clear_since = None

    # -- deciding --------------------------------------------------------------------
    def _decide(self, now: float, counts: Counts) -> Decision:
        import time

        t0 = time.perf_counter()
        decision = self._decide_inner(now, counts)
        decision = replace(decision, elapsed=time.perf_counter() - t0,
                           latched=self._latched)
        self.last = decision
        return decision

    def _decide_inner(self, now: float, counts: Counts) -> Decision:
        o = self.options
        if self._path is None or self._sweep is None:
            return Decision(now, "continue", "no motion to monitor", 1.0, counts=counts)
        silent = [s for s in o.sensors if s not in self._sources
                  or now - self._sources[s].stamp > o.stale_after]
        fresh = [s for s in self._sources if s not in silent]
        age = max([now - self._sources[s].stamp for s in fresh if s != OBSTACLES],
                  default=0.0)
        parts = [self._sources[s].elements for s in fresh]
        E = np.vstack(parts) if parts else np.zeros((0, 4))  # noqa: N806
        from . import _kernels

        tau_c, _ = self.state_at(now)
        if o.self_filter is not None and len(E):
            E = self._without_robot(E, now - age, tau_c)  # noqa: N806
            counts = replace(counts, robot=self._self_filtered)
        elements = _kernels.bucket(E, o.cell_size) if len(E) else (
            E, np.zeros((0, 4)), np.zeros(1, np.int64), np.zeros((0, 4)), np.zeros(1, np.int64))
        tau_l, r_l = self.state_at(now + o.command_latency)
        # A new profile starts from the raw profile half a width later (see
        # MonitoredPath.march); that is what the assessment marches from.
        current = self._timing_at(now + o.command_latency)
        raw = current.raw_state(now + o.command_latency + self._path.width / 2) \
            if current is not None else (tau_l, r_l)
        a = assess(self._path, self._sweep, elements, age, tau_c, raw[0], raw[1], o)
        base = dict(separation_now=a.separation_now, separation_path=a.separation_path,
                    protective_distance=a.protective_distance,
                    separation_kept=a.separation_kept, stopping_time=a.stopping_time,
                    stopping_distance=a.stopping_distance, counts=counts, closest=a.closest)
        if self._latched or silent:
            self._blocked_since = None  # only an obstacle's stop counts toward a re-plan
            why = ("kill switch (latched until reset)" if self._latched
                   else "sensor silence: " + ", ".join(silent))
            return self._stop(now, tau_l, r_l, why, base)
        return self._choose(now, a, tau_l, r_l, base, E)

    def _without_robot(self, E: np.ndarray, captured: float, tau_c: float  # noqa: N803
                       ) -> np.ndarray:
        """``E`` without the elements on the robot at the states it passed since
        ``captured`` (within ``self_filter`` plus the sampling spacing)."""
        from . import _kernels

        sweep = self._sweep
        assert sweep is not None and self.options.self_filter is not None
        s0 = sweep.index_at(self.state_at(captured)[0])
        s1 = min(sweep.index_at(tau_c) + 2, sweep.tau.size)
        on_robot = np.zeros(len(E), dtype=np.bool_)
        _kernels.near_robot(sweep.centers, sweep.spheres.radii, sweep.spheres.body_start,
                            sweep.bounding, s0, s1, E,
                            self.options.self_filter + sweep.spacing, on_robot)
        self._self_filtered = int(on_robot.sum())
        return np.ascontiguousarray(E[~on_robot])

    def _choose(self, now: float, a: Assessment, tau_l: float, r_l: float,
                base: dict[str, Any], E: np.ndarray) -> Decision:  # noqa: N803
        o = self.options
        if a.scale <= 0.0:
            why = (f"no speed scale >= {o.min_scale:g} keeps the protective distance; "
                   f"braking needs {a.protective_distance:.3f} m, has "
                   f"{a.separation_kept:.3f} m")
            if self._blocked_since is None:
                self._blocked_since = now
            decision = self._stop(now, tau_l, r_l, why, base)
            if self._replan_sent and self._replan_failed is not None and r_l == 0.0:
                return self._retry(decision, now, tau_l, a, E)
            if (self._blocked_since is not None and not self._replan_sent
                    and now - self._blocked_since >= o.replan_after and r_l == 0.0):
                self._replan_sent = True
                return replace(decision, kind="replan", reason="obstacle stays: " + why,
                               replan=self._request(now, tau_l, a, E))
            return decision
        self._blocked_since = None
        self._replan_sent, self._replan_failed = False, None  # clear: a new block re-plans
        if a.scale < self._scale:
            self._clear_since = None
            return self._emit(now, tau_l, r_l, a.scale, "slow",
                              f"full speed would not keep the protective distance; "
                              f"scale {a.scale:.2f}", base)
        if a.scale > self._scale:
            if self._clear_since is None:
                self._clear_since = now
            if now - self._clear_since >= o.hold_time:
                self._clear_since = None
                return self._emit(now, tau_l, r_l, a.scale, "resume",
                                  f"clear for {o.hold_time:.2f} s; scale {a.scale:.2f}", base)
        else:
            self._clear_since = None
        if self._scale >= 1.0:
            return Decision(now, "continue", "protective distance kept", 1.0, **base)
        kind: DecisionKind = "slow" if self._scale > 0 else "stop"
        return Decision(now, kind, f"holding scale {self._scale:.2f}", self._scale, **base)

    def _emit(self, now: float, tau_l: float, r_l: float, scale: float, kind: DecisionKind,
              reason: str, base: dict[str, Any]) -> Decision:
        assert self._path is not None
        start = now + self.options.command_latency
        try:
            timing, traj = self._path.replacement(
                start, scale, 0.0 if scale == 0 else np.inf, before=self._timing_at(start),
                tau0=tau_l, r0=r_l, kind=kind)
        except TimingError as exc:
            # No re-timing from this state stays within the limits as the controller
            # executes it (the motion is in a phase at its jerk limit): nothing is sent,
            # the robot keeps its current goal, and the next decision tries again.
            log.warning("monitor: %s not sent: %s", kind, exc)
            self.stats["deferred"] = self.stats.get("deferred", 0) + 1
            return Decision(now, kind, f"{reason}; deferred: no re-timing within the limits "
                            f"as executed from this state ({exc})", self._scale, **base)
        self._timings = [t for t in self._timings if t.start < start][-1:] + [timing]
        self._scale = scale
        return Decision(now, kind, reason, scale, replacement=traj, replacement_start=start,
                        **base)

    def _stop(self, now: float, tau_l: float, r_l: float, reason: str,
              base: dict[str, Any]) -> Decision:
        self._clear_since = None
        if self._scale == 0.0:
            return Decision(now, "stop", reason, 0.0, **base)
        return self._emit(now, tau_l, r_l, 0.0, "stop", reason, base)

    def _retry(self, decision: Decision, now: float, tau: float, a: Assessment,
               E: np.ndarray) -> Decision:  # noqa: N803
        """Still blocked after a failed re-plan: ask again once the obstacle's box has
        moved, else wait and say why."""
        assert self._replan_failed is not None
        failed, why = self._replan_failed
        request = self._request(now, tau, a, E)
        lo, hi = request.obstacle_center - request.obstacle_size / 2, \
            request.obstacle_center + request.obstacle_size / 2
        lo0, hi0 = failed.obstacle_center - failed.obstacle_size / 2, \
            failed.obstacle_center + failed.obstacle_size / 2
        if max(np.abs(lo - lo0).max(), np.abs(hi - hi0).max()) > REPLAN_MOVED:
            self._replan_failed = None
            return replace(decision, kind="replan",
                           reason="the obstacle moved since the last re-plan found no way",
                           replan=request)
        return replace(decision, reason=f"{decision.reason}; waiting for the obstacle to "
                       f"move: the last re-plan found no way ({why})")

    def _request(self, now: float, tau: float, a: Assessment, E: np.ndarray  # noqa: N803
                 ) -> ReplanRequest:
        assert self._path is not None
        o = self.options
        q = self._path.traj.sample([tau])[0][0]
        center = a.closest[:3] if a.closest is not None else np.zeros(3)
        near = E[np.linalg.norm(E[:, :3] - center, axis=1) <= o.replan_cluster] \
            if len(E) else np.zeros((0, 4))
        if len(near) == 0:
            near = np.array([[*center, 0.0]])
        lo = (near[:, :3] - near[:, 3:]).min(axis=0) - o.min_separation - o.sensor_uncertainty
        hi = (near[:, :3] + near[:, 3:]).max(axis=0) + o.min_separation + o.sensor_uncertainty
        return ReplanRequest(now, q, tau, self._path.traj.step_at(tau), (lo + hi) / 2, hi - lo)
