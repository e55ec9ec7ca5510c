"""Property: a pose set written to ``poses.yaml`` reads back bit for bit.

Random pose sets of the Ned3 Pro (names from the pose-name alphabet, YAML's reserved
words among them; values anywhere in the limits, with 1e-12, -0.0, 0.0 and full-precision
values among them) go through :func:`safepath.save_poses` (into no file, and over a file
holding another set, which is updated in place) and :func:`safepath.dump_poses`, and
:func:`safepath.load_poses` gives back the same names in the same order and every value
with the same bits.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from safepath import Robot, dump_poses, load_poses, load_robot, save_poses

from .strategies import bounded

#: Values a joint may hold where its limits allow: tiny, signed zeros, many decimals.
SPECIAL = (1e-12, -1e-12, 0.0, -0.0, 5e-324, 0.1 + 0.2, 1 / 3, -2 / 3, 1.0000000000000002)
#: Names a few of which the YAML 1.1 reader takes for a boolean or null.
YAML_WORDS = ("on", "Off", "yes", "NO", "true", "null", "y", "n", "grip", "safe")
NAMES = st.one_of(st.sampled_from(YAML_WORDS),
                  st.from_regex(r"[A-Za-z_][A-Za-z0-9_\-]{0,11}", fullmatch=True))


@cache
def _robot() -> Robot:
    return load_robot("ned3pro")


def _joint(lo: float, hi: float) -> st.SearchStrategy[float]:
    special = [v for v in SPECIAL if lo <= v <= hi]
    return st.one_of(st.floats(lo, hi), st.sampled_from(special))


def _pose_sets(robot: Robot) -> st.SearchStrategy[dict[str, np.ndarray]]:
    pose = st.tuples(*[_joint(float(lo), float(hi)) for lo, hi in
                       zip(robot.lower, robot.upper, strict=True)])
    return st.dictionaries(NAMES, pose.map(np.array), min_size=1, max_size=6)


def _assert_same(read: dict[str, np.ndarray], poses: dict[str, np.ndarray]) -> None:
    """Same names in the same order, and every value with the same bits."""
    assert list(read) == list(poses)
    for name, q in poses.items():
        assert read[name].tobytes() == np.asarray(q, dtype=float).tobytes(), \
            f"{name}: {read[name].tolist()} read back for {q.tolist()}"


@bounded(80)
@given(poses=_pose_sets(_robot()))
def test_saved_and_dumped_poses_read_back_bit_for_bit(poses: dict[str, np.ndarray]) -> None:
    robot = _robot()
    with TemporaryDirectory() as tmp:
        saved, dumped = Path(tmp) / "saved.yaml", Path(tmp) / "dumped.yaml"
        save_poses(saved, poses, robot, backup=False)
        _assert_same(load_poses(saved, robot), poses)
        dumped.write_text(dump_poses(poses))
        _assert_same(load_poses(dumped, robot), poses)


@bounded(80)
@given(before=_pose_sets(_robot()), after=_pose_sets(_robot()))
def test_poses_saved_over_a_file_read_back_bit_for_bit(before: dict[str, np.ndarray],
                                                       after: dict[str, np.ndarray]) -> None:
    """Saved over a file of other poses: the file's names keep their place, new ones follow
    in the order given."""
    robot = _robot()
    with TemporaryDirectory() as tmp:
        path = Path(tmp) / "poses.yaml"
        save_poses(path, before, robot, backup=False)
        save_poses(path, after, robot, backup=False)
        order = [n for n in before if n in after] + [n for n in after if n not in before]
        _assert_same(load_poses(path, robot), {name: after[name] for name in order})
