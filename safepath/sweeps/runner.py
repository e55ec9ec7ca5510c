"""One sweep: a task over seeds, streamed to disk, resumable, reported.

:func:`run_sweep` opens ``OUT/results.jsonl`` (:class:`~safepath.sweeps.store.ResultStore`),
runs only the seeds it does not hold yet on the chosen backend, writes each result the
moment it arrives, and at the end writes the report of all the sweep's seeds, in seed
order, from what the file holds: the same report whatever ran the seeds, in whatever
order, in however many starts.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from .backends import check_options, make_backend
from .progress import Progress
from .report import build_report, write_report
from .store import ResultStore
from .task import SweepTask, TaskResult

__all__ = ["SweepOptions", "SweepOutcome", "run_sweep", "RESULTS"]

#: The results file's name in the output folder.
RESULTS = "results.jsonl"


@dataclass(frozen=True, kw_only=True)
class SweepOptions:
    """How a sweep runs (nothing here changes its results).

    Attributes:
        workers: Local processes (default: the CPUs; 1: this process), or the CPUs of a
            local Ray runtime started for ``cluster="auto"``.
        cluster: None (this machine), ``auto`` or ``ray://HOST:PORT`` (Ray).
        progress: Draw a progress bar on standard error (the command line's; the library
            prints nothing by default).
        title: The report's title.
    """

    workers: int | None = None
    cluster: str | None = None
    progress: bool = False
    title: str = "sweep"

    def __post_init__(self) -> None:
        check_options(self.workers, self.cluster)


@dataclass(frozen=True)
class SweepOutcome:
    """What a sweep did.

    Attributes:
        results: Every seed's result, in seed order.
        ran: The seeds computed by this call, in the order they finished (the others
            were in the results file already).
        report: The report's figures (``report.json``'s content).
        folder: The output folder.
        backend: Where the seeds ran.
    """

    results: dict[int, TaskResult]
    ran: tuple[int, ...]
    report: dict[str, Any]
    folder: Path
    backend: str


def _seed_list(seeds: Iterable[int]) -> list[int]:
    out = list(seeds)
    if not out:
        raise InputError("nothing to run: give at least one seed", key="seeds")
    bad = [s for s in out if isinstance(s, bool) or not isinstance(s, int) or s < 0]
    if bad:
        raise InputError(f"expected integers >= 0, got {bad[0]!r}", key="seeds")
    if len(set(out)) != len(out):
        raise InputError("a seed is given twice", key="seeds")
    return out


def _run_missing(task: SweepTask, todo: list[int], store: ResultStore,
                 options: SweepOptions, total: int) -> tuple[list[int], str]:
    """Run the seeds the file lacks, each written down as it finishes.

    Returns:
        The seeds run, in the order they finished, and where they ran.
    """
    if not todo:
        return [], "none (every seed was in the file)"
    backend = make_backend(workers=options.workers, cluster=options.cluster)
    bar = Progress(total, total - len(todo), enabled=options.progress, label=options.title)
    ran: list[int] = []
    try:
        for seed, data, duration in backend.run(task, todo):
            result = store.append(seed, data, duration)
            ran.append(seed)
            bar.advance(failed=not result.ok)
    finally:
        bar.close()
        backend.close()
    return ran, backend.name


def run_sweep(task: SweepTask, seeds: Iterable[int], out: str | Path,
              options: SweepOptions | None = None) -> SweepOutcome:
    """Run ``task`` for every seed not yet in ``out``, then write its report.

    Args:
        task: The seeded task (sent to the workers).
        seeds: The sweep's seeds.
        out: The output folder: ``results.jsonl``, ``report.json``, ``report.html``.
        options: Backend and progress.

    Raises:
        InputError: No seed, bad options (:class:`SweepOptions`), or ``out`` holds
            another sweep's results.
    """
    options = options or SweepOptions()
    seed_list = _seed_list(seeds)
    folder = Path(out)
    if folder.exists() and not folder.is_dir():
        raise InputError("exists and is no folder", path=folder, key="--out")
    t0 = time.perf_counter()
    with ResultStore(folder / RESULTS, task.identity()) as store:
        todo = [s for s in seed_list if s not in store.finished]
        ran, where = _run_missing(task, todo, store, options, len(seed_list))
        results = {s: store.finished[s] for s in sorted(seed_list)}
        computed = sum(store.times[s] for s in seed_list)
    load = os.getloadavg()
    run = {"backend": where,
           "seeds run now": len(ran), "wall time now [s]": round(time.perf_counter() - t0, 2),
           "computation of all seeds [s]": round(computed, 2),
           "load": f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs"}
    report = build_report(options.title, results, task.labels(), task.replay, run)
    write_report(report, folder)
    return SweepOutcome(results, tuple(ran), report, folder, where)
