"""The figures table is generated from the benchmarks' results files, and the README
links it instead of carrying figures and dates (issue 26)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
README = ROOT / "README.md"

#: A date (2026-11-25, Nov 21) or a time of day in UTC (23:58 UTC).
DATED = re.compile(r"\b20\d\d-\d\d-\d\d\b|\b\d\d:\d\d(-\d\d:\d\d)? UTC\b|"
                   r"\b(Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec) \d{1,2}\b")


def _generate(results: Path, out: Path) -> str:
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "figures.py"),
                           "--results", str(results), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out.read_text()


def test_the_table_is_generated_from_the_results_files(tmp_path: Path) -> None:
    for path in RESULTS.glob("*.json"):
        shutil.copy(path, tmp_path / path.name)
    text = _generate(tmp_path, tmp_path / "FIGURES.md")
    assert text.startswith("# Benchmark figures")
    assert "NOT UNDERSTOOD" not in text, "a benchmark's results file changed: update its reader"
    for name in ("executed_motion.json", "peers.json", "replan.json", "twin.json"):
        if (tmp_path / name).exists():
            assert f"| `{name}` | not measured yet" not in text
    if (tmp_path / "peers.json").exists():
        assert "## Against other planners" in text and "| panda | safepath |" in text


def test_a_saved_run_becomes_a_row_and_a_missing_one_says_how(tmp_path: Path) -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from _results import save
    finally:
        sys.path.pop(0)
    save("plan_cycle", {
        "runs": 3, "seed": 0, "aim_median_ms": 50.0, "aim_p95_ms": 80.0,
        "aim_release_share": 0.2, "aim_motion_ratio": 0.7,
        "outcomes": {"safe": {"median_ms": 41.0, "p95_ms": 60.0, "release_share": 0.1,
                              "motion_ratio": 0.9}}}, load_before=0.5, results=tmp_path)
    saved = json.loads((tmp_path / "plan_cycle.json").read_text())
    assert saved["context"]["when"].endswith("UTC") and saved["context"]["load_before"] == 0.5
    text = (tmp_path / "FIGURES.md").read_text()
    assert "safe 41 / 60 ms (aim 50 / 80 ms, met; 3 runs)" in text
    assert "safe 0.90 (aim ≤ 0.7, **not met**)" in text
    assert ("| `collision_checks.json` | not measured yet | "
            "`.venv/bin/python benchmarks/collision_checks.py --save` |") in text
    (tmp_path / "panda_set.json").write_text('{"plans": 3}')  # a file the reader cannot read
    text = _generate(tmp_path, tmp_path / "FIGURES.md")
    assert "| `panda_set.json` | NOT UNDERSTOOD by benchmarks/figures.py (KeyError" in text


def test_the_readme_is_a_guide_not_a_log() -> None:
    text = README.read_text()
    assert len(text) <= 30_000, len(text)
    dated = [line for line in text.splitlines() if DATED.search(line)]
    assert len(dated) <= 3, dated
    assert "benchmarks/results/FIGURES.md" in text
    assert "make test" in text
    for link in re.findall(r"\]\(((?:docs|benchmarks)/[^)#\s]+)", text):
        assert (ROOT / link).exists(), link
