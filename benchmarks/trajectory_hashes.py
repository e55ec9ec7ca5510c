"""Hashes of the trajectories safepath plans, to show a refactoring changed no bit.

For the bundled cells (every route of ``scenes/*``) and the Panda problem set of the
peer benchmark at two seeds, it plans with the default options and prints one SHA-256
over the knot times, positions, velocities and accelerations of every trajectory (and
one per cell). A change that moves code without changing behaviour leaves every line the
same; commit messages of such changes quote the ``all`` line.

Run: ``.venv/bin/python benchmarks/trajectory_hashes.py [--seeds 0 7]``.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import safepath
from safepath import PlannerOptions, PlanOptions
from safepath.model.trajectory import Trajectory

ROOT = Path(__file__).resolve().parent.parent
PEERS = ROOT / "benchmarks" / "peers"


def _feed(digest: Any, traj: Trajectory) -> None:
    for array in (traj.t, traj.q, traj.qd, traj.qdd):
        digest.update(array.astype("<f8").tobytes())


def _panda(seed: int) -> str:
    spec = importlib.util.spec_from_file_location("peer_problems", PEERS / "problems.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    problems = json.loads((PEERS / "panda_problems.json").read_text())
    digest = hashlib.sha256()
    with tempfile.TemporaryDirectory() as tmp:
        folder = module.write_panda_cell(problems, Path(tmp) / "panda")
        cell = safepath.load_cell(folder)
        routes = safepath.load_routes(cell.folder, poses=list(cell.poses),
                                      objects=list(cell.scene.objects))
        for p in problems["problems"]:
            options = PlanOptions(planner=PlannerOptions(seed=int(p["seed"]) + seed))
            _feed(digest, safepath.plan_route(cell, routes[p["id"]], options))
    return digest.hexdigest()


def main(argv: list[str] | None = None) -> int:
    """Print the hashes; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 7],
                        help="seeds added to each Panda problem's seed")
    args = parser.parse_args(argv)
    overall = hashlib.sha256()
    for folder in sorted(p for p in (ROOT / "scenes").iterdir() if (p / "cell.yaml").exists()
                         or (p / "routes.yaml").exists()):
        cell = safepath.load_cell(folder)
        trajectories = safepath.plan_cell(cell, PlanOptions())
        digest = hashlib.sha256()
        for name in sorted(trajectories):
            _feed(digest, trajectories[name])
        print(f"{folder.name:<24} {len(trajectories):>3} trajectories  {digest.hexdigest()}")
        overall.update(digest.digest())
    for seed in args.seeds:
        h = _panda(seed)
        print(f"{'panda set, seed +' + str(seed):<24} {24:>3} trajectories  {h}")
        overall.update(bytes.fromhex(h))
    print(f"{'all':<24} {'':>3}               {overall.hexdigest()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
