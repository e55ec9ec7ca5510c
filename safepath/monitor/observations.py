"""What the monitor sees: laser scans, point clouds and obstacles from user code.

Every observation has a stamp [s] (the sensor's capture time, on the monitor's clock)
and a frame. Scans and clouds are in a sensor frame whose world pose the user gives
(:class:`~safepath.monitor.MonitorOptions` ``sensors``); obstacles are in the world.
They become *elements*: world spheres (x, y, z, radius) [m], a point being a sphere of
radius 0.

How odd values are handled (REP 117 for scans):

========================  ==========================================================
``nan`` range / point       an erroneous measurement: ignored, counted (``nan``)
``+inf`` range              nothing within range: ignored, counted (``no_return``)
``-inf`` range              something too close to measure: an element on the beam at
                            ``range_min`` (safety first), counted (``too_close``)
finite range < range_min    invalid reading: ignored, counted (``invalid``)
finite range > range_max    nothing within range: ignored, counted (``no_return``)
``inf`` point coordinate    ignored, counted (``invalid``)
empty scan or cloud         a valid observation that sees nothing
========================  ==========================================================

A message that cannot be read (missing fields, inconsistent sizes, a non-finite
angle or limit, a point layout without float x/y/z) raises
:class:`ObservationError` where it is converted, before the monitor changes anything.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["Scan", "Cloud", "Obstacles", "ObservationError", "Counts", "stamp_seconds"]


class ObservationError(InputError):
    """An observation that cannot be read; the monitor keeps its last decision."""


@dataclass(frozen=True)
class Counts:
    """What became of the readings of one observation.

    Attributes:
        used: Elements the monitor measures against.
        nan: NaN readings ignored.
        no_return: Readings that saw nothing within range.
        too_close: ``-inf`` ranges taken as an element at ``range_min``.
        invalid: Readings below ``range_min`` or with infinite coordinates, ignored.
        scene: Elements inside the static scene (within the scene filter), ignored.
        cropped: Elements outside the workspace, ignored.
        robot: Elements on the robot itself (``self_filter``), ignored (counted over
            every source of the decision).
    """

    used: int = 0
    nan: int = 0
    no_return: int = 0
    too_close: int = 0
    invalid: int = 0
    scene: int = 0
    cropped: int = 0
    robot: int = 0


def stamp_seconds(stamp: Any, *, key: str = "header.stamp") -> float:
    """``builtin_interfaces/Time`` (``sec``, ``nanosec``) or a number, as seconds."""
    if isinstance(stamp, (int, float, np.floating, np.integer)):
        value = float(stamp)
    else:
        try:
            value = float(stamp.sec) + 1e-9 * float(stamp.nanosec)
        except (AttributeError, TypeError, ValueError):
            raise ObservationError("not a time stamp (sec, nanosec)", key=key) from None
    if not np.isfinite(value):
        raise ObservationError(f"stamp must be finite, got {value}", key=key)
    return value


def _finite(value: Any, key: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ObservationError(f"expected a number, got {value!r}", key=key) from None
    if not np.isfinite(v):
        raise ObservationError(f"must be finite, got {v}", key=key)
    return v


def _header(msg: Any) -> tuple[float, str]:
    try:
        header = msg.header
        frame = header.frame_id
    except AttributeError:
        raise ObservationError("message without header.frame_id", key="header") from None
    if not isinstance(frame, str):
        raise ObservationError("frame_id must be a string", key="header.frame_id")
    return stamp_seconds(header.stamp), frame


@dataclass(frozen=True)
class Scan:
    """A planar laser scan (``sensor_msgs/LaserScan``) in its sensor's x-y plane.

    Attributes:
        stamp: Capture time [s].
        frame_id: Sensor frame (its world pose is given to the monitor).
        ranges: Ranges [m], beam ``i`` at ``angle_min + i * angle_increment`` from +x.
        angle_min: Angle of the first beam [rad].
        angle_increment: Angle between beams [rad].
        range_min: Smallest valid range [m].
        range_max: Largest valid range [m].
    """

    stamp: float
    frame_id: str
    ranges: np.ndarray = field(repr=False)
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp", stamp_seconds(self.stamp, key="stamp"))
        try:
            r = np.asarray(self.ranges, dtype=float)
        except (TypeError, ValueError):
            raise ObservationError("ranges must be numbers", key="ranges") from None
        if r.ndim != 1:
            raise ObservationError(f"ranges must be 1-D, got shape {r.shape}", key="ranges")
        object.__setattr__(self, "ranges", r)
        for name in ("angle_min", "angle_increment", "range_min", "range_max"):
            object.__setattr__(self, name, _finite(getattr(self, name), name))
        if r.size > 1 and self.angle_increment == 0.0:
            raise ObservationError("angle_increment is 0 with several beams",
                                   key="angle_increment")
        if not 0.0 <= self.range_min < self.range_max:
            raise ObservationError(f"need 0 <= range_min < range_max, got {self.range_min}"
                                   f", {self.range_max}", key="range_max")

    @classmethod
    def from_ros(cls, msg: Any) -> Scan:
        """From a ``sensor_msgs/msg/LaserScan`` (rosbags or rclpy).

        Raises:
            ObservationError: Missing fields, a non-finite angle or limit, or beams that
                do not span ``angle_min..angle_max``.
        """
        stamp, frame = _header(msg)
        try:
            fields = (msg.angle_min, msg.angle_max, msg.angle_increment, msg.range_min,
                      msg.range_max, msg.ranges)
        except AttributeError as exc:
            raise ObservationError(f"not a LaserScan ({exc})", key="LaserScan") from None
        a_min, a_max, inc, r_min, r_max, ranges = fields
        scan = cls(stamp, frame, np.asarray(ranges), a_min, inc, r_min, r_max)
        a_max = _finite(a_max, "angle_max")
        n = scan.ranges.size
        if n > 1:
            expected = scan.angle_min + (n - 1) * scan.angle_increment
            if abs(expected - a_max) > abs(scan.angle_increment) + 1e-6:
                raise ObservationError(
                    f"{n} beams from {scan.angle_min:.4f} by {scan.angle_increment:.6f} rad "
                    f"end at {expected:.4f}, not angle_max {a_max:.4f}", key="ranges")
        return scan

    def points(self) -> tuple[np.ndarray, Counts]:
        """Sensor-frame points (n, 3) [m] and what became of the beams."""
        r = self.ranges
        angles = self.angle_min + self.angle_increment * np.arange(r.size)
        nan = np.isnan(r)
        too_close = np.isneginf(r)
        finite = np.isfinite(r)
        ok = finite & (r >= self.range_min) & (r <= self.range_max)
        invalid = finite & (r < self.range_min)
        no_return = np.isposinf(r) | (finite & (r > self.range_max))
        use = ok | too_close
        rr = np.where(too_close, self.range_min, r)[use]
        a = angles[use]
        P = np.column_stack([rr * np.cos(a), rr * np.sin(a), np.zeros(rr.size)])
        return P, Counts(used=int(use.sum()), nan=int(nan.sum()),
                         no_return=int(no_return.sum()), too_close=int(too_close.sum()),
                         invalid=int(invalid.sum()))


_FLOAT_TYPES: dict[int, np.dtype[Any]] = {7: np.dtype("<f4"), 8: np.dtype("<f8")}
"""``sensor_msgs/PointField`` FLOAT32 and FLOAT64."""


@dataclass(frozen=True)
class Cloud:
    """A point cloud (``sensor_msgs/PointCloud2``'s x, y, z) in its sensor's frame.

    Attributes:
        stamp: Capture time [s].
        frame_id: Sensor frame.
        points: Points [m] (n, 3); NaN rows are ignored and counted.
    """

    stamp: float
    frame_id: str
    points: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp", stamp_seconds(self.stamp, key="stamp"))
        try:
            P = np.asarray(self.points, dtype=float)
        except (TypeError, ValueError):
            raise ObservationError("points must be numbers", key="points") from None
        if P.size == 0:
            P = P.reshape(0, 3)
        if P.ndim != 2 or P.shape[1] != 3:
            raise ObservationError(f"points must have shape (n, 3), got {P.shape}",
                                   key="points")
        object.__setattr__(self, "points", P)

    @classmethod
    def from_ros(cls, msg: Any) -> Cloud:
        """From a ``sensor_msgs/msg/PointCloud2`` with float32 or float64 x, y, z.

        Raises:
            ObservationError: Missing x/y/z fields, a layout that does not fit the
                data, or non-float coordinates.
        """
        stamp, frame = _header(msg)
        try:
            fields = {f.name: f for f in msg.fields}
            height, width = int(msg.height), int(msg.width)
            point_step, row_step = int(msg.point_step), int(msg.row_step)
            big = bool(msg.is_bigendian)
            data = np.asarray(msg.data, dtype=np.uint8).ravel()
        except (AttributeError, TypeError, ValueError) as exc:
            raise ObservationError(f"not a PointCloud2 ({exc})", key="PointCloud2") from None
        n = height * width
        if n == 0:
            return cls(stamp, frame, np.zeros((0, 3)))
        cols: list[tuple[int, np.dtype[Any]]] = []
        for name in ("x", "y", "z"):
            f = fields.get(name)
            if f is None:
                raise ObservationError(f"no '{name}' field (fields: {', '.join(fields)})",
                                       key="fields")
            dt = _FLOAT_TYPES.get(int(f.datatype))
            if dt is None or int(f.count) != 1:
                raise ObservationError(f"'{name}' must be one FLOAT32 or FLOAT64 "
                                       f"(datatype {f.datatype}, count {f.count})",
                                       key="fields")
            if int(f.offset) < 0 or int(f.offset) + dt.itemsize > point_step:
                raise ObservationError(f"'{name}' at offset {f.offset} does not fit a "
                                       f"{point_step}-byte point", key="point_step")
            cols.append((int(f.offset), dt.newbyteorder(">") if big else dt))
        if width * point_step > row_step or data.size != row_step * height:
            raise ObservationError(f"{data.size} bytes do not hold {height} rows of "
                                   f"{width} points ({point_step} B each, rows of "
                                   f"{row_step} B)", key="data")
        rows: np.ndarray = data.reshape(height, row_step)[:, :width * point_step]
        pts: np.ndarray = rows.reshape(n, point_step)
        P = np.empty((n, 3))
        for k, (offset, dt) in enumerate(cols):
            P[:, k] = pts[:, offset:offset + dt.itemsize].copy().view(dt).ravel()
        return cls(stamp, frame, P)

    def valid_points(self) -> tuple[np.ndarray, Counts]:
        """Finite points and what became of the others."""
        P = self.points
        if np.isfinite(P).all():  # the common case, one pass
            return P, Counts(used=len(P))
        nan = np.isnan(P).any(axis=1)
        finite = np.isfinite(P).all(axis=1)
        return P[finite], Counts(used=int(finite.sum()), nan=int(nan.sum()),
                                 invalid=int((~finite & ~nan).sum()))


@dataclass(frozen=True)
class Obstacles:
    """Obstacles from user code, in the world frame; they replace the previous ones.

    Attributes:
        stamp: When they were known there [s].
        spheres: Spheres (n, 4): centre [m] and radius [m].
        boxes: Boxes, each ``(T_world_box (4x4), size (3,) [m])``.
    """

    stamp: float
    spheres: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)), repr=False)
    boxes: tuple[tuple[np.ndarray, np.ndarray], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp", stamp_seconds(self.stamp, key="stamp"))
        S = np.asarray(self.spheres, dtype=float).reshape(-1, 4) if np.size(self.spheres) \
            else np.zeros((0, 4))
        if not np.all(np.isfinite(S)) or np.any(S[:, 3] < 0):
            raise ObservationError("spheres need finite centres and radii >= 0",
                                   key="spheres")
        object.__setattr__(self, "spheres", S)
        boxes = []
        for i, box in enumerate(self.boxes):
            try:
                T, size = np.asarray(box[0], dtype=float), np.asarray(box[1], dtype=float)
            except (TypeError, ValueError, IndexError):
                raise ObservationError("a box is (T_world_box, size)",
                                       key=f"boxes[{i}]") from None
            if T.shape != (4, 4) or size.shape != (3,) or not np.all(np.isfinite(T)) \
                    or not np.all(size > 0):
                raise ObservationError("a box needs a finite 4x4 placement and 3 sizes > 0",
                                       key=f"boxes[{i}]")
            boxes.append((T, size))
        object.__setattr__(self, "boxes", tuple(boxes))

    def elements(self, cell: float = 0.02) -> np.ndarray:
        """World spheres (n, 4) that enclose the obstacles (boxes: a sphere fit)."""
        import coal

        from ..collision.spheres import fit_spheres

        parts = [self.spheres]
        for T, size in self.boxes:
            fit = fit_spheres(coal.Box(*size), cell=cell).transformed(T)
            parts.append(np.column_stack([fit.outer_centers, fit.outer_radii]))
        return np.vstack(parts)
