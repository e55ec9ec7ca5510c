"""``safepath sim CELL --runs N [--out DIR] [--cluster ...]``: the twin's runs as a
resumable sweep.

Each seed's result goes to ``DIR/results.jsonl`` as it finishes (``DIR`` defaults to
``out/sweeps/<cell>-seed<first>-runs<N>``); a sweep started again on the same ``DIR``
runs only the seeds it lacks; at the end ``DIR/report.html`` and ``DIR/report.json`` hold
the figures, and the twin's table and the report's lines are printed.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["cmd_sweep", "default_folder"]


def default_folder(cell_name: str, seed: int, runs: int) -> Path:
    """Where a sweep without ``--out`` writes: ``out/sweeps/<cell>-seed<first>-runs<N>``
    (relative to the working directory; the same command finds it again and resumes)."""
    return Path("out") / "sweeps" / f"{cell_name}-seed{seed}-runs{runs}"


def _replay(args: argparse.Namespace, extra: str) -> str:
    return f"safepath sim {args.scene} --seed {{seed}} --runs 1{extra}"


def _pouring_task(args: argparse.Namespace, cell: Any, params: Any) -> Any:
    from .sweep_tasks import PouringTask

    extra = "".join(f" --{k} {getattr(args, k)}" for k in ("target", "tolerance")
                    if getattr(args, k, None) is not None)
    return PouringTask(str(cell.folder), params, _replay(args, extra))


def _quality_check_task(args: argparse.Namespace, cell: Any) -> Any:
    from ..cells.quality_check.commands import ControllerOptions
    from .quality_check import QualityCheckParams
    from .sweep_tasks import QualityCheckTask

    variants = [("safepath", "safepath", False)]
    if args.belt_runs:
        variants.append(("safepath_belt_running", "safepath", True))
    variants.append(("sequential", "sequential", False))
    built = tuple((key, QualityCheckParams(
        duration=args.duration, architecture=arch,  # type: ignore[arg-type]
        arrival_interval=args.arrival,
        controller=ControllerOptions(belt_runs_while_working=belt)))
        for key, arch, belt in variants)
    extra = f" --duration {args.duration:g} --arrival {args.arrival:g}" \
        + (" --belt-runs" if args.belt_runs else "")
    return QualityCheckTask(str(cell.folder), built, _replay(args, extra))


def cmd_sweep(args: argparse.Namespace, cell: Any, pouring: Any | None) -> int:
    """Run the cell's twin over ``--runs`` seeds as a sweep into ``--out`` (or the
    default folder, :func:`default_folder`) and print its table and report.

    Args:
        args: The command line.
        cell: The loaded cell.
        pouring: The pouring twin's parameters (None: the quality-check twin).

    Returns:
        0 when every run passed its checks, 1 when one failed (each failed seed is
        printed with the command that replays it alone).

    Raises:
        InputError: The output folder holding another sweep's results.
    """
    from ..sweeps import SweepOptions, run_sweep
    from ..sweeps.report import report_lines
    from .sweep_table import pouring_table, quality_check_table

    out = Path(args.out) if args.out else default_folder(Path(cell.folder).name, args.seed,
                                                          args.runs)
    print(f"sweep of {args.runs} seed(s) ({args.seed}..{args.seed + args.runs - 1}) into "
          f"{out}: the same command resumes it", flush=True)
    task = _pouring_task(args, cell, pouring) if pouring is not None \
        else _quality_check_task(args, cell)
    kind = "quality-check" if pouring is None else "pouring"
    title = f"{kind} twin of {cell.scene.name}"
    outcome = run_sweep(task, range(args.seed, args.seed + args.runs), out,
                        SweepOptions(workers=args.workers, cluster=args.cluster,
                                     progress=True, title=title))
    if pouring is not None:
        table = pouring_table(outcome.results, pouring.target, pouring.tolerance)
    else:
        table = quality_check_table(outcome.results, [key for key, _ in task.variants])
    for line in [*table, *report_lines(outcome.report)]:
        print(line)
    print(f"ran {len(outcome.ran)} of {args.runs} seeds on {outcome.backend} (the others "
          f"were in {out}/results.jsonl); wrote {out}/report.html and report.json")
    return 0 if not outcome.report["failures"] else 1
