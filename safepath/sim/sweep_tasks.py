"""The twin's runs as sweep tasks (:mod:`safepath.sweeps`): what a seed's run reports.

A task holds the scene folder's path and the frozen run parameters (all a worker needs:
the cell is loaded and planned once per worker process) and turns one run into figures
and checks. Wall times stay out of them: a seed's result is the same in any process, on
any backend.

* :class:`PouringTask`: the pouring twin (:func:`~safepath.sim.pouring.run_pouring`): the
  final mass, the drawn flow gain and scale latency, the executed limit ratio, the
  tracking error and clearance; checks: within tolerance, done without a fault, the
  clearance kept, no contact, within the position limits.
* :class:`QualityCheckTask`: the quality-check twin
  (:func:`~safepath.sim.quality_check.run_quality_check`) in each of its variants for the
  same seed (as ``safepath sim`` runs both architectures): vials per minute, cycle times,
  the executed limit ratio, clearance, robot idle time; checks: no unsafe vial packaged,
  no fault, the clearance kept, no contact.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

from ..sweeps import ReplayBySeed, TaskResult
from .pouring import PouringParams, run_pouring
from .quality_check import QualityCheckParams, run_quality_check

__all__ = ["PouringTask", "QualityCheckTask", "LiveSafetyTask"]


def _data(params: Any) -> dict[str, Any]:
    """Frozen parameters as JSON data (nested dataclasses as objects), for an identity."""
    return dict(json.loads(json.dumps(dataclasses.asdict(params), default=repr)))


def _kept(run: Any) -> bool:
    """The executed clearance is at least the margin less the tracking allowance."""
    return bool(run.clearance.clearance >= run.margin - run.tcp_deviation)


@dataclass(frozen=True)
class PouringTask(ReplayBySeed):
    """One pour per seed.

    Attributes:
        scene: The cell's scene folder (a path every worker can read).
        params: The runs' parameters.
        replay_command: The command of one seed, ``{seed}`` in place of the seed.
    """

    scene: str
    params: PouringParams
    replay_command: str

    def __call__(self, seed: int) -> TaskResult:
        """Run the pour of ``seed``."""
        run = run_pouring(self.scene, seed, self.params)
        return TaskResult(
            figures={"final_mass": run.final_mass, "gain": run.gain, "latency": run.latency,
                     "speed_ratio": float(run.speed_ratio.max()),
                     "tracking": 1000 * float(run.tracking.max()),
                     "clearance": 1000 * run.clearance.clearance,
                     "duration": run.duration},
            checks={"within_tolerance": run.within_tolerance,
                    "done": run.state == "done" and not run.faults,
                    "clearance_kept": _kept(run), "no_contact": run.contact_steps == 0,
                    "position_limits": run.limit_margin >= 0.0})

    def identity(self) -> dict[str, Any]:
        """The twin, the scene and the parameters."""
        return {"kind": "pouring twin", "scene": self.scene, "params": _data(self.params)}

    def labels(self) -> dict[str, str]:
        """The report's words."""
        p = self.params
        return {
            "within_tolerance": f"pours within {p.target:g} +- {p.tolerance:g} g",
            "done": "pours done without a fault",
            "clearance_kept": "executed clearance >= margin - tracking allowance",
            "no_contact": "runs without a MuJoCo contact of the arm with the cell",
            "position_limits": "runs within the joint position limits",
            "final_mass": "final mass [g]",
            "gain": "flow gain drawn [g/s/rad^1.5]",
            "latency": "scale latency drawn [s]",
            "speed_ratio": "executed speed / limit, largest joint",
            "tracking": "largest tracking error [mrad]",
            "clearance": "executed clearance [mm]",
            "duration": "simulated time [s]"}



@dataclass(frozen=True)
class QualityCheckTask(ReplayBySeed):
    """The quality-check twin's variants (architecture, belt) for each seed.

    Attributes:
        scene: The cell's scene folder (a path every worker can read).
        variants: ``(key, params)`` per variant, in order (``safepath``, ``sequential``, ...).
        replay_command: The command of one seed, ``{seed}`` in place of the seed.
    """

    scene: str
    variants: tuple[tuple[str, QualityCheckParams], ...]
    replay_command: str

    def __call__(self, seed: int) -> TaskResult:
        """Run every variant of ``seed``."""
        figures: dict[str, float | tuple[float, ...]] = {}
        checks: dict[str, bool] = {}
        for key, params in self.variants:
            run = run_quality_check(self.scene, seed, params)
            figures |= {f"{key}.vials_per_minute": float(run.vials_per_minute),
                        f"{key}.cycle_time": tuple(float(t) for t in run.cycle_times),
                        f"{key}.speed_ratio": float(run.speed_ratio.max()),
                        f"{key}.clearance": 1000 * run.clearance.clearance,
                        f"{key}.robot_idle": 100 * run.robot_idle / run.duration}
            checks |= {f"{key}.no_unsafe_packaged": run.unsafe_packaged == 0,
                       f"{key}.no_fault": not run.faults,
                       f"{key}.clearance_kept": _kept(run),
                       f"{key}.no_contact": run.contact_steps == 0}
        return TaskResult(figures=figures, checks=checks)

    def identity(self) -> dict[str, Any]:
        """The twin, the scene and each variant's parameters."""
        return {"kind": "quality-check twin", "scene": self.scene,
                "variants": {key: _data(params) for key, params in self.variants}}

    def labels(self) -> dict[str, str]:
        """The report's words."""
        out: dict[str, str] = {}
        for key, _ in self.variants:
            out |= {f"{key}.no_unsafe_packaged": f"runs with no unsafe vial packaged ({key})",
                    f"{key}.no_fault": f"runs without a controller fault ({key})",
                    f"{key}.clearance_kept": "executed clearance >= margin - tracking "
                                             f"allowance ({key})",
                    f"{key}.no_contact": f"runs without a MuJoCo contact ({key})"}
        for key, _ in self.variants:
            out |= {f"{key}.vials_per_minute": f"vials per minute ({key})",
                    f"{key}.cycle_time": f"cycle time [s] ({key})",
                    f"{key}.speed_ratio": f"executed speed / limit, largest joint ({key})",
                    f"{key}.clearance": f"executed clearance [mm] ({key})",
                    f"{key}.robot_idle": f"robot idle [%] ({key})"}
        return out



@dataclass(frozen=True)
class LiveSafetyTask(ReplayBySeed):
    """One run of the live-safety suite per seed (the body, silences and kill it draws).

    Attributes:
        scene: The cell's scene folder (a path every worker can read).
        duration: Simulated time per run [s].
        replay_command: The command of one seed, ``{seed}`` in place of the seed.
    """

    scene: str
    duration: float
    replay_command: str

    def __call__(self, seed: int) -> TaskResult:
        """Run the suite's seed ``seed``."""
        from .live_safety import run_live_safety

        run = run_live_safety(self.scene, seed, duration=self.duration)
        obstacle = run.obstacle
        return TaskResult(
            figures={"closest_moving": 1000 * obstacle.closest_moving,
                     "commanded_speed": obstacle.commanded_speed.ratio,
                     "commanded_acceleration": obstacle.commanded_acceleration.ratio,
                     "commanded_jerk": obstacle.commanded_jerk.ratio,
                     "replan_requests": float(run.replan_requests)},
            checks={"passed": run.ok,
                    "no_contact_moving": not run.contact_moving,
                    "separation_kept": obstacle.closest_moving >= run.min_separation,
                    "no_goal_after_kill": not run.goals_after_kill,
                    "no_deferred_stop": run.stats.get("deferred", 0) == 0,
                    "stops_within_limits": run.stats.get("stops_over_limit", 0) == 0,
                    "switches_continuous": run.switch_steps == 0,
                    "nothing_dropped": not run.dropped})

    def identity(self) -> dict[str, Any]:
        """The suite, the scene and the run's duration."""
        return {"kind": "live-safety suite", "scene": self.scene, "duration": self.duration}

    def labels(self) -> dict[str, str]:
        """The report's words."""
        return {
            "passed": "runs that passed every invariant of the suite",
            "no_contact_moving": "runs without contact while the arm moves",
            "separation_kept": "runs keeping the protective minimum while moving",
            "no_goal_after_kill": "runs with no goal after a kill (but its stop)",
            "no_deferred_stop": "runs with no deferred stop",
            "stops_within_limits": "runs with every stop within the limits",
            "switches_continuous": "runs whose goal switches never step the controller",
            "nothing_dropped": "runs dropping no held object",
            "closest_moving": "closest approach while the arm moves [mm]",
            "commanded_speed": "commanded speed / limit, largest",
            "commanded_acceleration": "commanded acceleration / limit, largest",
            "commanded_jerk": "commanded jerk / limit, largest",
            "replan_requests": "re-plan requests per run"}

