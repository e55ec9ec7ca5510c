"""The node core's one gate: every goal leaves through it; a latched kill or an inactive node
lets nothing out but a braking stop; the route moves on only at a path's end.

Real trajectories: the bundled cell's phase 1 (close vial, motion, open vial, motion),
planned by the core itself; the monitor names no sensor, so only the kill switch, the
lifecycle and the hold-time rule drive its decisions (and a laser in the re-plan case).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safepath.monitor import Decision
from safepath.monitor.node import (
    Command,
    Gripper,
    MonitorNodeCore,
    Publish,
    Replan,
    SendGoal,
)

from .conftest import BoxOnRoute, NodeCoreFactory

TICK = 0.02


def _goals(commands: list[Command]) -> list[SendGoal | Gripper]:
    return [c for c in commands if isinstance(c, (SendGoal, Gripper))]


def _published(commands: list[Command]) -> Decision:
    """The one decision the commands publish."""
    (decision,) = [c.decision for c in commands if isinstance(c, Publish)]
    return decision


def _started(node_core: NodeCoreFactory) -> tuple[MonitorNodeCore, SendGoal]:
    """A core on phase 1 whose first motion was sent at t = 0.5 s."""
    core = node_core()
    close = core.activate(0.0)
    assert isinstance(close[0], Gripper) and close[0].event.action == "close"
    first = core.on_gripper_done(0.5)
    assert isinstance(first[0], SendGoal) and first[0].reason == "next motion"
    return core, first[0]


def _tick_until(core: MonitorNodeCore, t: float, until: float) -> tuple[float, list[Command]]:
    out: list[Command] = []
    while t < until - 1e-9:
        t = round(t + TICK, 9)
        out += core.on_tick(t)
    return t, out


def test_a_kill_sends_its_stop_and_holds_every_other_goal(node_core: NodeCoreFactory,
                                                          monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    core, first = _started(node_core)
    assert first.start == 0.5  # the monitor follows the motion from then
    t, _ = _tick_until(core, 0.5, 2.0)
    kill = core.kill(t)
    stop = _goals(kill)
    # The kill's own stop goes out first (before its decision is published), stamped
    # where the monitor timed it.
    assert len(stop) == 1 and isinstance(stop[0], SendGoal) and stop[0].reason == "stop"
    assert kill[0] is stop[0]
    decision = _published(kill)
    assert decision.latched and stop[0].start == decision.replacement_start
    assert stop[0].trajectory is decision.replacement
    # Released and clear for the hold time: a real resume, sent with its start.
    core.reset()
    t, out = _tick_until(core, t, t + 1.5)
    resumes = [c for c in out if isinstance(c, Publish) and c.decision.kind == "resume"]
    assert len(resumes) == 1
    resume = resumes[0].decision
    sent = _goals(out)
    assert [g.reason for g in sent] == ["resume"]  # type: ignore[union-attr]
    assert sent[0].start == resume.replacement_start  # type: ignore[union-attr]
    # Killed again. A resume decided before the latch (a node running the monitor on
    # another thread could hand one over late) must not pass: the gate refuses it.
    assert [g.reason for g in _goals(core.kill(t + TICK))] == ["stop"]  # type: ignore[union-attr]
    refused = len(core.refused)
    monkeypatch.setattr(core.monitor, "tick", lambda now: resume)
    out = core.on_tick(t + 2 * TICK)
    assert _goals(out) == [] and isinstance(out[0], Publish)
    assert len(core.refused) == refused + 1
    assert core.refused[-1].command.reason == "resume"  # type: ignore[union-attr]
    assert core.refused[-1].why == "kill switch latched"


def test_a_kill_holds_the_next_motion_until_reset(node_core: NodeCoreFactory) -> None:
    core = node_core()
    core.activate(0.0)  # the gripper closes
    assert _goals(core.kill(0.2)) == []  # no motion yet: nothing to stop
    assert _goals(core.on_gripper_done(0.5)) == []
    assert core.refused[-1].command.reason == "next motion"  # type: ignore[union-attr]
    assert core.refused[-1].why == "kill switch latched"
    t, out = _tick_until(core, 0.5, 1.0)
    assert _goals(out) == [] and len(core.refused) == 1  # waits, refused once
    core.reset()
    out = core.on_tick(t + TICK)
    sent = _goals(out)
    assert len(sent) == 1 and isinstance(sent[0], SendGoal)
    assert sent[0].reason == "next motion" and sent[0].start == t + TICK
    assert sent[0].trajectory is core.motions[0][0]
    assert _goals(core.on_tick(t + 2 * TICK)) == []  # once


def test_a_kill_at_a_motions_end_holds_the_gripper(node_core: NodeCoreFactory) -> None:
    core, first = _started(node_core)
    end = 0.5 + first.trajectory.duration
    t, _ = _tick_until(core, 0.5, end - 0.1)
    # 5 ms before the end the motion comes to rest at its end within the command
    # latency: a stop replacement, if any, rests there too.
    stop = _goals(core.kill(end - 0.005))
    assert [g.reason for g in stop] in ([], ["stop"])  # type: ignore[union-attr]
    # The goal succeeds at the path's end: the gripper would open next.
    done = end + 0.1
    assert core.monitor is not None and core.monitor.at_end(done)
    assert _goals(core.on_motion_done(done)) == []
    assert isinstance(core.refused[-1].command, Gripper)
    assert core.refused[-1].command.event.action == "open"
    _, out = _tick_until(core, done, done + 0.5)
    assert _goals(out) == []
    core.reset()
    sent = _goals(core.on_tick(done + 0.5 + TICK))
    assert len(sent) == 1 and isinstance(sent[0], Gripper)
    assert sent[0].event.action == "open"
    # Where the route opens it: the end of the first motion.
    assert sent[0].q is not None
    np.testing.assert_array_equal(sent[0].q, first.trajectory.q[-1])


def test_a_stop_at_rest_mid_path_does_not_move_the_route_on(node_core: NodeCoreFactory,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    core, first = _started(node_core)
    t, _ = _tick_until(core, 0.5, 2.0)
    kill = core.kill(t)
    stop = _published(kill)
    assert stop.replacement is not None and stop.replacement_start is not None
    rest = stop.replacement_start + stop.replacement.duration
    core.reset()
    # The stop's goal succeeds at rest, mid-path: nothing follows, nothing is refused.
    assert core.monitor is not None and not core.monitor.at_end(rest + 0.01)
    assert core.on_motion_done(rest + 0.01) == []
    assert core.refused == []
    # The hold-time rule resumes the motion; only the goal reaching its end moves on.
    t, out = _tick_until(core, t, rest + 1.5)
    resume = [c.decision for c in out if isinstance(c, Publish) and c.decision.kind == "resume"]
    assert len(resume) == 1 and resume[0].replacement is not None
    end = resume[0].replacement_start + resume[0].replacement.duration
    assert core.on_motion_done(end - 0.5) == []  # not there yet
    t, _ = _tick_until(core, t, end)
    nxt = _goals(core.on_motion_done(end + 0.01))
    assert len(nxt) == 1 and isinstance(nxt[0], Gripper) and nxt[0].event.action == "open"
    # While the gripper acts no re-timing of the finished motion may move the arm (a
    # stale resume handed over late is refused).
    monkeypatch.setattr(core.monitor, "tick", lambda now: resume[0])
    assert _goals(core.on_tick(end + 0.02)) == []
    assert core.refused[-1].why == "no motion running"
    assert core.refused[-1].command.reason == "resume"  # type: ignore[union-attr]


def test_an_inactive_node_sends_its_stop_and_holds_the_rest(node_core: NodeCoreFactory) -> None:
    core, _ = _started(node_core)
    t, _ = _tick_until(core, 0.5, 2.0)
    stop = core.deactivate(t)  # mid-path: a stop goes out though the node is inactive
    assert core.state == "inactive"
    assert [g.reason for g in _goals(stop)] == ["stop"]  # type: ignore[union-attr]
    assert core.on_tick(t + TICK) == []  # inactive: no decisions, no goals
    assert core.activate(t + 2 * TICK) == []
    t, out = _tick_until(core, t + 2 * TICK, t + 1.5)  # resumes by the hold-time rule
    resume = [c.decision for c in out if isinstance(c, Publish) and c.decision.kind == "resume"]
    assert len(resume) == 1 and resume[0].replacement is not None
    assert [g.reason for g in _goals(out)] == ["resume"]  # type: ignore[union-attr]
    end = resume[0].replacement_start + resume[0].replacement.duration
    t, _ = _tick_until(core, t, end - 0.1)
    core.deactivate(end - 0.005)
    # The motion reaches its end while the node is inactive: the gripper waits.
    assert _goals(core.on_motion_done(end + 0.1)) == []
    refused = core.refused[-1]
    assert isinstance(refused.command, Gripper) and refused.why == "kill switch latched"
    assert core.activate(end + 0.2) == []
    sent = _goals(core.on_tick(end + 0.2 + TICK))
    assert len(sent) == 1 and isinstance(sent[0], Gripper) and sent[0].event.action == "open"


def test_a_replan_answered_while_killed_waits_for_reset(cell_dir: Path) -> None:
    from safepath.monitor.replan import replan

    box = BoxOnRoute(cell_dir)
    core, scan = box.core, box.scan
    request = None
    t = 0.0
    while request is None and t < 8.0:
        t = round(t + 1 / 30, 6)
        request = next((c for c in scan(t) if isinstance(c, Replan)), None)
    assert request is not None
    traj = replan(core.monitor.cell, request.route, request.request,  # type: ignore[union-attr]
                  held=request.held, margin=request.margin)
    core.kill(t)
    assert _goals(core.on_replanned(request.request, traj, t)) == []
    assert core.refused[-1].why == "kill switch latched"
    first = core.refused[-1].command
    assert isinstance(first, SendGoal) and first.reason == "next motion"
    np.testing.assert_allclose(first.trajectory.q[0], request.request.q, atol=1e-9)
    t = round(t + 1 / 30, 6)
    assert _goals(scan(t)) == []  # still latched: the scans start nothing
    core.reset()
    t = round(t + 1 / 30, 6)
    sent = _goals(core.on_tick(t))  # the node's timer starts what waits
    assert len(sent) == 1 and isinstance(sent[0], SendGoal)
    assert sent[0].trajectory is first.trajectory and sent[0].start == t
