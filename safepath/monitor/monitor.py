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
from ..model.execution import ControllerModel, Switch
from ..model.interpolation import Interpolation
from ..model.trajectory import Trajectory
from .elements import OBSTACLES, scene_arrays, to_elements
from .lost import LostBodies
from .observations import Counts, ObservationError
from .options import MonitorOptions
from .parked import REPLAN_MOVED, ParkedBody, Rest, RestHistory, blocking_body, extent, shrink_box
from .profile import KNOT_NS, MonitoredPath, Timing
from .separation import Assessment, assess
from .sweep import PathSweep, RobotSpheres

__all__ = ["Monitor", "Decision", "ReplanRequest"]

log = logging.getLogger(__name__)

DecisionKind = Literal["continue", "slow", "stop", "resume", "replan"]


@dataclass(frozen=True)
class _GoalStart:
    """Where a goal sent at a decision takes effect (once per decision): when [s]
    (:meth:`Monitor._switch_time`), the path parameter [s] and path speed (0-1) there."""

    time: float
    tau: float
    r: float


@dataclass(frozen=True)
class ReplanRequest:
    """What a re-plan needs: where the robot rests and what blocks it.

    Attributes:
        time: Monitor time of the request [s].
        q: The joint state the robot rests at [rad].
        tau: Where on the followed trajectory it rests [s of that trajectory].
        step: The route step it rests in.
        obstacle_center: Centre of a world box holding the blocking body [m].
        obstacle_size: Its edge lengths [m]: the body's box inflated by C + Z_d on every
            side, except where that reached into the robot's enclosing spheres at ``q``:
            such a side is cut back to the spheres (``shrunk`` says which), never inside
            the body's box (:func:`safepath.monitor.parked.shrink_box`).
        body_center: Centre of the body's own box (its elements' extent over the rest
            window, not inflated) [m]; None: not measured (a request made by hand).
        body_size: Its edge lengths [m]; None: not measured.
        body_speed: The body's speed by the rest rule when asked [m/s].
        shrunk: Which sides of the box were cut back to the robot, in words ("": none).
        inflation: ``C + Z_d``, the body's box inflated by it before any cut [m]; None:
            not known (a request made by hand: the obstacle box is taken whole).
    """

    time: float
    q: np.ndarray
    tau: float
    step: str
    obstacle_center: np.ndarray
    obstacle_size: np.ndarray
    body_center: np.ndarray | None = None
    body_size: np.ndarray | None = None
    body_speed: float = 0.0
    shrunk: str = ""
    inflation: float | None = None


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
        switch: How the controller takes the replacement at ``replacement_start``
            (:class:`safepath.model.execution.Switch`: its state then, and any step).
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
    switch: Switch | None = field(default=None, repr=False)


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
        self._rest = RestHistory(self.options.rest_window, self.options.rest_speed)
        self._parked: list[ParkedBody] = []  # bodies re-planned around, still watched
        self._asked: list[ReplanRequest] = []  # the latest requests (add_static_box)
        self._parked_note = ""  # why a parked body was dropped, for the next stop
        self._lost = LostBodies(self.options.approach_speed, self.options.replan_cluster)
        self._last_stamp: dict[str, float] = {}
        self.last: Decision = Decision(0.0, "continue", "not started", 1.0)
        #: The controller as the monitor's goals drive it (None before the first
        #: :meth:`follow`): the verified motion from its start, then every replacement
        #: from its ``replacement_start``. Replacements begin at its state then.
        self.controller: ControllerModel | None = None
        self._interpolation: Interpolation = cell.robot.controller.interpolation
        self._any_instant = True  # the running goal is on the path at every instant
        self.stats = {"out_of_order": 0, "stale": 0, "malformed": 0}
        self._self_filtered = 0
        # The kernels loaded (or compiled, without a current build of them) now, not in
        # the first decision, which may have to stop the robot.
        from ._kernels import warm

        warm()

    # -- motion ----------------------------------------------------------------------
    def follow(self, traj: Trajectory, *, start: float, held: str | None = None,
               scale: float = 1.0) -> None:
        """Follow a verified motion that starts (at rest, or at its first state) at
        monitor time ``start`` [s].

        Args:
            traj: The motion (no gripper event strictly inside it).
            start: Monitor time of its first knot [s].
            held: Object the gripper holds during it (part of the robot), or None.
            scale: Speed scale to start with (1: its verified timing, sent as it is; 0:
                not sent, the arm waits at its start until a ``resume`` decision's
                replacement starts it).

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
        tau, q = self._path.knots[:2]
        self._sweep = PathSweep.build(self.cell.robot, self._spheres[held], tau, q,
                                      spacing=self.options.sweep_spacing)
        # The goal is the motion as verified, from ``start`` on: followed with no lead,
        # the path parameter at monitor time t is exactly t - start (a motion starts at
        # rest, Q' = 0 there, so its first speed scale is immaterial).
        timing = self._path.march(start, float(traj.t[0]), scale, scale, np.inf, lead=0.0)
        self._timings = [timing]
        if self.controller is None:
            self.controller = ControllerModel(traj.q[0], interpolation=self._interpolation)
        if scale > 0.0:
            self.controller.take(traj.t - traj.t[0], traj.q, traj.qd, traj.qdd, start=start)
        else:  # not sent yet: the arm rests at its start until a resume
            rest = np.zeros((1, traj.dof))
            self.controller.take(np.zeros(1), traj.q[:1], rest, rest, start=start)
        self._any_instant = True
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

    def at_end(self, time: float) -> bool:
        """Whether the followed motion has reached the end of its path at monitor time
        ``time`` [s]: its path parameter is within 1e-9 s of the path's last knot (a stop
        that rests before it has not; False while no motion is followed)."""
        if self._path is None:
            return False
        return self.state_at(time)[0] >= self._path.end - 1e-9

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
        """Take the box a re-plan went around as a *parked body*: while the body in it
        stays, its elements are left out of the separation test; it stays watched, and
        once it moves (:class:`~safepath.monitor.parked.ParkedBody`: no element left where
        it was, or an element in the box, or linked to the body, more than
        :data:`~safepath.monitor.parked.REPLAN_MOVED` beyond its box at rest) the box is
        dropped: the body is an obstacle like any other again, and the separation rule
        stops or slows the robot (the next stop says why).

        The body is the one measured for the latest request with this box (its
        ``body_center`` and ``body_size``); for any other box, the elements inside it now
        (none: any element that enters the box drops it).

        Args:
            center: World centre [m].
            size: Edge lengths [m].

        Raises:
            InputError: Not three finite numbers each, or an edge <= 0.
        """
        c = np.asarray(center, dtype=float)
        e = np.asarray(size, dtype=float)
        for key, v in (("center", c), ("size", e)):
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise InputError(f"expected 3 finite numbers [m], got {v!r}", key=key)
        if np.any(e <= 0):
            raise InputError(f"edge lengths must be > 0 [m], got {e!r}", key="size")
        lo, hi = c - e / 2, c + e / 2
        body: tuple[np.ndarray, np.ndarray] | None = None
        for r in reversed(self._asked):
            if r.body_center is not None and r.body_size is not None and \
                    np.array_equal(r.obstacle_center, c) and np.array_equal(r.obstacle_size, e):
                body = (r.body_center - r.body_size / 2, r.body_center + r.body_size / 2)
                break
        if body is None:
            E = self._elements()  # noqa: N806
            inside = E[np.all((E[:, :3] >= lo) & (E[:, :3] <= hi), axis=1)]
            body = extent(inside) if len(inside) else None
        self._parked.append(ParkedBody(lo, hi, None if body is None else body[0],
                                       None if body is None else body[1],
                                       self.options.replan_cluster))

    def replan_failed(self, request: ReplanRequest, reason: str) -> None:
        """A re-plan found no way (``reason``: the planner's why). The robot stays
        stopped; its stop decisions say why, and a new request is made once the body's
        box has moved (by more than :data:`~safepath.monitor.parked.REPLAN_MOVED` on any
        side) and the body is at rest again, while the robot is still blocked.

        Args:
            request: The request that failed.
            reason: Why, in words (e.g. the ``PlanningError``'s message).
        """
        self._replan_failed = (request, str(reason))

    def reset(self) -> None:
        """Release the kill switch, forget a body lost from view; resume by the hold time."""
        self._latched, self._clear_since = False, None
        self._lost.clear()

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

        tau_c, _ = self.state_at(now)
        if o.self_filter is not None and len(E):
            E = self._without_robot(E, now - age, tau_c)  # noqa: N806
            counts = replace(counts, robot=self._self_filtered)
        E, lost = self._lost.fill(E, [] if silent else [self._sources[s].stamp for s in fresh])
        if lost:  # a body vanished from view: kept where it was seen (.lost)
            self._parked_note = f"{self._parked_note}; {lost}".lstrip("; ")
            self.stats["lost"] = self.stats.get("lost", 0) + 1
        parked = self._parked_mask(E)
        switch = self._switch_time(now + o.command_latency)
        goal = _GoalStart(switch, *self.state_at(switch))
        # A new profile starts from the raw profile half a width later (see
        # MonitoredPath.march); that is what the assessment marches from.
        current = self._timing_at(switch)
        raw = current.raw_state(switch + self._path.width / 2) \
            if current is not None else (goal.tau, goal.r)
        a = self._assess(E, parked, age, tau_c, raw)
        body = blocking_body(E, a.closest, o.replan_cluster) \
            if a.closest is not None and a.scale < 1.0 else None  # what holds the robot back
        self._lost.seen([self._sources[s].stamp for s in fresh], body, a.closest,  # (.lost)
                        self._sources[OBSTACLES].elements if OBSTACLES in fresh else None)
        base = dict(separation_now=a.separation_now, separation_path=a.separation_path,
                    protective_distance=a.protective_distance,
                    separation_kept=a.separation_kept, stopping_time=a.stopping_time,
                    stopping_distance=a.stopping_distance, counts=counts, closest=a.closest)
        if self._latched or silent:
            self._blocked_since = None  # only an obstacle's stop counts toward a re-plan
            why = ("kill switch (latched until reset)" if self._latched
                   else "sensor silence: " + ", ".join(silent))
            return self._stop(now, goal, why, base)
        return self._choose(now, a, goal, base, body)

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

    def _choose(self, now: float, a: Assessment, goal: _GoalStart, base: dict[str, Any],
                body: np.ndarray | None) -> Decision:
        o = self.options
        if a.scale <= 0.0:
            why = (f"no speed scale >= {o.min_scale:g} keeps the protective distance; "
                   f"braking needs {a.protective_distance:.3f} m, has "
                   f"{a.separation_kept:.3f} m")
            if self._parked_note:
                why, self._parked_note = f"{why}; {self._parked_note}", ""
            if self._blocked_since is None:
                self._blocked_since = now
            decision = self._stop(now, goal, why, base)
            self._record_rest(body)
            if self._replan_sent and self._replan_failed is not None and goal.r == 0.0:
                return self._retry(decision, now, goal.tau)
            if (self._blocked_since is not None and not self._replan_sent
                    and now - self._blocked_since >= o.replan_after and goal.r == 0.0):
                return self._ask(decision, now, goal.tau)
            return decision
        self._blocked_since = None
        self._replan_sent, self._replan_failed = False, None  # clear: a new block re-plans
        self._rest.clear()
        self._parked_note = ""
        if a.scale < self._scale:
            self._clear_since = None
            return self._emit(now, goal, a.scale, "slow",
                              f"full speed would not keep the protective distance; "
                              f"scale {a.scale:.2f}", base)
        if a.scale > self._scale:
            if self._clear_since is None:
                self._clear_since = now
            if now - self._clear_since >= o.hold_time:
                self._clear_since = None
                return self._emit(now, goal, a.scale, "resume",
                                  f"clear for {o.hold_time:.2f} s; scale {a.scale:.2f}", base)
        else:
            self._clear_since = None
        if self._scale >= 1.0:
            return Decision(now, "continue", "protective distance kept", 1.0, **base)
        kind: DecisionKind = "slow" if self._scale > 0 else "stop"
        return Decision(now, kind, f"holding scale {self._scale:.2f}", self._scale, **base)

    def _switch_time(self, time: float) -> float:
        """When a goal sent now takes effect: ``time`` (the command latency after the
        decision), or, while a replacement runs, its first point at or after ``time``.

        A replacement's points lie on the verified path, but the controller's join
        between two of them does not exactly: a new replacement starts at one of them,
        where the controller's state (p, v, a) is a path state whose speed and path
        acceleration are known (at most one point spacing later). The verified motion
        itself is on the path at every instant."""
        if self.controller is None:
            return time
        # On a path's own knots a replacement's knots are the path's while it keeps the
        # verified timing (see MonitoredPath.knot): snap there too.
        own_knots = self._path is not None and self._path.knot != KNOT_NS / 1e9
        if self._any_instant and not own_knots:
            return time
        t_abs = self.controller.running[0]
        k = int(np.searchsorted(t_abs, time - 1e-9, side="left"))
        return time if k >= t_abs.size else float(t_abs[k])

    def _emit(self, now: float, goal: _GoalStart, scale: float, kind: DecisionKind,
              reason: str, base: dict[str, Any]) -> Decision:
        assert self._path is not None and self.controller is not None
        start, tau_l, r_l = goal.time, goal.tau, goal.r
        before = self._timing_at(start)
        if before is not None and \
                before.raw_state(start + self._path.width / 2)[0] >= self._path.end - 1e-9:
            # The running goal reaches the path's end (at rest) before a new profile could
            # change anything: it is the stop (and nothing is to be slowed or resumed).
            self._scale = scale
            return Decision(now, kind, f"{reason}; the running goal comes to rest at the "
                            "motion's end first: no replacement", self._scale, **base)
        try:
            timing, traj = self._path.replacement(
                start, scale, 0.0 if scale == 0 else np.inf, before=before,
                tau0=tau_l, r0=r_l, kind=kind)
        except TimingError as exc:
            if kind == "slow":  # no slowing within the limits: stopping may be
                try:
                    timing, traj = self._path.replacement(
                        start, 0.0, 0.0, before=before, tau0=tau_l, r0=r_l, kind="stop")
                    return self._sent(now, start, timing, traj, "stop", 0.0,
                                      f"{reason}; stopping: no slowing within the limits "
                                      f"as executed from this state ({exc})", base)
                except TimingError:
                    pass
            if kind == "resume":
                # Speeding up may wait: the robot keeps its lower speed, which the
                # separation allows, and the next decision tries again.
                log.info("monitor: resume not sent yet: %s", exc)
                self.stats["resume_waits"] = self.stats.get("resume_waits", 0) + 1
                return Decision(now, "slow" if self._scale > 0 else "stop",
                                f"{reason}; speed-up waits: no re-timing within the limits "
                                f"as executed from this state ({exc})", self._scale, **base)
            # Slowing or stopping is never postponed: brake to rest at once, as hard as
            # the acceleration limits allow, even where the executed jerk or acceleration
            # then exceeds a limit; the decision says by how much.
            timing, traj = self._path.forced_stop(start, before=before, tau0=tau_l, r0=r_l)
            ratios = traj.info["executed_ratios"]
            if max(ratios) <= 1.0:
                self.stats["gentle_stops"] = self.stats.get("gentle_stops", 0) + 1
                return self._sent(now, start, timing, traj, "stop", 0.0,
                                  f"{reason}; braking gentler than assessed (at rest after "
                                  f"{traj.duration:.3f} s, assessed "
                                  f"{base['stopping_time']:.3f} s{_held(traj)}): no braking "
                                  f"as assessed is within the limits from this state", base)
            log.warning("monitor: %s beyond the limits as executed (%s): %s", kind,
                        ", ".join(f"{x:.3f}" for x in ratios), exc)
            self.stats["stops_over_limit"] = self.stats.get("stops_over_limit", 0) + 1
            reason = (f"{reason}; braking at once beyond the limits as executed (speed, "
                      f"acceleration, jerk ratios {ratios[0]:.3f}, {ratios[1]:.3f}, "
                      f"{ratios[2]:.3f}): no re-timing within them from this state")
            kind, scale = "stop", 0.0
        return self._sent(now, start, timing, traj, kind, scale, reason, base)

    def _sent(self, now: float, start: float, timing: Timing, traj: Trajectory,
              kind: DecisionKind, scale: float, reason: str, base: dict[str, Any]
              ) -> Decision:
        """The decision that sends ``traj`` to start at ``start``: the controller model
        takes it, the monitor follows ``timing`` from then on."""
        assert self.controller is not None
        switch = self.controller.take(traj.t, traj.q, traj.qd, traj.qdd, start=start)
        if not switch.continuous:  # the path state and the controller's state disagree
            log.error("monitor: the %s goal starts %.3g rad, %.3g rad/s, %.3g rad/s^2 off "
                      "the controller's state", kind, switch.position_step,
                      switch.velocity_step, switch.acceleration_step)
            self.stats["switch_steps"] = self.stats.get("switch_steps", 0) + 1
        self._any_instant = False
        self._timings = [t for t in self._timings if t.start < start][-1:] + [timing]
        self._scale = scale
        return Decision(now, kind, reason, scale, replacement=traj, replacement_start=start,
                        switch=switch, **base)

    def _stop(self, now: float, goal: _GoalStart, reason: str, base: dict[str, Any]
              ) -> Decision:
        self._clear_since = None
        if self._scale == 0.0:
            return Decision(now, "stop", reason, 0.0, **base)
        return self._emit(now, goal, 0.0, "stop", reason, base)

    def _retry(self, decision: Decision, now: float, tau: float) -> Decision:
        """Still blocked after a failed re-plan: ask again once the body's box has moved
        and the body is at rest again, else wait and say why."""
        assert self._replan_failed is not None
        failed, why = self._replan_failed
        rest = self._rest.judge()
        if failed.body_center is not None and failed.body_size is not None:
            lo0 = failed.body_center - failed.body_size / 2
            hi0 = failed.body_center + failed.body_size / 2
        else:  # a request made by hand: its box less the inflation
            d = self.options.min_separation + self.options.sensor_uncertainty
            lo0 = failed.obstacle_center - failed.obstacle_size / 2 + d
            hi0 = failed.obstacle_center + failed.obstacle_size / 2 - d
        moved = max(np.abs(rest.lo - lo0).max(), np.abs(rest.hi - hi0).max())
        if not moved > REPLAN_MOVED:  # (nan: no body measured)
            return replace(decision, reason=f"{decision.reason}; waiting for the body to "
                           f"move: the last re-plan found no way ({why})")
        if not rest.at_rest:
            return replace(decision, reason=f"{decision.reason}; the body moved since the "
                           f"last re-plan found no way; no re-plan yet: {rest.why}")
        self._replan_failed = None
        return replace(decision, kind="replan",
                       reason="the body moved since the last re-plan found no way, and is "
                       f"at rest again ({rest.speed:.3f} m/s)",
                       replan=self._request(now, tau, rest))

    def _request(self, now: float, tau: float, rest: Rest) -> ReplanRequest:
        """The request: the rest state, and the body's box inflated by C + Z_d, cut back
        where it reaches into the robot's enclosing spheres at the rest state."""
        assert self._path is not None and self._sweep is not None
        o = self.options
        q = self._path.traj.sample([tau])[0][0]
        d = o.min_separation + o.sensor_uncertainty
        spheres = self._sweep.spheres
        centers, _ = spheres.place(self.cell.robot, q[None])
        lo, hi, shrunk = shrink_box(rest.lo - d, rest.hi + d, rest.lo, rest.hi, centers[0],
                                    spheres.radii)
        request = ReplanRequest(now, q, tau, self._path.traj.step_at(tau), (lo + hi) / 2, hi - lo,
                                (rest.lo + rest.hi) / 2, rest.hi - rest.lo, rest.speed, shrunk, d)
        self._asked = [*self._asked[-3:], request]
        return request

    # -- re-plan: the rest rule and the parked bodies (safepath.monitor.parked) --------
    def _ask(self, decision: Decision, now: float, tau: float) -> Decision:
        """Stopped for ``replan_after``: a re-plan request if the body is at rest, else
        the stop, saying why not yet."""
        rest = self._rest.judge()
        if not rest.at_rest:
            return replace(decision, reason=f"{decision.reason}; no re-plan yet: {rest.why}")
        self._replan_sent = True
        request = self._request(now, tau, rest)
        shrunk = f"; box {request.shrunk}" if request.shrunk else ""
        return replace(decision, kind="replan", replan=request,
                       reason=f"obstacle stays (at rest: {rest.speed:.3f} m/s over the last "
                       f"{self.options.rest_window:g} s){shrunk}: {decision.reason}")

    def _record_rest(self, body: np.ndarray | None) -> None:
        """Add the blocking body, as the newest observation shows it, to the rest rule."""
        if body is not None:
            self._rest.add(max(s.stamp for s in self._sources.values()), body)

    def _elements(self) -> np.ndarray:
        """The latest elements of every source (n, 4) [m]."""
        parts = [s.elements for s in self._sources.values()]
        return np.vstack(parts) if parts else np.zeros((0, 4))

    def _parked_mask(self, E: np.ndarray) -> np.ndarray:  # noqa: N803
        """Which elements of ``E`` belong to the parked bodies that stay; one that moved
        is dropped (an obstacle like any other again) and the next stop says so."""
        parked = np.zeros(len(E), dtype=bool)
        for body in list(self._parked):
            mask, moved = body.watch(E)
            if moved:
                self._parked.remove(body)
                self._parked_note = f"a parked body moved ({moved}): an obstacle again"
                log.warning("monitor: %s", self._parked_note)
                self.stats["parked_dropped"] = self.stats.get("parked_dropped", 0) + 1
            else:
                parked |= mask
        return parked

    def _assess(self, E: np.ndarray, parked: np.ndarray, age: float,  # noqa: N803
                tau_c: float, raw: tuple[float, float]) -> Assessment:
        """The protective-distance test of every element: those of parked bodies with
        their own ``v_h`` (``parked_speed``), the others with ``approach_speed``; the
        tighter outcome counts."""
        from . import _kernels

        assert self._path is not None and self._sweep is not None
        o = self.options

        def test(elements: np.ndarray, v_h: float) -> Assessment:
            bucketed = _kernels.bucket(elements, o.cell_size) if len(elements) else (
                elements, np.zeros((0, 4)), np.zeros(1, np.int64), np.zeros((0, 4)),
                np.zeros(1, np.int64))
            assert self._path is not None and self._sweep is not None
            return assess(self._path, self._sweep, bucketed, age, tau_c, raw[0], raw[1],
                          o, approach_speed=v_h)

        slower = o.parked_approach_speed < o.approach_speed
        if not (slower and parked.any()):
            return test(E, o.approach_speed)
        others = test(np.ascontiguousarray(E[~parked]), o.approach_speed)
        still = test(np.ascontiguousarray(E[parked]), o.parked_approach_speed)
        tight = min((others, still), key=lambda x: (x.scale, x.separation_kept
                                                    - x.protective_distance))
        return replace(tight, separation_now=min(others.separation_now, still.separation_now),
                       separation_path=min(others.separation_path, still.separation_path))


def _held(stop: Trajectory) -> str:
    """How long a stop follows the running motion before it brakes, as words."""
    hold = stop.info["stop"]["hold"]
    if hold == float("inf"):
        return "; it follows the running motion to its rest"
    return f"; it follows the running motion {hold:.3f} s first" if hold > 0 else ""
