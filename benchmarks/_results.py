"""Where a benchmark writes what it measured: ``benchmarks/results/<name>.json``.

Each file holds one benchmark's latest saved run (``--save``) with when, where and on
which commit it ran; saving also rewrites ``benchmarks/results/FIGURES.md``
(``benchmarks/figures.py``), so the table the README links is always the last runs'.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = RESULTS.parents[1]


def _commit() -> str:
    """The checked-out commit, ``+changes`` when the library's files differ from it."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "safepath"], cwd=ROOT,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (head or "unknown") + (" +changes" if dirty else "")


def context(load_before: float | None = None) -> dict[str, Any]:
    """When, where and on what the benchmark ran (stored beside its figures)."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "commit": _commit(), "python": platform.python_version(),
            "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
            "load_before": load_before, "load_after": load}


def save(name: str, figures: dict[str, Any], *, load_before: float | None = None,
         results: Path = RESULTS) -> Path:
    """Write ``<results>/<name>.json`` (the figures and :func:`context`), then FIGURES.md.

    Args:
        name: The benchmark's name (its script's stem).
        figures: What it measured (JSON-able).
        load_before: The 1-minute load average when it started.
        results: The results folder (tests pass a temporary one).
    """
    results.mkdir(parents=True, exist_ok=True)
    path = results / f"{name}.json"
    path.write_text(json.dumps({"context": context(load_before), **figures}, indent=1) + "\n")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import figures as table  # the generator, beside this file

    out = table.write(results, results / "FIGURES.md")
    print(f"written to {path} and {out}")
    return path
