"""The twin's table printed by ``safepath sim --runs N``, made from a sweep's results.

The seeds' figures and checks (:mod:`safepath.sim.sweep_tasks`) are all a sweep keeps, so
the table reads them rather than the runs: the same lines whichever backend ran the
seeds, and in however many starts. A seed that raised has no figures; the report lists
it with its replay command.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..sweeps import TaskResult

__all__ = ["pouring_table", "quality_check_table"]


def _values(results: Mapping[int, TaskResult], key: str) -> tuple[list[int], np.ndarray]:
    """The seeds holding figure ``key`` and its values (a list figure flattened)."""
    seeds, values = [], []
    for seed, result in results.items():
        value = result.figures.get(key)
        if value is None:
            continue
        for v in value if isinstance(value, tuple) else (value,):
            seeds.append(seed)
            values.append(v)
    return seeds, np.array(values, dtype=float)


def _passed(results: Mapping[int, TaskResult], key: str) -> str:
    checked = [r.checks[key] for r in results.values() if key in r.checks]
    return f"{sum(checked)} of {len(checked)}"


def _spread(values: np.ndarray) -> str:
    return (f"min {np.min(values):.2f}  median {np.median(values):.2f}  "
            f"p90 {np.percentile(values, 90):.2f}  max {np.max(values):.2f}")


def pouring_table(results: Mapping[int, TaskResult], target: float,
                  tolerance: float) -> list[str]:
    """The pouring twin's lines (final mass, controller, tracking, limits, clearance).

    Args:
        results: Each seed's result (:class:`~safepath.sim.sweep_tasks.PouringTask`).
        target: The mass to pour [g].
        tolerance: The tolerance around it [g].
    """
    seeds, masses = _values(results, "final_mass")
    if not seeds:
        return ["  (no run finished: see the failed seeds)"]
    k = int(np.argmax(np.abs(masses - target)))
    worst = results[seeds[k]].figures
    std = masses.std(ddof=1) if len(masses) > 1 else 0.0
    _, tracking = _values(results, "tracking")
    speed_seeds, speed = _values(results, "speed_ratio")
    clear_seeds, clear = _values(results, "clearance")
    over = "OVER the limit" if speed.max() > 1.0 else "within the limits"
    return [
        f"  final mass [g]     mean {masses.mean():.2f}  std {std:.2f}  min {masses.min():.2f}"
        f"  max {masses.max():.2f}; worst {masses[k]:.2f} (seed {seeds[k]}, gain "
        f"{worst['gain']:.1f}, latency {worst['latency']:.3f} s); within {target:g} +- "
        f"{tolerance:g} g: {_passed(results, 'within_tolerance')}",
        f"  controller         {_passed(results, 'done')} done without a fault",
        f"  tracking [mrad]    largest {tracking.max():.2f} (largest joint)",
        f"  speed / limit      largest {speed.max():.4f} (seed "
        f"{speed_seeds[int(np.argmax(speed))]}; {over})",
        f"  position limits    {_passed(results, 'position_limits')} runs within",
        f"  executed clearance {clear.min():.1f} mm (seed {clear_seeds[int(np.argmin(clear))]}"
        f"); kept in {_passed(results, 'clearance_kept')} runs; no MuJoCo contact with the "
        f"cell in {_passed(results, 'no_contact')}"]


def quality_check_table(results: Mapping[int, TaskResult],
                        variants: Sequence[str]) -> list[str]:
    """The quality-check twin's lines per variant (vials per minute, cycle times, idle,
    limits, clearance, unsafe vials).

    Args:
        results: Each seed's result (:class:`~safepath.sim.sweep_tasks.QualityCheckTask`).
        variants: The variants' keys, in order (``safepath``, ``sequential``, ...).
    """
    lines: list[str] = []
    for key in variants:
        _, vpm = _values(results, f"{key}.vials_per_minute")
        if not len(vpm):
            lines += [f"\n[{key}]", "  (no run finished: see the failed seeds)"]
            continue
        _, cycles = _values(results, f"{key}.cycle_time")
        _, idle = _values(results, f"{key}.robot_idle")
        _, speed = _values(results, f"{key}.speed_ratio")
        clear_seeds, clear = _values(results, f"{key}.clearance")
        over = "over a limit" if speed.max() > 1.0 else "within the limits"
        lines += [
            f"\n[{key}]",
            f"  vials per minute   {vpm.mean():.2f} (runs {vpm.min():.2f}-{vpm.max():.2f}); "
            f"runs with no unsafe vial packaged: {_passed(results, f'{key}.no_unsafe_packaged')}",
            "  cycle time [s]     " + (_spread(cycles) if len(cycles) else "no cycle finished"),
            f"  idle               robot {idle.mean():.0f} % (mean of the runs)",
            f"  speed / limit      largest {speed.max():.3f} ({over})",
            f"  executed clearance {clear.min():.1f} mm (seed "
            f"{clear_seeds[int(np.argmin(clear))]}); kept in "
            f"{_passed(results, f'{key}.clearance_kept')} runs; no MuJoCo contact in "
            f"{_passed(results, f'{key}.no_contact')}; no fault in "
            f"{_passed(results, f'{key}.no_fault')}"]
    return lines
