"""The protective-distance test of every speed scale, for one decision.

For a decision at monitor time ``now`` on observations whose oldest is ``T_age`` old,
with the robot at path parameter ``tau_c``, a speed scale ``k`` is *safe* when::

    D(k) >= S_p(k) = v_h * (T_age + T_cmd + T(k)) + C + Z_d + Z_r

* ``T(k)``: from the moment the controller acts (``now + T_cmd``), the robot goes toward
  speed ``k`` for ``T_next`` (``stale_after``: the next decision comes at the latest
  then, or silence stops the robot), then brakes as hard as its acceleration limits
  allow along the same path; ``T(k)`` is the time until it is at rest
  (``T_next`` + the stopping time ``T_s``, both from the robot's own stop profile).
* ``D(k)``: the separation lower bound between the observed elements and *every*
  robot state on the path from ``tau_c`` to where that profile is at rest (the
  enclosing spheres at the sampled states, minus half the sampling spacing).
* ``v_h * (...)``: ISO/TS 15066's ``S_h``, how far a person walks meanwhile. Bodies a
  re-plan went around are tested with their own ``v_h`` (``MonitorOptions.parked_speed``,
  by default ``approach_speed``); with ``v_h = 0`` (a body that cannot move) a scale is
  also safe when ``D(k)`` is no smaller than the separation now: the robot may move
  away from a body it stopped next to, never toward it.

This is ISO/TS 15066's ``S_p = S_h + S_r + S_s + C + Z_d + Z_r`` with the robot's
terms ``S_r + S_s`` (its travel during reaction and stopping) not bounded by a speed
toward the person but measured: the separation is taken to the whole swept path. It
is never smaller than the ISO form's margin, and tighter where the robot moves away.
Under the stated assumptions (nobody faster than ``v_h``, observations at most
``stale_after`` apart, elements within ``Z_d`` of the real surfaces, the controller
acting within ``T_cmd``), the robot then never comes closer than ``C`` to a person.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .options import MonitorOptions
from .profile import BRAKE_HOLDS, MonitoredPath
from .sweep import PathSweep

__all__ = ["Assessment", "assess", "first_safe"]


def _kernels():  # noqa: ANN202
    from . import _kernels as K  # noqa: N812

    return K


@dataclass(frozen=True)
class Assessment:
    """The outcome of the protective-distance test.

    Attributes:
        scale: The largest safe speed scale (a multiple of ``scale_step``, at least
            ``min_scale``), or 0 when none is safe (stop).
        separation_now: Separation lower bound to the robot now [m] (inf: beyond cap).
        separation_path: Over the look-ahead horizon of the path [m].
        separation_kept: ``D`` of the chosen scale (or of stopping) [m].
        protective_distance: ``S_p`` of the chosen scale (or of stopping) [m].
        stopping_time: ``T_s`` of braking now [s].
        stopping_distance: Largest travel of any robot point while braking now [m].
        closest: The closest observed element (x, y, z, radius) [m], or None.
    """

    scale: float
    separation_now: float
    separation_path: float
    separation_kept: float
    protective_distance: float
    stopping_time: float
    stopping_distance: float
    closest: np.ndarray | None


class _Prefix:
    """Running minimum of the separation along the sweep from the current sample."""

    def __init__(self, sweep: PathSweep, s0: int, s1: int, elements: tuple[np.ndarray, ...],
                 cap: float) -> None:
        S, cells, cstart, blocks, bstart = elements
        n = max(s1 - s0, 1)
        self.out = np.full(n, cap)
        self.arg = np.full(n, -1, dtype=np.int64)
        if S.shape[0]:
            _kernels().prefix_separation(
                sweep.centers, sweep.spheres.radii, sweep.spheres.body_start, sweep.bounding,
                s0, s0 + n, S, cells, cstart, blocks, bstart, cap, self.out, self.arg)
        self.sweep, self.s0, self.cap, self.S = sweep, s0, cap, S

    def until(self, tau: float) -> float:
        """Separation bound over every state from the start to path parameter ``tau``."""
        s = self.sweep.index_at(tau)
        if self.sweep.tau[s] < tau - 1e-12:
            s += 1
        k = min(max(s - self.s0, 0), self.out.size - 1)
        v = float(self.out[k])
        return float("inf") if v >= self.cap else v - self.sweep.spacing / 2

    def closest(self) -> np.ndarray | None:
        a = int(self.arg[-1])
        return None if a < 0 else self.S[a].copy()


def first_safe(count: int, safe: Callable[[int], bool]) -> int:
    """The first index in ``range(count)`` (speed scales, fastest first) that ``safe``
    passes, found with few tests, or ``count`` when none is found: index 0 first (the
    common answer), then bisection below it.

    Only an index whose own test passed is returned, so where safety is not monotone in
    the scale the answer can only be more cautious than the first safe one, never unsafe;
    testing full speed first keeps such a case from slowing a motion whose full speed
    keeps the protective distance."""
    if count == 0 or safe(0):
        return 0
    lo, hi = 1, count  # unknown: [lo, hi); hi is safe (tested) or count
    while lo < hi:
        mid = (lo + hi) // 2
        if safe(mid):
            hi = mid
        else:
            lo = mid + 1
    return lo


def assess(path: MonitoredPath, sweep: PathSweep, elements: tuple[np.ndarray, ...],
           age: float, tau_c: float, tau_l: float, r_l: float,
           options: MonitorOptions, *, approach_speed: float | None = None) -> Assessment:
    """Test the speed scales for one decision (see the module doc).

    Args:
        path: The path being followed.
        sweep: Its sampled robot spheres.
        elements: Observed elements bucketed by :func:`_kernels.bucket`.
        age: Age of the oldest observation used [s].
        tau_c: Path parameter now [s].
        tau_l: Raw path parameter where a new profile would start (half the path's
            averaging width after ``now + T_cmd``) [s].
        r_l: Raw speed there, in [0, 1].
        options: Monitor options.
        approach_speed: ``v_h`` of these elements [m/s] (default
            ``options.approach_speed``; parked bodies have their own).
    """
    o = options
    v_h = o.approach_speed if approach_speed is None else float(approach_speed)
    grid = path.grid(tau_l)
    tau, _, qd, qdd = grid
    K = _kernels()  # noqa: N806
    n = tau.size
    bx, bu, bt = np.empty(n), np.empty(n), np.empty(n)

    def end_of(scale: float, brake_after: float) -> tuple[float, float, float]:
        """(where at rest, time to rest from start, when braking began) of a profile."""
        m, b, _ = K.march(tau, qd, qdd, path.amax, r_l * r_l, scale * scale, brake_after,
                          bx, bu, bt)
        tb = float(bt[b]) if b >= 0 else float(bt[m - 1])
        # The robot follows the raw profile averaged over the path's width: it starts
        # half a width after the command and comes to rest half a width after it.
        return float(tau[m - 1]), float(bt[m - 1]) + path.width, tb

    # The farthest any tested profile reaches: full speed, then braking.
    far, _, _ = end_of(1.0, o.stale_after + BRAKE_HOLDS[-1])
    s0 = sweep.index_at(tau_c)
    horizon = min(tau_c + o.horizon, path.end)
    s1 = sweep.index_at(max(far, horizon)) + 2
    prefix = _Prefix(sweep, s0, min(s1, sweep.tau.size), elements, o.range_cap)
    # Bodies that cannot move (v_h = 0) cannot close the distance: a path that never
    # comes closer to them than the robot is now is safe even inside C + Z_d + Z_r
    # (the robot may back away from a body it stopped next to).
    floor = prefix.until(tau_c) if v_h == 0.0 else np.inf

    def margin(scale: float, brake_after: float) -> tuple[float, float]:
        # A stop may hold the speed for up to BRAKE_HOLDS[-1] before braking.
        where, t_rest, _ = end_of(scale, brake_after + BRAKE_HOLDS[-1])
        needed = v_h * (age + o.command_latency + t_rest) + o.constant_terms
        return prefix.until(where), min(needed, floor)

    # Largest safe scale on the grid of multiples of scale_step (:func:`first_safe`).
    steps = np.arange(np.floor(1.0 / o.scale_step + 1e-9), 0, -1) * o.scale_step
    scales = [float(min(s, 1.0)) for s in steps if s >= o.min_scale - 1e-12]
    tested: dict[int, tuple[float, float]] = {}

    def safe(i: int) -> bool:
        tested[i] = margin(scales[i], o.stale_after)
        return tested[i][0] >= tested[i][1]

    lo = first_safe(len(scales), safe)
    chosen = scales[lo] if lo < len(scales) else 0.0
    if chosen > 0:
        kept, needed = tested[lo]
    where0, t_stop, _ = end_of(r_l, BRAKE_HOLDS[-1])
    if chosen == 0.0:
        kept, needed = prefix.until(where0), min(
            v_h * (age + o.command_latency + t_stop) + o.constant_terms, floor)
    travel = sweep.travel_between(tau_l, where0)
    return Assessment(chosen, prefix.until(tau_c), prefix.until(horizon), kept, needed,
                      t_stop, travel, prefix.closest())
