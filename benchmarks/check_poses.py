"""``safepath check`` on a poses file of many poses: poses per second and peak memory.

For each size (``--sizes``, default 1,000 and 30,000) a copy of the quality-check cell is
written to a temporary folder with that many fresh random poses (uniform inside the Ned3
Pro's joint limits, from ``--seed``; default: a new seed each run, printed) added to its
taught ones, and ``safepath check`` runs on it in a new process. Printed per size: the
process's wall time, what :func:`safepath.cell.check_poses` took in a second new process
(after :func:`safepath.load_cell`, timed there), the poses checked per second of it, the
time to load the cell (reading poses.yaml), and the peak resident memory of each process
(``ru_maxrss`` of the child alone, ``os.wait4``), with the machine's load before and after.

Run: ``.venv/bin/python benchmarks/check_poses.py [--sizes 1000 30000] [--seed N]
[--save]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "scenes" / "quality_check_cell"

_IN_PROCESS = """
import json, resource, sys, time
from safepath import load_cell
from safepath.cell import check_poses
t0 = time.perf_counter()
cell = load_cell(sys.argv[1])
t1 = time.perf_counter()
rows = check_poses(cell)
t2 = time.perf_counter()
print(json.dumps({"load": t1 - t0, "check": t2 - t1, "states": len(rows),
                  "poses": len(cell.poses)}))
"""


def big_cell(folder: Path, n: int, rng: np.random.Generator) -> Path:
    """A copy of the quality-check cell with ``n`` random in-limit poses added."""
    from safepath import load_cell

    cell_dir = folder / f"cell_{n}"
    shutil.copytree(CELL, cell_dir)
    cell = load_cell(cell_dir)
    lines = ["poses:"]
    rows = [*cell.poses.items(),
            *((f"r{i}", rng.uniform(cell.robot.lower, cell.robot.upper)) for i in range(n))]
    for name, q in rows:
        lines.append(f"  {name}: [{', '.join(repr(float(v)) for v in q)}]")
    (cell_dir / "poses.yaml").write_text("\n".join(lines) + "\n")
    return cell_dir


def run(argv: list[str]) -> tuple[float, float, str]:
    """Wall time [s], peak resident memory [MB] (of this child alone: ``os.wait4``) and
    standard output of a new process."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, cwd=ROOT, stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text, errors = out.read(), err.read()
    if proc.returncode not in (0, 1):  # 1: some random poses collide, as expected
        raise RuntimeError(f"{argv[:3]} failed ({proc.returncode}):\n{errors[-2000:]}")
    return wall, usage.ru_maxrss / 1024, text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 30000])
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--save", action="store_true",
                    help="write benchmarks/results/check_poses.json")
    args = ap.parse_args()
    seed = args.seed if args.seed is not None else int(time.time()) % 100_000
    load_before = os.getloadavg()[0]
    print(f"machine load (1 min): {load_before:.2f} on {os.cpu_count()} cores; seed {seed}")
    script = Path(sys.executable).with_name("safepath")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "safepath.cli"]
    rng = np.random.default_rng(seed)
    figures = {}
    print(f"{'poses':>7} {'states':>7} {'check [s]':>10} {'poses/s':>9} {'load [s]':>9} "
          f"{'peak [MB]':>10} {'check process [s]':>18} {'its peak [MB]':>14}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            cell_dir = big_cell(Path(tmp), n, rng)
            wall, peak_cli, out = run([*command, "check", str(cell_dir)])
            assert "states valid" in out, out[-500:]
            _, peak, child = run([sys.executable, "-c", _IN_PROCESS, str(cell_dir)])
            inner = json.loads(child)
            rate = inner["poses"] / inner["check"]
            print(f"{inner['poses']:>7} {inner['states']:>7} {inner['check']:>10.2f} "
                  f"{rate:>9.0f} {inner['load']:>9.2f} {peak:>10.0f} {wall:>18.2f} "
                  f"{peak_cli:>14.0f}")
            figures[str(n)] = {"poses": inner["poses"], "states": inner["states"],
                               "check_s": inner["check"], "poses_per_s": rate,
                               "load_cell_s": inner["load"], "peak_mb": peak,
                               "check_process_s": wall, "check_process_peak_mb": peak_cli}
    print(f"machine load after: {os.getloadavg()[0]:.2f}")
    if args.save:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from _results import save

        saved = save("check_poses", {"seed": seed, "sizes": figures}, load_before=load_before)
        print(f"saved {saved}")


if __name__ == "__main__":
    main()
