"""Taught joint poses: ``poses.yaml`` in both layouts the Niryo cell uses.

Layouts read:

* nested, as the cell node loads it::

    poses:
      grip: [-0.0168, -0.0208, -0.8436, -0.0459, -0.6519, -0.0245]

* flat, as ``record_joint_pose.sh`` appends it (one ``name: [..]`` line per pose)::

    grip: [-0.0168,-0.0208,-0.8436,-0.0459,-0.6519,-0.0245]

A file may hold both (a nested file to which the recorder appended lines). A pose may
also be given as a TCP pose (position, orientation quaternion (x, y, z, w), optional
frame, and the ``ik_start:`` pose the inverse kinematics starts from, given before it), solved
when the file is read: see :mod:`safepath.cell.tcp_targets`. Saving updates the file in place
(round-trip YAML: comments, key order, layout and unchanged values kept; changed values
at full double precision), atomically, keeping its mode and the previous file as
``poses.yaml~``.
"""

from __future__ import annotations

import io
import logging
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import PoseError
from ..files._io import atomic_write_text, brief, check_names, parse_yaml, read_text
from ..model.robot import Robot
from ._plain_poses import read_plain
from .tcp_targets import is_cartesian, parse_cartesian, solve_target

__all__ = ["load_poses", "save_poses", "dump_poses", "POSE_NAME"]

log = logging.getLogger(__name__)

#: What a pose name may be: a letter or underscore, then letters, digits, ``_`` or ``-``.
POSE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


def load_poses(path: str | Path, robot: Robot, *, names: Sequence[str] | None = None
               ) -> dict[str, np.ndarray]:
    """Read and validate a poses file.

    Args:
        path: The YAML file.
        robot: Gives the joint count and limits every pose is checked against.
        names: If given, the pose names the file must hold: a missing one or an
            unknown extra one is an error.

    Returns:
        Pose name to joint vector [rad], in file order.

    Raises:
        PoseError: Malformed YAML, a pose with the wrong count, a non-finite value, a
            value outside the joint limits, a bad or unknown name; names file and key.
    """
    path = Path(path)
    text = read_text(path, error=PoseError)
    data = read_plain(text)  # the common layouts, fast; anything else: YAML
    if data is None:
        data = parse_yaml(text, path, error=PoseError)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise PoseError("expected a mapping of pose names to joint lists", path=path)
    raw = _entries(data, path)
    poses: dict[str, np.ndarray] = {}
    for name, (key, q) in raw.items():  # file order: a TCP pose's ik_start comes before it
        poses[name] = _tcp_pose(name, key, q, robot, path, poses) if is_cartesian(q) \
            else _pose(name, key, q, robot, path)
    if names is not None:
        known = list(names)
        for name, (key, _) in raw.items():
            check_names([name], known, path=path, key=key, what="pose name", error=PoseError)
        missing = [n for n in known if n not in poses]
        if missing:
            raise PoseError(f"missing pose(s): {', '.join(missing)}", path=path)
    return poses


def _entries(data: dict, path: Path) -> dict[str, tuple[str, object]]:
    """Pose name to (YAML key, raw value): top-level entries and those under ``poses:``."""
    raw: dict[str, tuple[str, object]] = {}
    for key, value in data.items():
        _check_text(key, path)
        if key == "poses" and isinstance(value, dict):
            for name, q in value.items():
                _check_text(name, path)
                _add(raw, str(name), f"poses.{name}", q, path)
        elif key == "poses" and value is None:
            continue
        else:
            if isinstance(value, dict) and not is_cartesian(value) and _like_poses(key):
                # A misspelt `poses:` (its mapping is no pose): name the key, not its content.
                check_names([key], ["poses"], path=path, key=str(key), what="top-level key",
                            error=PoseError)
            _add(raw, str(key), str(key), value, path)
    return raw


def _like_poses(key: object) -> bool:
    """Whether ``key`` is spelt close to ``poses`` (difflib loads only for such a key)."""
    import difflib

    return bool(difflib.get_close_matches(str(key), ["poses"]))


def _tcp_pose(name: str, key: str, spec: object, robot: Robot, path: Path,
              known: dict[str, np.ndarray]) -> np.ndarray:
    """A pose given as a TCP pose, solved by IK from the ``ik_start`` pose given before it."""
    assert isinstance(spec, dict)
    if not POSE_NAME.match(name):
        raise PoseError(f"'{name}' is not a valid pose name", path=path, key=key)
    if "seed" in spec:  # its former name ("seed" means a random seed only)
        raise PoseError("`seed:` is now `ik_start:` (the pose the inverse kinematics starts "
                        "from)", path=path, key=f"{key}.seed")
    target = parse_cartesian(spec, path=path, key=key, extra=frozenset({"ik_start"}))
    start = spec.get("ik_start")
    if not isinstance(start, str) or start not in known:
        raise PoseError("a TCP pose needs `ik_start:`, the name of a pose given before it in "
                        "this file", path=path, key=f"{key}.ik_start")
    return robot.as_joint_vector(solve_target(robot, target, known[start], path=path, key=key),
                                 name=key, path=path)


def _pose(name: str, key: str, q: object, robot: Robot, path: Path) -> np.ndarray:
    """One pose entry, validated: its name, a list of numbers, then the robot's checks."""
    if not POSE_NAME.match(name):
        raise PoseError(f"'{name}' is not a valid pose name", path=path, key=key)
    if not isinstance(q, list):
        raise PoseError(f"expected a list of {robot.dof} joint values, got {brief(q)}",
                        path=path, key=key)
    for i, v in enumerate(q):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise PoseError(f"value {i} is not a number: {brief(v)}", path=path, key=key)
    return robot.as_joint_vector(q, name=key, path=path)


def _check_text(name: object, path: Path) -> None:
    """Refuse a pose name YAML read as something other than text (``on``, ``no``,
    ``null``... unquoted are booleans or null): it would come back under another name."""
    if not isinstance(name, str):
        raise PoseError(f"the name read as {name!r} is not text: YAML reads on, off, yes, "
                        "no, true, false and null unquoted as booleans or null; quote it",
                        path=path, key=str(name))


def _name_text(name: str) -> str:
    """``name`` as a YAML key that reads back as that text: single-quoted when YAML 1.1
    (PyYAML, which reads the file) would read it bare as a boolean or null."""
    return name if yaml.safe_load(name) == name else f"'{name}'"


def _same_bits(a: float | np.ndarray, b: float | np.ndarray) -> bool:
    """Whether two values or joint vectors hold the same doubles bit for bit (-0.0 is not
    0.0)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return x.shape == y.shape and x.tobytes() == y.tobytes()


def _add(raw: dict[str, tuple[str, object]], name: str, key: str, q: object, path: Path) -> None:
    if name in raw:
        raise PoseError(f"pose '{name}' is defined twice", path=path, key=key)
    raw[name] = (key, q)


def dump_poses(poses: Mapping[str, Sequence[float] | np.ndarray]) -> str:
    """The nested YAML text of ``poses``, with every value at full double precision."""
    lines = ["poses:"]
    for name, q in poses.items():
        values = ", ".join(_float_text(v) for v in np.asarray(q, dtype=float))
        lines.append(f"  {_name_text(name)}: [{values}]")
    return "\n".join(lines) + "\n"


def save_poses(path: str | Path, poses: Mapping[str, Sequence[float] | np.ndarray],
               robot: Robot, *, backup: bool = True,
               before_replace: Callable[[Path], None] | None = None) -> None:
    """Validate ``poses`` and atomically write them to ``path``.

    An existing file that loads is updated in place: its comments, its key order, its
    layout (nested or flat) and the text of every value that does not change are kept
    (bit for bit: -0.0 is a change);
    a changed value is written at full double precision, a pose not in ``poses`` is
    removed, a new one is added under ``poses:``. A file that does not load, or no
    file, is written whole in the nested layout. The file keeps its mode (see
    :func:`safepath.files._io.atomic_write`); the previous file, if any, is kept as
    ``<path>~`` when ``backup`` is true. When validation or writing fails, the file on
    disk is left as it was.

    Args:
        path: The poses file.
        poses: Every pose the file is to hold [rad].
        robot: Gives the joint count and limits every pose is checked against.
        backup: Keep the previous file as ``<path>~``.
        before_replace: Called with the temporary file holding the new text, once it is
            on disk and before it replaces ``path`` (the review session's save log).

    Raises:
        PoseError: A pose is malformed or outside the limits, or the file cannot be
            written (nothing is written).
    """
    path = Path(path)
    checked = {}
    for name, q in poses.items():
        if not POSE_NAME.match(str(name)):
            raise PoseError(f"'{name}' is not a valid pose name", path=path, key=str(name))
        checked[str(name)] = robot.as_joint_vector(q, name=f"poses.{name}", path=path)
    text = _updated_text(path, checked, robot)
    atomic_write_text(path, dump_poses(checked) if text is None else text, backup=backup,
                      error=PoseError, before_replace=before_replace)


def _updated_text(path: Path, poses: dict[str, np.ndarray], robot: Robot) -> str | None:
    """The text of ``path`` with ``poses`` written into it (round-trip YAML), or None when
    there is no poses file to keep (missing, or it does not load)."""
    if not path.exists():
        return None
    try:
        current = load_poses(path, robot)
        text = read_text(path, error=PoseError)
    except PoseError as exc:
        log.warning("%s does not load (%s): it is replaced whole, the old file kept as "
                    "the backup", path, exc)
        return None
    from ruamel.yaml.comments import CommentedMap

    round_trip = _round_trip_yaml()
    data = round_trip.load(text)
    if not isinstance(data, CommentedMap):  # an empty file
        return None
    _merge(data, current, poses)
    out = io.StringIO()
    round_trip.dump(data, out)
    return out.getvalue()


def _merge(data: Any, current: dict[str, np.ndarray], poses: dict[str, np.ndarray]) -> None:
    """Make the round-trip document ``data`` (whose poses are ``current``) hold ``poses``,
    touching only what changes."""
    from ruamel.yaml.comments import CommentedMap
    from ruamel.yaml.scalarstring import SingleQuotedScalarString

    nested = data.get("poses") if isinstance(data.get("poses"), dict) else None

    def home(name: str) -> Any:
        return nested if nested is not None and name in nested else data

    for name in current:
        if name not in poses:
            del home(name)[name]
    for name, q in poses.items():
        if name not in current:
            if nested is None:
                data["poses"] = nested = CommentedMap()
            key = name if _name_text(name) == name else SingleQuotedScalarString(name)
            nested[key] = _flow_list(q)
        elif not _same_bits(current[name], q):
            node = home(name)[name]
            if isinstance(node, list) and len(node) == len(q):
                # Values that stay keep their text; what stays is what the file reads as
                # (current), bit for bit: ruamel's own reading of a value may differ from it
                # in the last bit, and -0.0 == 0.0.
                for i, v in enumerate(q):
                    if not _same_bits(current[name][i], v):
                        node[i] = float(v)
            else:  # a TCP pose edited in joint space
                home(name)[name] = _flow_list(q)


def _round_trip_yaml() -> Any:
    """A ruamel round-trip YAML that writes floats as PyYAML reads them back."""
    from ruamel.yaml import YAML
    from ruamel.yaml.representer import RoundTripRepresenter
    from ruamel.yaml.scalarfloat import ScalarFloat

    class Representer(RoundTripRepresenter):
        pass

    def exact(r: Any, v: float) -> Any:
        return r.represent_scalar("tag:yaml.org,2002:float", _float_text(v))

    def kept(r: Any, v: ScalarFloat) -> Any:
        # A value read from the file keeps its layout, unless ruamel's re-emitted text
        # would read back as another double (it drops a digit of some long mantissas).
        node = RoundTripRepresenter.represent_scalar_float(r, v)
        read = yaml.safe_load(node.value)
        return node if isinstance(read, float) and _same_bits(read, v) else exact(r, v)

    Representer.add_representer(float, exact)
    Representer.add_representer(ScalarFloat, kept)
    round_trip = YAML()
    round_trip.Representer = Representer
    round_trip.width = 1 << 16  # a pose stays on its line
    round_trip.preserve_quotes = True
    return round_trip


def _flow_list(q: np.ndarray) -> Any:
    from ruamel.yaml.comments import CommentedSeq

    seq = CommentedSeq(float(v) for v in q)
    seq.fa.set_flow_style()
    return seq


def _float_text(v: float) -> str:
    """``repr`` of ``v`` (the shortest text that reads back to the same double), with the
    mantissa's dot and the exponent's sign that YAML 1.1 (PyYAML) needs to read a float:
    ``1e-07`` would read back as a string."""
    text = repr(float(v))
    if "e" in text:
        mantissa, exponent = text.split("e")
        mantissa = mantissa if "." in mantissa else mantissa + ".0"
        exponent = exponent if exponent[0] in "+-" else "+" + exponent
        text = f"{mantissa}e{exponent}"
    return text
