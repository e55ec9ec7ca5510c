"""Short closed-loop twins of the cells' own controllers, on real MuJoCo."""

from __future__ import annotations

import numpy as np
import pytest

from safepath import Trajectory
from safepath.errors import InputError
from safepath.monitor import MonitorOptions
from safepath.monitor.node import MonitorNodeCore, NodeParameters
from safepath.sim.conveyor import VerdictService
from safepath.sim.monitor_loop import MonitorTwin
from safepath.sim.quality_check import QualityCheckParams, run_quality_check


@pytest.mark.parametrize("lead", [0.005, 0.0])
def test_a_kill_just_before_a_motion_ends_stays_latched(cell_dir, lead: float) -> None:
    core = MonitorNodeCore(NodeParameters(scene=str(cell_dir), route="phase1",
                                          options=MonitorOptions()))
    core.configure()
    loop = MonitorTwin(core)
    parts = core.sequence
    first_motion = next(p for p in parts if isinstance(p, Trajectory))
    # phase1: close, motion, open, motion. The first motion starts when the close is done.
    motion_start = loop.options.gripper_time
    kill_at = motion_start + first_motion.duration - lead
    loop.run(kill_at + 3.0, kill_at=kill_at)
    # The first motion was sent; after the kill, neither the gripper nor the next motion
    # (a kill at the end's own instant comes before the controller's result of it).
    assert [c.detail for c in loop.issued if c.kind == "gripper"] == ["close"]
    assert [a.action for a in loop.gripper_actions] == ["close"]
    assert [g.reason for g in loop.arm_goals if g.reason == "next motion"] == ["next motion"]
    assert [c.detail for c in loop.after(kill_at, "goal")] in ([], ["stop"])
    # And the arm stays where the kill left it.
    times, q = loop.times, loop.positions
    settled = q[times >= kill_at + 0.5]
    assert settled.size and np.ptp(settled, axis=0).max() < 1e-3


def _params(**verdict: object) -> QualityCheckParams:
    return QualityCheckParams(duration=40.0, arrival_interval=2.0, belt_length=0.1,
                              verdict=VerdictService(**verdict))  # type: ignore[arg-type]


def test_a_verdict_timeout_sends_the_vial_to_the_reject_bin(cell_dir) -> None:
    # The service never answers: every vial must be rejected after the 5 s time-out.
    run = run_quality_check(str(cell_dir), 3, _params(p_timeout=1.0, p_malformed=0.0))
    assert run.cycles, "no cycle completed"
    assert {c.reason for c in run.cycles} == {"no verdict within 5 s"}
    assert {c.route for c in run.cycles} == {"phase2_unsafe"}
    assert run.rejected == len(run.cycles) and run.packaging == 0
    assert all(c.verdict_time >= 5.0 for c in run.cycles)
    assert not run.faults


def test_the_twin_is_deterministic_and_safe_verdicts_reach_packaging(cell_dir) -> None:
    params = _params(p_timeout=0.0, p_malformed=0.0)
    a = run_quality_check(str(cell_dir), 7, params)
    b = run_quality_check(str(cell_dir), 7, params)
    assert a.cycle_times.tolist() == b.cycle_times.tolist()
    assert np.array_equal(a.tracking, b.tracking)
    assert a.packaging > 0 and a.unsafe_packaged == 0
    assert a.contact_steps == 0
    # Executed clearance: the simulated arm keeps the cell's margin, less its tracking.
    assert a.clearance.clearance >= a.margin - 0.005


def test_bad_parameters_are_typed_errors(cell_dir) -> None:
    with pytest.raises(InputError, match="architecture"):
        QualityCheckParams(architecture="parallel")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="seed"):
        run_quality_check(str(cell_dir), -1)


