"""Taught poses: both file layouts, every bad input as a typed error, atomic saving."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from safepath import (
    PoseError,
    Robot,
    SafepathError,
    dump_poses,
    load_cell,
    load_poses,
    save_poses,
)

GRIP = [-0.0168, -0.0208, -0.8436, -0.0459, -0.6519, -0.0245]
HIGH1 = [-0.0154, -0.0056, 0.0734, 0.0016, -1.5969, -0.0168]


def _flat(name: str, q: list[float]) -> str:
    """One line as record_joint_pose.sh appends it: ``name: [a,b,...]``, no spaces."""
    return f"{name}: [{','.join(repr(v) for v in q)}]\n"


def _write(tmp_path: Path, text: str, name: str = "poses.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------------------
# Layouts
# ------------------------------------------------------------------------------------------
def test_nested_layout(tmp_path: Path, robot: Robot) -> None:
    path = _write(tmp_path, f"# taught\nposes:\n  grip: {GRIP}\n  high1: {HIGH1}\n")
    poses = load_poses(path, robot)
    assert list(poses) == ["grip", "high1"]
    np.testing.assert_array_equal(poses["grip"], GRIP)
    np.testing.assert_array_equal(poses["high1"], HIGH1)
    assert poses["grip"].dtype == float and poses["grip"].shape == (6,)


def test_flat_layout_as_the_recorder_appends_it(tmp_path: Path, robot: Robot) -> None:
    text = _flat("grip", GRIP) + _flat("high1", HIGH1)
    assert "grip: [-0.0168,-0.0208," in text  # the recorder's format, no spaces
    poses = load_poses(_write(tmp_path, text), robot)
    assert list(poses) == ["grip", "high1"]
    np.testing.assert_array_equal(poses["grip"], GRIP)
    np.testing.assert_array_equal(poses["high1"], HIGH1)


def test_mixed_layout(tmp_path: Path, robot: Robot) -> None:
    text = f"poses:\n  grip: {GRIP}\n" + _flat("high1", HIGH1)
    poses = load_poses(_write(tmp_path, text), robot)
    assert list(poses) == ["grip", "high1"]
    np.testing.assert_array_equal(poses["high1"], HIGH1)


def test_numbers_written_with_an_exponent_and_no_dot_are_numbers(tmp_path: Path,
                                                                robot: Robot) -> None:
    """Python writes 0.00008 as ``8e-05``: YAML 1.2 reads that as a number, PyYAML (YAML
    1.1) as a string, and a pose a generator wrote with it was "not a number" (found on a
    fresh Panda problem set). A quoted one stays a string, refused."""
    q = [0.0, -8e-05, 0.0, 1e-3, 0.0, 0.0]
    text = "poses:\n  grip: [" + ", ".join(repr(v) for v in q) + "]\n"
    assert "-8e-05" in text
    poses = load_poses(_write(tmp_path, text), robot)
    np.testing.assert_array_equal(poses["grip"], q)
    with pytest.raises(PoseError, match="value 1 is not a number"):
        load_poses(_write(tmp_path, 'poses:\n  grip: [0.0, "8e-05", 0, 0, 0, 0]\n', "q.yaml"),
                   robot)


def test_empty_file_has_no_poses(tmp_path: Path, robot: Robot) -> None:
    assert load_poses(_write(tmp_path, "# nothing taught yet\n"), robot) == {}
    assert load_poses(_write(tmp_path, "poses:\n", "p2.yaml"), robot) == {}


def test_bundled_poses_in_both_layouts_agree(cell, robot: Robot, tmp_path: Path) -> None:
    flat = "".join(_flat(name, q.tolist()) for name, q in cell.poses.items())
    poses = load_poses(_write(tmp_path, flat), robot)
    assert list(poses) == ["grip", "high1", "high2", "low1", "safe", "unsafe"]
    for name, q in cell.poses.items():
        np.testing.assert_array_equal(poses[name], q)


def test_duplicate_across_layouts(tmp_path: Path, robot: Robot) -> None:
    path = _write(tmp_path, f"poses:\n  grip: {GRIP}\n" + _flat("grip", GRIP))
    with pytest.raises(PoseError, match="defined twice") as info:
        load_poses(path, robot)
    assert info.value.path == path and info.value.key == "grip"


@pytest.mark.parametrize("layout", ["flat", "nested"])
def test_duplicate_within_one_layout(tmp_path: Path, robot: Robot, layout: str) -> None:
    again = [*GRIP[:-1], 0.0]
    if layout == "flat":
        text = _flat("grip", GRIP) + _flat("grip", again)
    else:
        text = f"poses:\n  grip: {GRIP}\n  grip: {again}\n"
    with pytest.raises(PoseError, match="grip"):
        load_poses(_write(tmp_path, text), robot)


# ------------------------------------------------------------------------------------------
# Bad input: typed errors naming the file and the key
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "key", "match"),
    [
        (f"poses:\n  grip: {GRIP[:5]}\n", "poses.grip", "expected 6 joint values, got 5"),
        (_flat("grip", GRIP[:5]), "grip", "expected 6 joint values, got 5"),
        ("poses:\n  grip: [0.0, 0.0, .nan, 0.0, 0.0, 0.0]\n", "poses.grip",
         "joint_3 is not finite"),
        ("grip: [0.0, .inf, 0.0, 0.0, 0.0, 0.0]\n", "grip", "joint_2 is not finite"),
        ("poses:\n  grip: [0.0, 0.0, 0.0, 0.0, 0.0, 3.5]\n", "poses.grip",
         r"joint_6 = 3\.50000 rad is outside its limits"),
        ("poses:\n  grip: [1.0e+308, 0.0, 0.0, 0.0, 0.0, 0.0]\n", "poses.grip",
         r"joint_1 = 1e\+308 rad is outside its limits \[-2\.96000"),  # not 309 digits
        ('poses:\n  grip: [0.0, "0.5", 0.0, 0.0, 0.0, 0.0]\n', "poses.grip",
         "value 1 is not a number"),
        ("poses:\n  grip: [0.0, 0.0, 0.0, 0.0, zero, 0.0]\n", "poses.grip",
         "value 4 is not a number"),
        ("poses:\n  grip: [0.0, 0.0, 0.0, 0.0, true, 0.0]\n", "poses.grip",
         "value 4 is not a number"),
        ("poses:\n  grip: 0.5\n", "poses.grip", "expected a list of 6 joint values"),
        ("poses:\n  1grip: [0, 0, 0, 0, 0, 0]\n", "poses.1grip", "not a valid pose name"),
    ],
)
def test_bad_pose(tmp_path: Path, robot: Robot, text: str, key: str, match: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(PoseError, match=match) as info:
        load_poses(path, robot)
    assert info.value.path == path
    assert info.value.key == key
    assert str(path) in str(info.value) and f"'{key}'" in str(info.value)


@pytest.mark.parametrize("text", ["poses:\n  grip: [0.0, 0.0\n", "grip: [1, 2]]\n",
                                  "poses: {grip: [0, 0, 0, 0, 0, 0]\n", "\tgrip: [0]\n"])
def test_malformed_yaml(tmp_path: Path, robot: Robot, text: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(PoseError, match="malformed YAML") as info:
        load_poses(path, robot)
    assert info.value.path == path and str(path) in str(info.value)
    assert "\n" not in str(info.value)  # one line for the command line


# The plain lines a file of many poses is made of are read without PyYAML's nodes
# (cell/_plain_poses.py); what they give must be what YAML gives, bit for bit and type
# for type, and anything the fast reader does not read exactly must go to YAML.
PLAIN_OR_NOT = [
    ("poses:\n  a: [1.0, -0.0, 0, -0, 12, -1.5e-07]\n  b-2: [0.5,0.25]\n", True),
    ("poses:\n  a: [1.0]\nb: [2.0]\nposes_2: [ 1.0 , 2 ]", True),
    ("a: [1.0e+400, -1.5e-3]\nposes: [1.0]\n", True),
    ("a: [1e-05]\n", False),  # YAML 1.1: a string (no point), not a number
    ("a: [1.0e5]\n", False),  # a string too (an exponent needs its sign)
    ("a: [01, 0x1f]\n", False),  # octal and hex integers
    ("a: [1_000.0]\n", False),
    ("On: [1.0]\n", False), ("null: [1.0]\n", False), ("NO: [1.0]\n", False),
    ("poses:\n  a: [1.0]\nb: [2.0]\n  c: [1.0]\n", False),  # malformed
    ("a: [1.0]\na: [2.0]\n", False), ("poses:\n  a: [1.0]\nposes: [1.0]\n", False),
    ("a: [1.0] # note\n", False), ("a: [1.0]\n\nb: [2.0]\n", False), ("a: []\n", False),
    ("a: [1.0, ]\n", False), ("a: [.5]\n", False), ("a: [+1.0]\n", False),
    ("a: [1.0]\r\n", False), ("poses:\n", False), ("", False), ("---\na: [1.0]\n", False),
]


@pytest.mark.parametrize(("text", "plain"), PLAIN_OR_NOT)
def test_plain_pose_lines_read_exactly_as_yaml(text: str, plain: bool) -> None:
    from safepath.cell._plain_poses import read_plain
    from safepath.files._io import parse_yaml

    got = read_plain(text)
    assert (got is not None) == plain
    if got is not None:
        expected = parse_yaml(text, Path("poses.yaml"))  # what the YAML path reads
        assert repr(got) == repr(expected)  # same types, -0.0 kept, same order


def test_a_dumped_file_of_many_poses_reads_as_yaml_reads_it(tmp_path: Path,
                                                           robot: Robot) -> None:
    """dump_poses' layout (full-precision floats, ``1.0e-05`` and ``-5.0e-324`` among
    them) read by load_poses equals the same file read by YAML, bit for bit."""
    import yaml

    from safepath.cell._plain_poses import read_plain

    rng = np.random.default_rng(7)
    poses = {f"p{i}": rng.uniform(robot.lower, robot.upper) for i in range(300)}
    poses["tiny"] = np.array([1e-05, -5e-324, 0.0, -0.0, 1.0, 2.5e-10])
    path = _write(tmp_path, dump_poses(poses))
    assert read_plain(path.read_text()) is not None
    by_yaml = yaml.safe_load(path.read_text())["poses"]
    loaded = load_poses(path, robot)
    assert list(loaded) == list(by_yaml)
    for name, q in loaded.items():
        assert q.tobytes() == np.array(by_yaml[name], dtype=float).tobytes()


def test_not_a_mapping(tmp_path: Path, robot: Robot) -> None:
    path = _write(tmp_path, "- [0, 0, 0, 0, 0, 0]\n")
    with pytest.raises(PoseError, match="expected a mapping"):
        load_poses(path, robot)


def test_missing_file(tmp_path: Path, robot: Robot) -> None:
    with pytest.raises(PoseError, match="file not found") as info:
        load_poses(tmp_path / "nope.yaml", robot)
    assert info.value.path == tmp_path / "nope.yaml"


def test_expected_names(tmp_path: Path, robot: Robot) -> None:
    path = _write(tmp_path, f"poses:\n  grip: {GRIP}\n  high1: {HIGH1}\n")
    assert list(load_poses(path, robot, names=["grip", "high1"])) == ["grip", "high1"]
    with pytest.raises(PoseError, match="unknown pose name 'high1'") as info:
        load_poses(path, robot, names=["grip"])
    assert info.value.key == "poses.high1" and info.value.path == path
    with pytest.raises(PoseError, match="missing pose.*low1"):
        load_poses(path, robot, names=["grip", "high1", "low1"])


def test_unknown_pose_of_a_cell(cell) -> None:
    np.testing.assert_array_equal(cell.pose("grip"), cell.poses["grip"])
    with pytest.raises(PoseError, match="unknown pose 'nope'") as info:
        cell.pose("nope")
    assert info.value.path == cell.poses_path and info.value.key == "nope"
    for name in cell.poses:
        assert name in str(info.value)


def test_cell_with_a_bad_pose_names_the_file(cell_copy: Path) -> None:
    path = cell_copy / "poses.yaml"
    with path.open("a") as handle:
        handle.write("crash: [0.0, 0.0, 0.0, 0.0]\n")
    with pytest.raises(PoseError, match="expected 6 joint values") as info:
        load_cell(cell_copy)
    assert info.value.path == path and info.value.key == "crash"


# ------------------------------------------------------------------------------------------
# Saving
# ------------------------------------------------------------------------------------------
def test_dump_and_save_round_trip_at_full_precision(tmp_path: Path, cell, robot: Robot) -> None:
    text = dump_poses(cell.poses)
    assert text.startswith("poses:\n")
    path = tmp_path / "poses.yaml"
    save_poses(path, cell.poses, robot)
    assert path.read_text() == text
    assert not (tmp_path / "poses.yaml~").exists()  # nothing to back up
    again = load_poses(path, robot)
    assert list(again) == list(cell.poses)
    for name, q in cell.poses.items():
        np.testing.assert_array_equal(again[name], q)  # bit-exact


def test_names_yaml_reads_as_booleans_or_null_round_trip_quoted(tmp_path: Path,
                                                                 robot: Robot) -> None:
    """(Found by tests/properties/test_poses_round_trip.py.) A pose named on, no or null
    is written quoted and reads back under its name; written bare by hand, it is an error
    naming it, not a pose renamed True."""
    path = tmp_path / "poses.yaml"
    poses = {"on": np.array(GRIP), "null": np.array(HIGH1)}
    save_poses(path, poses, robot)
    assert list(load_poses(path, robot)) == ["on", "null"]
    save_poses(path, {"null": np.array(GRIP), "no": np.array(HIGH1)}, robot)
    assert list(load_poses(path, robot)) == ["null", "no"]
    with pytest.raises(PoseError, match="quote it") as err:
        load_poses(_write(tmp_path, f"poses:\n  on: {GRIP}\n", "bare.yaml"), robot)
    assert err.value.key == "True"


def test_saving_over_a_file_keeps_every_bit(tmp_path: Path, robot: Robot) -> None:
    """(Found by tests/properties/test_poses_round_trip.py.) Saved over a file, a 0.0
    that becomes -0.0 is written, and a value that stays reads back as it was (ruamel's
    own text of some long values drops a digit)."""
    path = tmp_path / "poses.yaml"
    before = [0.0, 8.840633872400459e-189, 0.0, 0.0, 0.0, 0.0]
    save_poses(path, {"grip": before}, robot)
    after = [-0.0, 8.840633872400459e-189, 0.0, 0.0, 0.0, 1e-12]
    save_poses(path, {"grip": after, "high1": HIGH1}, robot)
    assert load_poses(path, robot)["grip"].tobytes() == np.array(after).tobytes()


def test_save_keeps_a_backup(tmp_path: Path, robot: Robot) -> None:
    path = _write(tmp_path, _flat("grip", GRIP))
    old = path.read_bytes()
    save_poses(path, {"grip": GRIP, "high1": HIGH1}, robot)
    assert (tmp_path / "poses.yaml~").read_bytes() == old
    assert list(load_poses(path, robot)) == ["grip", "high1"]
    save_poses(path, {"grip": GRIP}, robot, backup=False)
    assert (tmp_path / "poses.yaml~").read_bytes() == old  # untouched without backup
    assert _temp_files(tmp_path) == []


def _temp_files(folder: Path) -> list[Path]:
    return [p for p in folder.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize(
    ("poses", "match"),
    [
        ({"grip": GRIP, "crash": [0.0, 0.0, 0.0, 0.0, 0.0, 9.0]}, "joint_6"),
        ({"grip": GRIP[:5]}, "expected 6"),
        ({"grip": [np.nan] * 6}, "not finite"),
        ({"bad name": GRIP}, "not a valid pose name"),
    ],
)
def test_failed_save_leaves_the_file_untouched(tmp_path: Path, robot: Robot, poses: dict,
                                               match: str) -> None:
    path = _write(tmp_path, _flat("grip", GRIP))
    old = path.read_bytes()
    with pytest.raises(PoseError, match=match) as info:
        save_poses(path, poses, robot)
    assert info.value.path == path
    assert path.read_bytes() == old
    assert not (tmp_path / "poses.yaml~").exists()
    assert _temp_files(tmp_path) == []


def test_write_failure_leaves_the_file_intact(tmp_path: Path, robot: Robot,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    path = _write(tmp_path, _flat("grip", GRIP))
    old = path.read_bytes()

    def broken_replace(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises((OSError, SafepathError)):
        save_poses(path, {"grip": GRIP, "high1": HIGH1}, robot)
    monkeypatch.undo()
    assert path.read_bytes() == old
    assert _temp_files(tmp_path) == []
    np.testing.assert_array_equal(load_poses(path, robot)["grip"], GRIP)


def test_save_into_a_new_folder(tmp_path: Path, robot: Robot) -> None:
    path = tmp_path / "new" / "poses.yaml"
    save_poses(path, {"grip": GRIP}, robot)
    np.testing.assert_array_equal(load_poses(path, robot)["grip"], GRIP)
