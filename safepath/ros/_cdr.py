"""The bulk of a cycle's bag as CDR bytes, laid out with numpy.

A cycle's bag (:func:`safepath.ros.bag.write_bag`) is mostly rows of numbers: hundreds of
``/joint_states`` that differ only in their stamps and values (the same joint names, as
many positions and velocities, no efforts), and ``JointTrajectory`` messages of thousands
of points that all carry as many values. rosbags serialises them one value at a time;
here each layout is made once and the values filled in with numpy, by the CDR rules
rosbags serialises by: little endian after the 4-byte encapsulation header, each value
aligned to its size from the end of that header (a ``float64[]`` only when it has
values), a string as its length with the null byte, then its bytes and the null, each
point of a sequence aligned to its first field (4 bytes). ``tests/ros/test_bag.py``
compares the bytes with rosbags' own serialisation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import RosError

__all__ = ["check_seconds", "joint_states_cdr", "joint_trajectory_cdr"]

#: CDR, little endian (the encapsulation header).
_HEADER = b"\x00\x01\x00\x00"
_NS = 1_000_000_000


def check_seconds(ns: np.ndarray | int, what: str) -> None:
    """Refuse times [ns] whose seconds a ROS 2 Time or Duration (``int32 sec``, from 0
    here) cannot hold.

    Raises:
        RosError: Naming ``what`` and the times' range.
    """
    ns = np.asarray(ns, dtype=np.int64)
    if ns.size and not (ns.min() >= 0 and ns.max() // _NS <= np.iinfo(np.int32).max):
        raise RosError(f"{what} from {ns.min()} to {ns.max()} ns: their seconds must fit "
                       f"a ROS 2 Time or Duration (0 .. 2^31 - 1)")


def _layout(names: Sequence[str], count: int) -> tuple[bytearray, int, int]:
    """The bytes of one message with zero stamp and values, and where its positions and
    velocities start (in the bytes, the header included)."""
    out = bytearray()

    def align(size: int) -> None:
        out.extend(b"\x00" * (-len(out) % size))

    def u32(value: int) -> None:
        align(4)
        out.extend(int(value).to_bytes(4, "little"))

    def string(text: str) -> None:
        data = text.encode()
        u32(len(data) + 1)
        out.extend(data + b"\x00")

    u32(0)  # header.stamp.sec
    u32(0)  # header.stamp.nanosec
    string("")  # header.frame_id
    u32(len(names))
    for name in names:
        string(name)
    starts = []
    for _ in range(2):  # position, velocity
        u32(count)
        if count:
            align(8)
        starts.append(len(_HEADER) + len(out))
        out.extend(b"\x00" * (8 * count))
    u32(0)  # effort: none
    return bytearray(_HEADER) + out, starts[0], starts[1]


def joint_states_cdr(stamps_ns: np.ndarray, names: Sequence[str], position: np.ndarray,
                     velocity: np.ndarray) -> list[bytes]:
    """The CDR bytes of one ``JointState`` per row: stamped ``stamps_ns`` [ns since the
    epoch], an empty ``frame_id``, ``names``, the row's positions [rad] and velocities
    [rad/s] (each (rows, len(names))), no efforts.

    Raises:
        RosError: A stamp before the epoch or whose seconds do not fit the message's
            ``int32``.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    rows, count = len(stamps), len(names)
    check_seconds(stamps, "/joint_states stamps")
    template, at_position, at_velocity = _layout(names, count)
    buf = np.tile(np.frombuffer(bytes(template), dtype=np.uint8), (rows, 1))
    header = len(_HEADER)
    buf[:, header:header + 4] = (stamps // _NS).astype("<i4")[:, None].view(np.uint8)
    buf[:, header + 4:header + 8] = (stamps % _NS).astype("<u4")[:, None].view(np.uint8)
    for start, values in ((at_position, position), (at_velocity, velocity)):
        data = np.ascontiguousarray(values, dtype="<f8").reshape(rows, count)
        buf[:, start:start + 8 * count] = data.view(np.uint8)
    return [row.tobytes() for row in buf]


def _point_layout(parity: int, counts: Sequence[int]
                  ) -> tuple[list[tuple[int, int]], int, int]:
    """A ``JointTrajectoryPoint`` whose ``float64[]`` fields hold ``counts`` values, laid
    out from an offset ``parity`` (0 or 4) past 8-byte alignment: where each field's
    length and values start and where its ``time_from_start`` starts, from that offset,
    and its size [bytes]."""
    pos = parity
    fields = []
    for count in counts:
        pos += -pos % 4
        length = pos
        pos += 4
        if count:
            pos += -pos % 8
        fields.append((length - parity, pos - parity))
        pos += 8 * count
    pos += -pos % 4
    return fields, pos - parity, pos + 8 - parity


def _point_starts(first: int, rows: int, size: dict[int, int]) -> np.ndarray:
    """Where each of ``rows`` points starts [bytes after the header], the first at
    ``first``, a point starting ``p`` past 8-byte alignment being ``size[p]`` long."""
    i = np.arange(rows, dtype=np.int64)
    a = size[first % 8]
    second = first + a
    b = size[second % 8]
    if a % 8 == 0:  # every point starts as the first does
        return first + i * a
    if b % 8 == 0:  # the second and every later one start alike
        return np.where(i == 0, first, second + (i - 1) * b)
    return first + (i // 2) * (a + b) + (i % 2) * a  # they alternate


def joint_trajectory_cdr(prefix: bytes, fields: Sequence[np.ndarray],
                         time_ns: np.ndarray) -> bytes:
    """The CDR bytes of a ``JointTrajectory`` from those of the same message without
    points (``prefix``, rosbags', ending in the points' count 0) and its points: the rows
    of ``fields`` (positions, velocities, accelerations, effort: each (points, values),
    any of them with no values) and their ``time_from_start`` [ns].

    Raises:
        RosError: ``prefix`` does not end in an empty sequence, or a time does not fit a
            ROS 2 Duration.
    """
    times = np.asarray(time_ns, dtype=np.int64)
    rows = times.size
    header = len(_HEADER)
    if len(prefix) < header + 4 or prefix[-4:] != bytes(4) or len(prefix) % 4:
        raise RosError("the message without points must end in an empty sequence")
    check_seconds(times, "time_from_start")
    counts = [int(np.shape(f)[1]) for f in fields]
    layouts = {parity: _point_layout(parity, counts) for parity in (0, 4)}
    first = len(prefix) - header
    starts = _point_starts(first, rows, {p: layout[2] for p, layout in layouts.items()})
    end = int(starts[-1]) + layouts[int(starts[-1]) % 8][2] if rows else first
    buf = np.zeros(header + end, dtype=np.uint8)
    buf[:len(prefix)] = np.frombuffer(prefix, dtype=np.uint8)
    buf[len(prefix) - 4:len(prefix)] = np.array([rows], dtype="<u4").view(np.uint8)
    for parity, (values, duration, _) in layouts.items():
        mine = np.flatnonzero(starts % 8 == parity)
        if mine.size == 0:
            continue
        base = header + starts[mine]
        for (length, at), count, field in zip(values, counts, fields, strict=True):
            _put(buf, base + length, np.full(mine.size, count, dtype="<u4"))
            if count:
                _put(buf, base + at, np.ascontiguousarray(field, dtype="<f8")[mine])
        _put(buf, base + duration, (times[mine] // _NS).astype("<i4"))
        _put(buf, base + duration + 4, (times[mine] % _NS).astype("<u4"))
    return buf.tobytes()


def _put(buf: np.ndarray, at: np.ndarray, values: np.ndarray) -> None:
    """Write each row of ``values`` (its bytes) into ``buf`` from offset ``at[row]``."""
    data = np.ascontiguousarray(values).reshape(len(at), -1).view(np.uint8)
    buf[at[:, None] + np.arange(data.shape[1])] = data
