"""The classes of the messages safepath writes, generated ahead of time and kept on disk
(safepath.ros._type_cache): defined as rosbags' whole store defines them, read back
instead of built in a new process, and never read when stale or damaged."""

from __future__ import annotations

import logging
import os
import pickle
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import Nodetype
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from safepath.errors import RosError
from safepath.model.trajectory import Trajectory
from safepath.ros import _type_cache, _written_types
from safepath.ros._writing_store import WritingStore
from safepath.ros.bag import ARM_GOAL_TOPIC, TRAJECTORY_TOPIC, write_bag
from safepath.ros.goals import (
    follow_joint_trajectory_goal,
    joint_trajectory,
    split_at_gripper_events,
)
from safepath.ros.messages import DEFINITIONS, WRITTEN_TYPES, typestore, written_typestore

from .test_messages import assert_same, phase1, phase2, populate

REPO = Path(__file__).resolve().parents[2]


def rosbags_store() -> Typestore:
    """rosbags' ROS 2 Humble store plus our definitions, parsed here as any reader would:
    classes of its own, nothing generated ahead of time."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in DEFINITIONS.items():
        alias = name.replace("/srv/", "/msg/")
        types[name] = get_types_from_msg(text, alias)[alias]
    store.register(types)
    return store


def _counting(text: str) -> tuple[Callable[[], str], list[int]]:
    made = [0]

    def make() -> str:
        made[0] += 1
        return text

    return make, made


@pytest.fixture()
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty cache folder of this test's own."""
    monkeypatch.setenv("SAFEPATH_CACHE", str(tmp_path))
    return tmp_path


def test_written_types_are_defined_as_rosbags_defines_them() -> None:
    reference = rosbags_store()
    written = written_typestore()
    assert set(WRITTEN_TYPES) <= set(written.fielddefs)
    for name, (_, fields) in written.fielddefs.items():
        assert written.fielddefs[name] == reference.fielddefs[name], name
        for _, desc in fields:  # every nested type is there too
            sub = desc[1][0] if desc[0] in (Nodetype.ARRAY, Nodetype.SEQUENCE) else desc
            if sub[0] == Nodetype.NAME:
                assert sub[1] in written.fielddefs, (name, sub[1])
        # One class per type, whichever store builds the message.
        assert typestore().types[name] is written.types[name]
        assert written.types[name].__module__ == "safepath.ros._written_types"


def test_bag_holds_rosbags_own_bytes_of_the_goals(tmp_path: Path) -> None:
    """Every trajectory and goal in a bag is, byte for byte, what rosbags' own store (not
    the classes kept ahead of time) serialises of the message the goal builders give, and
    every topic's definition is the one that store gives."""
    start = 1_700_000_000 * 10**9
    cycle = [phase1(), phase2("safe")]
    path = write_bag(tmp_path / "cycle", cycle, start_time_ns=start, goals=True)
    reference = rosbags_store()
    with Reader(path) as reader:
        for conn in reader.connections:
            assert conn.msgdef.data == reference.generate_msgdef(conn.msgtype, ros_version=2)[0]
            assert conn.digest == reference.hash_rihs01(conn.msgtype)
        raw: dict[str, list[tuple[int, bytes]]] = {}
        for conn, timestamp, data in reader.messages():
            raw.setdefault(conn.topic, []).append((timestamp, bytes(data)))
    motions = [p for traj in cycle for p in split_at_gripper_events(traj)
               if isinstance(p, Trajectory)]
    assert len(raw[TRAJECTORY_TOPIC]) == len(raw[ARM_GOAL_TOPIC]) == len(motions) == 5
    for (stamp, data), (_, goal), motion in zip(raw[TRAJECTORY_TOPIC], raw[ARM_GOAL_TOPIC],
                                               motions, strict=True):
        built = joint_trajectory(motion, stamp_ns=stamp, backend="rosbags")
        assert data == bytes(reference.serialize_cdr(built, built.__msgtype__))
        built = follow_joint_trajectory_goal(motion, backend="rosbags")
        assert goal == bytes(reference.serialize_cdr(built, built.__msgtype__))


def test_writing_store_serialises_as_rosbags_then_does_everything_else() -> None:
    """The store a bag is written with generates each type's serialiser only (no other
    code until one is called) and gives rosbags' bytes; then it reads, writes big-endian
    and converts to ROS 1 as any rosbags store does."""
    reference = rosbags_store()
    store = WritingStore(_written_types)
    rng = np.random.default_rng(7)
    messages = {name: populate(name, rng) for name in sorted(store.fielddefs)}
    for name, msg in messages.items():
        assert bytes(store.serialize_cdr(msg, name)) == \
            bytes(reference.serialize_cdr(msg, name)), name
        # Not generated yet: a stand-in of this library's, not rosbags' generated code.
        later = store.get_msgdef(name).deserialize_cdr_le
        assert later.__module__ == WritingStore.__module__, name
    for name, msg in messages.items():
        data = bytes(store.serialize_cdr(msg, name))
        assert_same(msg, store.deserialize_cdr(data, name), name)
        assert bytes(store.serialize_cdr(msg, name, little_endian=False)) == \
            bytes(reference.serialize_cdr(msg, name, little_endian=False)), name
        ros1 = store.serialize_ros1(msg, name)
        assert bytes(ros1) == bytes(reference.serialize_ros1(msg, name)), name
        assert bytes(store.cdr_to_ros1(data, name)) == \
            bytes(reference.cdr_to_ros1(data, name)), name
    assert store.get_msgdef(name).deserialize_cdr_le.__module__ != WritingStore.__module__


def test_source_is_made_once_then_read(cache: Path) -> None:
    make, made = _counting("FIELDDEFS = {}\n")
    text, origin = _type_cache.cached_source(make)
    path = _type_cache.entry_path(_type_cache.source_key())
    assert path is not None and path.parent == cache / _type_cache.FOLDER and path.is_file()
    assert (text, made[0]) == ("FIELDDEFS = {}\n", 1)
    assert _type_cache.cached_source(make) == (text, str(path))
    assert made[0] == 1  # read back, not made


@pytest.mark.parametrize("damage", ["flip", "cut", "empty", "other key", "no header"])
def test_damaged_entry_is_made_again(cache: Path, caplog: pytest.LogCaptureFixture,
                                     damage: str) -> None:
    make, made = _counting("FIELDDEFS = {'a/msg/B': ([], [])}\n")
    _type_cache.cached_source(make)
    path = _type_cache.entry_path(_type_cache.source_key())
    assert path is not None
    raw = path.read_bytes()
    head, _, body = raw.partition(b"\n")
    damaged = {"flip": raw[:-5] + b"C" + raw[-4:],  # 'a/msg/B' -> 'a/msg/C'
               "cut": raw[:-10], "empty": b"", "no header": body,
               # A whole entry, digest and all, but of another key.
               "other key": head.replace(_type_cache.source_key().encode(), b"0" * 64)
               + b"\n" + body}[damage]
    assert damaged != raw
    path.write_bytes(damaged)
    with caplog.at_level(logging.WARNING, logger="safepath.ros._type_cache"):
        text, _ = _type_cache.cached_source(make)
    assert text == "FIELDDEFS = {'a/msg/B': ([], [])}\n" and made[0] == 2
    assert any("made again" in r.getMessage() for r in caplog.records)
    assert path.read_bytes() == raw  # rewritten whole
    _type_cache.cached_source(make)
    assert made[0] == 2


def test_key_follows_what_the_source_is_made_from(tmp_path: Path) -> None:
    """Another definition (here one field renamed) is another key, so another entry: an
    entry made from the old definitions is never read for the new ones."""
    definitions = Path(_type_cache.__file__).with_name("_definitions.py")
    changed = tmp_path / definitions.name
    text = definitions.read_text()
    assert "float64 velocity      # [rad/s] or [m/s]" in text
    changed.write_text(text.replace("float64 velocity      # [rad/s] or [m/s]",
                                    "float64 speed         # [rad/s] or [m/s]", 1))
    keys = {_type_cache.source_key([definitions]), _type_cache.source_key([changed])}
    assert len(keys) == 2
    assert len({_type_cache.entry_path(k) for k in keys}) == 2
    assert _type_cache.source_key() == _type_cache.source_key(None)


def test_no_disk_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SAFEPATH_CACHE", "0")
    make, made = _counting("FIELDDEFS = {}\n")
    assert _type_cache.entry_path(_type_cache.source_key()) is None
    _type_cache.cached_source(make)
    _type_cache.cached_source(make)
    assert made[0] == 2


def test_a_type_defined_otherwise_is_refused_and_its_entry_removed(cache: Path) -> None:
    """Classes whose definitions differ from the whole store's are never used: the entry
    that gave them is removed (the next process makes it again)."""
    path = _type_cache.entry_path(_type_cache.source_key())
    assert path is not None
    _type_cache.cached_source(lambda: "FIELDDEFS = {}\n")
    assert path.is_file()
    other = get_typestore(Stores.EMPTY)
    other.register(get_types_from_msg("string text\n", "std_msgs/msg/String"))
    store = rosbags_store()
    with pytest.raises(RosError, match="std_msgs/msg/String"):
        _type_cache.use_written_classes(store, other)
    assert not path.exists()
    _type_cache.use_written_classes(store, written_typestore())  # the real ones fit
    assert store.types["std_msgs/msg/String"] is written_typestore().types["std_msgs/msg/String"]


_CHILD = textwrap.dedent("""
    import logging, pickle, sys
    from pathlib import Path
    from safepath.ros.bag import TRAJECTORY_TOPIC, read_bag, write_bag
    logging.basicConfig()
    trajs = pickle.loads(Path(sys.argv[1]).read_bytes())
    bag = write_bag(sys.argv[2], trajs, start_time_ns=1_700_000_000 * 10**9, goals=True)
    print(sorted(m for m in sys.modules if m.startswith("rosbags.typesys.stores.ros2")))
    Path(sys.argv[3]).write_bytes(pickle.dumps(read_bag(bag).on(TRAJECTORY_TOPIC)[0].msg))
""")


def _child(tmp_path: Path, name: str, trajs: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "SAFEPATH_CACHE": str(tmp_path / "cache"), "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-c", _CHILD, str(trajs), str(tmp_path / name / "cycle"),
                           str(tmp_path / f"{name}.pickle")], capture_output=True, text=True,
                          env=env, cwd=REPO, check=True, timeout=300)


def test_new_processes_write_the_same_bag_from_the_kept_classes(tmp_path: Path) -> None:
    """The first process makes the entry; the next one writes its bag without building
    rosbags' whole store (no ROS 2 distribution module imported), byte for byte the same;
    one after the entry is damaged warns, makes it again and writes the same bytes. A
    message pickled in one process reads back in another."""
    trajs = tmp_path / "trajs.pickle"
    trajs.write_bytes(pickle.dumps([phase1(), phase2("safe")]))
    first = _child(tmp_path, "first", trajs)
    assert "ros2_humble" in first.stdout  # made from the whole store
    second = _child(tmp_path, "second", trajs)
    assert second.stdout.strip() == "[]"
    entry = next((tmp_path / "cache" / _type_cache.FOLDER).iterdir())
    entry.write_bytes(entry.read_bytes().replace(b"float64", b"float32", 1))
    third = _child(tmp_path, "third", trajs)
    assert "made again" in third.stderr and "ros2_humble" in third.stdout
    bags = [(tmp_path / n / "cycle" / "cycle.mcap").read_bytes()
            for n in ("first", "second", "third")]
    assert bags[0] == bags[1] == bags[2]
    msg = pickle.loads((tmp_path / "first.pickle").read_bytes())
    assert type(msg) is written_typestore().types["trajectory_msgs/msg/JointTrajectory"]
    assert (tmp_path / "first.pickle").read_bytes() == (tmp_path / "third.pickle").read_bytes()
