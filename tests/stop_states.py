"""Seeded random stops of verified motions, for ``tests/monitor/test_stop_search.py`` and
``benchmarks/stop_search.py``.

A motion is followed as verified from time 0; at random instants the monitor's
re-timing (:class:`safepath.monitor.profile.MonitoredPath`) sends a replacement as the
monitor does: a slowing, a speed-up or a stop, each starting on a point of the goal then
running (where the controller's state is a path state), chained so that stops also come
while the motion already brakes or speeds up. A stop is the search the monitor runs
(:meth:`~MonitoredPath.replacement` to rest, else :meth:`~MonitoredPath.forced_stop`);
what is measured is its largest speed, acceleration or jerk ratio as executed
(``info["executed_ratios"]``: over 1.0 means no candidate was within the limits).

The motions: the bundled cells' plans (:func:`cell_motions`) and random via-point paths
on the bundled robots timed by :func:`safepath.timing.time_path`
(:func:`via_point_motion`).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from safepath import Trajectory
from safepath.errors import TimingError
from safepath.model.robot import Robot
from safepath.monitor.profile import KNOT_NS, MonitoredPath, Timing

__all__ = ["Follower", "Stop", "cell_motions", "chain_rng", "path_rng", "random_chain",
           "via_point_motion"]

ROOT = Path(__file__).resolve().parents[1]
#: Chained replacements before the stop, at most.
CHAIN = 3


@dataclass(frozen=True)
class Stop:
    """One stop sent.

    Attributes:
        start: When it starts, on the motion's clock [s].
        events: The replacements before it: (start [s], speed scale), oldest first.
        ratios: Its speed, acceleration and jerk ratios to the limits as executed.
        forced: Whether the search fell back on :meth:`MonitoredPath.forced_stop`.
        duration: Its time to rest [s].
        hold: How long it follows the running profile before it brakes [s] (``inf``: it
            follows it to where it rests; 0: it brakes at once).
    """

    start: float
    events: tuple[tuple[float, float], ...]
    ratios: tuple[float, float, float]
    forced: bool
    duration: float
    hold: float

    @property
    def worst(self) -> float:
        """Its largest ratio to a limit as executed."""
        return max(self.ratios)


class Follower:
    """The monitor's chain of goals along one motion: what runs, and where the next
    replacement starts (on the running goal's next point)."""

    def __init__(self, traj: Trajectory, robot: Robot) -> None:
        self.path = MonitoredPath(traj, robot)
        t0 = float(traj.t[0])
        self.timings = [self.path.march(0.0, t0, 1.0, 1.0, np.inf, lead=0.0)]
        self.goal = (0.0, np.asarray(traj.t, dtype=float) - t0)  # (stamp, point times)
        #: Every goal sent: (stamp [s], trajectory), the verified motion first.
        self.goals: list[tuple[float, Trajectory]] = [(0.0, traj)]
        # The verified motion, on a path whose knots are not evenly spaced, is switched
        # from at any instant (Monitor._switch_time); every other goal on its points.
        self.any_instant = self.path.knot == KNOT_NS / 1e9

    def timing_at(self, time: float) -> Timing:
        """The profile followed at ``time`` [s]."""
        return [t for t in self.timings if t.start <= time][-1]

    def switch_time(self, time: float) -> float | None:
        """The running goal's first point at or after ``time`` (None: it has ended)."""
        stamp, points = self.goal
        if self.any_instant:
            return time if time <= stamp + points[-1] else None
        k = int(np.searchsorted(points + stamp, time - 1e-9, side="left"))
        return None if k >= points.size else float(points[k] + stamp)

    def send(self, time: float, scale: float) -> tuple[Trajectory, bool] | None:
        """The replacement toward ``scale`` decided at ``time`` and whether it is a forced
        stop (None: nothing to send, the running goal rests first or a speed-up waits)."""
        start = self.switch_time(time)
        if start is None:
            return None
        before = self.timing_at(start)
        if before.raw_state(start + self.path.width / 2)[0] >= self.path.end - 1e-9:
            return None
        tau, r = before.state_at(start)
        forced = False
        try:
            timing, traj = self.path.replacement(start, scale, 0.0 if scale == 0 else np.inf,
                                                 before=before, tau0=tau, r0=r,
                                                 kind="stop" if scale == 0 else "slow")
        except TimingError:
            if scale > before.state_at(start)[1]:
                return None  # a speed-up waits for a later decision
            try:
                timing, traj = self.path.replacement(start, 0.0, 0.0, before=before, tau0=tau,
                                                     r0=r, kind="stop")
            except TimingError:
                timing, traj = self.path.forced_stop(start, before=before, tau0=tau, r0=r)
                forced = True
        self.timings = [t for t in self.timings if t.start < start][-1:] + [timing]
        self.goal = (start, np.asarray(traj.t, dtype=float))
        self.goals.append((start, traj))
        self.any_instant = False
        return traj, forced


def random_chain(traj: Trajectory, robot: Robot, rng: np.random.Generator, *,
                 late: float | None = None) -> tuple[list[Stop], Follower]:
    """One chain on ``traj``: from a random instant of it (of its last ``late`` seconds
    if given), up to :data:`CHAIN` random speed scales (0.1-1 in steps of 0.05, or a
    stop) 0.02-0.3 s apart, then a stop (if not stopping already); the stops sent, and
    the follower (its goals)."""
    follower = Follower(traj, robot)
    time = float(rng.uniform(0.0, traj.duration)) if late is None else \
        traj.duration - float(rng.uniform(0.0, min(late, traj.duration)))
    events: list[tuple[float, float]] = []
    stops = []
    scale = 1.0
    for k in range(CHAIN + 1):
        last = k == CHAIN or rng.random() < 0.35
        if last and scale == 0.0:
            break  # stopping already (the monitor sends no second stop)
        options = [s for s in np.arange(2, 21) * 0.05 if abs(s - scale) > 1e-9]
        new = 0.0 if last or (scale > 0 and rng.random() < 0.3) else float(rng.choice(options))
        sent = follower.send(time, new)
        if sent is not None:
            rep, forced = sent
            if new == 0.0:
                stops.append(Stop(follower.goal[0], tuple(events),
                                  tuple(rep.info["executed_ratios"]), forced, rep.duration,
                                  float(rep.info["stop"]["hold"])))
            events.append((follower.goal[0], new))
            scale = new
        if last:
            break
        time += float(rng.uniform(0.02, 0.3))
    return stops, follower


def chain_rng(seed: int, source: str, motion: int, chain: int) -> np.random.Generator:
    """The generator of chain ``chain`` on motion ``motion`` of ``source`` (a cell or a
    robot) for seed ``seed``: a chain replays alone from these."""
    return np.random.default_rng([seed, zlib.crc32(source.encode()), motion, chain])


def path_rng(seed: int, robot: str, path: int) -> np.random.Generator:
    """The generator of random via-point path ``path`` on ``robot`` for seed ``seed``."""
    return np.random.default_rng([seed, zlib.crc32(robot.encode()), path, 1 << 20])


def via_point_motion(robot: Robot, rng: np.random.Generator,
                     knot_period: float | None = None) -> Trajectory:
    """A random via-point path of the timing suite (``tests/timing_suite.py``: 2-4 route
    steps with their own speed scales and TCP speed limits, blended at the via points),
    timed by :func:`~safepath.timing.time_path` (knots ``knot_period`` [s] apart, default
    the timing's), as one motion."""
    from timing_suite import timed_problem

    piece, _ = timed_problem(robot, rng, knot_period)
    return Trajectory(robot.joint_names, piece.t, piece.q, piece.qd, piece.qdd,
                      np.zeros(piece.t.size, dtype=int), ("move",), robot=robot.name,
                      limits=robot.motion_limits, interpolation=robot.controller.interpolation)


def cell_motions(name: str, knot_period: float | None = None
                 ) -> tuple[Robot, list[Trajectory]]:
    """The motions (between gripper events) of every route of the bundled cell ``name``,
    planned (seed 0; knots ``knot_period`` [s] apart, default the timing's), and its
    robot."""
    from safepath import PlanOptions, load_cell, plan_cell
    from safepath.ros import split_at_gripper_events
    from safepath.timing import TimingOptions

    cell = load_cell(ROOT / "scenes" / name)
    options = PlanOptions() if knot_period is None else \
        PlanOptions(timing=TimingOptions(knot_period=knot_period))
    motions = [m for traj in plan_cell(cell, options).values()
               for m in split_at_gripper_events(traj)
               if isinstance(m, Trajectory) and m.t.size > 2]
    return cell.robot, motions
