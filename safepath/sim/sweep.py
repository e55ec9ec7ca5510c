"""Many runs of the twin in parallel, with a local process pool.

:func:`run_many` maps :func:`~safepath.sim.quality_check.run_quality_check` or
:func:`~safepath.sim.pouring.run_pouring` (plain, picklable functions of
``(cell, seed, params)``; chosen by the parameters' type) over seeds and parameter sets with
``concurrent.futures.ProcessPoolExecutor`` and returns the runs themselves (with their
bag material when asked). Many seeds streamed to disk, resumable, on the pool or on Ray,
with a report: :mod:`safepath.sweeps` with the tasks of :mod:`safepath.sim.sweep_tasks`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from ..errors import InputError
from .pouring import PouringParams, run_pouring
from .quality_check import QualityCheckParams, run_quality_check

__all__ = ["run_many"]


def run_many(cell: str | Path, seeds: Iterable[int],
             params: Sequence[QualityCheckParams | PouringParams] | QualityCheckParams
             | PouringParams | None = None, *, workers: int | None = None,
             record: bool = False) -> list[Any]:
    """Every combination of ``params`` and ``seeds``, params-major, in that order.

    Args:
        cell: The cell's scene folder.
        seeds: The runs' seeds.
        params: One parameter set or several (default: one default set of the
            quality-check cell): :class:`QualityCheckParams` run the quality-check twin,
            :class:`PouringParams` the pouring twin.
        workers: Processes (default: the CPUs; 1 runs in this process).
        record: Keep every run's bag material (``record=True`` of each run; sent back
            from the workers with the run).

    Raises:
        InputError: No seed, or ``workers`` < 1.
    """
    sets = [params or QualityCheckParams()] if not isinstance(params, Sequence) \
        else list(params)
    seed_list = list(seeds)
    if not seed_list or not sets:
        raise InputError("nothing to run: give at least one seed and one parameter set",
                         key="seeds")
    workers = workers if workers is not None else (os.cpu_count() or 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"expected an integer >= 1, got {workers!r}", key="workers")
    jobs = [(str(cell), seed, p, record) for p in sets for seed in seed_list]
    if workers == 1:
        return [_run(*job) for job in jobs]
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs))) as pool:
        return list(pool.map(_run, *zip(*jobs, strict=True)))


def _run(cell: str, seed: int, params: QualityCheckParams | PouringParams,
         record: bool = False) -> Any:
    """One run, of the twin the parameters are for."""
    if isinstance(params, PouringParams):
        return run_pouring(cell, seed, params, record=record)
    if isinstance(params, QualityCheckParams):
        return run_quality_check(cell, seed, params, record=record)
    raise InputError(f"expected QualityCheckParams or PouringParams, got "
                     f"{type(params).__name__}", key="params")
