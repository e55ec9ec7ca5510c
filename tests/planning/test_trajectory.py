"""The Trajectory value: exact JSON round trip, CSV, sampling, resampling, bad input."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
from pathlib import Path

import numpy as np
import pytest

import safepath
from safepath import GripperEvent, MotionLimits, Trajectory, TrajectoryError, load_trajectory

from .conftest import Plans

NAMES = ("a", "b")


def _small() -> Trajectory:
    t = np.array([0.0, 0.5, 1.0])
    q = np.array([[0.0, 1.0], [0.25, 0.5], [0.5, 0.0]])
    qd = np.array([[0.0, 0.0], [0.5, -1.0], [0.0, 0.0]])
    qdd = np.array([[1.0, -2.0], [0.0, 0.0], [-1.0, 2.0]])
    return Trajectory(NAMES, t, q, qd, qdd, np.array([0, 0, 1]), ("0 move x", "1 move y"),
                      (GripperEvent(1.0, "open", "2 open", "vial"),), "toy", "r", {"k": 1})


def _assert_same(a: Trajectory, b: Trajectory) -> None:
    for name in ("t", "q", "qd", "qdd", "step_index"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.joint_names, a.steps, a.events, a.robot, a.route) == \
        (b.joint_names, b.steps, b.events, b.robot, b.route)
    assert a.info == b.info
    assert a.limits == b.limits


def test_json_round_trip_is_exact(bundled: Plans, tmp_path: Path) -> None:
    traj = bundled.trajectories["phase2_safe"]
    path = tmp_path / "phase2_safe.json"
    text = traj.to_json(path)
    loaded = load_trajectory(path)
    _assert_same(traj, loaded)
    assert loaded.to_json() == text
    assert json.loads(path.read_text())["format"] == "safepath.trajectory/1"
    assert loaded.limits is not None and loaded.limits == traj.limits


def test_a_planned_trajectory_carries_its_robots_limits_read_only(bundled: Plans) -> None:
    """Issue 37: the limits a trajectory was timed under are one typed record on it (not
    an ``info`` dictionary), equal to its robot's, and nobody can change them in place."""
    traj = bundled.trajectories["phase1"]
    robot = safepath.load_robot("ned3pro")
    assert isinstance(traj.limits, MotionLimits) and traj.limits == robot.motion_limits
    assert "limits" not in traj.info
    with pytest.raises(ValueError):
        traj.limits.jerk[0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        traj.limits.velocity = traj.limits.velocity * 2  # type: ignore[misc]


def test_a_file_written_with_the_limits_in_info_loads_them(tmp_path: Path) -> None:
    """Trajectory files whose limits sat in ``info["limits"]`` load them as the record."""
    limits = MotionLimits([1.0, 2.0], [3.0, 4.0], [50.0, 60.0])
    data = dataclasses.replace(_small(), limits=limits).to_dict()
    data["info"] = {**data["info"], "limits": data.pop("limits")}
    (tmp_path / "old.json").write_text(json.dumps(data))
    loaded = load_trajectory(tmp_path / "old.json")
    assert loaded.limits == limits and loaded.info == {"k": 1}


@pytest.mark.parametrize("bad, key", [
    ({"velocity": [1.0, 0.0], "acceleration": [1, 1], "jerk": [1, 1]}, "limits.velocity"),
    ({"velocity": [1.0, 1.0], "acceleration": [1, "x"], "jerk": [1, 1]},
     "limits.acceleration"),
    ({"velocity": [1.0, 1.0], "acceleration": [1, 1], "jerk": [1, float("nan")]},
     "limits.jerk"),
    ({"velocity": [1.0, 1.0], "acceleration": [1, 1]}, "limits"),
    ({"velocity": [1.0], "acceleration": [1, 1], "jerk": [1, 1]}, "limits.jerk"),
    ({"velocity": [1.0, 1.0, 1.0], "acceleration": [1, 1, 1], "jerk": [1, 1, 1]},
     "limits"),
])
def test_bad_limits_in_a_file_are_refused_naming_them(tmp_path: Path, bad: dict,
                                                       key: str) -> None:
    data = _small().to_dict()
    data["limits"] = bad
    (tmp_path / "bad.json").write_text(json.dumps(data))
    with pytest.raises(TrajectoryError) as info:
        load_trajectory(tmp_path / "bad.json")
    assert info.value.key == key and info.value.path == tmp_path / "bad.json"


def test_csv_header_and_rows(bundled: Plans, tmp_path: Path) -> None:
    traj = bundled.trajectories["phase1"]
    text = traj.to_csv(tmp_path / "phase1.csv")
    assert (tmp_path / "phase1.csv").read_text() == text
    rows = list(csv.reader(io.StringIO(text)))
    names = traj.joint_names
    assert rows[0] == (["t", "step"] + [f"q_{n}" for n in names] + [f"qd_{n}" for n in names]
                       + [f"qdd_{n}" for n in names])
    assert len(rows) == 1 + traj.t.size
    assert all(len(r) == 2 + 3 * traj.dof for r in rows[1:])
    assert float(rows[-1][0]) == traj.t[-1]
    np.testing.assert_array_equal([float(v) for v in rows[5][2:2 + traj.dof]], traj.q[4])
    assert {r[1] for r in rows[1:]} == {traj.steps[k] for k in set(traj.step_index.tolist())}
    resampled = list(csv.reader(io.StringIO(traj.to_csv(period=0.01))))
    assert len(resampled) == 1 + traj.resample(0.01).t.size


@pytest.mark.parametrize("steps", ["as planned", "quoted", "empty"])
def test_csv_is_what_the_csv_writer_writes_row_by_row(bundled: Plans, steps: str) -> None:
    """The rows are joined by hand (fast); they read as the csv writer's rows do, step
    names that need quoting included, and every number reads back as the same float
    (written as its shortest round-trip text, not necessarily ``repr``'s spelling)."""
    traj = bundled.trajectories["phase1"]
    if steps != "as planned":
        names = tuple(f'{s}, "{i}"\n' if steps == "quoted" else "" for i, s in
                      enumerate(traj.steps))
        traj = dataclasses.replace(traj, steps=names)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(traj.to_csv().splitlines()[0].split(","))
    for k in range(traj.t.size):
        writer.writerow([repr(float(traj.t[k])), traj.steps[traj.step_index[k]]]
                        + [repr(float(v)) for v in np.hstack([traj.q[k], traj.qd[k],
                                                              traj.qdd[k]])])
    ours = list(csv.reader(io.StringIO(traj.to_csv())))
    theirs = list(csv.reader(io.StringIO(buf.getvalue())))
    assert ours[0] == theirs[0] and len(ours) == len(theirs)
    assert [r[1] for r in ours] == [r[1] for r in theirs]
    numbers = [[float(v) for v in r[:1] + r[2:]] for r in ours[1:]]
    assert numbers == [[float(v) for v in r[:1] + r[2:]] for r in theirs[1:]]


def test_sample_at_knots_returns_knots(bundled: Plans) -> None:
    traj = bundled.trajectories["phase1"]
    idx = np.arange(0, traj.t.size, 7)
    q, qd, qdd = traj.sample(traj.t[idx])
    np.testing.assert_allclose(q, traj.q[idx], atol=1e-12)
    np.testing.assert_allclose(qd, traj.qd[idx], atol=1e-9)
    np.testing.assert_allclose(qdd, traj.qdd[idx], atol=1e-9)
    # Clamped to the ends outside the time range.
    q_out, qd_out, _ = traj.sample([-1.0, traj.duration + 1.0])
    np.testing.assert_array_equal(q_out[0], traj.q[0])
    np.testing.assert_allclose(q_out[1], traj.q[-1], atol=1e-12)
    assert not np.any(qd_out[0])


def test_sample_between_knots_is_smooth() -> None:
    traj = _small()
    q, qd, qdd = traj.sample([0.25, 0.75])
    # The quintic join of the knots (a controller's): positions between the knots.
    assert 0.0 < q[0, 0] < 0.25 and 0.25 < q[1, 0] < 0.5
    # Velocity and acceleration are the derivatives of position (central differences).
    h = 1e-5
    qp, vp, _ = traj.sample([0.3 + h])
    qm, vm, _ = traj.sample([0.3 - h])
    _, v, a = traj.sample([0.3])
    np.testing.assert_allclose((qp - qm) / (2 * h), v, atol=1e-6)
    np.testing.assert_allclose((vp - vm) / (2 * h), a, atol=1e-5)
    # Every knot's position, velocity and acceleration is matched from both sides.
    for side in (-1e-9, 1e-9):
        qs, vs, as_ = traj.sample([0.5 + side])
        np.testing.assert_allclose(qs[0], traj.q[1], atol=1e-7)
        np.testing.assert_allclose(vs[0], traj.qd[1], atol=1e-6)
        np.testing.assert_allclose(as_[0], traj.qdd[1], atol=1e-5)


def test_resample_keeps_the_ends(bundled: Plans) -> None:
    traj = bundled.trajectories["phase2_unsafe"]
    for period in (0.008, 0.0123, 1.0):
        out = traj.resample(period)
        assert out.t[0] == traj.t[0] and out.t[-1] == traj.t[-1]
        np.testing.assert_array_equal(out.q[0], traj.q[0])
        np.testing.assert_array_equal(out.q[-1], traj.q[-1])
        np.testing.assert_array_equal(out.qd[-1], traj.qd[-1])
        assert np.all(np.diff(out.t) <= period + 1e-12) and np.all(np.diff(out.t) > 0)
        assert out.duration == traj.duration
        assert out.steps == traj.steps and out.events == traj.events
        assert out.step_index[0] == traj.step_index[0]
        assert out.step_index[-1] == traj.step_index[-1]


def test_step_at(bundled: Plans) -> None:
    traj = bundled.trajectories["phase1"]
    assert traj.step_at(0.0) == traj.steps[traj.step_index[0]]
    assert traj.step_at(traj.duration) == traj.steps[traj.step_index[-1]]
    k = traj.t.size // 2
    assert traj.step_at(float(traj.t[k])) == traj.steps[traj.step_index[k]]


def test_duration_and_step_durations_of_a_toy() -> None:
    traj = _small()
    assert traj.duration == 1.0 and traj.dof == 2
    # Step 0 owns knots 0 and 1 and spans to knot 2 (the next step's first).
    assert traj.step_durations() == {"0 move x": 1.0, "1 move y": 0.0}


def _args(**changes: object) -> dict[str, object]:
    good = _small()
    kwargs: dict[str, object] = dict(joint_names=NAMES, t=good.t, q=good.q, qd=good.qd,
                                     qdd=good.qdd, step_index=good.step_index,
                                     steps=good.steps)
    kwargs.update(changes)
    return kwargs


@pytest.mark.parametrize(("changes", "key"), [
    ({"t": np.array([0.0, 0.5, 0.5])}, "t"),
    ({"t": np.array([0.0, 1.0, 0.5])}, "t"),
    ({"t": np.array([0.0, np.nan, 1.0])}, "t"),
    ({"t": np.array([])}, "t"),
    ({"q": np.array([[0.0, 1.0], [np.nan, 0.5], [0.5, 0.0]])}, "q"),
    ({"qd": np.array([[0.0, 1.0], [np.inf, 0.5], [0.5, 0.0]])}, "qd"),
    ({"q": np.zeros((3, 3))}, "q"),
    ({"qdd": np.zeros((2, 2))}, "qdd"),
    ({"step_index": np.array([0, 1])}, "step_index"),
    ({"step_index": np.array([0, 0, 2])}, "step_index"),
])
def test_bad_arrays_raise(changes: dict[str, object], key: str) -> None:
    with pytest.raises(TrajectoryError) as info:
        Trajectory(**_args(**changes))  # type: ignore[arg-type]
    assert info.value.key == key


@pytest.mark.parametrize("period", [0.0, -0.01, float("nan"), float("inf")])
def test_bad_period_raises(period: float) -> None:
    with pytest.raises(TrajectoryError, match="period"):
        _small().resample(period)


def test_bad_files_raise_naming_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.json"
    with pytest.raises(TrajectoryError) as info:
        load_trajectory(missing)
    assert info.value.path == missing
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(TrajectoryError) as info:
        load_trajectory(broken)
    assert info.value.path == broken
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"format": "something/1"}))
    with pytest.raises(TrajectoryError) as info:
        load_trajectory(other)
    assert info.value.key == "format"
    data = _small().to_dict()
    del data["qd"]
    partial = tmp_path / "partial.json"
    partial.write_text(json.dumps(data))
    with pytest.raises(TrajectoryError) as info:
        load_trajectory(partial)
    assert info.value.key == "qd" and info.value.path == partial
    data = _small().to_dict()
    data["t"] = [0.0, 0.2, 0.1]
    unordered = tmp_path / "unordered.json"
    unordered.write_text(json.dumps(data))
    with pytest.raises(TrajectoryError) as info:
        load_trajectory(unordered)
    assert info.value.key == "t" and info.value.path == unordered


def test_equal_copies_compare_equal(tmp_path: Path) -> None:
    a = _small()
    a.to_json(tmp_path / "a.json")
    assert load_trajectory(tmp_path / "a.json") == a
