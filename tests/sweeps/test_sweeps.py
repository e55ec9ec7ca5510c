"""One sweep runner: results streamed to a JSON-lines file, resumed after a kill, the same
results bit for bit in this process, on a local pool and on Ray."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path
from typing import Any

import pytest

from safepath.errors import InputError, WorkerLost
from safepath.sweeps import RESULTS, SweepOptions, TaskResult, run_sweep
from safepath.sweeps.store import ResultStore

from .conftest import quick_task

QUIET = SweepOptions(workers=1, progress=False, title="quick")


def _lines(folder: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (folder / RESULTS).read_text().splitlines()]


def _by_seed(folder: Path) -> dict[int, Any]:
    """Each seed's result as the file holds it (the computation time apart)."""
    return {line["seed"]: line["result"] for line in _lines(folder)[1:]}


def _differences(*runs: dict[int, Any]) -> str:
    """Which seed and key differ between runs (the assertion's message)."""
    out = []
    for seed in sorted(runs[0]):
        for part in ("figures", "checks"):
            values = [r.get(seed, {}).get(part, {}) for r in runs]
            for key in sorted(set().union(*values)):
                seen = [v.get(key) for v in values]
                if any(s != seen[0] for s in seen):
                    out.append(f"seed {seed} {part}.{key}: {seen}")
    return "\n".join(out) or "no figure or check differs"


def _figures(report: dict[str, Any]) -> dict[str, Any]:
    """The report without its ``run`` part (backend, times, load)."""
    return {k: v for k, v in report.items() if k != "run"}


def test_a_sweep_killed_mid_line_finishes_only_the_missing_seeds(task: Any, tmp_path: Path
                                                                 ) -> None:
    out = tmp_path / "sweep"
    first = run_sweep(task, range(4), out, QUIET)
    assert sorted(first.ran) == [0, 1, 2, 3]
    lines = (out / RESULTS).read_bytes().split(b"\n")
    assert len(lines) == 6 and lines[-1] == b""  # header, 4 seeds, the final newline
    whole = _by_seed(out)
    # The kill: the file ends halfway through its fourth line (the third seed written);
    # the last seed's line never came.
    kept = b"\n".join(lines[:3]) + b"\n" + lines[3][: len(lines[3]) // 2]
    (out / RESULTS).write_bytes(kept)
    done_before = {json.loads(line)["seed"] for line in lines[1:3]}
    missing = {0, 1, 2, 3} - done_before

    again = run_sweep(task, range(4), out, QUIET)
    assert sorted(again.ran) == sorted(missing) and len(missing) == 2
    assert _by_seed(out) == whole  # every seed once, the same results
    assert len(_lines(out)) == 5
    assert _figures(again.report) == _figures(first.report)
    # Nothing missing: nothing runs, and the report is written again all the same.
    assert run_sweep(task, range(4), out, QUIET).ran == ()
    # Extended: only the new seeds run.
    assert run_sweep(task, range(6), out, QUIET).ran == (4, 5)


def test_another_task_or_a_broken_middle_line_is_refused(task: Any, cell_dir: Path,
                                                         tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    run_sweep(task, range(2), out, QUIET)
    with pytest.raises(InputError, match=r"results.jsonl.*another sweep \(task.variants."
                                         r"safepath.arrival_interval is 2.0, this sweep.s 3.0"):
        run_sweep(quick_task(cell_dir, arrival=3.0), range(2), out, QUIET)
    lines = (out / RESULTS).read_text().splitlines()
    (out / RESULTS).write_text("\n".join([lines[0], lines[1][:20], lines[2]]) + "\n")
    with pytest.raises(InputError, match="line 2 is no result"):
        run_sweep(task, range(2), out, QUIET)
    # One sweep writes a file at a time.
    with ResultStore(tmp_path / "other.jsonl", task.identity()), \
            pytest.raises(InputError, match="another sweep is writing"):
        ResultStore(tmp_path / "other.jsonl", task.identity())
    with pytest.raises(InputError, match="twice"):
        run_sweep(task, [1, 1], tmp_path / "twice", QUIET)
    with pytest.raises(InputError, match="--cluster"):
        SweepOptions(cluster="http://host:1")
    with pytest.raises(InputError, match="--workers"):
        SweepOptions(workers=0)


def test_this_process_a_local_pool_and_ray_give_the_same_results(task: Any, tmp_path: Path
                                                                 ) -> None:
    """This process (after whatever the test session ran in it before), a local pool and
    Ray: bit for bit, the same lines per seed (in whatever order they finished) and the
    same report (coal's first query no longer leaks into later distances:
    ``tests/test_coal_first_query.py``)."""
    ray = pytest.importorskip("ray")  # installed by the dev extra: `make test` runs this
    seeds = range(4)
    here = run_sweep(task, seeds, tmp_path / "here", QUIET)
    pool = run_sweep(task, seeds, tmp_path / "pool", SweepOptions(workers=2, progress=False,
                                                                  title="quick"))
    on_ray = run_sweep(task, seeds, tmp_path / "ray",
                       SweepOptions(workers=2, cluster="auto", progress=False, title="quick"))
    assert not ray.is_initialized()  # the runtime the sweep started is shut down
    assert here.backend == "this process" and "pool of 2" in pool.backend
    assert on_ray.backend.startswith("Ray at auto")
    here_lines, pool_lines, ray_lines = (_by_seed(tmp_path / name)
                                         for name in ("here", "pool", "ray"))
    assert here_lines == pool_lines, _differences(here_lines, pool_lines)
    assert _figures(here.report) == _figures(pool.report)
    assert here_lines == ray_lines, _differences(here_lines, ray_lines)
    assert _figures(here.report) == _figures(on_ray.report)
    # The results are the runs' own: the arm moved (a clearance was measured) in some seed.
    assert any(d["count"] for d in here.report["distributions"]
               if d["key"] == "safepath.clearance")


class _DiesAtSeed2:
    """A task whose worker process dies at seed 2 (as an out-of-memory kill would)."""

    def __call__(self, seed: int) -> TaskResult:
        if seed == 2:
            os.kill(os.getpid(), signal.SIGKILL)  # as the out-of-memory killer would
        return TaskResult(figures={"seed": float(seed)})

    def identity(self) -> dict[str, Any]:
        return {"kind": "dies at seed 2"}

    def labels(self) -> dict[str, str]:
        return {}

    def replay(self, seed: int) -> str:
        return f"replay {seed}"


def test_a_worker_that_dies_is_a_typed_error_and_the_finished_seeds_stay(tmp_path: Path
                                                                         ) -> None:
    with pytest.raises(WorkerLost, match="run the sweep again"):
        run_sweep(_DiesAtSeed2(), [2], tmp_path / "dies",
                  SweepOptions(workers=2, progress=False))
    out = tmp_path / "dies"
    run_sweep(_DiesAtSeed2(), [0, 1], out, SweepOptions(workers=2, progress=False))
    with pytest.raises(WorkerLost):
        run_sweep(_DiesAtSeed2(), [0, 1, 2], out, SweepOptions(workers=2, progress=False))
    assert sorted(_by_seed(out)) == [0, 1]
