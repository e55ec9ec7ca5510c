"""The sweep's report: the same figures as JSON (``report.json``) and as an HTML page with
plots (``report.html``, self-contained: inline SVG, no script, no external file).

Built from the results file alone, in seed order, so that a sweep's report is the same
whatever ran it; only its ``run`` part (backend, computation time, the machine's load)
says how it ran.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from html import escape
from pathlib import Path
from typing import Any

from ._svg import histogram_svg
from .stats import Distribution, Rate, distribution
from .task import TaskResult

__all__ = ["build_report", "write_report", "report_lines"]

#: The rate every report has: runs that ended without an exception.
FINISHED = "finished"


def _rates(results: Mapping[int, TaskResult], labels: Mapping[str, str]) -> list[Rate]:
    seeds = sorted(results)
    keys = _ordered([k for s in seeds for k in results[s].checks], labels)
    errors = tuple(s for s in seeds if results[s].error is not None)
    rates = [Rate(FINISHED, "runs that finished (no exception)", len(seeds) - len(errors),
                  len(seeds), errors)]
    for key in keys:
        ran = [s for s in seeds if key in results[s].checks]
        failed = tuple(s for s in ran if not results[s].checks[key])
        rates.append(Rate(key, labels.get(key, key), len(ran) - len(failed), len(ran), failed))
    return rates


def _distributions(results: Mapping[int, TaskResult], labels: Mapping[str, str]
                   ) -> list[Distribution]:
    seeds = sorted(results)
    out = []
    for key in _ordered([k for s in seeds for k in results[s].figures], labels):
        values: list[float] = []
        for s in seeds:
            value = results[s].figures.get(key)
            if value is not None:
                values.extend(value if isinstance(value, tuple) else (value,))
        out.append(distribution(key, labels.get(key, key), values))
    return out


def _ordered(keys: list[str], labels: Mapping[str, str]) -> list[str]:
    """The keys once each: the labels' order first, then the others as they came."""
    present = dict.fromkeys(keys)
    return [k for k in labels if k in present] + [k for k in present if k not in labels]


def _json_number(value: float) -> float | str:
    """JSON has no infinity: ``"inf"`` / ``"-inf"`` in its place (NaN is no figure)."""
    return value if math.isfinite(value) else ("inf" if value > 0 else "-inf")


def build_report(title: str, results: Mapping[int, TaskResult], labels: Mapping[str, str],
                 replay: Callable[[int], str], run: Mapping[str, Any]) -> dict[str, Any]:
    """The report's figures as JSON data.

    Args:
        title: What was swept.
        results: Each seed's result.
        labels: Words for the figure and check keys.
        replay: The command that replays a seed alone.
        run: How the sweep ran (backend, times, load): the report's only part that
            depends on it.
    """
    seeds = sorted(results)
    rates = _rates(results, labels)
    dists = _distributions(results, labels)
    failures = [{"seed": s, "error": results[s].error,
                 "failed": [labels.get(k, k) for k in results[s].failed],
                 "replay": replay(s)} for s in seeds if not results[s].ok]
    return {
        "title": title,
        "seeds": {"count": len(seeds), "first": seeds[0] if seeds else None,
                  "last": seeds[-1] if seeds else None},
        "rates": [{"key": r.key, "label": r.label, "passed": r.passed, "total": r.total,
                   "percent": 100 * r.passed / r.total if r.total else None,
                   "ci95_percent": [100 * x for x in r.interval] if r.total else None,
                   "text": r.sentence() if r.total else f"{r.label}: no run",
                   "failed_seeds": list(r.failed_seeds)} for r in rates],
        "distributions": [{"key": d.key, "label": d.label, **d.summary(),
                           "histogram": {"edges": list(d.edges), "counts": list(d.counts)},
                           "values": [_json_number(v) for v in d.values]} for d in dists],
        "failures": failures,
        "run": dict(run),
    }


#: Failed seeds :func:`report_lines` lists (all of them are in the report's files).
LINES_OF_FAILURES = 20


def report_lines(report: Mapping[str, Any]) -> list[str]:
    """The report in a few lines of text (the command line prints them): the rates, the
    distributions, and the first :data:`LINES_OF_FAILURES` failed seeds."""
    lines = [f"{report['title']}: {report['seeds']['count']} runs"]
    lines += [f"  {r['text']}" for r in report["rates"]]
    for d in report["distributions"]:
        if d["count"]:
            lines.append(f"  {d['label']}: mean {d['mean']:.4g}, std {d['std']:.3g}, "
                         f"min {d['min']:.4g}, median {d['median']:.4g}, max {d['max']:.4g} "
                         f"({int(d['count'])} values)")
    failures = report["failures"]
    for f in failures[:LINES_OF_FAILURES]:
        why = f["error"] or ", ".join(f["failed"])
        lines.append(f"  FAILED seed {f['seed']}: {why}; replay: {f['replay']}")
    if len(failures) > LINES_OF_FAILURES:
        lines.append(f"  ... and {len(failures) - LINES_OF_FAILURES} more failed seeds: "
                     "report.html, report.json")
    return lines


_STYLE = ("body{font-family:sans-serif;margin:24px;color:#222;max-width:1200px}"
          "table{border-collapse:collapse}td,th{border-bottom:1px solid #ddd;padding:4px 10px;"
          "text-align:left}code{background:#f4f4f4;padding:1px 4px}"
          ".plots{display:flex;flex-wrap:wrap;gap:18px}.plots figure{margin:0;width:560px}"
          "figcaption{font-size:13px;color:#444}.bad{color:#a00}")


def _html(report: Mapping[str, Any]) -> str:
    esc = escape
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{esc(report['title'])}"
             f"</title><style>{_STYLE}</style></head><body><h1>{esc(report['title'])}</h1>"]
    seeds, run = report["seeds"], report["run"]
    parts.append(f"<p>{seeds['count']} runs, seeds {seeds['first']}..{seeds['last']}; "
                 + "; ".join(f"{esc(str(k))}: {esc(str(v))}" for k, v in run.items())
                 + "</p><h2>Rates (95 % Wilson score interval)</h2><table>"
                 "<tr><th>check</th><th>passed</th><th>rate</th><th>95 % CI</th></tr>")
    for r in report["rates"]:
        if not r["total"]:
            continue
        low, high = r["ci95_percent"]
        bad = " class='bad'" if r["passed"] < r["total"] else ""
        parts.append(f"<tr{bad}><td>{esc(r['label'])}</td><td>{r['passed']:,} / "
                     f"{r['total']:,}</td><td>{r['percent']:.2f} %</td>"
                     f"<td>[{low:.2f}, {high:.2f}] %</td></tr>")
    parts.append("</table><h2>Distributions</h2><div class='plots'>")
    for d, dist in zip(report["distributions"], _rebuilt(report), strict=True):
        caption = (f"{esc(d['label'])}: mean {d['mean']:.4g}, std {d['std']:.3g}, "
                   f"min {d['min']:.4g}, median {d['median']:.4g}, p90 {d['p90']:.4g}, "
                   f"max {d['max']:.4g} ({int(d['count'])} values)") if d["count"] \
            else f"{esc(d['label'])}: no finite value"
        parts.append(f"<figure>{histogram_svg(dist)}<figcaption>{caption}</figcaption>"
                     "</figure>")
    parts.append(f"</div><h2>Failures ({len(report['failures'])})</h2>")
    if report["failures"]:
        parts.append("<table><tr><th>seed</th><th>why</th><th>replay alone</th></tr>")
        for f in report["failures"]:
            why = f["error"] or ", ".join(f["failed"])
            parts.append(f"<tr><td>{f['seed']}</td><td>{esc(why)}</td>"
                         f"<td><code>{esc(f['replay'])}</code></td></tr>")
        parts.append("</table>")
    else:
        parts.append("<p>none</p>")
    return "".join(parts) + "</body></html>\n"


def _rebuilt(report: Mapping[str, Any]) -> list[Distribution]:
    return [Distribution(d["key"], d["label"], (), tuple(d["histogram"]["edges"]),
                         tuple(d["histogram"]["counts"])) for d in report["distributions"]]


def write_report(report: Mapping[str, Any], folder: str | Path) -> tuple[Path, Path]:
    """Write ``report.json`` and ``report.html`` into ``folder``.

    Returns:
        The two files' paths.
    """
    folder = Path(folder)
    json_path, html_path = folder / "report.json", folder / "report.html"
    for path, text in ((json_path, json.dumps(report, indent=1, allow_nan=False) + "\n"),
                       (html_path, _html(report))):
        part = path.with_suffix(path.suffix + ".part")
        part.write_text(text)
        part.replace(path)
    return json_path, html_path
