"""Many runs of the twin in parallel, with a local process pool.

:func:`run_many` maps :func:`~safepath.sim.quality_check.run_quality_check` (a plain,
picklable function of ``(cell, seed, params)``) over seeds and parameter sets with
``concurrent.futures.ProcessPoolExecutor``. A cluster user hands the same function and
arguments to their engine's ``map`` (Dask, Ray, ...) instead; nothing here schedules.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from ..errors import InputError
from .quality_check import QualityCheckParams, QualityCheckRun, run_quality_check

__all__ = ["run_many"]


def run_many(cell: str | Path, seeds: Iterable[int],
             params: Sequence[QualityCheckParams] | QualityCheckParams | None = None, *,
             workers: int | None = None) -> list[QualityCheckRun]:
    """Every combination of ``params`` and ``seeds``, params-major, in that order.

    Args:
        cell: The cell's scene folder.
        seeds: The runs' seeds.
        params: One parameter set or several (default: one default set).
        workers: Processes (default: the CPUs; 1 runs in this process).

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
    jobs = [(str(cell), seed, p) for p in sets for seed in seed_list]
    if workers == 1:
        return [run_quality_check(*job) for job in jobs]
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs))) as pool:
        return list(pool.map(run_quality_check, *zip(*jobs, strict=True)))
