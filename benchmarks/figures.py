"""The current benchmark figures as one table: ``benchmarks/results/FIGURES.md``.

Reads the JSON files the benchmarks write into ``benchmarks/results/``, each its latest
saved run (``collision_checks.py``, ``plan_cycle.py``, ``timing_quality.py``,
``panda_set.py``, ``cold_start.py``, ``runtime_heartbeat.py``, ``monitor.py``,
``switches.py``, ``stop_search.py``, ``live_safety.py`` and ``sweeps.py`` with
``--save``; ``executed_motion.py``, ``replan.py``, ``twin.py`` and ``peers/run.py``
always), and writes one row per headline figure, with the command that measures it and
when, on what and at which load it was measured; then the peer comparison's table from
``peers.json``. A benchmark without a results file gets a row saying how to measure it.
Saving a benchmark (``_results.save``), ``executed_motion.py``, ``replan.py`` and
``peers/run.py`` run this too.

    .venv/bin/python benchmarks/figures.py [--results DIR] [--out FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"

Row = tuple[str, str]  # what, figure
Reader = Callable[[dict[str, Any]], list[Row]]


def _n(value: float) -> str:
    return f"{value:,.0f}"


def _span(values: list[float], fmt: str) -> str:
    low, high = format(min(values), fmt), format(max(values), fmt)
    return low if low == high else f"{low}-{high}"


def _met(ok: bool) -> str:
    return "met" if ok else "**not met**"


def _collision_checks(d: dict[str, Any]) -> list[Row]:
    single = [w for w in d["workloads"] if w["workload"].startswith("is_valid")]
    grid = [w["grid_rate"] for w in d["workloads"] if w.get("grid_rate")]
    low, high = min(w["rate"] for w in single), max(w["rate"] for w in single)
    cpu = min(w["cpu_rate"] for w in single)
    rows = [("single-state checks, Ned3 Pro in the cell (empty and holding the vial)",
             f"{_n(low)}-{_n(high)} /s (aim ≥ {_n(d['aim_state_checks'])}, "
             f"{_met(low >= d['aim_state_checks'])}; slowest per CPU second {_n(cpu)})")]
    if grid:
        rows.append(("grid states decided inside edge checks (2 mm grid)",
                     f"{_n(min(grid))}-{_n(max(grid))} /s (aim ≥ {_n(d['aim_grid_states'])}, "
                     f"{_met(min(grid) >= d['aim_grid_states'])})"))
    return rows


def _check_poses(d: dict[str, Any]) -> list[Row]:
    return [(f"`safepath check` of {_n(v['poses'])} poses (Ned3 Pro cell, random poses)",
             f"{_n(v['poses_per_s'])} poses/s, check {v['check_s']:.1f} s, process "
             f"{v['check_process_s']:.1f} s, peak {v['check_process_peak_mb']:.0f} MB")
            for v in d["sizes"].values()]


def _plan_cycle(d: dict[str, Any]) -> list[Row]:
    out = d["outcomes"]
    wall = ", ".join(f"{k} {v['median_ms']:.0f} / {v['p95_ms']:.0f} ms" for k, v in out.items())
    if all("first_plan_median_ms" in v for v in out.values()):
        wall += "; a first plan of the same inputs, median: " + ", ".join(
            f"{k} {v['first_plan_median_ms']:.0f} ms" for k, v in out.items())
    ok = all(v["median_ms"] <= d["aim_median_ms"] and v["p95_ms"] <= d["aim_p95_ms"]
             for v in out.values())
    share = ", ".join(f"{k} {v['release_share']:.1%}" for k, v in out.items())
    ratio = ", ".join(f"{k} {v['motion_ratio']:.2f}" for k, v in out.items())
    return [
        ("plan + time + verify the whole cycle, median / p95",
         f"{wall} (aim {d['aim_median_ms']:.0f} / {d['aim_p95_ms']:.0f} ms, {_met(ok)}; "
         f"{d['runs']} runs)"),
        ("release check's share of the planning time", f"{share} (aim ≤ "
         f"{d['aim_release_share']:.0%}, "
         f"{_met(all(v['release_share'] <= d['aim_release_share'] for v in out.values()))})"),
        ("cycle motion time over stop-and-go", f"{ratio} (aim ≤ {d['aim_motion_ratio']}, "
         f"{_met(all(v['motion_ratio'] <= d['aim_motion_ratio'] for v in out.values()))})"),
    ]


def _panda_set(d: dict[str, Any]) -> list[Row]:
    w, s, c = d["chain_ms"], d["search_ms"], d["cpu_ms"]
    return [("Panda set: plan + smooth + timing + verify, median / p95 (wall; CPU)",
             f"{w['median']:.1f} / {w['p95']:.1f} ms; CPU {c['median']:.1f} / "
             f"{c['p95']:.1f} ms (path search {s['median']:.1f} / {s['p95']:.1f} ms; "
             f"{d['plans']} plans)")]


def _cold_start(d: dict[str, Any]) -> list[Row]:
    m, aims = d["median_s"], d["aims"]
    mode = ", ".join(d["mode"])
    rows = [
        (f"cold start ({mode}): `import safepath`; a `safepath plan` process",
         f"{m['import']:.3f} s (aim {aims['import']}, {_met(m['import'] <= aims['import'])}); "
         f"{m['plan_process']:.3f} s (aim {aims['plan_process']}, "
         f"{_met(m['plan_process'] <= aims['plan_process'])})"),
        _cold_plans(m, aims),
    ]
    if "plan_bag_process" in m:  # files saved before the figure have none
        bag, aim = m["plan_bag_process"], aims["plan_bag_process"]
        rows.insert(1, ("cold start: a `safepath plan --bag` process (the cycle also as a "
                        "ROS 2 bag); over the plain `plan`",
                        f"{bag:.3f} s (aim {aim}, {_met(bag <= aim)}); "
                        f"+{bag - m['plan_process']:.3f} s"))
    return rows


def _cold_plans(m: dict[str, float], aims: dict[str, float]) -> Row:
    """The first plan against one that reuses no kept answers (files saved before that
    figure compared the first with the second, which reuses them)."""
    if "forgotten_plan" not in m:
        return ("cold start: `load_cell`; first vs second `plan_cell` in a new process",
                f"{m['load_cell']:.3f} s; {m['first_plan']:.3f} vs {m['second_plan']:.3f} s, "
                f"{m['ratio']:.2f}x (aim {aims['ratio']}x, {_met(m['ratio'] <= aims['ratio'])})")
    return ("cold start: `load_cell`; first `plan_cell` in a new process vs one that reuses "
            "no kept answers (vs the second, which does)",
            f"{m['load_cell']:.3f} s; {m['first_plan']:.3f} vs {m['forgotten_plan']:.3f} s, "
            f"{m['ratio']:.2f}x (aim {aims['ratio']}x, {_met(m['ratio'] <= aims['ratio'])}); "
            f"second {m['second_plan']:.3f} s, {m['ratio_kept']:.2f}x")


def _monitor(d: dict[str, Any]) -> list[Row]:
    aim = f"aim {d['aim_median_ms']:.0f} / {d['aim_p99_ms']:.0f} ms"
    rows = []
    for kind, label in (("scan", "LaserScan 360 beams"), ("cloud", "PointCloud2 5,000 points")):
        cpu, wall = d[f"{kind}_cpu_ms"], d[f"{kind}_wall_ms"]
        ok = cpu["median"] <= d["aim_median_ms"] and cpu["p99"] <= d["aim_p99_ms"]
        rows.append((f"monitor decision, {label}: CPU time of one core, median / p99 (wall)",
                     f"{cpu['median']:.2f} / {cpu['p99']:.2f} ms ({aim}, {_met(ok)}; wall "
                     f"{wall['median']:.2f} / {wall['p99']:.2f} ms; {d['decisions']} decisions)"))
    if d.get("closest_mm"):
        closest = " / ".join(f"{v:.0f}" for v in d["closest_mm"].values())
        speeds = " / ".join(d["closest_mm"])
        rows.append((f"monitor closed loop on phase 1, obstacle at {speeds} m/s: closest true "
                     "approach (python-fcl)",
                     f"{closest} mm (minimum separation {d['min_separation_mm']:.0f} mm)"))
    return rows


def _switches(d: dict[str, Any]) -> list[Row]:
    g, o, aim = d["goal_decision_ms"], d["other_decision_ms"], d["aim_goal_decision_ms"]
    ok = g["median"] <= aim["median"] and g["p99"] <= aim["p99"]
    r = d["executed_ratios"]
    return [(f"monitor switches to replacement goals ({d['runs']} random runs, "
             f"{d['switches']} switches)",
             f"largest step {d['largest_switch_step']:.1e}; executed speed / acceleration / "
             f"jerk ratio {r[0]:.3f} / {r[1]:.3f} / {r[2]:.3f}; stops deferred "
             f"{d['stops_deferred']}, braking gentler than assessed {d['gentle_stops']}, "
             f"beyond the limits {d['stops_over_limit']}"),
            ("monitor decision that sends a goal, median / p99 (without a goal)",
             f"{g['median']:.2f} / {g['p99']:.2f} ms (aim {aim['median']:.0f} / "
             f"{aim['p99']:.0f} ms, {_met(ok)}; {o['median']:.2f} / {o['p99']:.2f} ms)")]


def _stop_search(d: dict[str, Any]) -> list[Row]:
    sources = d["sources"]
    forced = sum(f["forced"] for f in sources.values())
    knots = "" if d.get("knot_period") is None else \
        f", motions timed with knots {d['knot_period'] * 1e3:g} ms apart"
    return [(f"monitor stops from random instants, braking and speeding up ({d['stops']} "
             f"stops on {len(sources)} cells and robots, seed {d['seed']}{knots})",
             f"beyond a limit as executed {d['over_limit']} (aim 0, "
             f"{_met(d['over_limit'] == 0)}); worst ratio {d['worst_ratio']:.7f}; "
             f"{forced} needed the fall-back search")]


def _runtime_heartbeat(d: dict[str, Any]) -> list[Row]:
    gaps = "; ".join(f"{name} {m['heartbeat_gap_max_ms']:.1f} ms"
                     for name, m in d["modes"].items())
    worker = next(iter(d["modes"].values()))["heartbeat_gap_max_ms"]
    return [("largest heartbeat gap of a node while it plans",
             f"{gaps} (aim {d['aim_gap_ms']:.0f} ms for the worker, "
             f"{_met(worker <= d['aim_gap_ms'])}; {d['runs']} plans per mode)")]


def _executed_motion(d: dict[str, Any]) -> list[Row]:
    ours = d["random/safepath"]
    cell = d["cell/safepath"]
    over = ours["over_limit_paths"] + cell["over_limit_paths"]
    paths = ours["paths"] + cell["paths"]
    worst = " / ".join(f"{max(a, b):.4f}" for a, b in zip(
        ours["worst_ratios_v_a_j"], cell["worst_ratios_v_a_j"], strict=True))
    others = "; ".join(
        f"{label} {' / '.join(f'{v:.4g}' for v in d[key]['worst_ratios_v_a_j'])}, "
        f"{d[key]['over_limit_paths']} of {d[key]['paths']} over"
        for key, label in (("random/toppra", "`toppra`"),
                           ("random/safepath_before", "safepath before jerk limits"))
        if key in d)
    t = ours["time_over_optimum"]
    rows = [("executed motion (the controller's quintic join): worst speed / acceleration / "
             "jerk ratio to the limits",
             f"safepath {worst}, {over} of {paths} paths over a limit"
             + (f"; {others}" if others else "")),
            ("motion time over the jerk-free TOPP-RA optimum (random paths), median / p95",
             f"{t['median']:.2f} / {t['p95']:.2f}; the cells' paths "
             f"{cell['time_over_optimum']['median']:.2f} / "
             f"{cell['time_over_optimum']['p95']:.2f}")]
    if "compute_vs_before" in d:
        rows.append(("timing compute per random path",
                     f"{ours['compute_ms_median']:.1f} ms, {d['compute_vs_before']:.1f}x "
                     "the jerk-free timing before"))
    return rows


def _replan(d: dict[str, Any]) -> list[Row]:
    r, c = d["replan"], d["clouds"]
    return [("monitor re-plan, request to new trajectory on a warm worker",
             f"median {r['latency_ms']['median']:.0f} ms, p90 {r['latency_ms']['p90']:.0f} ms "
             f"({r['found']} of {r['requests']} boxes re-planned)"),
            (f"monitor decision on {_n(c['points'])}-point clouds, CPU median / p99",
             f"{c['cpu_ms']['median']:.2f} / {c['cpu_ms']['p99']:.2f} ms")]


def _twin(d: dict[str, Any]) -> list[Row]:
    runs = d["runs"]
    ratio = [r["ratio_simulation"] for r in runs]
    vpm = [r["vials_per_minute"] for r in runs]
    rows = [("quality-check twin: simulated over real time (without the clearance check); "
             "vials per minute",
             f"{_span(ratio, '.0f')}x over {len(runs)} runs; {_span(vpm, 'g')}")]
    pour = d.get("pouring")
    if pour and pour.get("runs"):
        masses = [r["final_mass_g"] for r in pour["runs"]]
        inside = sum(abs(m - pour["target_g"]) <= pour["tolerance_g"] for m in masses)
        rows.append(("pouring twin: final masses (target ± tolerance)",
                     f"{min(masses):.2f}-{max(masses):.2f} g over {len(masses)} pours, "
                     f"{inside} of {len(masses)} within {pour['target_g']:g} ± "
                     f"{pour['tolerance_g']:g} g; "
                     f"{_span([r['ratio_simulation'] for r in pour['runs']], '.0f')}x real "
                     "time"))
    return rows


def _live_safety(d: dict[str, Any]) -> list[Row]:
    closest = d["closest_moving_m"]
    zero = ("contacts_moving", "below_minimum", "goals_after_kill", "deferred",
            "stops_over_limit", "switch_steps", "runs_over_limit", "dropped")
    met = all(d[k] == 0 for k in zero)
    ratios = " / ".join(f"{r:.3f}" for r in d["commanded_ratios"])
    rows = [("live-safety suite in the twin (bodies parked and crossing at up to 1.6 m/s, "
             "sensor silences, kills at random, before a motion's end, during re-plans): "
             "contacts while moving; closest approach while moving; goals after a kill; "
             "deferred / over-limit stops; stepped switches; dropped objects",
             f"{d['contacts_moving']}; "
             + ("-" if closest is None else f"{1000 * closest:.0f} mm")
             + f" (minimum {1000 * d['min_separation_m']:.0f} mm); {d['goals_after_kill']}; "
             f"{d['deferred']} / {d['stops_over_limit']}; {d['switch_steps']} of "
             f"{d['switches']} (largest commanded speed / accel / jerk ratio {ratios}); "
             f"{d['dropped']} (aim all 0 and closest ≥ minimum, {_met(met)}; {d['runs']} "
             f"runs, failing seeds: {', '.join(map(str, d['failing_seeds'])) or 'none'})")]
    asked = d["replan_requests"]
    if asked:
        rows.append(("live-safety suite: re-plans that succeeded",
                     f"{d['replan_taken']} of {asked} requests "
                     f"({d['replan_taken'] / asked:.0%})"))
    return rows


def _sweeps(d: dict[str, Any]) -> list[Row]:
    rows = d["backends"]
    one, two = rows["this process"], rows["local pool, 2 processes"]
    text = (f"{one['per_s']:.2f} / {two['per_s']:.2f} runs/s in 1 process / a pool of 2 "
            f"({two['per_s'] / one['per_s']:.2f}x)")
    ray = rows.get("Ray, local runtime of 2 CPUs")
    if ray is not None:
        text += (f"; Ray (local, 2 CPUs) {ray['per_s']:.2f} runs/s, "
                 f"{(ray['wall_s'] - two['wall_s']) / d['runs'] * 1000:+.0f} ms per run against "
                 f"the pool of 2, its start {ray['start_s']:.1f} s apart")
    text += "; the same results on every backend" if d["same_results"] \
        else "; **results differ between backends**"
    return [(f"sweeps: {d['runs']} quality-check twin runs of {d['duration_s']:g} s simulated",
             text)]


def _peers(d: dict[str, Any]) -> list[Row]:
    sp = d["summary"]["panda"]
    ours, rp = sp["safepath"], sp.get("roboplan", {})
    row = (f"safepath {ours['total']['median'] * 1000:.1f} / {ours['total']['p95'] * 1000:.0f} ms"
           f", verified {ours['verified_rate']:.0%}")
    if "total" in rp:
        row += (f"; roboplan {rp['total']['median'] * 1000:.1f} / "
                f"{rp['total']['p95'] * 1000:.0f} ms, verified {rp['verified_rate']:.0%} "
                f"({rp['total']['median'] / ours['total']['median']:.1f}x safepath's median)")
    return [("Panda set against other planners: plan + smooth + timing, median / p95", row)]


def _peers_context(d: dict[str, Any]) -> dict[str, Any]:
    m = d["machine"]
    return {"when": m["date"], "machine": f"{m['cpu']}, {m['cores']} cores",
            "load_before": m.get("load_average_1min_start"),
            "load_after": m.get("load_average_1min_end")}


def _legacy_context(d: dict[str, Any]) -> dict[str, Any]:
    """Files written before ``_results.save``: what they say about their run."""
    load = d.get("load") or d.get("load_before") or [None]
    after = d.get("load_after") or [None]
    return {"when": d.get("when"), "machine": d.get("machine"), "load_before": load[0],
            "load_after": after[0]}


def _timing_quality(d: dict[str, Any]) -> list[Row]:
    robots, aims = d["robots"], d["aims"]
    ms = ", ".join(f"{k} {v['ms']:.1f}" for k, v in robots.items())
    ratio = ", ".join(f"{k} {v['median']:.3f} / {v['p95']:.3f}" for k, v in robots.items())
    straight = ", ".join(f"{k} {v['straight']:.4f}" for k, v in robots.items())
    over = sum(v["over"] for v in robots.values())
    near = all(v["median"] <= aims["median"] and v["p95"] <= aims["p95"]
               for v in robots.values())
    return [
        ("time_path per via-point path, median [ms]",
         f"{ms} (aim ≤ {aims['ms']:.0f} ms, "
         f"{_met(all(v['ms'] <= aims['ms'] for v in robots.values()))})"),
        ("motion time over the jerk-free optimum of the same path, median / p95",
         f"{ratio} (aim ≤ {aims['median']} / {aims['p95']}, "
         f"{_met(near)}; "
         f"{over} paths over a limit as executed)"),
        ("straight moves over the analytic S-curve, median",
         f"{straight} (aim ≤ {aims['straight']}, "
         f"{_met(all(v['straight'] <= aims['straight'] for v in robots.values()))})"),
    ]


def _timing_suite(d: dict[str, Any]) -> list[Row]:
    robots = d["robots"]
    paths = sum(v["paths"] for v in robots.values())
    over = sum(v["overruns"] for v in robots.values())
    worst = max(v["worst"] for v in robots.values())
    retimed = ", ".join(f"{k} {100 * v['retimed']:.0f} %" for k, v in robots.items())
    return [(f"randomized timing suite: random via-point paths with their own speed scales "
             f"and TCP limits on {', '.join(robots)} ({d['problems']})",
             f"{paths:,} paths; over a limit as executed {over} (aim 0, {_met(over == 0)}); "
             f"worst ratio {worst:.7f}; timed more than once: {retimed}")]


#: Results file, command that writes it, its reader (in the table's order).
SOURCES: list[tuple[str, str, Reader]] = [
    ("collision_checks.json", "benchmarks/collision_checks.py --save", _collision_checks),
    ("check_poses.json", "benchmarks/check_poses.py --save", _check_poses),
    ("plan_cycle.json", "benchmarks/plan_cycle.py --save", _plan_cycle),
    ("timing_quality.json", "benchmarks/timing_quality.py --paths 40 --save",
     _timing_quality),
    ("timing_suite.json", "benchmarks/timing_suite.py --paths 20000 --out out/timing --save",
     _timing_suite),
    ("panda_set.json", "benchmarks/panda_set.py --save", _panda_set),
    ("peers.json", "make bench-peers", _peers),
    ("cold_start.json", "benchmarks/cold_start.py --save", _cold_start),
    ("runtime_heartbeat.json", "benchmarks/runtime_heartbeat.py --save", _runtime_heartbeat),
    ("monitor.json", "benchmarks/monitor.py --save", _monitor),
    ("switches.json", "benchmarks/switches.py --runs 200 --save", _switches),
    ("stop_search.json", "benchmarks/stop_search.py --save", _stop_search),
    ("live_safety.json", "benchmarks/live_safety.py --runs 200 --workers 2 --save",
     _live_safety),
    ("executed_motion.json", "benchmarks/executed_motion.py --random 40 --seed 23",
     _executed_motion),
    ("replan.json", "benchmarks/replan.py", _replan),
    ("twin.json", "benchmarks/twin.py", _twin),
    ("sweeps.json", "benchmarks/sweeps.py --save", _sweeps),
]


def _measured(ctx: dict[str, Any]) -> str:
    parts = [str(ctx[k]) for k in ("when", "commit") if ctx.get(k)]
    loads = [f"{ctx[k]:.1f}" for k in ("load_before", "load_after")
             if isinstance(ctx.get(k), (int, float))]
    if loads:
        parts.append("load " + "-".join(dict.fromkeys(loads)))
    return ", ".join(parts) or "-"


def _peer_table(path: Path) -> str:
    spec = importlib.util.spec_from_file_location(
        "peer_report", Path(__file__).resolve().parent / "peers" / "report.py")
    assert spec is not None and spec.loader is not None
    report = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(report)
    return str(report.table(json.loads(path.read_text())))


def render(results: Path = RESULTS) -> str:
    """The FIGURES.md text for the results files in ``results``."""
    lines = ["# Benchmark figures",
             "",
             "Generated by `benchmarks/figures.py` from the JSON files in this folder, each "
             "the latest saved run of the benchmark named in its row; do not edit by hand. "
             "Speed figures depend on the machine and its load (stated per row); run a "
             "command to measure them on yours.",
             "",
             "| what | figure | command | measured |",
             "|---|---|---|---|"]
    for name, command, read in SOURCES:
        path = results / name
        if not path.is_file():
            lines.append(f"| `{name}` | not measured yet | `.venv/bin/python {command}` | - |"
                         if not command.startswith("make") else
                         f"| `{name}` | not measured yet | `{command}` | - |")
            continue
        data = json.loads(path.read_text())
        ctx = data.get("context") or (_peers_context(data) if name == "peers.json"
                                      else _legacy_context(data))
        shown = command if command.startswith("make") else f".venv/bin/python {command}"
        try:
            rows = read(data)
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            # A benchmark changed its file: say so in the table rather than fail the run.
            rows = [(f"`{name}`", f"NOT UNDERSTOOD by benchmarks/figures.py "
                                  f"({type(exc).__name__}: {exc}): update its reader")]
        for what, figure in rows:
            lines.append(f"| {what} | {figure} | `{shown}` | {_measured(ctx)} |")
    peers = results / "peers.json"
    if peers.is_file():
        lines += ["", "## Against other planners", "",
                  "`make bench-peers`; method: [docs/peers.md](../../docs/peers.md). "
                  f"Run of {_measured(_peers_context(json.loads(peers.read_text())))}. "
                  "Ratios in brackets are the peer's figure over safepath's.", "",
                  _peer_table(peers), "", "![safepath against its peers](peers.png)"]
    return "\n".join(lines) + "\n"


def write(results: Path = RESULTS, out: Path | None = None) -> Path:
    """Write :func:`render` to ``out`` (default ``results/FIGURES.md``); returns the path."""
    out = out or results / "FIGURES.md"
    out.write_text(render(results))
    return out


def main(argv: list[str] | None = None) -> int:
    """Write the table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS, help="the results folder")
    parser.add_argument("--out", type=Path, default=None,
                        help="where to write the table (default: RESULTS/FIGURES.md)")
    args = parser.parse_args(argv)
    print(f"written to {write(args.results, args.out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
