"""What a sweep runs: a seeded task and the result it returns.

A task is a picklable object called with one seed in whatever process runs it (this
one, a worker of the local pool, a Ray worker): everything it needs travels with it (a
scene folder's path, frozen parameters), and a seed gives the same result anywhere. Its
result is plain data that a JSON line holds exactly: figures (numbers or lists of
numbers) and checks (pass or fail), or the error that stopped the run.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from ..errors import InputError

__all__ = ["SweepTask", "TaskResult", "execute", "Finished"]

Figure = float | tuple[float, ...]
#: A finished seed: ``(seed, result JSON data, computation time [s])``.
Finished = tuple[int, dict[str, Any], float]


@dataclass(frozen=True)
class TaskResult:
    """What one seed of a task gave.

    Attributes:
        figures: Measured values by key: a number, or several (one per cycle, ...).
        checks: Pass (True) or fail (False) by key; a run with a failed check is a failure.
        error: The exception that stopped the run (``Type: message``), or None.
    """

    figures: Mapping[str, Figure] = field(default_factory=dict)
    checks: Mapping[str, bool] = field(default_factory=dict)
    error: str | None = None

    @property
    def failed(self) -> tuple[str, ...]:
        """The keys of the failed checks (``error`` apart)."""
        return tuple(k for k, ok in self.checks.items() if not ok)

    @property
    def ok(self) -> bool:
        """No error and every check passed."""
        return self.error is None and not self.failed

    def to_json(self) -> dict[str, Any]:
        """The result as JSON data (figures as floats or lists of floats)."""
        figures = {k: list(v) if isinstance(v, tuple) else v for k, v in self.figures.items()}
        out: dict[str, Any] = {"figures": figures,
                               "checks": {k: bool(v) for k, v in self.checks.items()}}
        if self.error is not None:
            out["error"] = self.error
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> TaskResult:
        """The result of :meth:`to_json`'s data.

        Raises:
            InputError: Data of another shape.
        """
        if not isinstance(data, Mapping) or not isinstance(data.get("figures"), Mapping) \
                or not isinstance(data.get("checks"), Mapping):
            raise InputError(f"expected figures and checks, got {data!r:.80}", key="result")
        figures: dict[str, Figure] = {}
        for key, value in data["figures"].items():
            figures[key] = tuple(float(v) for v in value) if isinstance(value, list) \
                else float(value)
        checks = {k: bool(v) for k, v in data["checks"].items()}
        return cls(figures, checks, data.get("error"))


@runtime_checkable
class SweepTask(Protocol):
    """A seeded task a sweep maps over seeds (picklable: it is sent to the workers)."""

    def __call__(self, seed: int) -> TaskResult:
        """Run the task for one seed (the same result in any process)."""
        ...

    def identity(self) -> dict[str, Any]:
        """What the task is, as JSON data: a sweep resumes only an output of the same."""
        ...

    def labels(self) -> dict[str, str]:
        """The report's words for each figure and check key (units in brackets)."""
        ...

    def replay(self, seed: int) -> str:
        """The command that runs this seed alone."""
        ...


class ReplayBySeed:
    """What a task whose ``replay_command`` holds ``{seed}`` needs for :meth:`replay`
    (a base of frozen dataclasses that declare ``replay_command: str`` themselves)."""

    replay_command: str

    def replay(self, seed: int) -> str:
        """The command that runs ``seed`` alone."""
        return self.replay_command.format(seed=seed)


def execute(task: SweepTask, seed: int) -> Finished:
    """Run one seed where it was sent: its result as JSON data and its computation time.

    An exception of the task becomes the seed's ``error`` (the sweep goes on and the
    report lists the seed); ``KeyboardInterrupt`` and ``SystemExit`` stop the sweep.

    Returns:
        ``(seed, result JSON data, computation time [s])``.
    """
    t0 = time.perf_counter()
    try:
        result = task(seed)
        if not isinstance(result, TaskResult):
            raise TypeError(f"the task returned {type(result).__name__}, not a TaskResult")
        for key, value in result.figures.items():
            values = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, float) and not math.isnan(v) for v in values):
                raise TypeError(f"figure '{key}' is not a float or a tuple of floats "
                                f"(NaN is no figure): {value!r:.60}")
    except Exception as exc:  # noqa: BLE001 - one seed's failure is its result
        where = traceback.extract_tb(exc.__traceback__)[-1]
        result = TaskResult(error=f"{type(exc).__name__}: {exc} "
                                  f"({where.filename.rsplit('/', 1)[-1]}:{where.lineno})")
    return seed, result.to_json(), time.perf_counter() - t0
