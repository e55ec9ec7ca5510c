"""Sweeps: a seeded task over many seeds, on a local process pool or a Ray cluster.

* :func:`run_sweep` runs a :class:`SweepTask` over seeds, writes each seed's
  :class:`TaskResult` to ``OUT/results.jsonl`` as it finishes, resumes a sweep that was
  stopped (only the missing seeds run), and writes the report (``report.html`` with plots,
  ``report.json`` with the same figures);
* backends (:mod:`~safepath.sweeps.backends`): this process, a local process pool (the
  default), or Ray (``cluster="auto"`` or ``"ray://HOST:PORT"``; ``pip install
  safepath[cluster]``, imported only then);
* :func:`wilson_interval`: the rates' confidence interval.

The twin's tasks are :mod:`safepath.sim.sweep_tasks`; ``docs/sweeps.md`` is the guide.
"""

from __future__ import annotations

from .runner import RESULTS, SweepOptions, SweepOutcome, run_sweep
from .stats import wilson_interval
from .task import ReplayBySeed, SweepTask, TaskResult

__all__ = ["RESULTS", "ReplayBySeed", "SweepOptions", "SweepOutcome", "SweepTask", "TaskResult",
           "run_sweep", "wilson_interval"]
