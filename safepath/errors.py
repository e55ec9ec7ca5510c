"""The one exception tree of safepath.

Every failure the library reports is a :class:`SafepathError`. Each subclass carries
the evidence of what went wrong (the file, the key, the pose, the colliding pair,
the planner status) as attributes, and a message that names them, so that the
command line can print it as one line.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "SafepathError",
    "InputError",
    "ConfigError",
    "PoseError",
    "RobotNotFound",
    "FrameNotFound",
    "RobotNotSupported",
    "CollisionError",
    "PlanningError",
    "PlannerTimeout",
    "PourLandingError",
    "IKError",
    "TimingError",
    "ExecutedLimitError",
    "VerificationError",
    "UnprovenClearance",
    "TrajectoryError",
    "RosError",
    "WorkerLost",
    "unknown_name",
]

#: Up to this many known names are listed in full; beyond, only the closest are named.
_LIST_AT_MOST = 12


def unknown_name(what: str, name: str, known: Iterable[str]) -> str:
    """The one wording of "unknown X": the closest known names, or all of a short list.

    ``unknown_name("robot", "ur55", names)`` gives ``unknown robot 'ur55' (did you mean
    'ur5'?)`` rather than the 75 robot names; a short list is given in full.

    Args:
        what: What the name names (``key``, ``pose``, ``robot``, ...).
        name: The name that was given.
        known: The names that would have worked.
    """
    import difflib  # only when a name is wrong: not on every import of safepath

    names = [str(k) for k in known]
    # Compared case-blind ('UR5' finds 'ur5'), the known spelling given back.
    lowered: dict[str, str] = {}
    for known_name in names:
        lowered.setdefault(known_name.lower(), known_name)
    close = [lowered[c] for c in difflib.get_close_matches(str(name).lower(), list(lowered),
                                                           n=3, cutoff=0.6)]
    if close:
        hint = "did you mean " + " or ".join(f"'{c}'" for c in close) + "?"
    elif not names:
        hint = f"there is no {what}"
    elif len(names) <= _LIST_AT_MOST:
        hint = "known: " + ", ".join(names)
    else:
        hint = f"{len(names)} known, e.g. " + ", ".join(names[:_LIST_AT_MOST]) + ", ..."
    return f"unknown {what} '{name}' ({hint})"


class SafepathError(Exception):
    """Base class of every error raised by safepath.

    Errors pickle with all their evidence (they cross process boundaries in the runtime
    planner): they are rebuilt from their message and attributes, not re-constructed.
    """

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild_error, (type(self), self.args, self.__dict__.copy()))


def _rebuild_error(cls: type[SafepathError], args: tuple[Any, ...],
                   state: dict[str, Any]) -> SafepathError:
    error = cls.__new__(cls)
    Exception.__init__(error, *args)
    error.__dict__.update(state)
    return error


class InputError(SafepathError, ValueError):
    """Bad input in a file or an argument: names the file, the key and the reason.

    Attributes:
        path: File the bad value came from, or None for an in-memory value.
        key: Dotted key or name of the bad value inside the file.
        reason: What is wrong with it.
    """

    def __init__(self, reason: str, *, path: str | Path | None = None, key: str | None = None):
        self.path = None if path is None else Path(path)
        self.key = key
        self.reason = reason
        where = []
        if self.path is not None:
            where.append(str(self.path))
        if key:
            where.append(f"key '{key}'")
        prefix = ": ".join([", ".join(where)]) if where else ""
        super().__init__(f"{prefix}: {reason}" if prefix else reason)


class ConfigError(InputError):
    """A robot, scene or route description is malformed or inconsistent."""


class PoseError(InputError):
    """A joint pose is malformed, not finite, outside the joint limits or unknown."""


class RobotNotFound(InputError):
    """No robot of that name or path.

    Attributes:
        name: The name that was asked for.
        known: Names that would have worked.
    """

    def __init__(self, name: str, known: Sequence[str], *, path: str | Path | None = None):
        self.name = name
        self.known = list(known)
        super().__init__(unknown_name("robot", name, self.known), path=path, key="robot")


class FrameNotFound(InputError):
    """A frame or link name that the robot does not have.

    Attributes:
        name: The name that was asked for.
        frames: The frame names the robot has.
    """

    def __init__(self, name: str, frames: Sequence[str], *, path: str | Path | None = None,
                 key: str | None = None):
        self.name = name
        self.frames = list(frames)
        super().__init__(unknown_name("frame", name, self.frames), path=path, key=key)


class RobotNotSupported(ConfigError):
    """A valid robot description that is not an arm safepath plans for: a floating base,
    continuous joints, joints of several DoF, or no joint left to plan.

    Attributes:
        robot: The robot's name or file.
        joints: The joints at fault.
    """

    def __init__(self, reason: str, *, robot: str, joints: Sequence[str] = (),
                 path: str | Path | None = None, key: str | None = None):
        self.robot = robot
        self.joints = list(joints)
        super().__init__(reason, path=path, key=key)


class CollisionError(SafepathError):
    """A state that must be valid is not (in collision or outside the joint limits).

    Attributes:
        q: The joint vector [rad].
        pairs: The colliding pairs of geometry names.
        reason: Human-readable summary.
    """

    def __init__(self, reason: str, *, q: Any = None, pairs: Sequence[tuple[str, str]] = ()):
        self.q = q
        self.pairs = list(pairs)
        self.reason = reason
        super().__init__(reason)


class PlanningError(SafepathError):
    """No collision-free motion was found.

    Attributes:
        step: Name or index of the route step that failed, if any.
        status: The planner's status string, if a planner ran.
        route: Name of the route being planned, if known (see :meth:`in_route`).
        path: The routes file the route comes from, or None (routes built in Python).
    """

    def __init__(self, reason: str, *, step: str | None = None, status: str | None = None,
                 route: str | None = None, path: str | Path | None = None):
        self.step = step
        self.status = status
        self.reason = reason
        self.route = route
        self.path = None if path is None else Path(path)
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.path is not None:
            where.append(str(self.path))
        if self.route is not None:
            where.append(f"route '{self.route}'")
        if self.step is not None:
            where.append(f"step '{self.step}'")
        msg = f"{', '.join(where)}: {self.reason}" if where else self.reason
        if self.status:
            msg += f" (planner status: {self.status})"
        return msg

    def in_route(self, route: str, path: str | Path | None = None) -> PlanningError:
        """Name the route (and the routes file it comes from) in this error, as the
        planner of a route does for every error its steps raise; a route or file already
        named is kept. Returns the error itself (same type, same evidence)."""
        if self.route is None:
            self.route = route
        if self.path is None and path is not None:
            self.path = Path(path)
        self.args = (self._message(),)
        return self


class PlannerTimeout(PlanningError):
    """The planner ran out of its time budget before finding a path."""


class PourLandingError(PlanningError):
    """A pour can spill outside its receptacle: while the held container is tipped past
    its spill angle, a point of its opening's rim leaves the receptacle's opening (inside
    its wall) or dips below its top, or the step pours into nothing.

    Attributes:
        receptacle: The scene object the step pours into (None: the step names none).
        time: Time of the worst sample [s] (the route's clock).
        lip: The rim point's world position there [m].
        overshoot: How far outside the opening (or below the top) it is there [m].
        distance: Its distance from the receptacle's axis [m] (a box's: along the side
            it crosses; nan when it pours into nothing).
        limit: The most that distance may be: the opening's half-width inside the wall
            [m] (nan when it pours into nothing).
    """

    def __init__(self, reason: str, *, step: str, receptacle: str | None, time: float,
                 lip: Any, overshoot: float, distance: float = float("nan"),
                 limit: float = float("nan")):
        self.receptacle = receptacle
        self.time = time
        self.lip = lip
        self.overshoot = overshoot
        self.distance = distance
        self.limit = limit
        super().__init__(reason, step=step)


class IKError(PlanningError):
    """A Cartesian motion could not be followed by inverse kinematics.

    Attributes:
        fraction: Where along the line it failed, in [0, 1]; None for a target that is
            no line (a ``move`` to a TCP pose).
        position: The TCP target position there [m], world frame.
    """

    def __init__(self, reason: str, *, step: str | None = None,
                 fraction: float | None = 0.0, position: Any = None):
        self.fraction = fraction
        self.position = position
        where = "" if fraction is None else f" at {fraction:.0%} of the line"
        super().__init__(f"{reason}{where}", step=step)


class TimingError(SafepathError):
    """Time parameterisation failed or its result breaks a limit."""


class ExecutedLimitError(TimingError):
    """The motion a trajectory controller executes from a goal's points would break a joint
    limit (speed, acceleration or jerk); the goal is never sent.

    Attributes:
        key: The quantity over its limit (``velocity``, ``acceleration`` or ``jerk``).
        ratio: Its largest ratio to the limit.
    """

    def __init__(self, reason: str, *, key: str | None = None, ratio: float = float("nan")):
        super().__init__(reason)
        self.key = key
        self.ratio = ratio


class VerificationError(SafepathError):
    """A timed trajectory failed the independent re-check; it is never released.

    Attributes:
        time: Trajectory time of the first failing sample [s].
        q: The joint vector there [rad].
        pairs: The colliding pairs.
        step: Route step the sample belongs to.
    """

    def __init__(self, reason: str, *, time: float, q: Any, pairs: Sequence[tuple[str, str]],
                 step: str | None = None):
        self.time = time
        self.q = q
        self.pairs = list(pairs)
        self.step = step
        where = f" in step '{step}'" if step else ""
        super().__init__(f"{reason} at t={time:.3f} s{where}")


class UnprovenClearance(VerificationError):
    """A timed trajectory whose certified clearance bound against an object stays
    negative after the release check's finer check: by the verifier's own figures,
    contact between two samples is not ruled out, so it is never released.

    Attributes:
        pair: The pair (robot link or held object, environment object).
        bound: The certified lower bound on the pair's distance there [m] (negative).
        time: Trajectory time where the interval that bound covers starts [s].
        q: The joint vector there [rad].
        step: Route step it belongs to.
    """

    def __init__(self, reason: str, *, pair: tuple[str, str], bound: float, time: float,
                 q: Any, step: str | None = None):
        self.pair = pair
        self.bound = bound
        super().__init__(reason, time=time, q=q, pairs=[pair], step=step)


class TrajectoryError(InputError):
    """A trajectory is malformed (names, times, non-finite values, sampling)."""


class RosError(SafepathError):
    """A ROS 2 message or bag could not be built, written or read."""


class WorkerLost(SafepathError):
    """A sweep's worker process died, or its Ray cluster was lost, while seeds ran.

    The seeds finished before are on disk (the sweep's results file); running the same
    sweep again finishes the others.
    """
