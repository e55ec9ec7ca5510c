"""The controller's interpolation: chosen by ``controller.yaml``, recorded on the
trajectory, and what the goals carry and are checked with."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

import safepath
from safepath.errors import ConfigError, ExecutedLimitError, TrajectoryError
from safepath.model.controller_spec import ControllerSpec
from safepath.model.execution import check_executed, executed_peaks, join
from safepath.model.interpolation import CUBIC, LINEAR, QUINTIC, interpolation_named
from safepath.model.limits import MotionLimits
from safepath.model.scene import Scene
from safepath.model.trajectory import Trajectory, load_trajectory
from safepath.ros.goals import joint_trajectory

ROBOTS = Path(__file__).resolve().parents[2] / "robots"


def _robot_saying(tmp_path: Path, interpolation: str) -> Path:
    """A copy of the Ned3 Pro's folder whose controller.yaml names ``interpolation``."""
    folder = tmp_path / "ned3pro"
    shutil.copytree(ROBOTS / "ned3pro", folder)
    yaml = folder / "controller.yaml"
    text = yaml.read_text()
    assert "interpolation: quintic" in text
    yaml.write_text(text.replace("interpolation: quintic", f"interpolation: {interpolation}"))
    return folder


def test_a_cubic_controller_gets_cubic_goals_checked_as_cubic_joins(tmp_path: Path) -> None:
    """A robot whose controller.yaml says cubic: its trajectories record cubic, their
    samples lie on the cubic join, goal points carry no accelerations (a controller
    joins points that carry them as quintics), and the cubic join of the released points
    stays within every limit."""
    robot = safepath.load_robot(_robot_saying(tmp_path, "cubic"))
    assert robot.controller.interpolation is CUBIC
    q0 = np.zeros(robot.dof)
    q1 = np.array([0.5, 0.3, -0.4, 0.5, -0.5, 0.5])
    traj = safepath.plan(robot, Scene("empty", robot.name, ()), q0, q1)
    assert traj.interpolation is CUBIC
    mid = (traj.t[:-1] + traj.t[1:]) / 2
    cubic = join(traj.t, traj.q, traj.qd, traj.qdd, mid, interpolation=CUBIC)[0]
    quintic = join(traj.t, traj.q, traj.qd, traj.qdd, mid, interpolation=QUINTIC)[0]
    assert not np.array_equal(cubic, quintic)
    assert np.array_equal(traj.sample(mid)[0], cubic)
    msg = joint_trajectory(traj, controller=robot.controller, backend="rosbags")
    assert all(len(p.accelerations) == 0 and len(p.velocities) == robot.dof
               for p in msg.points)
    t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                  for p in msg.points])
    q = np.array([list(p.positions) for p in msg.points])
    qd = np.array([list(p.velocities) for p in msg.points])
    peaks = executed_peaks(t, q, qd, np.zeros_like(q), interpolation=CUBIC)
    assert peaks.interpolation == "cubic"
    assert max(peaks.ratios(*robot.motion_limits.arrays())) <= 1.0


def _rest_to_rest(amax: float) -> Trajectory:
    """One joint from 0 to 1 rad in 1 s, at rest at both ends: its quintic join peaks at
    10 / sqrt(3) = 5.77 rad/s^2, its cubic join at 6 rad/s^2 (at the ends)."""
    limits = MotionLimits(np.array([10.0]), np.array([amax]), np.array([100.0]))
    zero = np.zeros((2, 1))
    return Trajectory(("j",), np.array([0.0, 1.0]), np.array([[0.0], [1.0]]), zero, zero,
                      np.zeros(2, dtype=int), limits=limits)


def test_the_release_check_joins_points_as_the_controller_does() -> None:
    """Points whose quintic join stays within the acceleration limit but whose cubic
    join does not: released to a quintic controller, refused (typed) for a cubic one."""
    traj = _rest_to_rest(5.9)
    quintic = ControllerSpec(joint_names=("j",), period=2.0,
                             follow_joint_trajectory_action="/c/follow_joint_trajectory")
    cubic = dataclasses.replace(quintic, interpolation=CUBIC)
    assert len(joint_trajectory(traj, controller=quintic, backend="rosbags").points) == 2
    with pytest.raises(ExecutedLimitError, match="cubic join .* acceleration limit"):
        joint_trajectory(traj, controller=cubic, backend="rosbags")
    t, q, z = traj.t, traj.q, traj.qd
    assert check_executed(t, q, z, z, velocity_limits=np.array([10.0]),
                          acceleration_limits=np.array([6.0]), jerk_limits=np.array([100.0]),
                          interpolation=CUBIC)[1] == pytest.approx(1.0)


@pytest.mark.parametrize("interpolation", [QUINTIC, CUBIC, LINEAR])
def test_the_interpolation_round_trips_through_the_file(tmp_path: Path,
                                                       interpolation: object) -> None:
    traj = Trajectory(("j",), np.array([0.0, 1.0]), np.array([[0.0], [1.0]]),
                      np.zeros((2, 1)), np.zeros((2, 1)), np.zeros(2, dtype=int),
                      interpolation=interpolation)  # type: ignore[arg-type]
    path = tmp_path / "t.json"
    traj.to_json(path)
    back = load_trajectory(path)
    assert back.interpolation is interpolation and back == traj


def test_a_file_without_an_interpolation_loads_as_quintic_and_a_bad_one_is_refused(
        tmp_path: Path) -> None:
    data = _rest_to_rest(6.0).to_dict()
    assert data.pop("interpolation") == "quintic"
    assert Trajectory.from_dict(data).interpolation is QUINTIC
    data["interpolation"] = "spline"
    with pytest.raises(TrajectoryError, match="spline") as info:
        Trajectory.from_dict(data, path=tmp_path / "t.json")
    assert info.value.key == "interpolation" and info.value.path == tmp_path / "t.json"


def test_an_unknown_interpolation_in_controller_yaml_names_file_and_key(
        tmp_path: Path) -> None:
    folder = _robot_saying(tmp_path, "spline")
    with pytest.raises(ConfigError, match="expected one of") as info:
        safepath.load_robot(folder)
    assert info.value.key == "interpolation"
    assert info.value.path == folder / "controller.yaml"
    assert interpolation_named("linear") is LINEAR


def _random_knots(seed: int, n: int, dof: int, limits: tuple[float, float, float]
                  ) -> tuple[np.ndarray, ...]:
    """``n`` random knots of ``dof`` joints 2-6 ms apart, a limits row per interval (of 3),
    and the 3 rows of speed, acceleration and jerk limits (scaled by ``limits``)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.002, 0.006, n))
    q, qd, qdd = (rng.normal(0.0, s, (n, dof)) for s in (0.1, 1.0, 20.0))
    rows = tuple(rng.uniform(0.5, 2.0, (3, dof)) * s for s in limits)
    return t, q, qd, qdd, rng.integers(0, 3, n - 1), rows


@pytest.mark.parametrize("interpolation", [QUINTIC, CUBIC, LINEAR])
def test_per_interval_ratios_are_the_peaks_over_each_intervals_limits(interpolation) -> None:
    """Timing's check (``Interpolation.ratios``: compiled in one pass for a quintic) gives,
    per interval, the peaks of :meth:`~Interpolation.peaks` over the limits of the row it
    names, bit for bit, and a NaN point stays NaN (never dropped as a small ratio)."""
    t, q, qd, qdd, row, (vmax, amax, jmax) = _random_knots(3, 40, 4, (1.0, 10.0, 1e3))
    got = interpolation.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax)
    peaks = interpolation.peaks(t, q, qd, qdd, 1000.0)
    for x, p, lim in zip(got, peaks, (vmax, amax, jmax), strict=True):
        assert np.array_equal(x, np.max(p / lim[row], axis=1))
    assert np.min(got[0]) > 0.0
    for field in (q, qd, qdd):
        field[7, 2] = np.nan
        bad = interpolation.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax)
        for x in bad:
            assert np.isnan(x[6]) and np.isnan(x[7]) and not np.isnan(x[[5, 8]]).any()
        field[7, 2] = 0.0


@pytest.mark.parametrize("interpolation", [QUINTIC, CUBIC, LINEAR])
def test_ratios_of_listed_intervals_are_those_of_the_whole_pass(interpolation) -> None:
    """``at`` lists the intervals to compute: their ratios are the whole pass's at those
    intervals, bit for bit, in the listed order (a NaN one too)."""
    t, q, qd, qdd, row, (vmax, amax, jmax) = _random_knots(5, 60, 4, (1.0, 10.0, 1e3))
    q[20, 1] = np.nan
    whole = interpolation.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax, exact_from=0.5)
    at = np.array([58, 0, 19, 20, 33, 33, 7])
    got = interpolation.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax, exact_from=0.5,
                               at=at)
    for x, y in zip(got, whole, strict=True):
        assert x.shape == at.shape
        assert np.array_equal(x, y[at], equal_nan=True)
    assert np.isnan(got[0][2]) and np.isnan(got[0][3]) and not np.isnan(got[0][4])
    for bad in ([59], [-1]):  # 60 points: intervals 0 .. 58
        with pytest.raises(ValueError, match="intervals 0 .. 58"):
            interpolation.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax,
                                 at=np.array(bad))


@pytest.mark.parametrize("seed", range(6))
def test_the_quintics_whole_pass_is_the_per_interval_pass_bit_for_bit(seed: int) -> None:
    """Every interval with ``exact_from`` runs the vectorised pass (bounds along the
    intervals a joint at a time, blocks of 128, the exact peaks only where a bound reaches
    the threshold): its ratios are the per-interval pass's (``at`` listing every interval)
    bit for bit, across block ends, with screened and exact ratios mixed, knots on a
    4 ms grid and not, non-finite points (NaN for their intervals) and several rows."""
    rng = np.random.default_rng(seed)
    for n in (2, 3, 128, 129, 130, 257, 300):
        dof = int(rng.integers(1, 9))
        t, q, qd, qdd, row, (vmax, amax, jmax) = _random_knots(
            int(rng.integers(1 << 30)), n, dof, (1.0, 10.0, 1e3))
        if seed % 2:
            t = np.arange(n) * 0.004 + 0.5  # equal intervals, as the timing's knots
        for field in (q, qd, qdd)[: seed % 4]:
            field[int(rng.integers(n)), int(rng.integers(dof))] = (np.nan, np.inf)[seed % 2]
        every = np.arange(n - 1)
        middle = float(np.nanmedian(QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax,
                                                   jmax)[0]))
        for exact_from in (1e-3, 0.999, middle, 1e3):
            whole = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax,
                                   exact_from=exact_from)
            one_by_one = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax,
                                        exact_from=exact_from, at=every)
            for x, y in zip(whole, one_by_one, strict=True):
                assert x.shape == (n - 1,)
                assert np.array_equal(x, y, equal_nan=True)
    # The mix happened: some ratios are bounds (screened), some exact.
    exact = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax)[0]
    screened = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax,
                              exact_from=middle)[0]
    finite = np.isfinite(exact)
    assert np.any(screened[finite] != exact[finite])
    assert np.any(screened[finite] == exact[finite])


def test_a_uniform_stretch_scales_the_quintic_join_exactly() -> None:
    """What the timing's release relies on to recompute only the ratios near a limit
    after stretching its knots in time (``stretch_knots``): the join's peak speed,
    acceleration and jerk ratios scale by ``1/k^2`` and ``1/k^3``, to 1e-9 of the largest,
    and the speed bound, scaled by ``1/k``, still bounds the stretched join's speed
    (sampled at 200 kHz; the bound itself samples a longer interval once more)."""
    rng = np.random.default_rng(17)
    n = 300
    t = np.arange(n) * 0.004
    q, qd, qdd = (np.cumsum(rng.normal(0.0, s, (n, 3)), axis=0) for s in (0.002, 0.05, 2.0))
    row = np.zeros(n - 1, dtype=np.int64)
    lim = [np.ones((1, 3)) * x for x in (1.0, 10.0, 1e3)]
    before = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, *lim)
    for k in (1.0004, 1.07, 1.3):
        t2, qd2, qdd2, k2 = safepath.timing.stretch_knots(t, qd, qdd, k)
        assert k2 >= k
        after = QUINTIC.ratios(t2, q, qd2, qdd2, 1000.0, row, *lim)
        for power, (x, y) in enumerate(zip(before[1:], after[1:], strict=True), start=2):
            np.testing.assert_allclose(y, x / k2 ** power, rtol=0, atol=1e-9 * x.max())
        dense = np.linspace(t2[0], t2[-1], int((t2[-1] - t2[0]) * 200_000))
        at = np.clip(np.searchsorted(t2, dense, side="right") - 1, 0, n - 2)
        v = QUINTIC.evaluate(t2, q, qd2, qdd2, at, (dense - t2[at])[:, None])[1]
        peak = np.zeros(n - 1)
        np.maximum.at(peak, at, np.max(np.abs(v), axis=1))
        assert np.all(before[0] / k2 >= peak * (1 - 1e-9))
        assert np.all(after[0] >= peak * (1 - 1e-9))


def test_ratios_below_the_exact_threshold_are_bounds_above_it_the_peaks() -> None:
    """With ``exact_from``, the quintic's pass skips the exact peaks where a cheap bound
    stays below the threshold: every ratio at or above it is still the peaks' own, bit for
    bit, and every other one lies between the join's true peak (sampled at 200 kHz) and
    the threshold; at least one is a bound (the screen ran)."""
    n = 400
    t, q, qd, qdd, row, (vmax, amax, jmax) = _random_knots(11, n, 5, (2.0, 30.0, 1e4))
    exact = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax)
    below = tuple(float(np.median(x)) for x in exact)
    dense = np.linspace(t[0], t[-1], int((t[-1] - t[0]) * 200_000))
    k = np.clip(np.searchsorted(t, dense, side="right") - 1, 0, n - 2)
    p, v, a, _ = QUINTIC.evaluate(t, q, qd, qdd, k, (dense - t[k])[:, None])
    true_peak = [np.zeros(n - 1), np.zeros(n - 1)]
    for field, peak, lim in ((v, true_peak[0], vmax), (a, true_peak[1], amax)):
        np.maximum.at(peak, k, np.max(np.abs(field) / lim[row[k]], axis=1))
    for which in range(2):  # speed, acceleration
        got = QUINTIC.ratios(t, q, qd, qdd, 1000.0, row, vmax, amax, jmax,
                             exact_from=below[which])[which]
        at = exact[which] >= below[which]
        assert np.array_equal(got[at], exact[which][at])
        assert np.all(got[~at] < below[which])
        assert np.all(got[~at] >= true_peak[which][~at] * (1 - 1e-9))
        assert np.any(got[~at] != exact[which][~at])
