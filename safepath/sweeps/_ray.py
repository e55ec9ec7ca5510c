"""The Ray backend (``--cluster``): the same tasks on a Ray cluster or a local Ray runtime.

Ray (``pip install safepath[cluster]``) is imported here only, when a sweep asks for a
cluster. The task is put once in Ray's object store; each seed is one Ray task running
:func:`~safepath.sweeps.task.execute` on a worker, which keeps its process (and what the
task planned once per process) for the next seeds; results are taken with ``ray.wait`` as
they finish. A worker needs safepath installed and the task's files (a scene folder's
path) where the task names them.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from typing import Any

from ..errors import InputError, WorkerLost
from .task import Finished, SweepTask, execute

__all__ = ["RayCluster"]


def _ray() -> Any:
    try:
        import ray
    except ImportError:
        raise InputError("Ray is not installed: pip install 'safepath[cluster]'",
                         key="--cluster") from None
    return ray


class RayCluster:
    """Seeds as Ray tasks.

    Args:
        address: ``auto`` (the cluster ``RAY_ADDRESS`` or ``ray start`` on this machine
            names, else a local Ray runtime started for the sweep) or ``ray://HOST:PORT``.
        workers: CPUs of a local Ray runtime started here (default: the machine's);
            a running cluster keeps its own.

    Raises:
        InputError: Ray is not installed, or no cluster answers at ``address``.
        WorkerLost: (from :meth:`run`) Ray lost a worker or a node while seeds ran.
    """

    def __init__(self, address: str, *, workers: int | None = None) -> None:
        ray = _ray()
        self._started = False
        self.name = "Ray"
        if ray.is_initialized():  # a runtime this process runs already (a test's)
            self.name = f"Ray (this process's runtime, {self._cpus(ray)} CPUs)"
            return
        quiet: dict[str, Any] = {"logging_level": logging.WARNING, "log_to_driver": False}
        try:
            if address == "auto":
                try:
                    ray.init(address="auto", **quiet)
                except ConnectionError:  # no cluster running: a local runtime of our own
                    ray.init(num_cpus=workers, include_dashboard=False, **quiet)
            else:
                ray.init(address=address, **quiet)
        except ConnectionError as exc:
            raise InputError(f"no Ray cluster answers: {exc}", key="--cluster") from None
        self._started = True
        self.name = f"Ray at {address} ({self._cpus(ray)} CPUs)"

    @staticmethod
    def _cpus(ray: Any) -> int:
        return int(ray.cluster_resources().get("CPU", 0))

    def run(self, task: SweepTask, seeds: Sequence[int]) -> Iterator[Finished]:
        if not seeds:
            return
        ray = _ray()
        remote = ray.remote(execute)
        task_ref = ray.put(task)
        pending = [remote.remote(task_ref, seed) for seed in seeds]
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    yield ray.get(ref)
        except ray.exceptions.RayError as exc:  # a worker or node lost, not a seed's error
            raise WorkerLost(f"Ray lost a seed's worker ({type(exc).__name__}: {exc}"[:300]
                             + "): the seeds finished before are kept; run the sweep again "
                             "to finish the others") from None
        finally:
            for ref in pending:  # a stop (Ctrl-C, an error): run no more
                ray.cancel(ref)

    def close(self) -> None:
        """Shut down the runtime this backend started (one it found keeps running)."""
        if self._started:
            _ray().shutdown()
            self._started = False
