"""safepath's side of the peer benchmark (runs in the project venv).

Two modes, chosen by the job's ``mode``:

* ``cell``: :func:`safepath.plan_cell` on the bundled cell folder, once per seed, every
  route through the full pipeline (IK lines, OMPL when blocked, shortcut, blending,
  TOPPRA, FCL release check). The routes are used with their speed fractions and
  TCP speed limits removed (``equal_limits``) so that every planner times against the
  same joint limits; the as-authored run is timed too (``as_authored``).
* ``panda``: the Panda problems written as a scene folder (one ``move`` route per
  problem) and planned with :func:`safepath.plan_route`, the same pipeline.

Every timed plan is a first plan: what the planner keeps between plans
(:mod:`safepath.planning._repeats`) is forgotten before it. Defaults everywhere
(``PlanOptions()``: RRTConnect, 2 s budget, margin enforced at the scene's margin,
resolution 2 mm), except the seed.
"""

from __future__ import annotations

import dataclasses
import sys
import time

from _common import Timer, load_job, run_problems, time_checks, write_result

import safepath
from safepath.planning import PlannerOptions, _repeats


def _traj_result(traj: safepath.Trajectory) -> dict:
    # safepath releases its knots (every 4 ms, the benchmark's sample period) as they are.
    return {"t": traj.t, "q": traj.q, "step_index": traj.step_index.tolist(),
            "duration": float(traj.duration)}


def _cell(job: dict) -> list[dict]:
    cell = safepath.load_cell(job["cell_folder"])
    routes = safepath.load_routes(cell.folder, poses=list(cell.poses),
                                  objects=list(cell.scene.objects))
    equal = {name: dataclasses.replace(r, steps=tuple(
        dataclasses.replace(s, speed=1.0, tcp_speed=None) for s in r.steps))
        for name, r in routes.items()}
    safepath.plan_cell(cell, routes=equal)  # warm-up (lazy imports), untimed
    out = []
    for problem in job["problems"]:
        seed = int(problem["seed"])
        options = safepath.PlanOptions(planner=PlannerOptions(seed=seed))
        entry = {"id": problem["id"], "seed": seed, "route_names": list(routes)}
        try:
            _repeats.clear()  # a first plan: nothing kept from the warm-up or other seeds
            with Timer() as t_all:
                trajs = safepath.plan_cell(cell, options, routes=equal)
            _repeats.clear()
            with Timer() as t_authored:
                authored = safepath.plan_cell(cell, options, routes=routes)
        except safepath.SafepathError as exc:
            entry.update(ok=False, error=f"{type(exc).__name__}: {exc}")
            out.append(entry)
            continue
        entry.update(ok=True, error=None, cell_seconds=t_all.seconds,
                     as_authored_seconds=t_authored.seconds, routes={})
        for name, traj in trajs.items():
            res = _traj_result(traj)
            res.update(plan_seconds=traj.info["planning_time"] - traj.info["shortcut_time"],
                       smooth_seconds=traj.info["shortcut_time"],
                       total_seconds=traj.info["total_time"],
                       as_authored_duration=float(authored[name].duration),
                       steps=list(traj.steps))
            entry["routes"][name] = res
        out.append(entry)
        print(f"[safepath] cell seed {seed}: ok", file=sys.stderr, flush=True)
    return out


def _panda(job: dict) -> list[dict]:
    cell = safepath.load_cell(job["cell_folder"])
    routes = safepath.load_routes(cell.folder, poses=list(cell.poses),
                                  objects=list(cell.scene.objects))

    def solve(problem: dict) -> dict:
        options = safepath.PlanOptions(planner=PlannerOptions(seed=int(problem["seed"])))
        _repeats.clear()  # a first plan (the first problem is also the warm-up)
        try:
            traj = safepath.plan_route(cell, routes[problem["id"]], options)
        except safepath.SafepathError as exc:
            return {"ok": False, "error": f"{type(exc).__name__}: {exc}"[:500]}
        res = _traj_result(traj)
        # Path search (IK for lines, OMPL), as the RRT-only figures of the peers that
        # separate it; the shortcutter counts as smoothing.
        res.update(ok=True, error=None,
                   plan_seconds=traj.info["planning_time"] - traj.info["shortcut_time"],
                   smooth_seconds=traj.info["shortcut_time"],
                   total_seconds=traj.info["total_time"])
        return res

    return run_problems(job, solve)


def _checks(job: dict) -> dict:
    cell = safepath.load_cell(job["cell_folder"])
    checker = safepath.CollisionChecker(cell.robot, cell.scene,
                                        options=safepath.CheckOptions())
    return time_checks(job["check"]["states"], lambda q: not checker.is_valid(q))


def main() -> None:
    job, out = load_job()
    t0 = time.perf_counter()
    problems = _cell(job) if job["mode"] == "cell" else _panda(job)
    write_result(out, {
        "peer": "safepath", "version": safepath.__version__,
        "settings": {"planner": "PlanOptions() defaults: OMPL RRTConnect, time_limit 2 s, "
                                "100 shortcut attempts (min gain 2 %), TOPPRA, FCL release check",
                     "margin": "scene margin enforced while planning (cell: 10 mm; "
                               "panda: 0)",
                     "seed": "problem seed"},
        "checks": _checks(job), "problems": problems,
        "wall_seconds": time.perf_counter() - t0})


if __name__ == "__main__":
    main()
