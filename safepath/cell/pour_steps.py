"""Pour steps of a route: a tilt of the held cup about a point of it, and a circle.

Two step kinds extend the routes format (:mod:`safepath.cell.routes`) for pouring::

    - tilt: {axis: [-1, 0, 0], angle: 2.0071, pivot: [0.035, 0.04, 0.0]}
      max_angular_speed: 0.0873   # bound on the cup's angular speed [rad/s]
    - tilt: {orientation: [0.5, 0.5, 0.5, 0.5], pivot: [0.035, 0.04, 0.0]}
      max_angular_speed: 0.5236   # back upright
    - circle: {center: [-0.03, 0.0], turns: 1}
      tcp_speed: 0.05             # TCP speed limit on the circle [m/s]
      into: bowl                  # the pour lands in the bowl (checked)

A ``tilt`` turns the TCP from its orientation at the step's start to a goal orientation
(an absolute TCP quaternion ``orientation`` (x, y, z, w) in the world frame, or a turn by
``angle`` [rad] about the world ``axis``) on the SO(3) geodesic, about the fixed world
point that the ``pivot`` [m] (given in the TCP frame: a point of the held cup, e.g. the
lip it pours over) occupies at the step's start; the cup's angular speed stays within
``max_angular_speed``. A ``circle`` moves the TCP ``turns`` times round the horizontal
circle about the point ``center`` [m] (world x, y offset from the TCP at the circle's
start), height and orientation held, within the step's ``tcp_speed``. A circle follows a
tilt directly: the two are planned and timed as one continuous trajectory (the barista
pour, :func:`safepath.planning.pour.plan_barista`); a tilt alone is
:func:`safepath.planning.pour.plan_tilt`. Pour steps start and end at rest. ``into``
names the receptacle (a scene object, a vertical cylinder or an upright box) the pour
must land in: at every released sample of the step the cup's lip (the tilt's pivot, or
for a circle the pivot of its tilt, carried with the cup) lies above the receptacle and
within its opening (:func:`safepath.planning.landing.check_landing`).

Part of the routes format (any cell's routes may tilt and circle a held object), so it
stays in the library; the pouring cell's own logic is :mod:`safepath.cells.pouring`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..files._io import as_float, as_vector, check_keys
from .tcp_targets import quaternion_matrix

__all__ = ["Tilt", "Circle", "POUR_KINDS", "parse_pour", "parse_pour_step", "check_pour_fields",
           "parse_speed"]

#: The step kinds this module defines.
POUR_KINDS = ("tilt", "circle")


def _vector(value: Any, n: int, key: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(f"expected {n} numbers, got {value!r}", key=key) from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ConfigError(f"expected {n} finite numbers, got {value!r}", key=key)
    return out


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` [rad] about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


@dataclass(frozen=True)
class Tilt:
    """A tilt of the held cup about a fixed point.

    Attributes:
        pivot: The point turned about, in the TCP frame at the step's start [m] (a point
            of the held cup: the lip it pours over). At least 1 mm from the TCP (the
            angular speed is bounded through the TCP's speed about it).
        orientation: Goal TCP orientation in the world frame, quaternion (x, y, z, w),
            or None (then ``axis`` and ``angle``).
        axis: World axis of a relative turn (any length > 0), or None.
        angle: Angle of the relative turn [rad], 0 < |angle| <= pi, or None.
    """

    pivot: tuple[float, float, float]
    orientation: tuple[float, float, float, float] | None = None
    axis: tuple[float, float, float] | None = None
    angle: float | None = None

    def __post_init__(self) -> None:
        pivot = _vector(self.pivot, 3, "pivot")
        if math.hypot(*pivot) < 1e-3:
            raise ConfigError("the pivot must lie at least 1 mm from the TCP (the cup's "
                              f"angular speed is bounded through the TCP speed about it), "
                              f"got {list(pivot)}", key="pivot")
        object.__setattr__(self, "pivot", pivot)
        relative = self.axis is not None or self.angle is not None
        if self.orientation is not None and relative:
            raise ConfigError("give either orientation or axis and angle, not both",
                              key="orientation")
        if self.orientation is not None:
            quat = _vector(self.orientation, 4, "orientation")
            quaternion_matrix(quat, key="orientation")  # unit, finite: never normalised
            object.__setattr__(self, "orientation", quat)
            return
        if self.axis is None or self.angle is None:
            raise ConfigError("a tilt needs orientation [x, y, z, w], or axis [x, y, z] "
                              "and angle [rad]", key="axis" if self.axis is None else "angle")
        axis = _vector(self.axis, 3, "axis")
        if math.hypot(*axis) < 1e-9:
            raise ConfigError(f"the axis must not be zero, got {list(axis)}", key="axis")
        angle = self.angle
        if isinstance(angle, bool) or not isinstance(angle, (int, float)) \
                or not math.isfinite(angle) or not 0.0 < abs(angle) <= math.pi:
            raise ConfigError(f"the angle [rad] must be finite with 0 < |angle| <= pi, got "
                              f"{angle!r}", key="angle")
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "angle", float(angle))

    def goal(self, R_world_tcp: np.ndarray) -> np.ndarray:
        """The goal TCP orientation (3x3, world frame) from ``R_world_tcp`` at the start."""
        if self.orientation is not None:
            return quaternion_matrix(self.orientation)
        assert self.axis is not None and self.angle is not None  # checked when made
        axis = np.asarray(self.axis) / np.linalg.norm(self.axis)
        return _rotation(axis, self.angle) @ np.asarray(R_world_tcp)

    def pivot_in_world(self, T_world_tcp: np.ndarray) -> np.ndarray:
        """The pivot's world position [m] for the TCP pose at the step's start (4x4)."""
        T = np.asarray(T_world_tcp)
        return np.asarray(T[:3, :3] @ np.asarray(self.pivot) + T[:3, 3])

    def __str__(self) -> str:
        if self.orientation is not None:
            return "to(" + ",".join(f"{v:.3f}" for v in self.orientation) + ")"
        return f"{math.degrees(self.angle or 0.0):.1f}deg"


@dataclass(frozen=True)
class Circle:
    """A horizontal circle of the TCP, orientation and height held.

    Attributes:
        center: The circle's centre as a world (x, y) offset from the TCP at the
            circle's start [m]; its length is the radius (at least 1 mm).
        turns: Number of turns (> 0 counter-clockwise seen from above, < 0 clockwise).
    """

    center: tuple[float, float]
    turns: float = 1.0

    def __post_init__(self) -> None:
        center = _vector(self.center, 2, "center")
        if math.hypot(*center) < 1e-3:
            raise ConfigError(f"the centre must lie at least 1 mm from the TCP (the radius), "
                              f"got {list(center)}", key="center")
        object.__setattr__(self, "center", center)
        turns = self.turns
        if isinstance(turns, bool) or not isinstance(turns, (int, float)) \
                or not math.isfinite(turns) or turns == 0 or abs(turns) > 100:
            raise ConfigError(f"turns must be a non-zero number of at most 100, got {turns!r}",
                              key="turns")
        object.__setattr__(self, "turns", float(turns))

    @property
    def radius(self) -> float:
        """The circle's radius [m]."""
        return float(math.hypot(*self.center))

    def __str__(self) -> str:
        return f"r{self.radius * 1000:.0f}mm"


def parse_pour(kind: str, raw: Any, *, path: Path | None, key: str) -> Tilt | Circle:
    """A :class:`Tilt` or :class:`Circle` from its YAML mapping (the value of ``tilt:``
    or ``circle:``).

    Raises:
        ConfigError: Not a mapping, an unknown key (the closest known one named), a bad
            value (a non-unit or non-finite quaternion, a zero axis, ...); names file and
            key.
    """
    if not isinstance(raw, Mapping):
        example = ("{axis: [-1, 0, 0], angle: 2.0, pivot: [0.035, 0.04, 0]}" if kind == "tilt"
                   else "{center: [-0.03, 0], turns: 1}")
        raise ConfigError(f"expected a mapping such as {example}, got {raw!r}", path=path,
                          key=key)
    try:
        if kind == "tilt":
            check_keys(raw, ("pivot", "orientation", "axis", "angle"), path=path, prefix=key)
            if "pivot" not in raw:
                raise ConfigError("missing key (the point of the cup turned about, in the TCP "
                                  "frame [m])", path=path, key=f"{key}.pivot")
            vec = {name: as_vector(raw[name], n, path=path, key=f"{key}.{name}")
                   for name, n in (("pivot", 3), ("orientation", 4), ("axis", 3))
                   if name in raw}
            angle = as_float(raw["angle"], path=path, key=f"{key}.angle") \
                if "angle" in raw else None
            return Tilt(vec["pivot"], vec.get("orientation"), vec.get("axis"),  # type: ignore[arg-type]
                        angle)
        check_keys(raw, ("center", "turns"), path=path, prefix=key)
        if "center" not in raw:
            raise ConfigError("missing key (the centre's x, y offset from the TCP [m])",
                              path=path, key=f"{key}.center")
        center = as_vector(raw["center"], 2, path=path, key=f"{key}.center")
        turns = as_float(raw.get("turns", 1.0), path=path, key=f"{key}.turns")
        return Circle((center[0], center[1]), turns)
    except ConfigError as exc:
        if exc.path is not None:
            raise
        raise ConfigError(exc.reason, path=path, key=f"{key}.{exc.key}") from None


def parse_speed(raw: Mapping[str, Any], defaults: Mapping[str, Any], *, path: Path | None,
                key: str) -> float:
    """A step's ``speed`` (or the default's), a fraction of the limits in (0, 1].

    Raises:
        ConfigError: Not a number in (0, 1]; names file and key.
    """
    speed = as_float(raw.get("speed", defaults.get("speed", 1.0)), path=path,
                     key=f"{key}.speed", positive=True)
    if speed > 1.0:
        raise ConfigError(f"speed is a fraction of the limits, at most 1, got {speed:g}",
                          path=path, key=f"{key}.speed")
    return speed


def parse_pour_step(raw: Mapping[str, Any], kind: str, *, path: Path | None, key: str,
                    defaults: Mapping[str, Any]) -> tuple[Tilt | Circle, float, float]:
    """The fields of a ``tilt`` or ``circle`` step of ``routes.yaml``: what it does, its
    ``speed`` (fraction of the joint limits) and its bound (``max_angular_speed``
    [rad/s] of a tilt, ``tcp_speed`` [m/s] of a circle; either may come from
    ``defaults``).

    Raises:
        ConfigError: An unknown key (pour steps take no ``stop`` or ``max_tilt``: they
            start and end at rest and tilt the cup on purpose), a missing bound, a bad
            value; names file and key.
    """
    extra = "max_angular_speed" if kind == "tilt" else "tcp_speed"
    check_keys(raw, (kind, "speed", extra, "into"), path=path, prefix=key)
    speed = parse_speed(raw, defaults, path=path, key=key)
    bound = raw.get(extra, defaults.get(extra))
    if bound is None:
        what = "the cup's angular speed bound [rad/s]" if kind == "tilt" \
            else "the TCP speed limit on the circle [m/s]"
        raise ConfigError(f"missing key ({what})", path=path, key=f"{key}.{extra}")
    value = as_float(bound, path=path, key=f"{key}.{extra}", positive=True)
    return parse_pour(kind, raw[kind], path=path, key=f"{key}.{kind}"), speed, value


def check_pour_fields(kind: str, pour: Any, max_angular_speed: Any, tcp_speed: Any,
                      max_tilt: Any) -> None:
    """Check a :class:`~safepath.cell.routes.Step`'s pour fields against its kind.

    Raises:
        ConfigError: A tilt without a :class:`Tilt` or a positive ``max_angular_speed``,
            a circle without a :class:`Circle` or a ``tcp_speed``, a ``max_tilt`` on a
            pour step, pour fields on another kind.
    """
    is_pour = kind in POUR_KINDS
    want = {"tilt": Tilt, "circle": Circle}.get(kind)
    if want is not None and not isinstance(pour, want):
        raise ConfigError(f"a {kind} step needs a safepath.cell.pour_steps.{want.__name__}, got "
                          f"{pour!r}", key="pour")
    if not is_pour and pour is not None:
        raise ConfigError(f"a {kind} step has no pour, got {pour!r}", key="pour")
    w = max_angular_speed
    if kind == "tilt" and (isinstance(w, bool) or not isinstance(w, (int, float))
                           or not math.isfinite(w) or w <= 0):
        raise ConfigError(f"a tilt needs max_angular_speed, a number > 0 [rad/s], got {w!r}",
                          key="max_angular_speed")
    if kind != "tilt" and w is not None:
        raise ConfigError("max_angular_speed applies to tilt steps", key="max_angular_speed")
    if kind == "circle" and tcp_speed is None:
        raise ConfigError("a circle needs tcp_speed [m/s]", key="tcp_speed")
    if is_pour and max_tilt is not None:
        raise ConfigError(f"max_tilt does not apply to a {kind} step (it tilts the cup on "
                          "purpose)", key="max_tilt")
