"""Smoke test of the peer benchmark (benchmarks/peers): one Panda problem per planner,
through the same code path as ``python benchmarks/peers/run.py``.

Each peer runs in its own venv under ``benchmarks/results/envs/``: reused when cached,
created otherwise (on a fresh machine about 1-4 min for the three, most of it
pyroboplan's drake wheel and its toppra source build, about 2 GB; with the envs cached
the test takes about 30 s). A peer that cannot be installed must be reported as such, with
the reason; the test fails if a planner is silently missing.

Opt-in: it runs only with ``SAFEPATH_PEERS_SMOKE=1`` (set by ``make bench-peers``), so that
``make test`` runs the project's own tests and installs nothing.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
PEERS_DIR = REPO / "benchmarks" / "peers"
#: The variable that runs this module (``make bench-peers`` sets it).
OPT_IN = "SAFEPATH_PEERS_SMOKE"

pytestmark = pytest.mark.skipif(
    os.environ.get(OPT_IN) != "1",
    reason=f"installs the peers' venvs (~2 GB): set {OPT_IN}=1 or run `make bench-peers`")


def _load_run() -> ModuleType:
    spec = importlib.util.spec_from_file_location("peers_run", PEERS_DIR / "run.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["peers_run"] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def smoke(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, str, Path]:
    run = _load_run()
    out_dir = tmp_path_factory.mktemp("peers")
    out, chart = out_dir / "peers.json", out_dir / "peers.png"
    code = run.main(["--sets", "panda", "--limit", "1", "--out", str(out),
                     "--chart", str(chart)])
    assert code == 0
    return json.loads(out.read_text()), run.report.table(json.loads(out.read_text())), chart


def test_safepath_solves_and_passes_the_recheck(smoke: tuple[dict, str, Path]) -> None:
    data, _, _ = smoke
    res = data["sets"]["panda"]["results"]["safepath"]
    assert "run_error" not in res, res.get("run_error")
    (problem,) = res["problems"]
    assert problem["ok"], problem.get("error")
    assert problem["recheck"]["passed"], problem["recheck"].get("reason")
    assert problem["duration"] > 0 and problem["total_seconds"] >= problem["plan_seconds"] > 0
    row = data["summary"]["panda"]["safepath"]
    assert row["verified_rate"] == 1.0
    assert res["checks"]["per_second"] > 0


def test_every_peer_has_a_result_or_an_explicit_failure(smoke: tuple[dict, str, Path]
                                                        ) -> None:
    data, table, _ = smoke
    results = data["sets"]["panda"]["results"]
    for name in ("mplib", "pyroboplan", "roboplan"):
        install = data["install"][name]
        assert name in results, f"{name} silently missing"
        res = results[name]
        if not install["ok"]:
            assert install["error"], f"{name}: failed install without a reason"
            assert res["run_error"].startswith("not installed"), res
            assert f"| {name} | FAILED" in table
            continue
        if "run_error" in res:  # installed but the adapter crashed: said so
            assert res["run_error"]
            assert f"| panda | {name} | not run" in table
            continue
        (problem,) = res["problems"]
        assert problem["id"] == "p00"
        if problem["ok"]:
            # A returned path is always re-checked, and the verdict says why it failed.
            assert "passed" in problem["recheck"]
            assert problem["recheck"]["passed"] or problem["recheck"]["reason"]
        else:
            assert problem["error"]
        assert res["checks"]["count"] == 2000
        # The same world everywhere: every checker finds the same colliding states
        # among the random ones as safepath's (within a few touching cases).
        ref = results["safepath"]["checks"]["colliding"]
        assert abs(res["checks"]["colliding"] - ref) <= 10, (name, res["checks"], ref)


def test_outputs_are_written(smoke: tuple[dict, str, Path]) -> None:
    data, table, chart = smoke
    assert chart.exists() and chart.stat().st_size > 10_000
    assert "| panda | safepath | 1/1 |" in table
    assert data["machine"]["cores"] >= 1
    for name in ("safepath", "mplib", "pyroboplan", "roboplan"):
        assert name in data["install"]
