"""Robots: kinematics, collision geometry and limits, loaded by name or from a folder.

A robot folder (see ``robots/ned3pro``) holds a URDF with primitive collision shapes,
a ``robot.yaml`` with what a URDF cannot say (velocity and acceleration limits, the
TCP frame, the tool), and the computed list of link pairs that never need checking.
Robots of ``example-robot-data`` (``ur5``, ``panda``, ...) load by name too.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ._io import as_float, as_str, as_vector, get_key, read_yaml
from .errors import ConfigError, FrameNotFound, PoseError, RobotNotFound

__all__ = ["Robot", "ToolSpec", "load_robot", "robot_names", "ROBOTS_DIR"]

log = logging.getLogger(__name__)

#: The project's robot folders (``robots/<name>/robot.yaml``).
ROBOTS_DIR = Path(os.environ.get("SAFEPATH_ROBOTS", Path(__file__).resolve().parents[1] / "robots"))

@dataclass(frozen=True)
class ToolSpec:
    """The tool mounted on the flange.

    Attributes:
        name: Human-readable tool name.
        tool_id: Vendor tool id (Niryo: 11 for Gripper 1).
        contact_links: Links allowed to touch a grasped object.
        open_width: Inner jaw distance fully open [m].
        closed_width: Inner jaw distance fully closed [m].
    """

    name: str
    tool_id: int
    contact_links: tuple[str, ...]
    open_width: float
    closed_width: float


class Robot:
    """A serial arm: Pinocchio model, collision geometry, limits and TCP.

    Joint vectors are numpy arrays in the order of :attr:`joint_names` [rad].
    """

    def __init__(
        self,
        *,
        name: str,
        model: pin.Model,
        collision_model: pin.GeometryModel,
        visual_model: pin.GeometryModel | None,
        velocity_limits: Sequence[float] | np.ndarray,
        acceleration_limits: Sequence[float] | np.ndarray,
        tcp_frame: str,
        tool: ToolSpec | None = None,
        allowed_self_pairs: Sequence[tuple[str, str]] = (),
        source: Path | None = None,
        urdf_path: Path | None = None,
        allowed_collisions_path: Path | None = None,
    ) -> None:
        self.name = name
        self.model = model
        self.collision_model = collision_model
        self.visual_model = visual_model
        self.source = source
        self.urdf_path = urdf_path
        #: Where the robot folder keeps its allowed self-collision pairs (None: no folder).
        self.allowed_collisions_path = allowed_collisions_path
        self.joint_names: tuple[str, ...] = tuple(model.names[1:])
        self.lower = np.array(model.lowerPositionLimit, dtype=float)
        self.upper = np.array(model.upperPositionLimit, dtype=float)
        self.velocity_limits = np.asarray(velocity_limits, dtype=float)
        self.acceleration_limits = np.asarray(acceleration_limits, dtype=float)
        if model.nq != model.nv or model.nq != len(self.joint_names):
            raise ConfigError("only arms of revolute/prismatic 1-DoF joints are supported",
                              path=source, key="urdf")
        for label, arr in (("velocity_limits", self.velocity_limits),
                           ("acceleration_limits", self.acceleration_limits)):
            if arr.shape != (self.dof,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ConfigError(f"need {self.dof} finite positive values, got {arr.tolist()}",
                                  path=source, key=label)
        if not model.existFrame(tcp_frame):
            raise FrameNotFound(tcp_frame, [f.name for f in model.frames], path=source,
                                key="tcp_frame")
        self.tcp_frame = tcp_frame
        self.tcp_frame_id = model.getFrameId(tcp_frame)
        self.tool = tool
        self.allowed_self_pairs = frozenset(tuple(sorted(p)) for p in allowed_self_pairs)
        self._local = threading.local()  # one pinocchio Data per thread

    # -- basic facts -------------------------------------------------------------------
    @property
    def dof(self) -> int:
        """Number of joints."""
        return int(self.model.nq)

    @property
    def link_names(self) -> tuple[str, ...]:
        """Names of the links that carry collision geometry, in model order."""
        seen: dict[str, None] = {}
        for geom in self.collision_model.geometryObjects:
            seen[self.model.frames[geom.parentFrame].name] = None
        return tuple(seen)

    def geometry_link(self, geom_index: int) -> str:
        """Link (frame) name that carries collision geometry ``geom_index``."""
        geom = self.collision_model.geometryObjects[geom_index]
        return str(self.model.frames[geom.parentFrame].name)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, dof={self.dof}, tcp={self.tcp_frame!r})"

    # -- poses ---------------------------------------------------------------------------
    def as_joint_vector(self, q: Any, *, name: str = "q", path: Path | None = None,
                        check_limits: bool = True) -> np.ndarray:
        """Validate a joint vector: right length, finite, inside the limits.

        Raises:
            PoseError: Naming the pose and the offending joint.
        """
        try:
            arr = np.asarray(q, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise PoseError(f"not a vector of numbers: {q!r}", path=path, key=name) from None
        if arr.shape != (self.dof,):
            raise PoseError(f"expected {self.dof} joint values, got {arr.size}", path=path,
                            key=name)
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise PoseError(f"{self.joint_names[bad[0]]} is not finite ({arr[bad[0]]})",
                            path=path, key=name)
        if check_limits:
            violation = self.limit_violation(arr)
            if violation:
                raise PoseError(violation, path=path, key=name)
        return arr

    def within_limits(self, q: np.ndarray, tol: float = 0.0) -> bool:
        """Whether every joint lies inside its position limits (± ``tol`` [rad])."""
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def limit_violation(self, q: np.ndarray) -> str | None:
        """Describe the first joint outside its limits, or None."""
        for i, name in enumerate(self.joint_names):
            if not (self.lower[i] <= q[i] <= self.upper[i]):
                return (f"{name} = {q[i]:.5f} rad is outside its limits "
                        f"[{self.lower[i]:.5f}, {self.upper[i]:.5f}]")
        return None

    def frame_pose(self, q: np.ndarray, frame: str | None = None) -> pin.SE3:
        """Pose of ``frame`` (default: the TCP) in the world frame at ``q``."""
        fid = self.tcp_frame_id if frame is None else self._frame_id(frame)
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        pin.forwardKinematics(self.model, data, q)
        return pin.updateFramePlacement(self.model, data, fid).copy()

    def tcp_position(self, q: np.ndarray) -> np.ndarray:
        """TCP position in the world frame [m]."""
        return np.array(self.frame_pose(q).translation)

    def _frame_id(self, frame: str) -> int:
        if not self.model.existFrame(frame):
            raise FrameNotFound(frame, [f.name for f in self.model.frames])
        return int(self.model.getFrameId(frame))


# ------------------------------------------------------------------------------------------
# Loading
# ------------------------------------------------------------------------------------------
def robot_names() -> list[str]:
    """Names that :func:`load_robot` accepts: project folders, then example-robot-data."""
    names = sorted(p.parent.name for p in ROBOTS_DIR.glob("*/robot.yaml"))
    return names + _erd_names()


def _erd_names() -> list[str]:
    try:
        from example_robot_data.robots_loader import ROBOTS
    except ImportError:  # pragma: no cover - dependency is declared
        return []
    return sorted(ROBOTS)


def load_robot(name_or_path: str | Path, *, acceleration_limits: Sequence[float] | None = None
               ) -> Robot:
    """Load a robot by name (``"ned3pro"``, ``"ur5"``, ``"panda"``) or robot-folder path.

    Args:
        name_or_path: A folder under ``robots/``, a path to a robot folder or its
            ``robot.yaml``, or an ``example-robot-data`` name.
        acceleration_limits: Override the acceleration limits [rad/s^2].

    Raises:
        RobotNotFound: The name is neither a folder nor an example-robot-data robot.
        ConfigError: The robot files are malformed (names file and key).
    """
    text = str(name_or_path)
    candidate = Path(text)
    if candidate.name == "robot.yaml":
        candidate = candidate.parent
    if candidate.is_dir() and (candidate / "robot.yaml").exists():
        robot = _load_folder(candidate)
    elif (ROBOTS_DIR / text / "robot.yaml").exists():
        robot = _load_folder(ROBOTS_DIR / text)
    elif text in _erd_names():
        from ._erd import load_erd

        robot = load_erd(text)
    elif candidate.exists():
        raise ConfigError("not a robot folder (no robot.yaml)", path=candidate)
    else:
        raise RobotNotFound(text, robot_names())
    if acceleration_limits is not None:
        acc = np.asarray(acceleration_limits, dtype=float)
        if acc.shape != (robot.dof,) or not np.all(np.isfinite(acc)) or np.any(acc <= 0):
            raise ConfigError(f"need {robot.dof} finite positive values, got "
                              f"{np.asarray(acceleration_limits).tolist()}",
                              key="acceleration_limits")
        robot.acceleration_limits = acc
    return robot


def _load_folder(folder: Path) -> Robot:
    spec_path = folder / "robot.yaml"
    spec = read_yaml(spec_path)
    if not isinstance(spec, dict):
        raise ConfigError("expected a mapping at the top level", path=spec_path)
    name = as_str(get_key(spec, "name", path=spec_path), path=spec_path, key="name")
    urdf_rel = as_str(get_key(spec, "urdf", path=spec_path), path=spec_path, key="urdf")
    urdf = folder / urdf_rel
    if not urdf.exists():
        raise ConfigError(f"URDF file not found: {urdf}", path=spec_path, key="urdf")
    try:
        full = pin.buildModelFromUrdf(str(urdf))
        geom = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.COLLISION,
                                     package_dirs=[str(folder)])
        visual = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.VISUAL,
                                       package_dirs=[str(folder)])
    except (ValueError, RuntimeError, OSError) as exc:
        raise ConfigError(f"cannot load URDF ({str(exc).splitlines()[0]})", path=urdf) from None

    joints = get_key(spec, "joints", path=spec_path)
    if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
        raise ConfigError("expected a list of joint names", path=spec_path, key="joints")
    model_joints = list(full.names[1:])
    if joints != model_joints:
        raise ConfigError(f"joints {joints} do not match the URDF's movable joints "
                          f"{model_joints}", path=spec_path, key="joints")
    n = len(joints)
    vel = as_vector(get_key(spec, "velocity_limits", path=spec_path), n, path=spec_path,
                    key="velocity_limits")
    acc = as_vector(get_key(spec, "acceleration_limits", path=spec_path), n, path=spec_path,
                    key="acceleration_limits")
    tcp = as_str(get_key(spec, "tcp_frame", path=spec_path), path=spec_path, key="tcp_frame")
    tool = _parse_tool(spec.get("tool"), spec_path, full)
    pairs: list[tuple[str, str]] = []
    pairs_file = spec.get("allowed_collisions")
    pairs_path = folder / "allowed_collisions.yaml"
    if pairs_file is not None:
        pairs_path = folder / as_str(pairs_file, path=spec_path, key="allowed_collisions")
        if pairs_path.exists():
            pairs = _read_pairs(pairs_path, full)
        else:
            log.warning("%s: allowed_collisions file %s missing; only adjacent links skipped",
                        spec_path, pairs_path.name)
            pairs = adjacent_link_pairs(full, geom)
    return Robot(name=name, model=full, collision_model=geom, visual_model=visual,
                 velocity_limits=vel, acceleration_limits=acc, tcp_frame=tcp, tool=tool,
                 allowed_self_pairs=pairs, source=spec_path, urdf_path=urdf,
                 allowed_collisions_path=pairs_path)


def _parse_tool(raw: Any, path: Path, model: pin.Model) -> ToolSpec | None:
    if raw is None:
        return None
    links = get_key(raw, "contact_links", path=path, prefix="tool")
    if not isinstance(links, list):
        raise ConfigError("expected a list of link names", path=path, key="tool.contact_links")
    for link in links:
        if not model.existFrame(str(link)):
            raise FrameNotFound(str(link), [f.name for f in model.frames], path=path,
                                key="tool.contact_links")
    open_w = as_float(get_key(raw, "open_width", path=path, prefix="tool"), path=path,
                      key="tool.open_width", positive=True)
    closed_w = as_float(get_key(raw, "closed_width", path=path, prefix="tool"), path=path,
                        key="tool.closed_width", non_negative=True)
    tool_id = get_key(raw, "id", path=path, prefix="tool")
    if not isinstance(tool_id, int):
        raise ConfigError(f"expected an integer, got {tool_id!r}", path=path, key="tool.id")
    return ToolSpec(name=str(raw.get("name", "tool")), tool_id=tool_id,
                    contact_links=tuple(str(x) for x in links), open_width=open_w,
                    closed_width=closed_w)


def _read_pairs(path: Path, model: pin.Model) -> list[tuple[str, str]]:
    data = read_yaml(path)
    entries = get_key(data, "pairs", path=path)
    if not isinstance(entries, list):
        raise ConfigError("expected a list", path=path, key="pairs")
    out = []
    for i, entry in enumerate(entries):
        key = f"pairs[{i}]"
        if not isinstance(entry, dict) or "links" not in entry:
            raise ConfigError("expected {links: [a, b], reason: ...}", path=path, key=key)
        links = entry["links"]
        if not (isinstance(links, list) and len(links) == 2):
            raise ConfigError("expected two link names", path=path, key=f"{key}.links")
        for link in links:
            if not model.existFrame(str(link)):
                raise FrameNotFound(str(link), [f.name for f in model.frames], path=path,
                                    key=f"{key}.links")
        out.append((str(links[0]), str(links[1])))
    return out


def adjacent_link_pairs(model: pin.Model, geom: pin.GeometryModel) -> list[tuple[str, str]]:
    """Link pairs whose geometry hangs on the same or on parent/child joints."""
    links: dict[str, int] = {}
    for g in geom.geometryObjects:
        links[model.frames[g.parentFrame].name] = g.parentJoint
    out = []
    names = sorted(links)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            ja, jb = links[a], links[b]
            if ja == jb or model.parents[ja] == jb or model.parents[jb] == ja:
                out.append((a, b))
    return out
