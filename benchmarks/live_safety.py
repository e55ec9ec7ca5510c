"""The live-safety suite (issue 34's "Done when"): randomized, seeded closed-loop runs of
the monitor node in the MuJoCo twin on the bundled quality-check cell.

Each run (:func:`safepath.sim.live_safety.run_live_safety`, seed ``--seed + i``) draws a
body (crossing at up to 1.6 m/s from any direction, or parked on or beside the route, or
parked and leaving again), sensor silences, and a kill at a random instant, 0-5 ms before
a motion's end, or during a re-plan. Prints, with the machine's load before and after and
the wall time: runs; contacts while the arm moves; the closest approach while moving
against the protective minimum; goals sent after a kill (other than its own stop);
deferred stops; stops beyond the limits; switches over a limit as executed from the
controller's state; held objects dropped; re-plan requests, how many succeeded and why
the others did not; and the seed of every failing run (``--seed S --runs 1`` replays it).
Exits 1 when a run fails.

With ``--out DIR`` the runs are a sweep (``safepath.sweeps``, docs/sweeps.md): each seed's
invariants and figures written to ``DIR/results.jsonl`` as it finishes (a restart runs only
the missing seeds), on the local pool or on Ray (``--cluster auto|ray://HOST:PORT``), and
the report in ``DIR/report.html`` / ``report.json``; the report's lines are printed.

    .venv/bin/python benchmarks/live_safety.py [--runs 200] [--seed 0] [--workers 2] [--save]
    .venv/bin/python benchmarks/live_safety.py --runs 10000 --out out/live-safety [--cluster auto]
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
CELL = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"


def _run(seed: int, duration: float) -> Any:
    from safepath.sim.live_safety import run_live_safety

    return run_live_safety(str(CELL), seed, duration=duration)


def why_not(outcome: str) -> str:
    """A re-plan outcome other than ``taken``, shortened to its kind (names and
    figures kept only where they say which rule refused)."""
    if not outcome.startswith("failed: "):
        return outcome
    why = outcome.removeprefix("failed: ")
    if "no way around the obstacle" in why:
        tail = why.rsplit("; no other way: ", 1)
        return "no way around the obstacle" + (f" ({tail[1]})" if len(tail) == 2 else "")
    return re.sub(r"\d+\.\d+", "#", why)[:160]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1,
                        help="processes (each run is one process's work)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulated time per run [s] (default: the suite's, 14 s)")
    parser.add_argument("--save", action="store_true",
                        help="write benchmarks/results/live_safety.json")
    parser.add_argument("--out", default=None, help="run as a resumable sweep into DIR")
    parser.add_argument("--cluster", default=None,
                        help="with --out: run on Ray, 'auto' or ray://HOST:PORT")
    args = parser.parse_args(argv)
    from safepath.sim.live_safety import DURATION

    duration = args.duration or DURATION
    if args.out:
        return _sweep(args, duration)
    load_before = os.getloadavg()
    seeds = list(range(args.seed, args.seed + args.runs))
    started = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(max_workers=min(args.workers, len(seeds))) as pool:
            runs = list(pool.map(_run, seeds, [duration] * len(seeds)))
    else:
        runs = [_run(s, duration) for s in seeds]
    wall = time.perf_counter() - started
    figures = _figures(runs)
    _print(args, runs, figures, wall, load_before)
    if args.save:
        from _results import save

        save("live_safety", {"runs": len(runs), "seed": args.seed, "duration": duration,
                             "workers": args.workers, "wall_time": wall, **figures},
             load_before=load_before[0])
    return 1 if figures["failing_seeds"] else 0


def _sweep(args: argparse.Namespace, duration: float) -> int:
    """The suite as a sweep into ``--out``: prints the report's lines."""
    from safepath.sim.sweep_tasks import LiveSafetyTask
    from safepath.sweeps import SweepOptions, run_sweep
    from safepath.sweeps.report import report_lines

    replay = "python benchmarks/live_safety.py --seed {seed} --runs 1" + (
        f" --duration {duration:g}" if args.duration else "")
    outcome = run_sweep(LiveSafetyTask(str(CELL), duration, replay),
                        range(args.seed, args.seed + args.runs), args.out,
                        SweepOptions(workers=args.workers, cluster=args.cluster,
                                     progress=True, title="live-safety suite"))
    for line in report_lines(outcome.report):
        print(line)
    print(f"ran {len(outcome.ran)} of {args.runs} seeds on {outcome.backend}")
    return 1 if outcome.report["failures"] else 0


def no_way_by_rule(outcome: str) -> bool:
    """Whether a re-plan was not taken because no way can exist (the body sits on an
    approach line, which must be entered straight from its start) or may not be taken
    (a kill is latched: the gate holds every goal)."""
    return ("no way skips it" in outcome or "it is not left" in outcome
            or outcome.endswith("held by the gate"))


def _figures(runs: list[Any]) -> dict[str, Any]:
    """What the suite measured, JSON-able."""
    moving = [r.obstacle.closest_moving for r in runs
              if math.isfinite(r.obstacle.closest_moving)]
    worst = [max(getattr(r.obstacle, f"commanded_{k}").ratio for r in runs)
             for k in ("speed", "acceleration", "jerk")]
    outcomes = [o for r in runs for o in r.replan_outcomes]
    by_kind: dict[str, dict[str, int]] = {}
    for r in runs:
        row = by_kind.setdefault(r.draw.kind, {"runs": 0, "requests": 0, "taken": 0})
        row["runs"] += 1
        row["requests"] += r.replan_requests
        row["taken"] += sum(o == "taken" for o in r.replan_outcomes)
    kills = Counter(r.draw.kill for r in runs if r.obstacle.kill_time is not None)
    return {
        "contacts_moving": sum(r.contact_moving for r in runs),
        "closest_moving_m": min(moving) if moving else None,
        "min_separation_m": runs[0].min_separation,
        "below_minimum": sum(r.obstacle.closest_moving < r.min_separation for r in runs),
        "kills": dict(kills),
        "kills_in_replan": sum(r.kill_in_replan for r in runs),
        "goals_after_kill": sum(len(r.goals_after_kill) for r in runs),
        "deferred": sum(r.stats.get("deferred", 0) for r in runs),
        "stops_over_limit": sum(r.stats.get("stops_over_limit", 0) for r in runs),
        "gentle_stops": sum(r.stats.get("gentle_stops", 0) for r in runs),
        "switches": sum(r.switches for r in runs),
        "switch_steps": sum(r.switch_steps for r in runs),
        "runs_over_limit": sum(any(getattr(r.obstacle, f"commanded_{k}").ratio > 1 + 1e-6
                                   for k in ("speed", "acceleration", "jerk")) for r in runs),
        "commanded_ratios": worst,
        "dropped": sum(len(r.dropped) for r in runs),
        "silences": sum(len(r.draw.silences) for r in runs),
        "replan_requests": sum(r.replan_requests for r in runs),
        "replan_answered": len(outcomes),
        "replan_taken": sum(o == "taken" for o in outcomes),
        "replan_way_may_exist": sum(not no_way_by_rule(o) for o in outcomes),
        "replan_not_taken": dict(Counter(why_not(o) for o in outcomes if o != "taken")),
        "replan_by_kind": by_kind,
        "failing_seeds": [r.seed for r in runs if not r.ok],
        "failures": {str(r.seed): list(r.failures) for r in runs if not r.ok},
    }


def _print(args: argparse.Namespace, runs: list[Any], f: dict[str, Any], wall: float,
           load_before: tuple[float, float, float]) -> None:
    load_after = os.getloadavg()
    kinds = Counter(r.draw.kind for r in runs)
    print(f"live-safety suite: {len(runs)} runs (seeds {args.seed}..{args.seed + len(runs) - 1}"
          f"), {', '.join(f'{k} {n}' for k, n in sorted(kinds.items()))}; {wall:.0f} s wall "
          f"({wall / max(len(runs), 1):.1f} s a run, {args.workers} worker(s)); load "
          f"{' '.join(f'{x:.2f}' for x in load_before)} -> "
          f"{' '.join(f'{x:.2f}' for x in load_after)} on {os.cpu_count()} CPUs")
    closest = "-" if f["closest_moving_m"] is None else f"{1000 * f['closest_moving_m']:.0f} mm"
    print(f"contacts while the arm moves: {f['contacts_moving']}; closest approach while "
          f"moving {closest} (protective minimum {1000 * f['min_separation_m']:.0f} mm, "
          f"runs below it: {f['below_minimum']})")
    kills = ", ".join(f"{k} {n}" for k, n in sorted(f["kills"].items()))
    print(f"kills pressed: {sum(f['kills'].values())} ({kills}; {f['kills_in_replan']} while a "
          f"re-plan was being planned); goals sent after a kill (other than its own stop): "
          f"{f['goals_after_kill']}")
    print(f"deferred stops: {f['deferred']}; stops beyond the limits: {f['stops_over_limit']} "
          f"(braking gentler than assessed: {f['gentle_stops']})")
    r = f["commanded_ratios"]
    print(f"switches over a limit as executed from the controller's state: "
          f"{f['switch_steps']} of {f['switches']} switches step the state, "
          f"{f['runs_over_limit']} runs over a limit (largest commanded speed / acceleration "
          f"/ jerk ratio {r[0]:.4f} / {r[1]:.4f} / {r[2]:.4f})")
    print(f"held objects dropped: {f['dropped']}; sensor silences: {f['silences']} "
          f"({sum(x.dropped_messages for x in runs)} messages dropped)")
    print(f"re-plan requests: {f['replan_requests']}, answered {f['replan_answered']}, "
          f"succeeded {f['replan_taken']}" + "".join(
              f"; {k}: {v['taken']} of {v['requests']}"
              for k, v in sorted(f["replan_by_kind"].items()) if v["requests"]))
    may = f["replan_way_may_exist"]
    share = f" ({100 * f['replan_taken'] / may:.0f} %, aim 75 %)" if may else ""
    print(f"re-plans where a way may exist (not ruled out by an approach line, no kill "
          f"latched): {f['replan_taken']} of {may} taken{share}")
    for why, n in sorted(f["replan_not_taken"].items(), key=lambda x: -x[1]):
        print(f"  not taken x{n}: {why}")
    if not f["failing_seeds"]:
        print("failing runs: none")
        return
    print(f"failing runs: {len(f['failing_seeds'])} (replay one: .venv/bin/python "
          f"benchmarks/live_safety.py --seed S --runs 1)")
    for run in runs:
        if not run.ok:
            print(f"  seed {run.seed}: {run.draw.describe()}: {'; '.join(run.failures)}")


if __name__ == "__main__":
    raise SystemExit(main())
