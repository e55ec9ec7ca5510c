"""Figures, table and chart of the peer benchmark (from the JSON that run.py writes).

Per problem set and planner:

* ``solved``: the planner reported a timed path (its own success);
* ``recheck``: fraction of those paths that pass the dense re-check (same FCL checker,
  2 mm resolution, margin 0, start/goal and position limits checked);
* ``verified``: solved and passing, over all problems (the success rate that counts);
* ``plan``: path-planning time, median and p95 over solved problems [s];
* ``total``: planning + smoothing + time parameterisation (+ safepath's own release
  check), median and p95 [s];
* ``duration``: motion duration of the timed path, median over the problems that both
  this planner and safepath solved and verified [s], and the same median for safepath;
* ``checks_per_second``: single-state collision checks per second (2000 random states).

On the cell a problem is one route with one seed: for a peer, every motion step of the
route (each planned as a joint move); times and durations are sums over the steps.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["summarise", "table", "chart"]

ORDER = ("safepath", "mplib", "pyroboplan", "roboplan")


def _stats(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"median": None, "p95": None}
    a = np.asarray(values, dtype=float)
    return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95))}


def _cell_runs(name: str, res: dict) -> dict[str, dict]:
    """Per (route, seed): ok, passed, plan, total, duration."""
    runs: dict[str, dict] = {}
    if name == "safepath":
        for entry in res["problems"]:
            seed = entry["seed"]
            for route, r in (entry.get("routes") or {}).items():
                runs[f"{route}/s{seed}"] = {
                    "ok": True, "passed": bool(r["recheck"]["passed"]),
                    "reason": r["recheck"].get("reason"), "plan": r["plan_seconds"],
                    "total": r["total_seconds"], "duration": r["duration"]}
            if not entry.get("ok"):  # plan_cell raised: every route of that seed fails
                for route in entry.get("route_names", ["cell"]):
                    runs[f"{route}/s{seed}"] = {"ok": False, "passed": False,
                                                "reason": entry.get("error")}
        return runs
    groups: dict[str, list[dict]] = defaultdict(list)
    for p in res["problems"]:
        route, _, seed = p["id"].split("/")
        groups[f"{route}/{seed}"].append(p)
    for key, steps in groups.items():
        ok = all(s.get("ok") for s in steps)
        passed = ok and all(s.get("recheck", {}).get("passed") for s in steps)
        reason = next((f"{s['id']}: {s.get('error') or s.get('recheck', {}).get('reason')}"
                       for s in steps if not (s.get("ok")
                                              and s.get("recheck", {}).get("passed"))), None)
        runs[key] = {"ok": ok, "passed": passed, "reason": reason,
                     "steps": len(steps),
                     "steps_passed": sum(bool(s.get("ok") and s["recheck"]["passed"])
                                         for s in steps)}
        if ok:
            runs[key].update(plan=sum(s["plan_seconds"] for s in steps),
                             total=sum(s["total_seconds"] for s in steps),
                             duration=sum(s["duration"] for s in steps))
    return runs


def _panda_runs(res: dict) -> dict[str, dict]:
    runs = {}
    for p in res["problems"]:
        rc = p.get("recheck", {})
        runs[p["id"]] = {"ok": bool(p.get("ok")), "passed": bool(p.get("ok") and rc.get("passed")),
                         "reason": p.get("error") or rc.get("reason")}
        if p.get("ok"):
            runs[p["id"]].update(plan=p["plan_seconds"], total=p["total_seconds"],
                                 duration=p["duration"])
    return runs


def summarise(out: dict) -> dict:
    """Figures per set and planner (see the module docstring)."""
    summary: dict[str, Any] = {}
    for set_name, s in out["sets"].items():
        runs_by: dict[str, dict[str, dict]] = {}
        rows: dict[str, dict] = {}
        for name, res in s["results"].items():
            if "run_error" in res:
                rows[name] = {"error": res["run_error"][:300]}
                continue
            runs_by[name] = (_cell_runs(name, res) if set_name == "cell"
                             else _panda_runs(res))
        ref = runs_by.get("safepath", {})
        for name, runs in runs_by.items():
            n = len(runs)
            solved = [r for r in runs.values() if r["ok"]]
            passed = [r for r in solved if r["passed"]]
            common = [k for k, r in runs.items()
                      if r["passed"] and ref.get(k, {}).get("passed")]
            res = s["results"][name]
            row = {
                "problems": n, "solved": len(solved), "passed": len(passed),
                "solved_rate": len(solved) / n if n else None,
                "recheck_pass": len(passed) / len(solved) if solved else None,
                "verified_rate": len(passed) / n if n else None,
                "plan": _stats([r["plan"] for r in solved]),
                "total": _stats([r["total"] for r in solved]),
                "duration_common": (float(np.median([runs[k]["duration"] for k in common]))
                                    if common else None),
                "duration_common_safepath": (float(np.median([ref[k]["duration"]
                                                              for k in common]))
                                             if common else None),
                "common": len(common),
                "duration_all": _stats([r["duration"] for r in passed])["median"],
                "checks_per_second": res.get("checks", {}).get("per_second"),
                "checks_colliding": res.get("checks", {}).get("colliding"),
                "velocity_ratio_max": None,
                "failures": {k: r["reason"] for k, r in runs.items() if not r["passed"]},
            }
            if name != "safepath":
                # Returned paths the re-check finds colliding, and how many of those the
                # peer's own checker also flags at one of its output samples.
                hit = [p for p in res["problems"] if p.get("ok")
                       and str(p.get("recheck", {}).get("reason", "")).startswith("collision")]
                row["recheck_collisions"] = len(hit)
                row["own_checker_agrees"] = sum(
                    (p.get("own_check_colliding_samples") or 0) > 0 for p in hit)
            if set_name == "cell" and name != "safepath":
                row["steps"] = sum(r["steps"] for r in runs.values())
                row["steps_passed"] = sum(r["steps_passed"] for r in runs.values())
            ratios = [p.get("recheck", {}).get("velocity_ratio") for p in res["problems"]
                      if p.get("recheck")]
            if name == "safepath" and set_name == "cell":
                ratios = [r["recheck"].get("velocity_ratio") for e in res["problems"]
                          for r in (e.get("routes") or {}).values()]
            ratios = [v for v in ratios if v is not None]
            row["velocity_ratio_max"] = max(ratios) if ratios else None
            rows[name] = row
        summary[set_name] = rows
    return summary


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v * 1000:.0f}"


def _ratio(v: float | None, ref: float | None) -> str:
    if v is None or ref is None or ref == 0:
        return ""
    return f" ({v / ref:.2g}x)"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.0f}%"


def _install_rows(out: dict) -> list[str]:
    """The install table's lines (size and import time, ratios to safepath)."""
    lines = ["", "| planner | install | install time [s] | size [MB] | import [s] |",
             "|---|---|---|---|---|"]
    inst = out["install"]
    sp = inst.get("safepath", {})
    for name in ORDER:
        if name not in inst:
            continue
        i = inst[name]
        if not i.get("ok"):
            err = " ".join((i.get("error") or "?").split())
            lines.append(f"| {name} | FAILED: {err[:90]} | "
                         f"{i.get('install_seconds') or '-'} | - | - |")
            continue
        size = i.get("closure", {}).get("bytes")
        size_s = "-" if size is None else f"{size / 2**20:.0f}" + _ratio(
            size, sp.get("closure", {}).get("bytes"))
        imp = i.get("import_seconds")
        imp_s = "-" if imp is None else f"{imp:.2f}" + _ratio(imp, sp.get("import_seconds"))
        how = "project venv" if name == "safepath" else (
            "ok (cached venv)" if i.get("cached") else "ok")
        secs = i.get("install_seconds")
        lines.append(f"| {name} | {how} | {'-' if secs is None else secs} | {size_s} | "
                     f"{imp_s} |")
    return lines


def table(out: dict) -> str:
    """The results table (plain text, markdown-compatible), ratios to safepath."""
    lines = []
    head = ("| set | planner | solved | re-check pass | verified | plan med / p95 [ms] | "
            "plan+smooth+timing med / p95 [ms] | duration med [s] (same problems as "
            "safepath) | checks/s |")
    lines += [head, "|" + "---|" * 9]
    for set_name, rows in out["summary"].items():
        sp = rows.get("safepath", {})
        for name in ORDER:
            if name not in rows:
                continue
            r = rows[name]
            if "error" in r:
                why = " ".join(r["error"].split())[:80]
                lines.append(f"| {set_name} | {name} | not run: {why} "
                             "| | | | | | |")
                continue
            solved = f"{r['solved']}/{r['problems']}"
            if "steps" in r:
                solved += f" (steps {r['steps_passed']}/{r['steps']} verified)"
            plan = (f"{_ms(r['plan']['median'])} / {_ms(r['plan']['p95'])}"
                    + _ratio(r["plan"]["median"], sp.get("plan", {}).get("median")))
            total = (f"{_ms(r['total']['median'])} / {_ms(r['total']['p95'])}"
                     + _ratio(r["total"]["median"], sp.get("total", {}).get("median")))
            if r["duration_common"] is None:
                dur = "-"
            elif name == "safepath":
                dur = f"{r['duration_common']:.2f}"
            else:
                dur = (f"{r['duration_common']:.2f} vs {r['duration_common_safepath']:.2f}"
                       f" ({r['duration_common'] / r['duration_common_safepath']:.2g}x, "
                       f"n={r['common']})")
            cps = r.get("checks_per_second")
            checks = "-" if cps is None else (
                f"{cps:,.0f}" + _ratio(cps, sp.get("checks_per_second")))
            recheck = _pct(r["recheck_pass"])
            if r.get("recheck_collisions"):
                recheck += (f" ({r['recheck_collisions']} colliding; own checker flags "
                            f"{r['own_checker_agrees']})")
            lines.append(f"| {set_name} | {name} | {solved} | {recheck} | "
                         f"{_pct(r['verified_rate'])} | {plan} | {total} | {dur} | {checks} |")
    lines += _install_rows(out)
    for name, pub in out.get("published", {}).items():
        lines += ["", f"{name}: NOT MEASURED HERE ({pub['install_attempt']}). Published: "
                  f"{pub['figure']} [{pub['source']}]; {pub['not_comparable']}."]
    return "\n".join(lines)


def chart(out: dict, path: Path) -> None:
    """Bar chart of the main figures (matplotlib, Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = list(out["summary"])
    names = [n for n in ORDER if any(n in out["summary"][s] for s in sets)]
    panels = [
        ("verified success rate [%]", lambda r: 100 * (r.get("verified_rate") or 0), False),
        ("re-check pass [% of returned paths]",
         lambda r: 100 * (r.get("recheck_pass") or 0), False),
        ("planning time, median [ms]",
         lambda r: 1000 * (r.get("plan", {}).get("median") or np.nan), True),
        ("plan + smooth + timing, median [ms]",
         lambda r: 1000 * (r.get("total", {}).get("median") or np.nan), True),
        ("motion duration / safepath's (same problems)",
         lambda r: ((r.get("duration_common") or np.nan)
                    / (r.get("duration_common_safepath") or np.nan)), False),
        ("single-state checks per second", lambda r: r.get("checks_per_second") or np.nan,
         True),
    ]
    fig, axes = plt.subplots(2, 3, figsize=(14, 7.5))
    width = 0.8 / max(len(sets), 1)
    x = np.arange(len(names))
    for ax, (title, get, log) in zip(axes.ravel(), panels, strict=True):
        for k, s in enumerate(sets):
            rows = out["summary"][s]
            vals = [get(rows[n]) if n in rows and "error" not in rows[n] else np.nan
                    for n in names]
            bars = ax.bar(x + (k - (len(sets) - 1) / 2) * width, vals, width, label=s)
            for b, v in zip(bars, vals, strict=True):
                text = "n/a" if not np.isfinite(v) else (f"{v:.0f}" if "%" in title else "")
                if text:
                    ax.annotate(text, (b.get_x() + b.get_width() / 2,
                                       v if np.isfinite(v) else 0), ha="center",
                                va="bottom", fontsize=7)
        ax.set_title(title, fontsize=10)
        ax.set_xticks(x, names, fontsize=9)
        if log:
            ax.set_yscale("log")
        ax.grid(axis="y", alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, title="problem set", loc="lower center", ncol=len(sets),
               fontsize=9)
    m = out["machine"]
    fig.suptitle(f"safepath vs peers (re-check: FCL, 2 mm, margin 0) — {m['cpu']}, "
                 f"{m['cores']} cores, {m['date']}", fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
