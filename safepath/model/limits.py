"""The joint speed limits a motion is timed under and checked against, as one record.

:class:`MotionLimits` holds a robot's joint velocity, acceleration and jerk limits (one
value per joint, in its joint order), read-only. A robot gives its own
(:attr:`safepath.Robot.motion_limits`); a :class:`~safepath.model.trajectory.Trajectory`
carries those it was timed under (:attr:`~safepath.model.trajectory.Trajectory.limits`),
which the goal builders of :mod:`safepath.ros` check the controller's executed motion
against. It is never looked up again by a robot's name.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["MotionLimits"]

_FIELDS = ("velocity", "acceleration", "jerk")


def limit_vector(values: Any, key: str, path: str | Path | None = None, *,
                 dof: int | None = None) -> np.ndarray:
    """``values`` as read-only, finite, positive limits, one per joint (``dof`` of them
    when given), or a ConfigError naming ``key`` (and ``path``)."""
    want = "finite positive values, one per joint" if dof is None \
        else f"{dof} finite positive values"
    try:
        arr = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"need {want}, got {values!r}", path=path, key=key) from None
    if arr.ndim != 1 or arr.size == 0 or (dof is not None and arr.size != dof) \
            or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ConfigError(f"need {want}, got {arr.tolist()}", path=path, key=key)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class MotionLimits:
    """Joint velocity, acceleration and jerk limits, one value per joint, read-only.

    Attributes:
        velocity: Velocity limits [rad/s or m/s], shape (dof,).
        acceleration: Acceleration limits [rad/s^2 or m/s^2], shape (dof,).
        jerk: Jerk limits [rad/s^3 or m/s^3], shape (dof,).

    Raises:
        ConfigError: A value that is not finite and positive, or arrays of different
            lengths (names the field).
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    def __post_init__(self) -> None:
        for name in _FIELDS:
            object.__setattr__(self, name, limit_vector(getattr(self, name), name))
        if not self.velocity.size == self.acceleration.size == self.jerk.size:
            raise ConfigError(f"expected as many values in each, got {self.velocity.size}, "
                              f"{self.acceleration.size} and {self.jerk.size}", key="jerk")

    @property
    def dof(self) -> int:
        """The number of joints."""
        return int(self.velocity.size)

    def __eq__(self, other: object) -> bool:
        """Equal when every limit is equal, exactly."""
        if not isinstance(other, MotionLimits):
            return NotImplemented
        return all(np.array_equal(getattr(self, n), getattr(other, n)) for n in _FIELDS)

    __hash__ = None  # type: ignore[assignment]  # arrays inside: not hashable

    def columns(self, cols: Sequence[int]) -> MotionLimits:
        """The limits of the joints ``cols``, in that order."""
        idx = list(cols)
        return MotionLimits(self.velocity[idx], self.acceleration[idx], self.jerk[idx])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(velocity, acceleration, jerk)."""
        return self.velocity, self.acceleration, self.jerk

    def to_dict(self) -> dict[str, list[float]]:
        """JSON form: ``{"velocity": [...], "acceleration": [...], "jerk": [...]}``."""
        return {name: [float(v) for v in getattr(self, name)] for name in _FIELDS}

    @classmethod
    def from_dict(cls, data: Any, *, path: str | Path | None = None,
                  key: str = "limits") -> MotionLimits:
        """Inverse of :meth:`to_dict`.

        Raises:
            ConfigError: Not a mapping of the three fields, or a bad value (names the
                file and the field).
        """
        if not isinstance(data, Mapping) or set(data) != set(_FIELDS):
            raise ConfigError(f"expected the keys {list(_FIELDS)}, got "
                              f"{sorted(data) if isinstance(data, Mapping) else data!r}",
                              path=path, key=key)
        arrays = [limit_vector(data[n], f"{key}.{n}", path) for n in _FIELDS]
        try:
            return cls(*arrays)
        except ConfigError as exc:
            raise ConfigError(exc.reason, path=path, key=f"{key}.{exc.key}") from None
