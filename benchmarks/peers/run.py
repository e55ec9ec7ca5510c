"""Benchmark safepath against its peers, side by side, in one run (issue 6).

``python benchmarks/peers/run.py`` (see README.md next to this file):

1. creates or reuses one venv per peer (mplib, pyroboplan, roboplan) with
   :mod:`envs`; a peer that fails to install is reported, not dropped;
2. writes one job per problem set (the quality-check cell; the Panda table set of
   ``panda_problems.json``) and runs every planner's adapter on it in a subprocess,
   safepath's in the project venv, each peer's in its own;
3. re-checks every returned timed path with the same independent checker
   (:class:`safepath.verify.FclVerifier`, resolution 2 mm, margin 0), and checks it
   starts at the start, ends at the goal and stays inside the position limits;
4. prints the table (with ratios to safepath), writes ``benchmarks/results/peers.json``
   and the bar chart ``benchmarks/results/peers.png``.

Fixed seeds everywhere: the Panda set's (in the JSON), the cell's planner seeds
0..N-1, the random states of the collision-check figure (seed 1).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import envs  # noqa: E402
import problems as probs  # noqa: E402
import report  # noqa: E402

REPO = HERE.parents[1]
RESULTS = REPO / "benchmarks" / "results"
CELL = REPO / "scenes" / "quality_check_cell"
PLANNERS = ("safepath", "mplib", "pyroboplan", "roboplan")
SAMPLE_PERIOD = 0.004  # [s], safepath's knot period; every peer's output sampled so
RESOLUTION = 0.002  # [m], the re-check's resolution (safepath's default)
CHECK_STATES = 2000
GOAL_TOLERANCE = 1e-3  # [rad]


# -- robot files ---------------------------------------------------------------------------
def _srdf(robot: Any, path: Path) -> Path:
    """An SRDF disabling exactly the self pairs safepath never checks: its allowed pairs,
    and links rigidly attached to the same joint (locked Panda fingers on the hand)."""
    pairs = {tuple(sorted(p)) for p in robot.allowed_self_pairs}
    geoms = robot.collision_model.geometryObjects
    by_joint: dict[int, set[str]] = {}
    for g in geoms:
        by_joint.setdefault(int(g.parentJoint), set()).add(robot.model.frames[g.parentFrame].name)
    for links in by_joint.values():
        pairs |= {(a, b) for a in links for b in links if a < b}
    lines = ['<?xml version="1.0"?>', f'<robot name="{robot.name}">']
    lines += [f'  <disable_collisions link1="{a}" link2="{b}" reason="safepath"/>'
              for a, b in sorted(pairs) if a != b]
    path.write_text("\n".join(lines + ["</robot>", ""]))
    return path


def _panda_urdf(robot: Any, work: Path) -> tuple[Path, list[str]]:
    """A copy of example-robot-data's Panda URDF with absolute mesh paths."""
    src = Path(robot.urdf_path).resolve()
    robots_dir = src.parents[2]  # .../share/example-robot-data/robots
    text = src.read_text().replace("package://example-robot-data/robots/",
                                   str(robots_dir) + "/")
    dst = work / "panda.urdf"
    dst.write_text(text)
    return dst, [str(robots_dir.parent.parent)]


# -- jobs ----------------------------------------------------------------------------------
def cell_job(work: Path, seeds: int) -> tuple[dict, dict]:
    """The cell job (one problem per motion step and seed) and what verification needs."""
    import safepath

    cell = safepath.load_cell(CELL)
    robot = cell.robot
    steps = probs.cell_steps(cell)
    spec = probs.robot_spec(robot, robot.urdf_path, _srdf(robot, work / "ned3pro.srdf"),
                            all_joints=list(robot.joint_names), fixed={}, package_dirs=[])
    worlds = {s.world: probs.world_spec(robot, cell.scene, held=s.held, resting=s.resting,
                                        allowed=s.allowed) for s in steps}
    worlds["check"] = probs.world_spec(robot, cell.scene)
    problems = [{"id": f"{s.route}/{s.index}/s{seed}", "route": s.route, "step": s.index,
                 "label": s.label, "world": s.world, "start": s.start.tolist(),
                 "goal": s.goal.tolist(), "seed": seed}
                for seed in range(seeds) for s in steps]
    job = {"mode": "cell", "peer": "?", "robot": spec, "worlds": worlds, "problems": problems,
           "cell_folder": str(CELL), "sample_period": SAMPLE_PERIOD,
           "check": {"world": "check",
                     "states": probs.random_states(robot, CHECK_STATES, 1).tolist()},
           "safepath_problems": [{"id": f"cell/s{seed}", "seed": seed}
                                 for seed in range(seeds)]}
    return job, {"cell": cell, "steps": steps}


def panda_job(work: Path, limit: int | None, seed: int | None = None) -> tuple[dict, dict]:
    """The Panda job and what verification needs (``seed``: a freshly generated problem
    set instead of the repository's ``panda_problems.json``)."""
    import safepath

    data = json.loads(probs.PANDA_PROBLEMS.read_text()) if seed is None \
        else probs.generate_panda_problems(seed=seed)
    if limit is not None:
        data = dict(data, problems=data["problems"][:limit])
    folder = probs.write_panda_cell(data, work / "panda_cell")
    cell = safepath.load_cell(folder)
    robot = cell.robot
    urdf, package_dirs = _panda_urdf(robot, work)
    fixed = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}
    spec = probs.robot_spec(robot, urdf, _srdf(robot, work / "panda.srdf"),
                            all_joints=list(robot.joint_names) + list(fixed), fixed=fixed,
                            package_dirs=package_dirs)
    world = probs.world_spec(robot, cell.scene)
    problems = [{"id": p["id"], "world": "w0", "start": p["start"], "goal": p["goal"],
                 "seed": p["seed"]} for p in data["problems"]]
    job = {"mode": "panda", "peer": "?", "robot": spec, "worlds": {"w0": world},
           "problems": problems, "cell_folder": str(folder), "sample_period": SAMPLE_PERIOD,
           "check": {"world": "w0",
                     "states": probs.random_states(robot, CHECK_STATES, 1).tolist()}}
    return job, {"cell": cell}


# -- running -------------------------------------------------------------------------------
def run_adapter(name: str, python: str, job: dict, work: Path, timeout: float) -> dict:
    """Run one planner's adapter on one job; a crash or time-out is a run failure."""
    job = dict(job, peer=name)
    if name == "safepath":
        job["problems"] = job.pop("safepath_problems", job["problems"])
    else:
        job.pop("safepath_problems", None)
    tag = f"{name}_{job['mode']}"
    job_path, out_path = work / f"{tag}_job.json", work / f"{tag}_result.json"
    job_path.write_text(json.dumps(job))
    log_path = RESULTS / "envs" / f"{tag}.log"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    adapter = HERE / "adapters" / f"{name}_adapter.py"
    env = dict(os.environ, PYTHONHASHSEED="0", OMP_NUM_THREADS="1",
               MPLBACKEND="Agg", PYTHONDONTWRITEBYTECODE="1")
    t0 = time.perf_counter()
    try:
        with open(log_path, "w") as log:
            proc = subprocess.run([python, str(adapter), str(job_path), str(out_path)],
                                  stdout=log, stderr=subprocess.STDOUT, timeout=timeout,
                                  env=env, cwd=str(work))
    except subprocess.TimeoutExpired:
        return {"run_error": f"timed out after {timeout:.0f} s (log: {log_path})"}
    wall = time.perf_counter() - t0
    if proc.returncode != 0 or not out_path.exists():
        tail = log_path.read_text()[-1500:]
        return {"run_error": f"adapter exit {proc.returncode}: {tail}"}
    result = json.loads(out_path.read_text())
    result["adapter_wall_seconds"] = wall
    return result


# -- verification --------------------------------------------------------------------------
def _verifier(robot: Any, scene: Any, *, held: str | None = None,
              resting: dict | None = None, allowed: tuple = ()) -> Any:
    from safepath.verify import FclVerifier

    return FclVerifier(robot, scene, held=held, resting=resting, allowed=allowed,
                       resolution=RESOLUTION, margin=0.0, enforce_margin=False)


def check_path(verifier: Any, robot: Any, t: np.ndarray, q: np.ndarray,
               start: np.ndarray | None, goal: np.ndarray | None) -> dict:
    """The dense re-check of one timed path: ends, position limits, collisions."""
    from safepath import VerificationError

    out: dict[str, Any] = {"passed": False}
    if len(t) < 2 or q.shape[1] != robot.dof or not np.all(np.isfinite(q)):
        out["reason"] = "malformed path"
        return out
    if start is not None and np.max(np.abs(q[0] - start)) > GOAL_TOLERANCE:
        out["reason"] = f"does not start at the start ({np.max(np.abs(q[0] - start)):.4f} rad)"
        return out
    if goal is not None and np.max(np.abs(q[-1] - goal)) > GOAL_TOLERANCE:
        out["reason"] = f"does not end at the goal ({np.max(np.abs(q[-1] - goal)):.4f} rad)"
        return out
    excess = max(float(np.max(robot.lower - q)), float(np.max(q - robot.upper)))
    if excess > 1e-6:
        out["reason"] = f"leaves the position limits by {excess:.4f} rad"
        return out
    dt = np.diff(t)
    if np.any(dt <= 0):
        out["reason"] = "time not increasing"
        return out
    v = np.abs(np.diff(q, axis=0)) / dt[:, None]
    out["velocity_ratio"] = float(np.max(v / robot.velocity_limits))
    try:
        res = verifier.verify(t, q, np.zeros_like(q))
    except VerificationError as exc:
        out["reason"] = f"collision at t={exc.time:.3f} s: " + ", ".join(
            f"{a}/{b}" for a, b in exc.pairs)
        return out
    out.update(passed=True, min_clearance=res.min_clearance)
    return out


def verify_cell(results: dict, ctx: dict) -> None:
    """Re-check every cell result in place; aggregate peers' steps into routes."""
    cell, steps = ctx["cell"], ctx["steps"]
    robot = cell.robot
    by_key = {(s.route, s.index): s for s in steps}
    verifiers = {s.world: _verifier(robot, cell.scene, held=s.held, resting=s.resting,
                                    allowed=s.allowed) for s in steps}
    for name, res in results.items():
        if "run_error" in res:
            continue
        if name == "safepath":
            for entry in res["problems"]:
                for route, r in (entry.get("routes") or {}).items():
                    t, q = np.asarray(r["t"]), np.asarray(r["q"])
                    idx = np.asarray(r["step_index"])
                    checks = []
                    for sidx in sorted(set(idx.tolist())):
                        sel = np.flatnonzero(idx == sidx)
                        lo, hi = max(int(sel[0]) - 1, 0), int(sel[-1]) + 1
                        step = by_key.get((route, sidx))
                        if step is None:  # knots of a gripper action: no motion
                            continue
                        checks.append(check_path(verifiers[step.world], robot, t[lo:hi],
                                                 q[lo:hi], None, None))
                    r["recheck"] = {"passed": all(c["passed"] for c in checks),
                                    "reason": next((c.get("reason") for c in checks
                                                    if not c["passed"]), None),
                                    "velocity_ratio": max((c.get("velocity_ratio", 0.0)
                                                           for c in checks), default=0.0)}
                    del r["t"], r["q"], r["step_index"]
            continue
        for p in res["problems"]:
            if p.get("ok"):
                step = by_key[(p["id"].split("/")[0], int(p["id"].split("/")[1]))]
                p["recheck"] = check_path(verifiers[step.world], robot, np.asarray(p["t"]),
                                          np.asarray(p["q"]), step.start, step.goal)
            p.pop("t", None)
            p.pop("q", None)


def verify_panda(results: dict, ctx: dict, job: dict) -> None:
    """Re-check every Panda result in place."""
    cell = ctx["cell"]
    verifier = _verifier(cell.robot, cell.scene)
    goals = {p["id"]: p for p in job["problems"]}
    for res in results.values():
        if "run_error" in res:
            continue
        for p in res["problems"]:
            if p.get("ok"):
                prob = goals[p["id"]]
                p["recheck"] = check_path(verifier, cell.robot, np.asarray(p["t"]),
                                          np.asarray(p["q"]), np.asarray(prob["start"]),
                                          np.asarray(prob["goal"]))
            p.pop("t", None)
            p.pop("q", None)
            p.pop("step_index", None)


# -- main ----------------------------------------------------------------------------------
def machine() -> dict:
    """What this ran on."""
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = None
    try:
        mem = round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (ValueError, OSError):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "memory_gib": mem,
            "os": platform.platform(), "python": platform.python_version(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
            "load_average_1min_start": round(os.getloadavg()[0], 2)}


#: Not measured here: vamp-planner is published on PyPI as source only, and its CMake
#: build downloads CPM.cmake and its dependencies (no network here besides the package
#: registries; Eigen3 headers are missing too). Checked 2026-11-21 with vamp-planner
#: 0.6.4: "file DOWNLOAD cannot compute hash on failed download ... CPM.cmake".
PUBLISHED = {
    "vamp": {
        "measured_here": False,
        "install_attempt": "pip install vamp-planner (0.6.4, sdist only): CMake configure "
                           "fails, it downloads CPM.cmake from GitHub and needs Eigen3",
        "figure": "RRT-Connect on the Franka Panda MotionBenchMaker problems: median "
                  "planning time 35 microseconds, one core of a consumer desktop PC",
        "source": "W. Thomason, Z. Kingston, L. E. Kavraki, 'Motions in Microseconds via "
                  "Vectorized Sampling-Based Planning', ICRA 2024, pp. 8749-8756, "
                  "arXiv:2309.14545; figure as stated in the authors' repository README "
                  "(KavrakiLab/vamp)",
        "not_comparable": "different problems (MotionBenchMaker), machine, collision model "
                          "(spheres) and no time parameterisation",
    },
}


def _compact(value: Any, digits: int = 6) -> Any:
    """Round floats to ``digits`` significant digits and drop tracebacks (small JSON)."""
    if isinstance(value, float):
        return float(f"{value:.{digits}g}")
    if isinstance(value, dict):
        return {k: _compact(v, digits) for k, v in value.items() if k != "trace"}
    if isinstance(value, list):
        return [_compact(v, digits) for v in value]
    return value


def _dumps(out: dict) -> str:
    """Indented JSON with every per-problem record on one line (small, diffable)."""
    rows: list[str] = []

    def hide(value: Any) -> Any:
        if isinstance(value, dict):
            if "id" in value:
                rows.append(json.dumps(value, separators=(",", ":")))
                return f"@@ROW{len(rows) - 1}@@"
            return {k: hide(v) for k, v in value.items()}
        if isinstance(value, list):
            return [hide(v) for v in value]
        return value

    text = json.dumps(hide(out), indent=1)
    for i, row in enumerate(rows):
        text = text.replace(f'"@@ROW{i}@@"', row, 1)
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default="cell,panda", help="problem sets (cell,panda)")
    ap.add_argument("--peers", default="mplib,pyroboplan,roboplan")
    ap.add_argument("--cell-seeds", type=int, default=5, help="planner seeds on the cell")
    ap.add_argument("--limit", type=int, default=None, help="first N Panda problems only")
    ap.add_argument("--panda-seed", type=int, default=None,
                    help="generate a fresh Panda problem set from this seed")
    ap.add_argument("--no-install", action="store_true", help="use cached peer venvs only")
    ap.add_argument("--timeout", type=float, default=1500.0, help="per adapter run [s]")
    ap.add_argument("--out", type=Path, default=RESULTS / "peers.json")
    ap.add_argument("--chart", type=Path, default=RESULTS / "peers.png")
    ap.add_argument("--work", type=Path, default=None,
                    help="keep jobs and raw results in this folder (default: a temp dir)")
    args = ap.parse_args(argv)
    sets = [s for s in args.sets.split(",") if s]
    peers = [p for p in args.peers.split(",") if p]
    t_start = time.perf_counter()

    statuses = {p: envs.ensure_env(envs.PEERS[p], create=not args.no_install) for p in peers}
    pythons = {"safepath": sys.executable}
    pythons.update({p: s.python for p, s in statuses.items() if s.ok and s.python})
    install = {"safepath": {"ok": True, "python": sys.executable, "note": "project venv"}}
    install.update({p: s.to_json() for p, s in statuses.items()})
    for name, python in pythons.items():
        dist = "safepath" if name == "safepath" else envs.PEERS[name].distribution
        modules = ("safepath",) if name == "safepath" else envs.PEERS[name].imports
        bare = envs.import_seconds(python, ("sys",))
        install[name]["import_seconds"] = max(envs.import_seconds(python, modules) - bare, 0.0)
        install[name]["closure"] = envs.closure_size(python, dist)

    out: dict[str, Any] = {"machine": machine(), "install": install, "sets": {},
                           "settings": {"sample_period": SAMPLE_PERIOD,
                                        "recheck_resolution": RESOLUTION,
                                        "recheck_margin": 0.0, "cell_seeds": args.cell_seeds,
                                        "check_states": CHECK_STATES, "check_seed": 1}}
    with tempfile.TemporaryDirectory(prefix="safepath_peers_") as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for set_name in sets:
            if set_name == "cell":
                job, ctx = cell_job(work, args.cell_seeds)
            else:
                job, ctx = panda_job(work, args.limit, args.panda_seed)
            results: dict[str, Any] = {}
            for name in ("safepath", *peers):
                if name not in pythons:
                    results[name] = {"run_error": "not installed: "
                                     + str(statuses[name].error)[:300]}
                    continue
                print(f"[run] {set_name}: {name} ...", file=sys.stderr, flush=True)
                results[name] = run_adapter(name, pythons[name], job, work, args.timeout)
            if set_name == "cell":
                verify_cell(results, ctx)
            else:
                verify_panda(results, ctx, job)
            out["sets"][set_name] = {"problems": len(job["problems"]), "results": results}
    out["summary"] = report.summarise(out)
    out["published"] = PUBLISHED
    out["wall_seconds"] = time.perf_counter() - t_start
    out["machine"]["load_average_1min_end"] = round(os.getloadavg()[0], 2)
    out = _compact(out)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(_dumps(out) + "\n")
    print(report.table(out))
    report.chart(out, args.chart)
    print(f"\nwrote {args.out} and {args.chart} in {out['wall_seconds']:.0f} s")
    if args.out.resolve() == (RESULTS / "peers.json").resolve():
        sys.path.insert(0, str(REPO / "benchmarks"))
        import figures  # benchmarks/figures.py: the table the README links

        print(f"and {figures.write()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
