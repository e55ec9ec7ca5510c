"""The randomized timing suite as a sweep task: the same lines in this process and on a
pool, a seed's figures those of its path timed alone, resumed without recomputing."""

from __future__ import annotations

from pathlib import Path

from timing_suite import TimingSuiteTask, executed_worst, path_rng, suite_robot, timed_problem

from safepath.sweeps import RESULTS, SweepOptions, run_sweep


def _lines(folder: Path) -> list[str]:
    """The seeds' lines without their computation time, in seed order."""
    import json

    rows = [json.loads(x) for x in (folder / RESULTS).read_text().splitlines()[1:]]
    return sorted(json.dumps([r["seed"], r["result"]], sort_keys=True) for r in rows)


def test_the_timing_suite_sweep_is_the_same_in_this_process_and_on_a_pool(tmp_path: Path
                                                                          ) -> None:
    task = TimingSuiteTask(("ned3pro",), "replay {seed}")
    seeds = range(40, 44)
    alone = run_sweep(task, seeds, tmp_path / "one", SweepOptions(workers=1))
    pool = run_sweep(task, seeds, tmp_path / "pool", SweepOptions(workers=2))
    assert pool.backend.startswith("a local pool") and alone.backend == "this process"
    assert _lines(tmp_path / "one") == _lines(tmp_path / "pool")
    assert alone.results == pool.results
    robot = suite_robot("ned3pro")
    piece, scales = timed_problem(robot, path_rng(42, "ned3pro"))
    assert alone.results[42].figures["ned3pro.worst_ratio"] == executed_worst(robot, piece,
                                                                              scales)
    rates = {r["key"]: r for r in pool.report["rates"]}
    assert rates["ned3pro.no_overrun"]["total"] == 4
    assert run_sweep(task, seeds, tmp_path / "pool", SweepOptions(workers=2)).ran == ()
