"""Short closed-loop twins of the cells' own controllers, on real MuJoCo."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from safepath import Trajectory
from safepath.cells.quality_check.commands import ControllerOptions
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
    # 50 s: seed 7's second cycle, its first safe vial, ends between 40 and 50 s (a vial
    # counts as packaged once its cycle has ended).
    params = replace(_params(p_timeout=0.0, p_malformed=0.0), duration=50.0)
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




def test_the_sequential_baseline_gets_a_verdict_time_out_its_publisher_can_meet(
        cell_dir) -> None:
    """Issue 35: the sequential baseline reads the verdict from publications every 5 s but
    waited 5 s for it, and timed out 24 % of its verdicts by its own choice. Its time-out
    is now the publications' longest answer (period + longest inference); one given
    explicitly is kept."""
    verdict = VerdictService(p_timeout=0.0, p_malformed=0.0)  # every request is answered
    params = QualityCheckParams(duration=120.0, architecture="sequential", verdict=verdict)
    run = run_quality_check(str(cell_dir), 1, params)
    assert len(run.cycles) >= 2
    assert not [c for c in run.cycles if c.reason.startswith("no verdict")], run.reasons
    assert run.verdict_timeout == pytest.approx(5.0 + verdict.latency[1])
    assert max(c.verdict_time for c in run.cycles) <= run.verdict_timeout
    # An explicit time-out is the user's: kept, and then it does cut the wait short (1 s,
    # well below the publications' 5 s period: whether a 5 s one cuts a wait depends on
    # where the motions' timing puts the requests in that period).
    explicit = run_quality_check(str(cell_dir), 1, replace(
        params, controller=ControllerOptions(verdict_timeout=1.0)))
    assert explicit.verdict_timeout == 1.0
    assert "no verdict within 1 s" in explicit.reasons
    # The safepath architecture's service answers each request: the controller's 5 s.
    assert QualityCheckParams().controller.verdict_wait == 5.0


def test_the_counts_add_up_when_the_run_ends_inside_a_cycle(cell_dir) -> None:
    """Issue 35: a sequential run reported 21 cycles for 13 packaged + 9 rejected vials:
    the vial placed by phase 2 was counted before its cycle ended (the arm back at the
    conveyor), so a run that ended between the two counted one vial more than cycles.
    Here the run ends half a second before the first cycle's report, after the vial was
    placed."""
    params = _params(p_timeout=0.0, p_malformed=0.0)
    whole = run_quality_check(str(cell_dir), 5, params, record=True)
    assert whole.record is not None
    report_at = next(t for t, e in whole.record.events if e["type"] == "cycle")
    opened = [t for t, kind, _ in whole.record.goals if kind == "tool" and t < report_at]
    end = report_at - 0.5
    assert opened[-1] + params.twin.gripper_time < end  # the vial placed before the end
    cut = run_quality_check(str(cell_dir), 5, replace(params, duration=end))
    assert cut.cycles == ()
    assert cut.packaging + cut.rejected == len(cut.cycles) == 0
    assert cut.in_progress == 1  # the vial placed, its cycle not ended
    for run in (whole, cut):
        assert run.packaging + run.rejected == len(run.cycles)
