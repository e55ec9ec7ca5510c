"""Routes as data: ``routes.yaml`` of a scene folder, or routes built in Python.

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
          - line: {position: [0.4, -0.2, 0.21], orientation: [0, 0.7071, 0, 0.7071]}
                                   # a TCP pose (quaternion x, y, z, w), see tcp_targets
      phase2_safe:
        after: phase1              # starts in the world phase1 leaves (vial on the plate)
        start: high2
        steps: [...]

Motion steps (``move``, ``line``, and ``via``, a move that never stops) do not stop at
their end unless ``stop: true`` is given or a gripper action or the route's end follows:
the robot blends through them. Pour steps (``tilt``, ``circle``: a held cup turned about
a point of it, a horizontal circle of the TCP) are defined in :mod:`safepath.cell.pour_steps`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ..errors import ConfigError
from ..files._io import (
    as_float,
    as_str,
    as_vector,
    check_keys,
    check_names,
    get_key,
    read_mapping,
)
from .pour_steps import POUR_KINDS, Circle, Tilt, check_pour_fields, parse_pour_step, parse_speed
from .tcp_targets import CartesianTarget, is_cartesian, parse_cartesian

__all__ = ["Target", "Step", "Route", "load_routes", "load_cycle", "check_cycle", "check_routes",
           "after_chain"]

StepKind = Literal["move", "line", "open", "close", "tilt", "circle"]
_STEP_KINDS = ("move", "line", "open", "close", *POUR_KINDS)


@dataclass(frozen=True)
class Target:
    """Where a motion step goes.

    Attributes:
        pose: A taught pose, or None for a target relative to the current TCP.
        offset: TCP translation added in the world frame [m] (orientation kept); a
            non-zero offset is reached by inverse kinematics seeded from the pose.
        cartesian: A TCP pose (position and orientation) reached by inverse kinematics
            seeded from where the robot is; ``pose`` is then None.
    """

    pose: str | None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cartesian: CartesianTarget | None = None

    def __post_init__(self) -> None:
        if self.pose is not None and (not isinstance(self.pose, str) or not self.pose):
            raise ConfigError(f"expected a pose name or None, got {self.pose!r}", key="pose")
        try:
            offset = tuple(float(v) for v in self.offset)
        except (TypeError, ValueError):
            raise ConfigError(f"expected three numbers [m], got {self.offset!r}",
                              key="offset") from None
        if len(offset) != 3 or not all(math.isfinite(v) for v in offset):
            raise ConfigError(f"expected three finite numbers [m], got {self.offset!r}",
                              key="offset")
        object.__setattr__(self, "offset", offset)
        if self.pose is None and not any(offset) and self.cartesian is None:
            raise ConfigError("a target relative to the TCP needs a non-zero offset",
                              key="offset")
        if self.cartesian is not None and (not isinstance(self.cartesian, CartesianTarget)
                                           or self.pose is not None or any(offset)):
            raise ConfigError("a TCP-pose target is a CartesianTarget alone (no pose, no "
                              "offset)", key="cartesian")

    @property
    def exact_pose(self) -> str | None:
        """The taught pose, if the target is exactly it."""
        return self.pose if not any(self.offset) and self.cartesian is None else None

    def __str__(self) -> str:
        if self.cartesian is not None:
            return "tcp(" + ",".join(f"{v:.3f}" for v in self.cartesian.position) + ")"
        if self.exact_pose:
            return self.exact_pose
        off = ",".join(f"{v:+.3f}" for v in self.offset)
        return f"{self.pose or 'here'}{off}"


@dataclass(frozen=True)
class Step:
    """One step of a route.

    Attributes:
        kind: ``move``, ``line``, ``open``, ``close``, ``tilt`` or ``circle``.
        target: Where a motion goes (None for gripper actions).
        object: Object a gripper action takes or releases (None: the scene's grasp).
        speed: Fraction of the velocity and acceleration limits, in (0, 1].
        tcp_speed: TCP speed limit [m/s], or None.
        stop: Whether the robot stops at the end of this motion.
        max_tilt: Largest angle between the held object's axis and the vertical at
            every released sample of this step [rad], or None (an orientation path
            constraint: "keep the cup upright").
        pour: What a ``tilt`` or ``circle`` step does (:class:`~safepath.cell.pour_steps.Tilt`,
            :class:`~safepath.cell.pour_steps.Circle`); None for the other kinds.
        max_angular_speed: Bound on the held cup's angular speed during a ``tilt``
            [rad/s] (required there; None elsewhere). A ``circle`` needs ``tcp_speed``.
        into: The receptacle a ``tilt`` or ``circle`` pours into (a scene object), or
            None: at every released sample of the step the cup's pouring lip (the
            tilt's ``pivot``, carried by the cup) lies above the receptacle's opening
            (:func:`safepath.planning.landing.check_landing`).
        via: Whether the step is a ``via`` point: a ``move`` that never stops (its
            label says ``via``; it plans and times as a move with ``stop`` False).
    """

    kind: StepKind
    target: Target | None
    object: str | None = None
    speed: float = 1.0
    tcp_speed: float | None = None
    stop: bool = False
    max_tilt: float | None = None
    pour: Tilt | Circle | None = None
    max_angular_speed: float | None = None
    into: str | None = None
    via: bool = False

    def __post_init__(self) -> None:
        check_names([self.kind], _STEP_KINDS, path=None, key="kind", what="step kind")
        if not isinstance(self.via, bool) or (self.via and (self.kind != "move" or self.stop)):
            raise ConfigError(f"via marks a move that never stops, got via={self.via!r} on a "
                              f"{self.kind} step with stop={self.stop!r}", key="via")
        if self.into is not None and (self.kind not in POUR_KINDS
                                      or not isinstance(self.into, str) or not self.into):
            raise ConfigError(f"into names the receptacle of a tilt or circle step, got "
                              f"{self.into!r} on a {self.kind} step", key="into")
        check_pour_fields(self.kind, self.pour, self.max_angular_speed, self.tcp_speed,
                          self.max_tilt)
        motion = self.kind in ("move", "line")
        if motion and not isinstance(self.target, Target):
            raise ConfigError(f"a {self.kind} step needs a Target, got {self.target!r}",
                              key="target")
        if not motion and self.target is not None:
            raise ConfigError(f"a {self.kind} step has no target, got {self.target!r}",
                              key="target")
        if self.object is not None and (not isinstance(self.object, str) or not self.object):
            raise ConfigError(f"expected an object name or None, got {self.object!r}",
                              key="object")
        if isinstance(self.speed, bool) or not isinstance(self.speed, (int, float)) \
                or not 0.0 < self.speed <= 1.0:
            raise ConfigError(f"speed is a fraction of the limits in (0, 1], got "
                              f"{self.speed!r}", key="speed")
        if self.tcp_speed is not None and (
                isinstance(self.tcp_speed, bool) or not isinstance(self.tcp_speed, (int, float))
                or not math.isfinite(self.tcp_speed) or self.tcp_speed <= 0):
            raise ConfigError(f"tcp_speed must be a number > 0 [m/s] or None, got "
                              f"{self.tcp_speed!r}", key="tcp_speed")
        if not isinstance(self.stop, bool):
            raise ConfigError(f"expected True or False, got {self.stop!r}", key="stop")

    @property
    def is_motion(self) -> bool:
        """Whether the step moves the arm."""
        return self.kind in ("move", "line", *POUR_KINDS)

    def label(self, index: int) -> str:
        """Short unique name, e.g. ``2 line high1`` (``5 via high2`` for a via point)."""
        what = self.target if self.target is not None else (self.pour or self.object or "")
        return f"{index} {'via' if self.via else self.kind} {what}".rstrip()


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

    def __post_init__(self) -> None:
        for key in ("name", "start"):
            value = getattr(self, key)
            if not isinstance(value, str) or not value:
                raise ConfigError(f"expected a non-empty string, got {value!r}", key=key)
        steps = tuple(self.steps)
        if not steps or not all(isinstance(s, Step) for s in steps):
            raise ConfigError(f"expected a non-empty sequence of Step, got {self.steps!r}",
                              key="steps")
        object.__setattr__(self, "steps", steps)
        for i, step in enumerate(steps):
            if step.kind == "circle" and (i == 0 or steps[i - 1].kind != "tilt"):
                raise ConfigError("a circle follows a tilt directly (the two are one "
                                  "continuous motion)", key=f"steps[{i}].circle")
        if self.after is not None and (not isinstance(self.after, str) or not self.after):
            raise ConfigError(f"expected a route name or None, got {self.after!r}",
                              key="after")

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
    data = read_mapping(path, ("routes", "defaults", "cycle"))
    raw = get_key(data, "routes", path=path)
    if not isinstance(raw, dict) or not raw:
        raise ConfigError("expected a non-empty mapping of route names", path=path,
                          key="routes")
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise ConfigError("expected a mapping", path=path, key="defaults")
    check_keys(defaults, ("speed", "tcp_speed"), path=path, prefix="defaults")
    routes = {str(name): _parse_route(str(name), r, path, poses, objects, defaults)
              for name, r in raw.items()}
    _check_chains(routes, path)
    return routes


def check_routes(routes: Mapping[str, Route], *, poses: Sequence[str], objects: Sequence[str]
                 ) -> dict[str, Route]:
    """Check routes built in Python as :func:`load_routes` checks a file's.

    Args:
        routes: Routes by name (each :class:`Route`'s name must be its key).
        poses: Known pose names.
        objects: Known object names.

    Returns:
        The routes, as a new dict.

    Raises:
        ConfigError: A route under another name, an unknown pose, object or route to
            follow, an ``after`` cycle; the key names the route and step.
    """
    if not isinstance(routes, Mapping) or not routes:
        raise ConfigError("expected a non-empty mapping of route names to Route",
                          key="routes")
    out: dict[str, Route] = {}
    for name, route in routes.items():
        key = f"routes.{name}"
        if not isinstance(route, Route):
            raise ConfigError(f"expected a Route, got {type(route).__name__}", key=key)
        if route.name != name:
            raise ConfigError(f"the route is named '{route.name}'", key=key)
        check_names([route.start], poses, path=None, key=f"{key}.start", what="pose")
        for i, step in enumerate(route.steps):
            where = f"{key}.steps[{i}]"
            if step.target is not None and step.target.pose is not None:
                check_names([step.target.pose], poses, path=None, key=f"{where}.{step.kind}",
                            what="pose")
            if step.object is not None:
                check_names([step.object], objects, path=None, key=f"{where}.{step.kind}",
                            what="object")
            if step.into is not None:
                check_names([step.into], objects, path=None, key=f"{where}.into",
                            what="object")
        out[name] = route
    _check_chains(out, None)
    return out


def load_cycle(path: str | Path, routes: Mapping[str, Route]) -> list[str] | None:
    """The ``cycle`` of ``routes.yaml``: the routes in the order one cycle of the cell
    runs them (e.g. ``[pick_cup, slow_pour, barista_pour, place_cup]``), or None when
    the file gives none. Checked by :func:`check_cycle`.

    Raises:
        ConfigError: Not a list of route names, an unknown route, or a cycle that does
            not hold together; names file and key.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "routes.yaml"
    raw = read_mapping(path, ("routes", "defaults", "cycle")).get("cycle")
    if raw is None:
        return None
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"expected a non-empty list of route names, got {raw!r}", path=path,
                          key="cycle")
    cycle = [as_str(name, path=path, key=f"cycle[{k}]") for k, name in enumerate(raw)]
    check_cycle(routes, cycle, path=path)
    return cycle


def _held_after(routes: Mapping[str, Route], names: Sequence[str]) -> bool:
    """Whether the gripper holds something after running ``names`` from the scene's
    initial world."""
    held = False
    for name in names:
        for step in routes[name].steps:
            if step.kind in ("open", "close"):
                held = step.kind == "close"
    return held


def check_cycle(routes: Mapping[str, Route], cycle: Sequence[str], *,
                path: Path | None = None) -> None:
    """Check that ``cycle`` runs as one repeating cycle of the cell: known routes, each
    starting in the world the one before it leaves (the gripper holding something or
    not, as its own ``after`` chain assumes), the first after the last.

    Raises:
        ConfigError: An unknown route, or a route that starts holding something the one
            before it does not leave held (or the other way round); names the key.
    """
    for k, name in enumerate(cycle):
        check_names([name], routes, path=path, key=f"cycle[{k}]", what="route")
    for k in [*range(1, len(cycle)), 0]:  # the wrap (last to first) last
        name, before = cycle[k], cycle[k - 1]
        assumed = _held_after(routes, after_chain(routes, name)[:-1])
        left = _held_after(routes, after_chain(routes, before))
        if assumed != left:
            state = {True: "holding the object", False: "with the gripper empty"}
            raise ConfigError(f"route '{name}' starts {state[assumed]} (after "
                              f"{routes[name].after or 'the scene'}), but '{before}' before it "
                              f"in the cycle ends {state[left]}", path=path, key=f"cycle[{k}]")


def after_chain(routes: Mapping[str, Route], name: str) -> list[str]:
    """``name`` and the routes it follows (``after``), the first one first.

    Raises:
        ConfigError: ``name`` or a route it follows is unknown.
    """
    chain = [name]
    for route in _followed(routes, name, None):
        chain.insert(0, route)
    return chain


def _followed(routes: Mapping[str, Route], name: str, path: Path | None) -> Iterator[str]:
    """The routes ``name`` follows, nearest first; refuses unknown names and cycles."""
    check_names([name], routes, path=path, key="routes", what="route")
    seen = {name}
    after = routes[name].after
    while after is not None:
        check_names([after], routes, path=path, key=f"routes.{name}.after", what="route")
        if after in seen:
            raise ConfigError("routes follow each other in a cycle", path=path,
                              key=f"routes.{name}.after")
        seen.add(after)
        yield after
        after = routes[after].after


def _check_chains(routes: Mapping[str, Route], path: Path | None) -> None:
    for name in routes:
        for _ in _followed(routes, name, path):
            pass


def _check_pose(name: Any, poses: Sequence[str], path: Path, key: str) -> str:
    name = as_str(name, path=path, key=key)
    check_names([name], poses, path=path, key=key, what="pose")
    return name


def _parse_target(raw: Any, poses: Sequence[str], path: Path, key: str) -> Target:
    """``high1``, ``{pose: safe, offset: [0, 0, 0.05]}`` or ``{up: 0.05}``."""
    if isinstance(raw, str):
        return Target(_check_pose(raw, poses, path, key))
    if is_cartesian(raw):
        return Target(None, cartesian=parse_cartesian(raw, path=path, key=key))
    if isinstance(raw, dict):
        if "up" in raw:
            check_keys(raw, ("up",), path=path, prefix=key)
            dz = as_float(raw["up"], path=path, key=f"{key}.up")
            if dz == 0.0:
                raise ConfigError("a move up by 0 goes nowhere", path=path, key=f"{key}.up")
            return Target(None, (0.0, 0.0, dz))
        check_keys(raw, ("pose", "offset"), path=path, prefix=key)
        pose = _check_pose(get_key(raw, "pose", path=path, prefix=key), poses, path,
                           f"{key}.pose")
        offset = as_vector(raw.get("offset", [0.0, 0.0, 0.0]), 3, path=path,
                           key=f"{key}.offset")
        return Target(pose, (offset[0], offset[1], offset[2]))
    raise ConfigError(f"expected a pose name, {{pose: .., offset: [..]}}, {{up: ..}} or "
                      f"{{position: [..], orientation: [x, y, z, w]}}, "
                      f"got {raw!r}", path=path, key=key)


def _parse_route(name: str, raw: Any, path: Path, poses: Sequence[str],
                 objects: Sequence[str], defaults: Mapping[str, Any]) -> Route:
    key = f"routes.{name}"
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping", path=path, key=key)
    check_keys(raw, ("start", "steps", "after", "note"), path=path, prefix=key)
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
    try:
        return Route(name, start, steps, after)
    except ConfigError as exc:  # the order of the steps (a circle after its tilt)
        raise ConfigError(exc.reason, path=path, key=f"{key}.{exc.key}") from None


def _parse_step(raw: Any, path: Path, key: str, poses: Sequence[str], objects: Sequence[str],
                defaults: Mapping[str, Any]) -> Step:
    if isinstance(raw, str) and raw in ("open", "close"):
        raw = {raw: None}
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping such as {move: high2}", path=path, key=key)
    kinds = [k for k in ("move", "line", "via", "open", "close", *POUR_KINDS) if k in raw]
    if len(kinds) != 1:
        raise ConfigError("a step needs exactly one of move, line, via, open, close, tilt, "
                          "circle", path=path, key=key)
    kind = kinds[0]
    if kind in POUR_KINDS:
        return _pour_step(raw, kind, path, key, defaults, objects)
    check_keys(raw, (kind, "speed", "tcp_speed", "stop", "max_tilt"), path=path, prefix=key)
    speed = parse_speed(raw, defaults, path=path, key=key)
    tcp = raw.get("tcp_speed", defaults.get("tcp_speed"))
    tcp_speed = None if tcp is None else as_float(tcp, path=path, key=f"{key}.tcp_speed",
                                                  positive=True)
    stop = raw.get("stop", False)
    if not isinstance(stop, bool):
        raise ConfigError(f"expected true or false, got {stop!r}", path=path, key=f"{key}.stop")
    if kind in ("open", "close"):
        if "max_tilt" in raw:
            raise ConfigError("max_tilt applies to motions", path=path, key=f"{key}.max_tilt")
        obj = raw[kind]
        if obj is not None:
            obj = as_str(obj, path=path, key=f"{key}.{kind}")
            check_names([obj], objects, path=path, key=f"{key}.{kind}", what="object")
        return Step(kind, None, obj, speed, tcp_speed, True)  # type: ignore[arg-type]
    target = _parse_target(raw[kind], poses, path, f"{key}.{kind}")
    tilt = raw.get("max_tilt")
    max_tilt = None if tilt is None else as_float(tilt, path=path, key=f"{key}.max_tilt",
                                                  non_negative=True)
    if max_tilt is not None and max_tilt > 3.1416:
        raise ConfigError(f"max_tilt is an angle [rad] in [0, pi], got {max_tilt:g}",
                          path=path, key=f"{key}.max_tilt")
    if kind == "via":
        if stop:
            raise ConfigError("a via point never stops", path=path, key=f"{key}.stop")
        return Step("move", target, None, speed, tcp_speed, False, max_tilt, via=True)
    return Step(kind, target, None, speed, tcp_speed, stop, max_tilt)  # type: ignore[arg-type]



def _pour_step(raw: dict, kind: str, path: Path, key: str, defaults: Mapping[str, Any],
               objects: Sequence[str]) -> Step:
    pour, speed, bound = parse_pour_step(raw, kind, path=path, key=key, defaults=defaults)
    into = raw.get("into")
    if into is not None:
        into = as_str(into, path=path, key=f"{key}.into")
        check_names([into], objects, path=path, key=f"{key}.into", what="object")
    if isinstance(pour, Tilt):
        return Step("tilt", None, None, speed, pour=pour, max_angular_speed=bound, into=into)
    return Step("circle", None, None, speed, tcp_speed=bound, pour=pour, into=into)
