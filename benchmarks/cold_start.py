"""Cold start: what a new process pays before its first trajectory.

Every figure is measured in new Python processes (this interpreter, ``subprocess``),
``--runs`` times, and printed as median, min and max [s]:

* ``import safepath``: ``time.perf_counter`` around the import, inside the child;
* ``safepath plan scenes/quality_check_cell --out <new temporary folder>``: the wall
  time of the whole process (interpreter start to exit), measured by the parent;
* :func:`safepath.load_cell` of the bundled cell in a new process (after ``import
  safepath``): it also loads python-fcl and the compiled kernels, the code every plan
  runs, so that the first plan does not;
* the first :func:`safepath.plan_cell` of the bundled cell in a new process (after
  ``load_cell``), then two more in the same process: the second, which reuses the
  answers the planner keeps between plans (:mod:`safepath.planning._repeats`: IK goals,
  checked lines, joint moves, splines), and a third with those forgotten first
  (``_repeats.clear()``), which computes every answer again with the code loaded and the
  cell's checkers built. The target ratio is the first over the third: what a first plan
  pays over a plan of the same work (``benchmarks/plan_cycle.py`` reports the same
  "first plan" figure); the first over the second, printed too, also counts the kept
  answers;
* the first call of one safepath kernel in a new process (after ``import safepath``):
  loading the kernels compiled ahead of time (``safepath build-kernels``, see
  ``safepath._aot``), or, without a current build, importing numba and loading its
  cached kernel: the fixed price the first plan pays for its kernels.

The first line says which kernels the children ran; ``--jit`` makes them use numba's
JIT even where a build exists (``SAFEPATH_AOT=0``), for the figures without it.

Nothing is a cache hit of results: every process plans from scratch, every ``plan``
writes to a new folder, and safepath keeps no planning results on disk. The on-disk
caches in use are those of compiled code: Python bytecode (``__pycache__/*.pyc``, as an
installed package has them; the children run without ``PYTHONDONTWRITEBYTECODE`` unless
``--no-bytecode`` is given, which measures every import compiled from source), the
kernels compiled ahead of time (user cache) or numba's compiled kernels
(``*.nbi``/``*.nbc`` in ``__pycache__`` or ``NUMBA_CACHE_DIR``), the operating system's
file cache, and one of derived geometry: the sphere layer's robot part (sphere fits and
hull tables, ``$SAFEPATH_CACHE/robot-parts``, read by ``load_cell``); ``--no-part-cache``
turns that one off in the children (``SAFEPATH_CACHE=0``: every process fits them).
``--warmup`` runs (default 1, not counted) fill them first, so the figures are those of
an installed copy, not of the first run after an install (which also compiles the numba
kernels, several seconds).

Targets, printed with the results: ``import safepath`` <= 0.3 s, the ``plan`` process
<= 0.5 s, the first ``plan_cell`` <= 2 x one that reuses no kept answers.

Run: ``.venv/bin/python benchmarks/cold_start.py [--runs 7] [--warmup 1] [--jit]
[--no-bytecode] [--no-part-cache]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CELL_DIR = ROOT / "scenes" / "quality_check_cell"
#: Targets [s] (the plan ratio: the first plan_cell over one that reuses no kept answers).
AIM_IMPORT, AIM_PLAN, AIM_RATIO = 0.3, 0.5, 2.0  # the plan process: issue 39

_IMPORT = """
import time
t0 = time.perf_counter()
import safepath
print(time.perf_counter() - t0)
"""

_FIRST_SECOND = """
import json, sys, time
import safepath
from safepath.planning import _repeats
t = time.perf_counter()
cell = safepath.load_cell(sys.argv[1])
t0 = time.perf_counter()
safepath.plan_cell(cell)
t1 = time.perf_counter()
safepath.plan_cell(cell)
t2 = time.perf_counter()
_repeats.clear()
t3 = time.perf_counter()
safepath.plan_cell(cell)
t4 = time.perf_counter()
print(json.dumps([t0 - t, t1 - t0, t2 - t1, t4 - t3]))
"""

_KERNEL = """
import time
import numpy as np
import safepath
t0 = time.perf_counter()
from safepath.kinematics import _ik_kernel
_ik_kernel.log6(np.eye(3), np.zeros(3), np.empty(6))
print(time.perf_counter() - t0)
"""

_STATUS = """
import sys
from safepath import _aot
print(_aot.status())
"""

#: Environment of the children (``--jit`` adds SAFEPATH_AOT=0; bytecode is written and
#: read unless ``--no-bytecode``).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def child(code: str, *args: str) -> str:
    """Run ``code`` in a new interpreter; return its standard output."""
    proc = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True,
                          text=True, check=False, env=ENV)
    if proc.returncode != 0:
        raise RuntimeError(f"child failed:\n{proc.stderr[-2000:]}")
    return proc.stdout


def plan_command() -> list[str]:
    """The ``safepath`` console script next to this interpreter, else ``-m safepath.cli``."""
    script = Path(sys.executable).with_name("safepath")
    return [str(script)] if script.exists() else [sys.executable, "-m", "safepath.cli"]


def plan_process(command: list[str]) -> float:
    """Wall time of one ``safepath plan`` process [s], writing to a new folder."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        proc = subprocess.run([*command, "plan", str(CELL_DIR), "--out", tmp], cwd=ROOT,
                              capture_output=True, text=True, check=False, env=ENV)
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"safepath plan failed:\n{proc.stderr[-2000:]}")
    return wall


def load() -> str:
    """The 1-minute load average, or 'n/a'."""
    return f"{os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else "n/a"


def row(name: str, values: Sequence[float], aim: float | None = None) -> str:
    """One table row: median, min, max and the target."""
    med = statistics.median(values)
    target = "" if aim is None else f"<= {aim:.1f}  {'met' if med <= aim else 'NOT met'}"
    return f"{name:<40} {med:8.3f} {min(values):8.3f} {max(values):8.3f}   {target}"


def main(argv: Sequence[str] | None = None) -> int:
    """Measure and print the cold-start figures; returns the exit status (0)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7, help="new processes per figure")
    parser.add_argument("--warmup", type=int, default=1,
                        help="uncounted runs first (fill the compiled-code caches)")
    parser.add_argument("--jit", action="store_true",
                        help="numba's JIT kernels even where an ahead-of-time build exists")
    parser.add_argument("--no-bytecode", action="store_true",
                        help="children neither read nor write Python bytecode caches (every "
                             "import compiled from source)")
    parser.add_argument("--no-part-cache", action="store_true",
                        help="children fit the robot's spheres afresh (SAFEPATH_CACHE=0)")
    parser.add_argument("--save", action="store_true",
                        help="write the figures to benchmarks/results/cold_start.json and "
                             "rewrite benchmarks/results/FIGURES.md")
    args = parser.parse_args(argv)
    if args.runs < 1 or args.warmup < 0:
        parser.error("--runs must be at least 1 and --warmup at least 0")
    if args.jit:
        ENV["SAFEPATH_AOT"] = "0"
    if args.no_bytecode:
        ENV["PYTHONDONTWRITEBYTECODE"] = "1"
        empty = tempfile.TemporaryDirectory(prefix="safepath-nopyc-")  # removed at exit
        ENV["PYTHONPYCACHEPREFIX"] = empty.name
    if args.no_part_cache:
        ENV["SAFEPATH_CACHE"] = "0"

    command = plan_command()
    print(f"cold_start: python {platform.python_version()} on {platform.machine()}, "
          f"{os.cpu_count()} cores, load average {load()} (before)")
    print(f"{args.runs} new processes per figure after {args.warmup} uncounted warm-up "
          f"run(s); plan command: {' '.join(Path(c).name for c in command)} plan "
          f"{CELL_DIR.relative_to(ROOT)} --out <new temporary folder>")
    print(f"kernels: {child(_STATUS).strip()}")
    print("Python bytecode: " + ("off (every import compiled from source)" if args.no_bytecode
                                 else "cached in __pycache__ (as installed)"))
    print("robot parts (sphere fits): " + ("fitted in every process (SAFEPATH_CACHE=0)"
                                           if args.no_part_cache else "disk cache"))
    for _ in range(args.warmup):
        plan_process(command)
        child(_FIRST_SECOND, str(CELL_DIR))

    imports, plans, loads, first, second, forgotten, kernel = [], [], [], [], [], [], []
    for _ in range(args.runs):  # interleaved, so that load changes hit every figure alike
        imports.append(float(child(_IMPORT)))
        plans.append(plan_process(command))
        loaded, a, b, c = json.loads(child(_FIRST_SECOND, str(CELL_DIR)))
        loads.append(loaded)
        first.append(a)
        second.append(b)
        forgotten.append(c)
        kernel.append(float(child(_KERNEL)))
    ratios = [a / c for a, c in zip(first, forgotten, strict=True)]
    ratios_kept = [a / b for a, b in zip(first, second, strict=True)]

    print()
    header = f"{'[s]':<40} {'median':>8} {'min':>8} {'max':>8}   target"
    print(header)
    print("-" * len(header))
    print(row("import safepath", imports, AIM_IMPORT))
    print(row("safepath plan (process wall)", plans, AIM_PLAN))
    print(row("load_cell in a new process", loads))
    print(row("first plan_cell in a new process", first))
    print(row("second plan_cell (kept answers reused)", second))
    print(row("third plan_cell (kept answers forgotten)", forgotten))
    print(row("first / third plan_cell [ratio]", ratios, AIM_RATIO))
    print(row("first / second plan_cell [ratio]", ratios_kept))
    print(row("first kernel call (load the kernels)", kernel))
    print(f"load average {load()} (after)")
    if args.save:
        save_figures(args, {"import": imports, "plan_process": plans, "load_cell": loads,
                            "first_plan": first, "second_plan": second,
                            "forgotten_plan": forgotten, "ratio": ratios,
                            "ratio_kept": ratios_kept})
    return 0


def save_figures(args: argparse.Namespace, values: dict[str, list[float]]) -> None:
    """Write the medians to ``benchmarks/results/cold_start.json`` (``_results.save``)."""
    from _results import save

    mode = ["JIT kernels" if args.jit else "compiled kernels",
            "no bytecode cache" if args.no_bytecode else "bytecode cached",
            "no robot-part cache" if args.no_part_cache else "robot-part cache"]
    save("cold_start", {"runs": args.runs, "mode": mode,
                        "aims": {"import": AIM_IMPORT, "plan_process": AIM_PLAN,
                                 "ratio": AIM_RATIO},
                        "median_s": {k: statistics.median(v) for k, v in values.items()}})


if __name__ == "__main__":
    raise SystemExit(main())
