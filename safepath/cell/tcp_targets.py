"""Cartesian targets: a position and an orientation quaternion for the TCP (or a frame on it).

Used by ``poses.yaml`` (a pose given as a TCP pose, solved by inverse kinematics from an
`ik_start` pose) and by ``routes.yaml`` (a motion step to a TCP pose)::

    above_cup:
      position: [0.40, -0.20, 0.21]           # [m], world (= robot base) frame
      orientation: [0.0, 0.7071, 0.0, 0.7071]  # quaternion (x, y, z, w)
      frame: end_effector_link                 # optional: the frame placed there (default TCP)
      ik_start: home                           # poses.yaml only: the IK starts here

Quaternions are written (x, y, z, w), as in ROS ``geometry_msgs/Quaternion``. One that is
not finite, or whose norm is not within :data:`UNIT_TOLERANCE` of 1, is a
:class:`~safepath.errors.ConfigError` naming the file and key: safepath does not guess
what a non-unit quaternion was meant to be. Within the tolerance (printed values rounded
to four decimals are off by up to ~2e-4) it is used normalised.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ConfigError
from ..files._io import as_str, as_vector

if TYPE_CHECKING:
    import pinocchio as pin

    from ..model.robot import Robot

__all__ = ["UNIT_TOLERANCE", "CartesianTarget", "parse_cartesian", "is_cartesian",
           "quaternion_matrix"]

#: Largest accepted | |q| - 1 | of a written quaternion.
UNIT_TOLERANCE = 1e-3
_KEYS = {"position", "orientation", "frame"}


@dataclass(frozen=True)
class CartesianTarget:
    """A pose of the TCP (or of a frame rigidly attached to it) in the world frame.

    Attributes:
        position: Position [m] (x, y, z).
        orientation: Unit quaternion (x, y, z, w).
        frame: The robot frame placed there, or None for the TCP.
    """

    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    frame: str | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ConfigError(f"expected 3 finite numbers, got {self.position!r}",
                              key="position")
        quaternion_matrix(self.orientation, key="orientation")

    @property
    def rotation(self) -> np.ndarray:
        """Rotation matrix of the orientation (3x3)."""
        return quaternion_matrix(self.orientation)

    def tcp_pose(self, robot: Robot) -> pin.SE3:
        """The TCP pose that puts ``frame`` at this target.

        Raises:
            FrameNotFound: The robot has no such frame.
            ConfigError: The frame does not move rigidly with the TCP.
        """
        import pinocchio as pin

        T = pin.SE3(self.rotation, np.asarray(self.position, dtype=float))
        if self.frame is None or self.frame == robot.tcp_frame:
            return T
        fid = robot._frame_id(self.frame)
        model = robot.model
        if model.frames[fid].parentJoint != model.frames[robot.tcp_frame_id].parentJoint:
            raise ConfigError(f"frame {self.frame} does not move rigidly with the TCP "
                              f"{robot.tcp_frame}", key="frame")
        q = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
        T_frame_tcp = robot.frame_pose(q, self.frame).actInv(robot.frame_pose(q))
        return T * T_frame_tcp


def is_cartesian(raw: Any) -> bool:
    """Whether a YAML value is a Cartesian target (a mapping with ``position``)."""
    return isinstance(raw, Mapping) and "position" in raw


def quaternion_matrix(q: Any, *, path: Path | None = None, key: str | None = None
                      ) -> np.ndarray:
    """Rotation matrix of a written quaternion (x, y, z, w), validated.

    Raises:
        ConfigError: Not four finite numbers, or a norm not within
            :data:`UNIT_TOLERANCE` of 1 (naming ``path`` and ``key``).
    """
    try:
        arr = np.asarray(q, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"expected a quaternion [x, y, z, w], got {q!r}", path=path,
                          key=key) from None
    if arr.shape != (4,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"expected a quaternion of 4 finite numbers [x, y, z, w], got "
                          f"{np.asarray(q).tolist()!r}", path=path, key=key)
    norm = float(np.linalg.norm(arr))
    if not abs(norm - 1.0) <= UNIT_TOLERANCE:
        raise ConfigError(f"not a unit quaternion: {arr.tolist()} has norm {norm:.4f} "
                          f"(safepath does not normalise it; tolerance {UNIT_TOLERANCE:g})",
                          path=path, key=key)
    x, y, z, w = arr / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def parse_cartesian(raw: Mapping[str, Any], *, path: Path | None, key: str,
                    extra: frozenset[str] = frozenset()) -> CartesianTarget:
    """A :class:`CartesianTarget` from its YAML mapping (``extra``: other keys allowed).

    Raises:
        ConfigError: Unknown keys, a bad position or quaternion; names file and key.
    """
    unknown = set(raw) - _KEYS - extra
    if unknown:
        raise ConfigError(f"unknown key(s) {sorted(unknown)}", path=path, key=key)
    pos = as_vector(raw.get("position"), 3, path=path, key=f"{key}.position")
    if not all(math.isfinite(v) for v in pos):
        raise ConfigError(f"position must be finite, got {pos}", path=path,
                          key=f"{key}.position")
    if "orientation" not in raw:
        raise ConfigError("missing orientation [x, y, z, w]", path=path, key=key)
    quaternion_matrix(raw["orientation"], path=path, key=f"{key}.orientation")
    quat = [float(v) for v in raw["orientation"]]
    frame = raw.get("frame")
    if frame is not None:
        frame = as_str(frame, path=path, key=f"{key}.frame")
    return CartesianTarget((pos[0], pos[1], pos[2]), (quat[0], quat[1], quat[2], quat[3]),
                           frame)


def solve_target(robot: Robot, target: CartesianTarget, q_init: np.ndarray, *,
                 path: Path | None = None, key: str | None = None) -> np.ndarray:
    """Joint vector [rad] that puts the target's frame at the target, found by inverse
    kinematics started at ``q_init`` [rad] (deterministic: the solution nearest its branch).

    Raises:
        PoseError: No solution within the joint limits from ``q_init`` (names file, key).
    """
    from ..errors import PoseError
    from ..kinematics import solve_ik

    try:
        T = target.tcp_pose(robot)
    except ConfigError as exc:
        raise ConfigError(exc.reason, path=path, key=f"{key}.{exc.key}" if key else exc.key
                          ) from None
    from ..errors import IKError

    try:
        return solve_ik(robot, T, np.asarray(q_init, dtype=float), step=key)
    except IKError:
        where = ", ".join(f"{float(v):.4g}" for v in target.position)
        raise PoseError(f"no inverse-kinematics solution for position [{where}] from the "
                        "pose it starts at (`ik_start`, `--near`): out of reach, or at a "
                        "joint limit", path=path, key=key) from None
