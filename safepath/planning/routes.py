"""Routes as data: ``routes.yaml`` of a scene folder.

A route starts at a taught pose and lists steps::

    routes:
      phase1:
        start: grip
        steps:
          - close: vial            # gripper action: a stop; the vial is attached
          - line: high1            # straight TCP line to the pose (orientation kept)
            speed: 0.3             # fraction of the joint limits for this step
            tcp_speed: 0.10        # TCP speed limit [m/s]
          - move: high2            # free joint move (planned around obstacles)
          - move: {pose: low1, offset: [0, 0, 0.05]}   # 5 cm above a taught pose
          - line: low1
          - open: vial             # released where it is
          - line: {up: 0.05}       # straight up from where the TCP is
      phase2_safe:
        after: phase1              # starts in the world phase1 leaves (vial on the plate)
        start: high2
        steps: [...]

Motion steps (``move``, ``line``, and ``via``, a move that never stops) do not stop at
their end unless ``stop: true`` is given or a gripper action or the route's end follows:
the robot blends through them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from .._io import as_float, as_str, as_vector, get_key, read_yaml
from ..errors import ConfigError

__all__ = ["Target", "Step", "Route", "load_routes"]

StepKind = Literal["move", "line", "open", "close"]


@dataclass(frozen=True)
class Target:
    """Where a motion step goes.

    Attributes:
        pose: A taught pose, or None for a target relative to the current TCP.
        offset: TCP translation added in the world frame [m] (orientation kept); a
            non-zero offset is reached by inverse kinematics seeded from the pose.
    """

    pose: str | None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def exact_pose(self) -> str | None:
        """The taught pose, if the target is exactly it."""
        return self.pose if not any(self.offset) else None

    def __str__(self) -> str:
        if self.exact_pose:
            return self.exact_pose
        off = ",".join(f"{v:+.3f}" for v in self.offset)
        return f"{self.pose or 'here'}{off}"


@dataclass(frozen=True)
class Step:
    """One step of a route.

    Attributes:
        kind: ``move``, ``line``, ``open`` or ``close``.
        target: Where a motion goes (None for gripper actions).
        object: Object a gripper action takes or releases (None: the scene's grasp).
        speed: Fraction of the velocity and acceleration limits, in (0, 1].
        tcp_speed: TCP speed limit [m/s], or None.
        stop: Whether the robot stops at the end of this motion.
    """

    kind: StepKind
    target: Target | None
    object: str | None = None
    speed: float = 1.0
    tcp_speed: float | None = None
    stop: bool = False

    @property
    def is_motion(self) -> bool:
        """Whether the step moves the arm."""
        return self.kind in ("move", "line")

    def label(self, index: int) -> str:
        """Short unique name, e.g. ``2 line high1``."""
        what = self.target if self.target is not None else (self.object or "")
        return f"{index} {self.kind} {what}".rstrip()


@dataclass(frozen=True)
class Route:
    """A named route.

    Attributes:
        name: Route name.
        start: Taught pose it starts from.
        steps: The steps.
        after: Route whose final world state this one starts in (or None: the scene's).
    """

    name: str
    start: str
    steps: tuple[Step, ...]
    after: str | None = None

    def labels(self) -> list[str]:
        """Step labels in order."""
        return [s.label(i) for i, s in enumerate(self.steps)]


def load_routes(path: str | Path, *, poses: Sequence[str], objects: Sequence[str]
                ) -> dict[str, Route]:
    """Read ``routes.yaml``.

    Args:
        path: The file (or the scene folder holding it).
        poses: Known pose names.
        objects: Known object names.

    Raises:
        ConfigError: Malformed file, unknown step kind, unknown pose or object, a bad
            speed, an ``after`` cycle; names file and key.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "routes.yaml"
    data = read_yaml(path)
    raw = get_key(data, "routes", path=path)
    if not isinstance(raw, dict) or not raw:
        raise ConfigError("expected a non-empty mapping of route names", path=path,
                          key="routes")
    defaults = data.get("defaults", {}) if isinstance(data, dict) else {}
    if not isinstance(defaults, dict):
        raise ConfigError("expected a mapping", path=path, key="defaults")
    routes = {str(name): _parse_route(str(name), r, path, poses, objects, defaults)
              for name, r in raw.items()}
    for route in routes.values():
        seen = {route.name}
        after = route.after
        while after is not None:
            if after not in routes:
                raise ConfigError(f"unknown route '{after}' (routes: {', '.join(routes)})",
                                  path=path, key=f"routes.{route.name}.after")
            if after in seen:
                raise ConfigError("routes follow each other in a cycle", path=path,
                                  key=f"routes.{route.name}.after")
            seen.add(after)
            after = routes[after].after
    return routes


def _check_pose(name: Any, poses: Sequence[str], path: Path, key: str) -> str:
    name = as_str(name, path=path, key=key)
    if name not in poses:
        raise ConfigError(f"unknown pose '{name}' (known: {', '.join(poses)})", path=path,
                          key=key)
    return name


def _parse_target(raw: Any, poses: Sequence[str], path: Path, key: str) -> Target:
    """``high1``, ``{pose: safe, offset: [0, 0, 0.05]}`` or ``{up: 0.05}``."""
    if isinstance(raw, str):
        return Target(_check_pose(raw, poses, path, key))
    if isinstance(raw, dict):
        if set(raw) == {"up"}:
            dz = as_float(raw["up"], path=path, key=f"{key}.up")
            return Target(None, (0.0, 0.0, dz))
        unknown = set(raw) - {"pose", "offset"}
        if unknown:
            raise ConfigError(f"unknown key(s) {sorted(unknown)}", path=path, key=key)
        pose = _check_pose(get_key(raw, "pose", path=path, prefix=key), poses, path,
                           f"{key}.pose")
        offset = as_vector(raw.get("offset", [0.0, 0.0, 0.0]), 3, path=path,
                           key=f"{key}.offset")
        return Target(pose, (offset[0], offset[1], offset[2]))
    raise ConfigError(f"expected a pose name, {{pose: .., offset: [..]}} or {{up: ..}}, "
                      f"got {raw!r}", path=path, key=key)


def _parse_route(name: str, raw: Any, path: Path, poses: Sequence[str],
                 objects: Sequence[str], defaults: Mapping[str, Any]) -> Route:
    key = f"routes.{name}"
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key=key)
    start = _check_pose(get_key(raw, "start", path=path, prefix=key), poses, path,
                        f"{key}.start")
    steps_raw = get_key(raw, "steps", path=path, prefix=key)
    if not isinstance(steps_raw, list) or not steps_raw:
        raise ConfigError("expected a non-empty list of steps", path=path, key=f"{key}.steps")
    steps = tuple(_parse_step(s, path, f"{key}.steps[{i}]", poses, objects, defaults)
                  for i, s in enumerate(steps_raw))
    after = raw.get("after")
    if after is not None:
        after = as_str(after, path=path, key=f"{key}.after")
    return Route(name, start, steps, after)


def _parse_step(raw: Any, path: Path, key: str, poses: Sequence[str], objects: Sequence[str],
                defaults: Mapping[str, Any]) -> Step:
    if isinstance(raw, str) and raw in ("open", "close"):
        raw = {raw: None}
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping such as {move: high2}", path=path, key=key)
    kinds = [k for k in ("move", "line", "via", "open", "close") if k in raw]
    if len(kinds) != 1:
        raise ConfigError("a step needs exactly one of move, line, via, open, close",
                          path=path, key=key)
    kind = kinds[0]
    unknown = set(raw) - {kind, "speed", "tcp_speed", "stop"}
    if unknown:
        raise ConfigError(f"unknown key(s) {sorted(unknown)}", path=path, key=key)
    speed = as_float(raw.get("speed", defaults.get("speed", 1.0)), path=path,
                     key=f"{key}.speed", positive=True)
    if speed > 1.0:
        raise ConfigError(f"speed is a fraction of the limits, at most 1, got {speed:g}",
                          path=path, key=f"{key}.speed")
    tcp = raw.get("tcp_speed", defaults.get("tcp_speed"))
    tcp_speed = None if tcp is None else as_float(tcp, path=path, key=f"{key}.tcp_speed",
                                                  positive=True)
    stop = raw.get("stop", False)
    if not isinstance(stop, bool):
        raise ConfigError(f"expected true or false, got {stop!r}", path=path, key=f"{key}.stop")
    if kind in ("open", "close"):
        obj = raw[kind]
        if obj is not None:
            obj = as_str(obj, path=path, key=f"{key}.{kind}")
            if obj not in objects:
                raise ConfigError(f"unknown object '{obj}' (objects: {', '.join(objects)})",
                                  path=path, key=f"{key}.{kind}")
        return Step(kind, None, obj, speed, tcp_speed, True)  # type: ignore[arg-type]
    target = _parse_target(raw[kind], poses, path, f"{key}.{kind}")
    if kind == "via":
        if stop:
            raise ConfigError("a via point never stops", path=path, key=f"{key}.stop")
        return Step("move", target, None, speed, tcp_speed, False)
    return Step(kind, target, None, speed, tcp_speed, stop)  # type: ignore[arg-type]
