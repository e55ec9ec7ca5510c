"""Time-optimal timing of a joint path with TOPP-RA, under the robot's limits, strictly.

The path (a polyline of joint waypoints) is interpolated by a cubic spline through
evenly spaced points; blended via points follow a blend with continuous curvature
(:mod:`._blend`; the caller re-checks the spline for collisions and falls back to
stopping at corners). A straight rest-to-rest move is timed in closed form: the
jerk-limited S-curve along the line (:mod:`._scurve`). Any other path: TOPP-RA (our numba
kernel in :mod:`._topp`) finds the fastest timing under joint velocity and acceleration
limits that vary along the path (each route step has its own speed scale and an optional
TCP speed limit), with a constant path acceleration between gridpoints, and two moving
averages limit its jerk (:mod:`._smooth`). The averages mix the profile's speeds over
their width: a step's TCP speed limit (with ``TimingOptions(limits_ahead=True)`` its speed
scale too) holds on TOPP-RA's grid from as far before and after the step as the averages
reach (``ahead`` of :func:`~safepath.timing.path_limits`), so that a slower step is not
entered at the faster one's speed.

TOPP-RA enforces the limits at its gridpoints (which follow the spline's pieces, see
:mod:`._path_limits`); the output knots between them may still exceed a limit a little.
Knots whose excess would take a time stretch of more than :data:`RETRY_ABOVE` get the
limits tightened around them (each window at least as wide as the run's before) and the
path is timed again (``retries`` runs in all); what is left is removed by stretching time
uniformly, which divides velocities by ``k`` and accelerations by ``k^2``. No released
knot exceeds a limit: the ratios of the released knots are checked, and a
:class:`~safepath.errors.TimingError` is raised rather than release one over 1.0. The
same holds for the TCP's speed where a step limits it: the knots' join (as the robot's
controller joins them: ``controller.yaml``'s interpolation, a quintic for points with
accelerations) is sampled at >= 1 kHz (forward kinematics with velocities) and stretched
in time until every sample is within its step's limit.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import TimingError
from ..model._knots import interval_index
from ..model.execution import CHECK_RATE
from ..model.robot import Robot
from . import _scurve, _smooth, _topp
from ._blend import blended_points, corner_pieces, resampled
from ._path_limits import PathLimits, PathSpline, jet, path_limits, tcp_limits
from ._release import (
    _NS,
    RETIME_ABOVE,
    Run,
    TimedPiece,
    interval_ratios,
    ns_grid,
    release,
    stretch_knots,
)
from ._spline import CubicPath
from ._tcp_check import TcpLimits

__all__ = ["TimingOptions", "TimedPiece", "PathSpline", "spline_path", "time_path",
           "stretch_knots",
           "rest_to_rest_time", "RETIME_ABOVE", "RETRY_ABOVE"]

log = logging.getLogger(__name__)

CornerBlend = Literal["gap", "g2"]
#: The ways a blended via point can be cut (:func:`spline_path`).
CORNER_BLENDS: tuple[str, ...] = ("gap", "g2")
#: Time stretch (relative, above 1) that a run's knots would need, above which the path
#: is timed again with the limits tightened where they exceeded one. Below it the stretch
#: is kept: on 150 seeded via-point paths of five arms, a second run won back at most
#: 1.1 % of the motion time after a first run's stretch of under 2 % (none at all on the
#: UR5), for the cost of a whole run.
RETRY_ABOVE = 2e-2
#: The fewest knots a run is sampled at across the total width of its two moving averages
#: (``TimingOptions.max_knot_spacing``): on 40 seeded via paths of five arms, knots 4
#: knot periods apart where the averages spanned 64 ms or more left the median motion time
#: within 0.2 % of knots one period apart (the Panda, whose averages span 16 ms, keeps one
#: period: sampled every three it lost 0.4 %), and 6 periods apart re-timed a third of the
#: UR5's and Gen3's paths.
KNOTS_ACROSS_AVERAGES = 4
#: Chord across a ``"gap"`` blend, relative to the way along the polyline it replaces,
#: below which the corner counts as a turn-back and is passed through, not cut.
_TURN_BACK = 1e-9


@dataclass(frozen=True, kw_only=True)
class TimingOptions:
    """Options of the time parameterisation.

    Attributes:
        speed_scale: Global fraction of the velocity and acceleration limits, in (0, 1].
        knot_period: Period of the knots [s] (longer by the final stretch, if any): a
            run's knots lie one or more of it apart (``max_knot_spacing``).
        spacing: Spacing of the spline's interpolation points along the path [rad].
        grid_step: Largest spacing of TOPP-RA's gridpoints along the path [rad] (each
            spline piece is cut evenly). The moving averages spread the profile over tens
            of milliseconds: on 30 seeded via paths each of five arms, 0.005 rad instead
            of 0.01 changed the median motion time by -0.15 to +0.1 % for 10-25 % more
            of the timing's work.
        retries: TOPP-RA runs (the first included) with locally tightened limits before
            the remaining excess is removed by stretching time.
        blend_radii: Blend radii tried at via points, largest first [rad]; 0 passes
            through the via pose exactly.
        jerk_scale: Fraction of the jerk limits, in (0, 1] (on top of ``speed_scale``
            and the steps' speeds, which scale every limit).
        jerk_window: The first moving average's width as a fraction of the one that
            spreads the profile's largest acceleration swing within the jerk limits, in
            (0, 1]: shorter is faster, the tightening and stretch then make up the rest.
        jerk_smoothing: Width of the second moving average, in knot periods (at least):
            the jerk then changes over several knots, which the quintic join follows.
        corner_blend: How blended via points are cut (:func:`spline_path`): ``"gap"``
            (the spline bridges the interpolation points left out) or ``"g2"`` (a blend
            with continuous curvature, closer to the corner; the default: its timing is
            nearer the jerk-free optimum, see ``benchmarks/timing_quality.py``).
        limits_ahead: Hold each route step's speed scale and TCP speed limit on TOPP-RA's
            grid as far around the step as the moving averages reach
            (:func:`~safepath.timing.path_limits` ``ahead``), so that a path whose steps
            have different limits is timed in one run instead of being re-timed where
            the averages carried a faster step's speed into a slower one. Off by default
            for now: with it the bundled cell's stops fall elsewhere, and the monitor's
            re-plan closed loop (``tests/monitor/test_parked.py``) re-planned fewer of
            its parked bodies (10 of 14 with a way, against 12 of 16).
        tcp_ahead: Hold each route step's TCP speed limit ahead in the same way (on by
            default; ``limits_ahead`` implies it). The TCP's speed of the released knots'
            executed motion is checked and stretched in time to within every step's
            limit either way; without it, a faster step's TCP speed carried into a slower
            one stretches the whole piece (3 % in the bundled pouring cell).
        max_duration: Longest timing of one piece of path [s]: TOPP-RA's profile of a
            path that it can only pass almost at rest somewhere (a blend too tight for its
            grid) comes out finite but absurdly long; it is refused (``TimingError``, so a
            planner tries a smaller blend) before its knots are made.
        max_knot_spacing: A run is timed, checked and released on knots up to this many
            knot periods apart, as many as its moving averages leave room for
            (:data:`KNOTS_ACROSS_AVERAGES` across their total width). Their join is the
            motion; a goal adds points of it where its controller wants them closer
            (a quintic matched at both ends of a part of a quintic is that part). 1:
            every run at the knot period.
    """

    speed_scale: float = 1.0
    knot_period: float = 0.004
    spacing: float = 0.06
    grid_step: float = 0.01
    retries: int = 3
    blend_radii: tuple[float, ...] = (0.6, 0.3, 0.1, 0.0)
    jerk_scale: float = 1.0
    jerk_window: float = 1.0
    jerk_smoothing: float = 3.0
    corner_blend: CornerBlend = "g2"
    limits_ahead: bool = False
    tcp_ahead: bool = True
    max_duration: float = 3600.0
    max_knot_spacing: int = 4

    def __post_init__(self) -> None:
        from ..errors import ConfigError

        if not 0 < self.speed_scale <= 1:
            raise ConfigError(f"speed_scale must lie in (0, 1], got {self.speed_scale}",
                              key="speed_scale")
        if not self.knot_period > 0:
            raise ConfigError(f"knot_period must be > 0, got {self.knot_period}",
                              key="knot_period")
        if not self.grid_step > 0:
            raise ConfigError(f"grid_step must be > 0, got {self.grid_step}", key="grid_step")
        if self.retries < 1:
            raise ConfigError(f"retries must be >= 1, got {self.retries}", key="retries")
        for key in ("jerk_scale", "jerk_window"):
            value = getattr(self, key)
            if not 0 < value <= 1:
                raise ConfigError(f"{key} must lie in (0, 1], got {value}", key=key)
        if self.corner_blend not in CORNER_BLENDS:
            raise ConfigError(f"corner_blend must be one of {CORNER_BLENDS}, got "
                              f"{self.corner_blend!r}", key="corner_blend")
        if not self.max_duration > 0:
            raise ConfigError(f"max_duration must be > 0 [s], got {self.max_duration}",
                              key="max_duration")
        if not (isinstance(self.max_knot_spacing, int) and self.max_knot_spacing >= 1):
            raise ConfigError(f"max_knot_spacing must be an integer >= 1 [knot periods], "
                              f"got {self.max_knot_spacing!r}", key="max_knot_spacing")
        if not self.jerk_smoothing >= 1:
            raise ConfigError(f"jerk_smoothing must be >= 1 [knot periods], got "
                              f"{self.jerk_smoothing}", key="jerk_smoothing")


def spline_path(waypoints: Sequence[np.ndarray], spacing: float, *,
                corners: Sequence[tuple[int, float]] = (),
                blend: CornerBlend = "gap") -> tuple[PathSpline, np.ndarray, np.ndarray]:
    """A cubic spline through a polyline resampled every ``spacing`` [rad].

    Args:
        waypoints: The polyline.
        spacing: Largest distance between interpolation points [rad].
        corners: Interior waypoints the spline may cut (via points), each with its
            blend radius [rad].
        blend: How a corner is cut. ``"gap"``: the interpolation points closer than the
            radius to the corner (and the corner itself) are left out, and the spline
            bridges the gap. ``"g2"``: the path leaves the polyline the radius before the
            corner and joins it again the radius after, along a blend whose curvature is
            continuous (:mod:`._blend`; a radius over half the way to the next corner is
            reduced to that).

    Returns:
        The spline (not-a-knot, :class:`~safepath.timing._spline.CubicPath`, scipy's
        ``CubicSpline`` without its import cost), the path parameter of each input
        waypoint (its closest point, or the blend's middle, for a cut corner), and the
        spline's interpolation parameters.
    """
    W = np.asarray(waypoints, dtype=float)
    cut = [(c, r) for c, r in corners if 0 < c < len(W) - 1 and r > 0]
    exact = corner_pieces(W, cut) if cut and blend == "g2" else None
    if exact is not None:
        breaks, coefficients, s_way = exact
        return CubicPath.from_pieces(breaks, coefficients), s_way, breaks
    if cut and blend == "g2":
        P, S, s_way = blended_points(W, cut, spacing)
        return CubicPath(S, P), s_way, S
    P, S, s_way = resampled(W, spacing)
    if cut:
        keep = _gap_kept(P, S, s_way, cut)
        P = P[keep]
        # Re-parametrise the kept points by chord length, and map the waypoints.
        chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        s_way = np.interp(s_way, S[keep], chord)
        S = chord
    if len(P) == 2:  # a straight line: a linear "spline"
        P = np.vstack([P[0], 0.5 * (P[0] + P[1]), P[1]])
        S = np.array([0.0, S[-1] / 2, S[-1]])
    path = CubicPath(S, P)
    return path, s_way, S


def _gap_kept(P: np.ndarray, S: np.ndarray, s_way: np.ndarray,  # noqa: N803
              cut: Sequence[tuple[int, float]]) -> np.ndarray:
    """Which interpolation points the ``"gap"`` blends keep: those farther than the radius
    from each cut corner. A corner where the path turns back exactly the way it came
    (its gap's two sides coincide, to :data:`_TURN_BACK` of the way between them, and the
    spline's chord-length parameter could not increase across it) is not cut: the path
    passes through it, at rest (its direction reverses there)."""
    keep = np.ones(len(S), dtype=bool)
    keep[0] = keep[-1] = True
    for c, r in cut:
        trial = keep & ~(np.abs(S - s_way[c]) < r)
        trial[0] = trial[-1] = True
        before = int(np.flatnonzero(trial & (S < s_way[c]))[-1])
        after = int(np.flatnonzero(trial & (S > s_way[c]))[0])
        if np.linalg.norm(P[after] - P[before]) <= _TURN_BACK * (S[after] - S[before]):
            continue
        keep = trial
    return keep


def time_path(robot: Robot, path: PathSpline, s_way: np.ndarray, *, scales: Sequence[float],
              tcp_speeds: Sequence[float | None], options: TimingOptions = TimingOptions(),
              step: str | None = None) -> TimedPiece:
    """Time a spline path rest to rest, jerk-limited, within the limits as executed.

    TOPP-RA's profile is smoothed by two moving averages (:mod:`._smooth`), sampled at
    knots up to ``options.max_knot_spacing`` knot periods apart (as far as the averages'
    width allows), and the join of the knots (as the robot's trajectory controller
    executes them, ``PathLimits.interpolation``) is checked against the joint speed,
    acceleration and jerk limits on every interval. Where it exceeds one, the limits
    along the part of the path that interval averaged are tightened and the path is timed
    again (``options.retries`` runs in all); what is left is removed by stretching time
    uniformly, which scales the join exactly (speeds by ``1/k``, accelerations by
    ``1/k^2``, jerks by ``1/k^3``). The released knots are those knots, stretched
    (:mod:`._release`): their join is the motion checked, and a goal adds points of it
    where its controller wants them closer (:func:`safepath.ros.joint_trajectory`).

    Args:
        robot: Limits and kinematics.
        path: Spline from :func:`spline_path`.
        s_way: Path parameter of the input waypoints (segment boundaries).
        scales: Speed scale of each input segment, in (0, 1].
        tcp_speeds: TCP speed limit of each input segment [m/s], or None.
        options: Timing options.
        step: Step name for errors.

    Raises:
        TimingError: TOPP-RA found no feasible timing, or the released knots' join would
            break a limit.
    """
    where = f" (step '{step}')" if step else ""
    limits = path_limits(robot, path, s_way, scales, tcp_speeds,
                         speed_scale=options.speed_scale, grid_step=options.grid_step,
                         jerk_scale=options.jerk_scale,
                         ahead=_widest_window(robot, options)
                         if options.limits_ahead or options.tcp_ahead else 0.0,
                         scales_ahead=options.limits_ahead)
    if len(s_way) == 2 and tcp_speeds[0] is None and _straight(path, limits):
        return release(_time_straight(path, limits, options, where), limits, where)
    f_acc = np.ones(limits.grid.size)
    f_x = np.ones(limits.grid.size)
    best: Run | None = None
    tau_a: float | None = None
    runs = 0
    for attempt in range(options.retries):
        runs += 1
        run = _time_once(path, limits, f_acc, f_x, options, tau_a, where)
        tau_a = run.smoothed.tau_a if run.smoothed is not None else None
        if best is not None and run.stretched >= best.stretched:
            break  # tightening did not pay: more of it will not either
        best = run
        if run.stretch <= 1.0 + RETRY_ABOVE or attempt + 1 == options.retries:
            break
        log.debug("timing attempt %d needs a time stretch of %.6f; tightening locally",
                  attempt, run.stretch)
        _tighten(f_acc, f_x, limits.grid, run)
    assert best is not None  # options.retries >= 1
    # The path's TCP rate is estimated only where a segment limits the TCP's speed.
    tcp = None if limits.tcp_rate is None else TcpLimits(
        robot, tcp_limits(tcp_speeds), max(1, int(np.ceil(options.knot_period * CHECK_RATE))),
        limits.grid, limits.tcp_rate)
    return dataclasses.replace(release(best, limits, where, tcp), runs=runs)


def _straight(path: PathSpline, limits: PathLimits) -> bool:
    """Whether the path is a straight line (no curvature at any gridpoint)."""
    curvature = float(np.abs(limits.at_grid.ddq).max())
    return curvature <= 1e-9 * max(1.0, float(path.x[-1]))


def _time_straight(path: PathSpline, limits: PathLimits, options: TimingOptions,
                   where: str) -> Run:
    """The time-optimal jerk-limited motion along a straight path in closed form
    (:mod:`._scurve`): the joint limits projected on the line, the phases whole knot
    periods, so that the knots' quintic join is the motion itself."""
    d = np.abs(limits.at_grid.dq[0])
    moving = d > 1e-12
    v, a, j = (float(np.min(lim[0][moving] / d[moving]))
               for lim in (limits.vmax_seg, limits.amax_seg, limits.jmax_seg))
    if not (v > 0 and a > 0 and j > 0):
        raise TimingError("no feasible timing: a limit of the moving joints is 0" + where)
    curve = _scurve.s_curve(float(path.x[-1]), v, a, j, options.knot_period)
    t, s, sd, sdd = _scurve.sample(curve)
    q, ps, pss = jet(path, s)
    qd = ps * sd[:, None]
    qdd = pss * (sd ** 2)[:, None] + ps * sdd[:, None]
    qd[0] = qd[-1] = 0.0  # at rest (not -0.0)
    qdd[0] = qdd[-1] = 0.0
    segment = np.zeros(t.size, dtype=np.int64)
    return Run(t, s, sd, q, qd, qdd, segment, interval_ratios(t, q, qd, qdd, segment, limits),
               None)


def _time_once(path: PathSpline, limits: PathLimits, f_acc: np.ndarray, f_x: np.ndarray,
               options: TimingOptions, tau_a: float | None, where: str) -> Run:
    """One TOPP-RA run with the acceleration limits scaled by ``f_acc`` and the squared
    speed bounds by ``f_x`` per gridpoint, smoothed, sampled at knots and checked.

    Its first average is as wide as its own profile's swings need (:func:`_jerk_window`),
    and at least ``tau_a`` [s] (the run before's, None for a first run); the profile is
    not measured when ``tau_a`` already spreads the largest swing the limits allow
    (:func:`_swing_window`): tightened limits may move the profile's swings, never widen
    them past that."""
    x = _topp.solve(limits.grid, limits.at_grid.xmax * f_x, *limits.rows, f_acc)
    if x is None:
        raise TimingError("TOPP-RA found no feasible timing" + where)
    profile = _topp.parametrize(limits.grid, x)
    if not (np.isfinite(profile.duration) and profile.duration > 0):
        raise TimingError(f"TOPP-RA gave a duration of {profile.duration} s" + where)
    if profile.duration > options.max_duration:
        slowest = int(np.argmax(np.diff(profile.t)))
        raise TimingError(f"TOPP-RA's timing takes {profile.duration:.4g} s, over "
                          f"max_duration {options.max_duration:g} s: the path is passed "
                          f"almost at rest at s = {limits.grid[slowest]:.4f} rad" + where)
    if tau_a is None or tau_a < _swing_window(limits.amax_seg / limits.jmax_seg, options):
        own = _jerk_window(profile, limits, options)
        tau_a = own if tau_a is None else max(tau_a, own)
    tau_b = _second_window(tau_a, options)
    sm = _smooth.smooth(profile, tau_a, tau_b)
    duration = sm.duration
    every = _spacing(tau_a + tau_b, limits, options)
    n = max(2, int(np.ceil(duration / (every * options.knot_period))) + 1)
    # Knots a whole number of nanoseconds apart: a goal carries its times in integer
    # nanoseconds, and the quintic join of knots 4 ms apart is sensitive to a 1 ns shift
    # (its jerk by ~0.2 %). The last knot may come a few ns after the motion's end (at
    # rest).
    t = ns_grid(n, int(np.ceil(duration / (n - 1) * _NS)))
    s, sd, _, q, qd, qdd = _smooth.along(sm, path, t)
    qd[0] = qd[-1] = 0.0  # at rest (not -0.0)
    qdd[0] = qdd[-1] = 0.0
    segment = interval_index(limits.s_way, s, limits.vmax_seg.shape[0])
    return Run(t, s, sd, q, qd, qdd, segment, interval_ratios(t, q, qd, qdd, segment, limits),
               sm)


def _spacing(width: float, limits: PathLimits, options: TimingOptions) -> int:
    """How many knot periods apart a run's knots lie: at least
    :data:`KNOTS_ACROSS_AVERAGES` knots across its moving averages' total ``width`` [s],
    at most ``options.max_knot_spacing`` periods; one where a step limits the TCP's speed
    (its check is tuned to knots one period apart) or the controller's join is not a
    quintic."""
    if limits.tcp_rate is not None or limits.interpolation.order != 5:
        return 1
    fit = int(np.floor(width / (KNOTS_ACROSS_AVERAGES * options.knot_period) + 1e-9))
    return max(1, min(options.max_knot_spacing, fit))


def _widest_window(robot: Robot, options: TimingOptions) -> float:
    """The total width of the two moving averages [s] on a profile whose joint
    accelerations swing between their limits (twice a limit over the jerk limit, for
    the joint where that takes longest; :func:`_jerk_window`)."""
    tau_a = _swing_window(robot.acceleration_limits / (options.jerk_scale * robot.jerk_limits),
                          options)
    return tau_a + _second_window(tau_a, options)


def _swing_window(ratio: np.ndarray, options: TimingOptions) -> float:
    """Width of the first moving average [s] that spreads a joint's acceleration swing
    between its limits within its jerk limit, for the joint where that takes longest
    (``ratio``: acceleration over jerk limits [s], any shape), times
    ``options.jerk_window``."""
    return max(2.0 * float(np.max(ratio)) * options.jerk_window, options.knot_period)


def _second_window(tau_a: float, options: TimingOptions) -> float:
    """Width of the second moving average [s] after a first of ``tau_a`` [s]."""
    return max(options.jerk_smoothing * options.knot_period, 0.15 * tau_a)


def _jerk_window(profile: _topp.Profile, limits: PathLimits, options: TimingOptions) -> float:
    """Width of the first moving average [s]: the shortest over which no joint's
    acceleration along TOPP-RA's profile changes by more than its jerk limit times the
    width (the average spreads every change over the width), times
    ``options.jerk_window``. The profile is sampled every two knot periods: on 40
    seeded via paths each of five arms (``benchmarks/timing_quality.py --seed 99101``),
    that left the median motion time within -0.5 to +0.1 % of sampling every period,
    re-timed fewer paths (Gen3 15 to 5 %, Ned3 Pro 62 to 48 %) and took up to 13 % less
    of the timing's work (median per robot; seeds 99101-99103, one median 1 % more);
    sampling twice per period changed the motion time by under 0.1 % for 5-12 % more
    work."""
    dt = 2.0 * options.knot_period
    samples = max(0, int(np.ceil(profile.duration / dt)))  # np.arange(0, duration, dt)
    # Along the profile; the path's tangent and curvature between gridpoints linear in s
    # (a cubic's are quadratic and linear; gridpoints lie <= grid_step apart). At rest
    # (zero acceleration) before and after: the first and last changes count.
    at = limits.at_grid
    f = np.empty((at.dq.shape[1], samples + 2))
    kernels = _topp.compiled_kernels()
    kernels["jerk_rows"](*(np.ascontiguousarray(x, dtype=np.float64) for x in (
        profile.t, profile.grid, profile.sd, profile.u)), float(dt),
        *(np.ascontiguousarray(x, dtype=np.float64) for x in (
            limits.s_way, limits.jmax_seg, limits.grid, at.dq, at.ddq)),
        np.empty(limits.jmax_seg.size), f)
    lo = kernels["jerk_shift"](f, float(dt))
    return max(lo * dt * options.jerk_window, options.knot_period)


def _tighten(f_acc: np.ndarray, f_x: np.ndarray, grid: np.ndarray, run: Run) -> None:
    """Tighten the limits (in place) along the part of the path each interval over a limit
    averaged: its window of the profile, ``tau_a + tau_b`` before it to its end. Each
    gridpoint takes the largest excess of the windows over it, once."""
    v, a, j = run.ratios
    sm = run.smoothed
    assert sm is not None  # only TOPP-RA's runs are tightened
    over = np.flatnonzero(run.ratios.max(axis=0) > 1.0)
    if over.size == 0:
        return
    width = sm.tau_a + sm.tau_b
    end = sm.profile.duration
    # (np.minimum/np.maximum: np.clip checks its arguments' types on every call.)
    ends = np.concatenate([run.t[over] - width, run.t[over + 1]])
    s_ends = _topp.evaluate(sm.profile, np.minimum(np.maximum(ends, 0.0), end))[0]
    s_lo, s_hi = s_ends[:over.size], s_ends[over.size:]
    g_lo = interval_index(grid, s_lo, grid.size)
    g_hi = np.minimum(np.maximum(np.searchsorted(grid, s_hi, side="left") + 1, 1), grid.size)
    pad = 1.0 + RETIME_ABOVE
    # Acceleration and jerk scale with the path acceleration; speed with sqrt(x), the
    # jerk's speed terms with x^(3/2).
    acc = 1.0 / (np.maximum(np.maximum(a[over], j[over]), 1.0) * pad)
    xs = np.minimum(1.0 / np.maximum(v[over], 1.0) ** 2,
                    1.0 / np.maximum(j[over], 1.0) ** (2.0 / 3.0)) / pad
    _topp.compiled_kernels()["tighten"](g_lo.astype(np.int64), g_hi.astype(np.int64), acc, xs,
                                        np.ones(grid.size), np.ones(grid.size), f_acc, f_x)


def rest_to_rest_time(delta: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> float:
    """Time-optimal rest-to-rest duration of a straight joint move [s] (trapezoid)."""
    d = np.abs(np.asarray(delta, dtype=float))
    moving = d > 1e-12
    if not np.any(moving):
        return 0.0
    # Along the line, path speed <= min v_i/d_i, path acceleration <= min a_i/d_i (s in [0,1]).
    v = float(np.min(vmax[moving] / d[moving]))
    a = float(np.min(amax[moving] / d[moving]))
    if v * v / a >= 1.0:  # triangle profile
        return 2.0 * np.sqrt(1.0 / a)
    return 1.0 / v + v / a
