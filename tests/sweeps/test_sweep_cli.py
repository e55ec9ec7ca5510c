"""``safepath sim CELL --out DIR``: the twin's seeds as a sweep, resumed, reported; a pour
that fails its checks is listed with the command that replays it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from safepath.cli import main
from safepath.sim.pouring import PouringParams
from safepath.sim.sweep_tasks import PouringTask
from safepath.sweeps import SweepOptions, run_sweep


def test_the_command_writes_the_sweep_and_a_second_start_runs_nothing(
        cell_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    argv = ["sim", str(cell_dir), "--runs", "2", "--seed", "5", "--duration", "12",
            "--arrival", "2", "--workers", "1", "--out", str(out)]
    assert main(argv) == 0
    text, bar = capsys.readouterr()
    assert "ran 2 of 2 seeds on this process" in text
    assert "2/2" in bar  # the progress bar, on standard error
    report = json.loads((out / "report.json").read_text())
    assert report["seeds"] == {"count": 2, "first": 5, "last": 6}
    keys = [d["key"] for d in report["distributions"]]
    assert "safepath.vials_per_minute" in keys and "sequential.cycle_time" in keys
    assert (out / "report.html").read_text().count("<svg") == len(keys)
    assert main(argv) == 0
    assert "ran 0 of 2 seeds" in capsys.readouterr().out


def test_runs_without_out_sweep_into_the_default_folder_and_resume_there(
        cell_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """``--runs N`` alone is a sweep: its folder named on the first line, the twin's table
    among the printed lines, and the same command run again computes nothing."""
    monkeypatch.chdir(tmp_path)
    argv = ["sim", str(cell_dir), "--runs", "2", "--seed", "5", "--duration", "12",
            "--arrival", "2", "--workers", "1"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    out = Path("out") / "sweeps" / f"{cell_dir.name}-seed5-runs2"
    assert text.splitlines()[0].startswith(f"sweep of 2 seed(s) (5..6) into {out}")
    assert "[safepath]" in text and "vials per minute" in text and "[sequential]" in text
    assert "ran 2 of 2 seeds on this process" in text
    assert {p.name for p in out.iterdir()} >= {"results.jsonl", "report.html", "report.json"}
    assert json.loads((out / "report.json").read_text())["seeds"]["count"] == 2
    assert main(argv) == 0
    assert "ran 0 of 2 seeds" in capsys.readouterr().out


@pytest.mark.parametrize(("extra", "key"), [(["--out", "OUT", "--bag", "BAG"], "--bag"),
                                            (["--out", "OUT", "--cluster", "x"], "--cluster")])
def test_bad_sweep_options_are_one_line_and_exit_2(cell_dir: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str],
                                                   extra: list[str], key: str) -> None:
    extra = [str(tmp_path / a) if a in ("OUT", "BAG") else a for a in extra]
    assert main(["sim", str(cell_dir), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"key '{key}'" in err, err


def test_failed_pours_are_listed_with_their_replay_command(repo_root: Path, tmp_path: Path
                                                           ) -> None:
    """1.5 s of a pour (the tilt alone) pours nothing: every seed fails 'within
    tolerance', and the report names each with the command that replays it."""
    scene = str(repo_root / "scenes" / "pouring_cell")
    task = PouringTask(scene, PouringParams(pick_and_place=False, max_time=1.5),
                       "safepath sim scenes/pouring_cell --seed {seed} --runs 1")
    outcome = run_sweep(task, [3, 4], tmp_path / "pour",
                        SweepOptions(workers=1, progress=False, title="pour"))
    rates = {r["key"]: r for r in outcome.report["rates"]}
    within = rates["within_tolerance"]
    assert (within["passed"], within["total"], within["failed_seeds"]) == (0, 2, [3, 4])
    assert within["text"] == "pours within 100 +- 3.5 g: 0 / 2, 0.00 % [0.00, 65.76] 95 % CI"
    assert rates["finished"]["passed"] == 2
    assert [(f["seed"], f["replay"]) for f in outcome.report["failures"]] == [
        (3, "safepath sim scenes/pouring_cell --seed 3 --runs 1"),
        (4, "safepath sim scenes/pouring_cell --seed 4 --runs 1")]
    masses = next(d for d in outcome.report["distributions"] if d["key"] == "final_mass")
    assert masses["count"] == 2 and masses["max"] < 1.0


def test_the_live_safety_suite_as_a_sweep_reports_its_runs(cell_dir: Path, tmp_path: Path
                                                           ) -> None:
    """Each seed's checks are the suite's own judgement of the same run."""
    from safepath.sim.live_safety import run_live_safety
    from safepath.sim.sweep_tasks import LiveSafetyTask

    task = LiveSafetyTask(str(cell_dir), 3.0, "replay {seed}")
    outcome = run_sweep(task, [24, 25], tmp_path / "live",
                        SweepOptions(workers=1, progress=False, title="live"))
    direct = run_live_safety(str(cell_dir), 24, duration=3.0)
    result = outcome.results[24]
    assert result.checks["passed"] == direct.ok
    assert result.figures["closest_moving"] == 1000 * direct.obstacle.closest_moving
    assert result.figures["commanded_jerk"] == direct.obstacle.commanded_jerk.ratio
    assert {r["key"] for r in outcome.report["rates"]} >= {"passed", "separation_kept",
                                                           "no_goal_after_kill"}
