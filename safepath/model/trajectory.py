"""Timed joint trajectories: the library's output.

A :class:`Trajectory` holds dense knots (time, position, velocity, acceleration), the
route step every knot belongs to, the gripper events, and the interpolation of the
controller it is for. Between knots it is joined as that controller joins a goal's points
(:attr:`Trajectory.interpolation`, :mod:`safepath.model.interpolation`; quintic unless the
robot's ``controller.yaml`` says otherwise), so that
what :meth:`Trajectory.sample` gives at any instant is what the robot executes when the
knots are sent as a goal's points. It exports to JSON (lossless) and
CSV, and reports its duration per step.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import orjson

from ..errors import ConfigError, TrajectoryError
from ..files._io import atomic_write_text, read_text
from ._knots import interval_index
from .interpolation import QUINTIC, Interpolation, interpolation_named
from .limits import MotionLimits

__all__ = ["GripperEvent", "Trajectory", "load_trajectory"]

#: The knot arrays of a trajectory's JSON form, in their order after the rest.
_ARRAYS = ("t", "q", "qd", "qdd", "step_index")

#: The file format tag (unchanged since trajectories were first written: the module moved).
FORMAT = "safepath.trajectory/1"


@dataclass(frozen=True)
class GripperEvent:
    """A gripper action at a stop of the trajectory.

    Attributes:
        time: When it happens [s] (the robot is at rest).
        action: ``open`` or ``close``.
        step: Route step name.
        object: Object attached (close) or released (open), if any.
    """

    time: float
    action: Literal["open", "close"]
    step: str
    object: str | None = None


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A timed, verified joint trajectory.

    Attributes:
        joint_names: Joint order of the columns.
        t: Knot times [s], strictly increasing, starting at 0.
        q: Positions [rad], shape (N, dof).
        qd: Velocities [rad/s], shape (N, dof).
        qdd: Accelerations [rad/s^2], shape (N, dof).
        step_index: For each knot, the index into :attr:`steps` it belongs to.
        steps: Route step names.
        events: Gripper events.
        robot: Robot name.
        route: Route name.
        info: Free-form facts (planning time, clearance, ...), JSON-serialisable.
        limits: The joint speed limits it was timed under, which its goals' executed
            motion is checked against (None: a trajectory built without them; a goal
            of it then needs ``limits=``).
        interpolation: How the controller it is for joins its knots (its robot's
            ``controller.yaml``; quintic by default and for files written without it):
            what :meth:`sample`, its goals and their checks join knots with.
    """

    joint_names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    q: np.ndarray = field(repr=False)
    qd: np.ndarray = field(repr=False)
    qdd: np.ndarray = field(repr=False)
    step_index: np.ndarray = field(repr=False)
    steps: tuple[str, ...] = ()
    events: tuple[GripperEvent, ...] = ()
    robot: str = ""
    route: str = ""
    info: dict[str, Any] = field(default_factory=dict, compare=False)
    limits: MotionLimits | None = None
    interpolation: Interpolation = QUINTIC

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        t = np.asarray(self.t, dtype=float)
        if t.ndim != 1 or t.size < 1:
            raise TrajectoryError("times must be a non-empty 1-D array", key="t")
        for name in ("q", "qd", "qdd"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.shape != (t.size, n):
                raise TrajectoryError(f"expected shape {(t.size, n)}, got {arr.shape}", key=name)
            if not np.all(np.isfinite(arr)):
                row = int(np.argwhere(~np.isfinite(arr))[0][0])
                raise TrajectoryError(f"non-finite value at knot {row}", key=name)
            object.__setattr__(self, name, arr)
        if not np.all(np.isfinite(t)):
            raise TrajectoryError("non-finite time", key="t")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            k = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise TrajectoryError(f"times not increasing at knot {k + 1} "
                                  f"({t[k]:.6f} -> {t[k + 1]:.6f} s)", key="t")
        object.__setattr__(self, "t", t)
        idx = np.asarray(self.step_index, dtype=int)
        if idx.shape != t.shape:
            raise TrajectoryError(f"expected {t.size} step indices, got {idx.size}",
                                  key="step_index")
        if self.steps and (idx.min() < 0 or idx.max() >= len(self.steps)):
            raise TrajectoryError("step index out of range", key="step_index")
        object.__setattr__(self, "step_index", idx)
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        self._check_controller(n)

    def _check_controller(self, n: int) -> None:
        """Refuse limits of another number of joints than ``n``, or no Interpolation."""
        if not isinstance(self.interpolation, Interpolation):
            raise TrajectoryError(f"expected an Interpolation, got {self.interpolation!r}",
                                  key="interpolation")
        if self.limits is not None:
            if not isinstance(self.limits, MotionLimits):
                raise TrajectoryError(f"expected MotionLimits, got "
                                      f"{type(self.limits).__name__}", key="limits")
            if self.limits.dof != n:
                raise TrajectoryError(f"expected limits of {n} joints, got "
                                      f"{self.limits.dof}", key="limits")

    def __eq__(self, other: object) -> bool:
        """Equal when every field is equal (arrays element by element, exactly)."""
        if not isinstance(other, Trajectory):
            return NotImplemented
        arrays = ("t", "q", "qd", "qdd", "step_index")
        return (all(np.array_equal(getattr(self, a), getattr(other, a)) for a in arrays)
                and (self.joint_names, self.steps, self.events, self.robot, self.route,
                     self.limits, self.interpolation)
                == (other.joint_names, other.steps, other.events, other.robot, other.route,
                    other.limits, other.interpolation))

    __hash__ = None  # type: ignore[assignment]  # mutable arrays inside

    # -- facts -----------------------------------------------------------------------------
    @property
    def duration(self) -> float:
        """Total motion time [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def dof(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    def step_durations(self) -> dict[str, float]:
        """Time spent in each step [s] (a step's knots span to the next step's first)."""
        out: dict[str, float] = {}
        for k, name in enumerate(self.steps):
            sel = np.flatnonzero(self.step_index == k)
            if sel.size == 0:
                out[name] = 0.0
                continue
            end = min(sel[-1] + 1, self.t.size - 1)
            out[name] = float(self.t[end] - self.t[sel[0]])
        return out

    def step_at(self, time: float) -> str:
        """Name of the step being executed at ``time`` [s]."""
        k = int(interval_index(self.t, time, self.t.size))
        return self.steps[self.step_index[k]] if self.steps else ""

    # -- sampling --------------------------------------------------------------------------
    def sample(self, times: Sequence[float] | np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at ``times`` [s] (clamped to the ends),
        on the join of the knots by :attr:`interpolation` (what the controller executes
        from them)."""
        from .execution import join

        ts = np.clip(np.asarray(times, dtype=float), self.t[0], self.t[-1])
        if self.t.size == 1:
            n = ts.size
            return (np.repeat(self.q, n, 0), np.repeat(self.qd, n, 0), np.repeat(self.qdd, n, 0))
        q, qd, qdd, _ = join(self.t, self.q, self.qd, self.qdd, ts,
                             interpolation=self.interpolation)
        return q, qd, qdd

    def resample(self, period: float) -> Trajectory:
        """The same trajectory sampled every ``period`` [s] (and at the final knot).

        The samples lie on this trajectory's motion, but their own join is not
        that motion (the knots are not kept): use it to export or plot, not to send.

        Raises:
            TrajectoryError: ``period`` is not positive and finite.
        """
        if not np.isfinite(period) or period <= 0:
            raise TrajectoryError(f"sampling period must be > 0, got {period}", key="period")
        times = np.arange(self.t[0], self.t[-1], period)
        if times.size == 0 or self.t[-1] - times[-1] > 1e-9:
            times = np.append(times, self.t[-1])
        q, qd, qdd = self.sample(times)
        qd[0], qdd[0] = self.qd[0], self.qdd[0]
        q[-1], qd[-1], qdd[-1] = self.q[-1], self.qd[-1], self.qdd[-1]
        k = interval_index(self.t, times, self.t.size)
        return Trajectory(self.joint_names, times, q, qd, qdd, self.step_index[k], self.steps,
                          self.events, self.robot, self.route, dict(self.info), self.limits,
                          self.interpolation)

    # -- export ----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Lossless JSON-compatible form (floats at full precision)."""
        return {**self._head(),
                **{name: getattr(self, name).tolist() for name in _ARRAYS}}

    def _head(self) -> dict[str, Any]:
        """:meth:`to_dict` without the knot arrays (``t``, ``q``, ``qd``, ``qdd``,
        ``step_index``), which follow it in that order."""
        return {
            "format": FORMAT,
            "robot": self.robot,
            "route": self.route,
            "joint_names": list(self.joint_names),
            "steps": list(self.steps),
            "events": [e.__dict__ for e in self.events],
            "info": self.info,
            **({} if self.limits is None else {"limits": self.limits.to_dict()}),
            "interpolation": self.interpolation.name,
        }

    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text (the form of :meth:`to_dict`); written atomically to ``path`` when
        given. The knot arrays are written by orjson (shortest round-trip text of every
        float, as Python's ``repr``, ~15x faster); the rest by :mod:`json`."""
        form = self._head()
        head = json.dumps(form, indent=None, separators=(",", ":"))
        arrays = "".join(f',"{name}":{_json_array(getattr(self, name))}' for name in _ARRAYS)
        text = head[:-1] + arrays + "}"
        if path is not None:
            atomic_write_text(path, text + "\n")
        return text

    def to_csv(self, path: str | Path | None = None, *, period: float | None = None) -> str:
        """CSV with columns t, step, q_*, qd_*, qdd_*; resampled at ``period`` if given."""
        traj = self if period is None else self.resample(period)
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(["t", "step"] + [f"q_{n}" for n in self.joint_names]
                        + [f"qd_{n}" for n in self.joint_names]
                        + [f"qdd_{n}" for n in self.joint_names])
        # Each step's cell quoted by the csv writer once; the numbers are the shortest
        # text that reads back as the same float (orjson's, as Python's repr; never
        # quoted), the rows cut from one array's JSON text: a fraction of the time of
        # one writerow per knot.
        cells = [_csv_cell(name) for name in traj.steps or ("",)]
        index = traj.step_index.tolist() if traj.steps else [0] * traj.t.size
        times = _json_array(traj.t)[1:-1].split(",")
        rows = _json_array(np.hstack([traj.q, traj.qd, traj.qdd]))[2:-2].split("],[")
        buf.writelines(f"{tk},{cells[i]},{row}\n"
                       for tk, i, row in zip(times, index, rows, strict=True))
        text = buf.getvalue()
        if path is not None:
            atomic_write_text(path, text)
        return text

    @classmethod
    def from_dict(cls, data: Any, *, path: str | Path | None = None) -> Trajectory:
        """Inverse of :meth:`to_dict`.

        Raises:
            TrajectoryError: Missing keys or inconsistent arrays (names the file).
        """
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise TrajectoryError(f"not a safepath trajectory (format {FORMAT!r} expected)",
                                  path=path, key="format")
        info = dict(data.get("info", {}))
        # Files written before the limits had a field of their own kept them in info.
        raw = data.get("limits", info.pop("limits", None))
        try:
            limits = None if raw is None else MotionLimits.from_dict(raw, path=path)
            events = tuple(GripperEvent(**e) for e in data.get("events", []))
            # Files written before the interpolation was recorded were quintic.
            interpolation = interpolation_named(data.get("interpolation", QUINTIC.name),
                                                path=path)
            return cls(tuple(data["joint_names"]), np.array(data["t"], dtype=float),
                       np.array(data["q"], dtype=float), np.array(data["qd"], dtype=float),
                       np.array(data["qdd"], dtype=float),
                       np.array(data["step_index"], dtype=int), tuple(data.get("steps", [])),
                       events, str(data.get("robot", "")), str(data.get("route", "")),
                       info, limits, interpolation)
        except ConfigError as exc:
            raise TrajectoryError(exc.reason, path=path, key=exc.key) from None
        except KeyError as exc:
            raise TrajectoryError("missing key", path=path, key=str(exc.args[0])) from None
        except TrajectoryError as exc:
            raise TrajectoryError(exc.reason, path=path, key=exc.key) from None
        except (TypeError, ValueError) as exc:
            raise TrajectoryError(f"malformed trajectory ({exc})", path=path) from None


def load_trajectory(path: str | Path) -> Trajectory:
    """Read a trajectory written by :meth:`Trajectory.to_json`."""
    path = Path(path)
    text = read_text(path, error=TrajectoryError)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TrajectoryError(f"cannot read trajectory ({exc})", path=path) from None
    return Trajectory.from_dict(data, path=path)


def _csv_cell(text: str) -> str:
    """``text`` as the csv writer writes it among other fields (quoted where needed)."""
    if not text:
        return ""
    one = io.StringIO()
    csv.writer(one, lineterminator="\n").writerow([text])
    return one.getvalue()[:-1]


def _json_array(arr: np.ndarray) -> str:
    """JSON text of a finite numeric array: every float the shortest text that reads back
    as the same value (``-0.0`` kept), ints as ints."""
    return orjson.dumps(np.ascontiguousarray(arr), option=orjson.OPT_SERIALIZE_NUMPY).decode()
