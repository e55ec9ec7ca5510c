"""Where a sweep's tasks run: this process, a local process pool (the default), or Ray.

A backend sends the task (pickled with each seed for the local pool, a few hundred bytes;
put once in Ray's object store for Ray) and each seed, runs
:func:`~safepath.sweeps.task.execute` there, and yields each seed's result as it
finishes, in whatever order they finish: the sweep writes them down
keyed by seed, so the order changes nothing of the results.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Protocol

from ..errors import InputError, WorkerLost
from .task import Finished, SweepTask, execute

__all__ = ["Backend", "InProcess", "LocalPool", "make_backend", "check_options"]


class Backend(Protocol):
    """Runs a task over seeds somewhere."""

    name: str

    def run(self, task: SweepTask, seeds: Sequence[int]) -> Iterator[Finished]:
        """Each seed's result as it finishes."""
        ...

    def close(self) -> None:
        """Release what the backend started."""
        ...


class InProcess:
    """Every seed in this process, one after the other (``workers=1``)."""

    name = "this process"

    def run(self, task: SweepTask, seeds: Sequence[int]) -> Iterator[Finished]:
        for seed in seeds:
            yield execute(task, seed)

    def close(self) -> None:
        """Nothing to release."""


class LocalPool:
    """A ``concurrent.futures`` process pool on this machine.

    Args:
        workers: Processes (>= 1).

    Raises:
        WorkerLost: (from :meth:`run`) A worker process died (killed, out of memory).
    """

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self.name = f"a local pool of {workers} processes"

    def run(self, task: SweepTask, seeds: Sequence[int]) -> Iterator[Finished]:
        if not seeds:
            return
        with ProcessPoolExecutor(max_workers=min(self.workers, len(seeds))) as pool:
            pending: set[Future[Finished]] = {pool.submit(execute, task, s) for s in seeds}
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        yield future.result()
            except BrokenProcessPool as exc:
                raise WorkerLost(f"a worker process of the pool died ({exc}): the seeds "
                                 "finished before are kept; run the sweep again to finish "
                                 "the others") from None
            finally:
                for future in pending:  # a stop (Ctrl-C, an error): start no more
                    future.cancel()

    def close(self) -> None:
        """The pool closes with each run."""


def check_options(workers: int | None, cluster: str | None) -> None:
    """Refuse backend options that name no backend.

    Raises:
        InputError: ``workers`` < 1, or a cluster address other than ``auto`` or
            ``ray://HOST:PORT``.
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise InputError(f"expected an integer >= 1, got {workers!r}", key="--workers")
    if cluster is not None and cluster != "auto" and not (
            isinstance(cluster, str) and cluster.startswith("ray://")
            and len(cluster) > len("ray://")):
        raise InputError(f"expected 'auto' or 'ray://HOST:PORT', got {cluster!r}",
                         key="--cluster")


def make_backend(*, workers: int | None = None, cluster: str | None = None) -> Backend:
    """The backend the options name.

    Args:
        workers: Local processes (default: the CPUs; 1 runs in this process); with a
            cluster, the CPUs of a local Ray runtime it starts (default: the CPUs).
        cluster: None for this machine; ``auto`` for Ray (the cluster ``RAY_ADDRESS`` or
            ``ray start`` on this machine names, else a local Ray runtime started for the
            sweep); ``ray://HOST:PORT`` for a Ray cluster's client server.

    Raises:
        InputError: Options that name no backend (:func:`check_options`).
    """
    check_options(workers, cluster)
    if cluster is not None:
        from ._ray import RayCluster

        return RayCluster(cluster, workers=workers)
    workers = workers if workers is not None else (os.cpu_count() or 1)
    return InProcess() if workers == 1 else LocalPool(workers)
