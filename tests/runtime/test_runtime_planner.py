"""RuntimePlanner: real worker processes planning the bundled quality-check cell.

Every result is compared array for array with planning in this process; errors must
come back with their safepath type and evidence; cancelling, time-outs and a killed
worker must leave the planner usable; and planning must not stall this process.
"""

from __future__ import annotations

import gc
import logging
import multiprocessing
import os
import pickle
import shutil
import signal
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import CancelledError, Future, wait
from pathlib import Path

import numpy as np
import pytest

from safepath import (
    Cell,
    ConfigError,
    FrameNotFound,
    IKError,
    PlannerOptions,
    PlannerTimeout,
    PlanOptions,
    PoseError,
    RobotNotFound,
    SafepathError,
    Trajectory,
    VerificationError,
    load_cell,
    load_routes,
    plan_cell,
)
from safepath.runtime import RuntimePlanner, WorkerError
from safepath.runtime._transport import decode_error, encode_error

#: The bundled cell (as in conftest.py).
CELL_DIR = Path(__file__).resolve().parents[2] / "scenes" / "quality_check_cell"

#: Generous bound on how long anything here may take [s] (a worker starts in ~1-3 s).
LONG = 60.0


def assert_same(a: Trajectory, b: Trajectory) -> None:
    """Bit-for-bit equal trajectories (``info`` holds timings and is not compared)."""
    for name in ("t", "q", "qd", "qdd", "step_index"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert (a.joint_names, a.steps, a.events, a.robot, a.route) == \
        (b.joint_names, b.steps, b.events, b.robot, b.route)


def in_process(cell: Cell, routes: list[str], seed: int) -> dict[str, Trajectory]:
    """Plan ``routes`` (a chain, first one first) in this process."""
    table = load_routes(cell.folder, poses=list(cell.poses), objects=list(cell.scene.objects))
    options = PlanOptions(planner=PlannerOptions(seed=seed))
    return plan_cell(cell, options, routes={n: table[n] for n in routes})


def wait_for(condition: Callable[[], bool], what: str, timeout: float = LONG) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.005)


@pytest.fixture(scope="module")
def reference() -> dict[str, Trajectory]:
    """The cell planned in this process with the default seed."""
    return plan_cell(load_cell(CELL_DIR))


@pytest.fixture(scope="module")
def blocked_cell(tmp_path_factory: pytest.TempPathFactory) -> Cell:
    """The bundled cell with a pillar where the TCP passes on the direct high1 -> high2
    move, so that OMPL has to plan a detour (and the seed changes the result)."""
    folder = tmp_path_factory.mktemp("blocked") / "cell"
    shutil.copytree(CELL_DIR, folder)
    cell = load_cell(CELL_DIR)
    x, y, z = cell.robot.tcp_position(0.5 * (cell.pose("high1") + cell.pose("high2")))
    scene = folder / "scene.yaml"
    scene.write_text(scene.read_text().replace("objects:\n", (
        "objects:\n  pillar:\n    shape: box\n    size: [0.05, 0.05, 0.06]\n"
        f"    xyz: [{x:.4f}, {y:.4f}, {z:.4f}]\n"), 1))
    return load_cell(folder)


@pytest.fixture(scope="module")
def blocked(blocked_cell: Cell) -> Iterator[RuntimePlanner]:
    """Two workers planning the blocked cell."""
    with RuntimePlanner(blocked_cell.folder, workers=2) as p:
        yield p


@pytest.fixture(scope="module")
def slow(blocked_cell: Cell) -> Iterator[RuntimePlanner]:
    """A planner whose every new plan of the blocked cell takes at least a second:
    RRTstar keeps optimizing the detour until its time limit."""
    options = PlanOptions(planner=PlannerOptions(planner="RRTstar", time_limit=1.0))
    with RuntimePlanner(blocked_cell.folder, options=options) as p:
        p.ready().result(timeout=LONG)
        yield p


@pytest.fixture(scope="module")
def planner() -> Iterator[RuntimePlanner]:
    with RuntimePlanner(CELL_DIR) as p:
        p.ready().result(timeout=LONG)
        yield p


# -- results ---------------------------------------------------------------------------------
def test_plan_route_equals_in_process_planning(planner: RuntimePlanner,
                                               reference: dict[str, Trajectory]) -> None:
    futures = {name: planner.plan_route(name) for name in reference}
    for name, future in futures.items():
        assert isinstance(future, Future)
        assert_same(future.result(timeout=LONG), reference[name])
    cell = planner.plan_cell().result(timeout=LONG)
    assert list(cell) == list(reference)
    for name, traj in cell.items():
        assert_same(traj, reference[name])


def test_seeds_reach_the_workers_when_ompl_plans(blocked: RuntimePlanner,
                                                blocked_cell: Cell) -> None:
    # The pillar blocks the direct high1 -> high2 move: OMPL plans, and the seed matters.
    one = blocked.plan_route("phase1", seed=1)
    two = blocked.plan_route("phase1", seed=2)
    assert_same(one.result(timeout=LONG), in_process(blocked_cell, ["phase1"], 1)["phase1"])
    assert_same(two.result(timeout=LONG), in_process(blocked_cell, ["phase1"], 2)["phase1"])
    assert one.result().t.shape != two.result().t.shape or \
        not np.array_equal(one.result().q, two.result().q)


# -- typed errors ----------------------------------------------------------------------------
def test_unknown_route_comes_back_as_config_error(planner: RuntimePlanner) -> None:
    with pytest.raises(ConfigError, match="unknown route 'nope'") as info:
        planner.plan_route("nope").result(timeout=LONG)
    assert info.value.key == "routes"
    assert info.value.path == CELL_DIR / "routes.yaml"
    assert "phase1" in str(info.value)


def test_colliding_pose_update_is_refused_with_the_pair(
        planner: RuntimePlanner, cell: Cell, reference: dict[str, Trajectory]) -> None:
    # Issue 28: a pose inside an obstacle was accepted silently (the plans then failed).
    bad = cell.pose("high2").copy()
    bad[1] -= 1.0  # shoulder forward: the forearm hits the camera post
    update = planner.update_poses({"high2": bad})
    plan = planner.plan_route("phase1")  # asked after the update
    with pytest.raises(PoseError) as info:
        update.result(timeout=LONG)
    assert info.value.key == "high2"
    assert "pose 'high2' is in collision" in str(info.value)
    assert "forearm_link / camera_post" in str(info.value)
    # A refused update changes nothing: the plan asked after it uses the taught pose.
    assert_same(plan.result(timeout=LONG), reference["phase1"])

    with pytest.raises(PoseError, match="joint_1") as pose_info:
        planner.update_poses({"high2": [10.0, 0, 0, 0, 0, 0]}).result(timeout=LONG)
    assert pose_info.value.key == "high2"
    with pytest.raises(PoseError, match="unknown pose 'nope'"):
        planner.update_poses({"nope": cell.pose("high2")}).result(timeout=LONG)

    planner.update_poses({"high2": cell.pose("high2")}).result(timeout=LONG)
    assert_same(planner.plan_route("phase1").result(timeout=LONG), reference["phase1"])


def test_errors_cross_the_process_boundary_with_their_evidence() -> None:
    errors: list[SafepathError] = [
        VerificationError("collision", time=1.5, q=np.arange(6.0),
                          pairs=[("forearm_link", "table")], step="2 move high2"),
        RobotNotFound("r2d2", ["ned3pro", "ur5"]),
        FrameNotFound("tcp2", ["tcp", "base"], key="tcp_frame"),
        IKError("no solution", step="1 line high1", fraction=0.25, position=np.ones(3)),
        PlannerTimeout("too slow", step="3 move low1", status="timeout"),
        WorkerError("gone", pid=12, exitcode=-9),
    ]
    for err in errors:
        try:
            raise err
        except SafepathError as caught:
            record = encode_error(caught)
        back = decode_error(pickle.loads(pickle.dumps(record)))
        assert type(back) is type(err)
        assert str(back) == str(err)
        assert back.__dict__.keys() == err.__dict__.keys()
        for key, value in err.__dict__.items():
            np.testing.assert_equal(getattr(back, key), value)
        assert "Traceback" in str(back.__cause__)


def test_a_scene_that_does_not_load_fails_ready_and_requests(cell_copy: Path) -> None:
    (cell_copy / "routes.yaml").write_text("routes:\n  broken:\n    start: nowhere\n")
    with RuntimePlanner(cell_copy) as broken:
        with pytest.raises(ConfigError) as info:
            broken.ready().result(timeout=LONG)
        assert info.value.path is not None and info.value.path.name == "routes.yaml"
        with pytest.raises(ConfigError):
            broken.plan_route("broken").result(timeout=LONG)
    with pytest.raises(ConfigError, match="scene folder not found"):
        RuntimePlanner(cell_copy / "missing")


# -- cancelling, time-outs, crashes ----------------------------------------------------------
def test_cancel_before_start_skips_the_work(planner: RuntimePlanner) -> None:
    before = planner.stats()
    first = planner.plan_cell(seed=11)
    second = planner.plan_route("phase1", seed=12)
    assert second.cancel()
    done, _ = wait([second], timeout=1.0)
    assert second in done and second.cancelled()
    first.result(timeout=LONG)
    # The worker thread drops the cancelled request when it gets to it.
    wait_for(lambda: planner.stats().skipped == before.skipped + 1, "the skip")
    after = planner.stats()
    assert after.sent == before.sent + 1
    assert after.pids == before.pids  # nothing was killed


#: Generous bound on answering from the cache [s] (about a millisecond; a worker that
#: has to load takes one to three seconds).
CACHED = 0.5


def timed(future: Future[Trajectory]) -> tuple[Trajectory, float]:
    """The result and how long it took from now [s]."""
    t0 = time.perf_counter()
    return future.result(timeout=LONG), time.perf_counter() - t0


def idle(planner: RuntimePlanner) -> bool:
    """No request running, every worker loaded (a stopped one is replaced)."""
    stats = planner.stats()
    return stats.busy == 0 and None not in stats.pids


def test_cancel_while_planning_keeps_the_cache_and_swaps_in_the_spare(
        slow: RuntimePlanner) -> None:
    # The worker planned the cell with the default seed while warming up: cached.
    cached, took = timed(slow.plan_route("phase2_safe"))
    assert took < CACHED
    wait_for(lambda: len(slow.stats().spares) == 1, "the spare to load")
    before = slow.stats()
    spare = before.spares[0]
    future = slow.plan_cell(seed=21)
    wait_for(lambda: slow.stats().busy == 1, "the worker to take the request")
    assert future.cancel()
    with pytest.raises(CancelledError):
        future.result(timeout=1.0)
    # The cache is in this process: the stopped worker took nothing with it.
    traj, took = timed(slow.plan_route("phase2_safe"))
    assert_same(traj, cached)
    assert took < CACHED, f"cached answer after a cancel took {took:.3f} s"
    # The spare took the stopped worker's place; a new spare loads behind it.
    wait_for(lambda: slow.stats().pids == (spare,), "the spare to take over", 5.0)
    wait_for(lambda: len(slow.stats().spares) == 1, "a new spare")
    after = slow.stats()
    assert after.killed == before.killed + 1
    assert after.cached >= before.cached + 1
    assert after.started == before.started + 1
    assert before.pids[0] not in after.pids + after.spares


def test_a_bad_pose_update_is_answered_at_once_while_the_worker_is_busy(
        slow: RuntimePlanner) -> None:
    """Issue 36: right after a cancel (the spare taking over, a new spare loading) and
    with the worker busy, a pose update with a value outside the limits, a wrong count
    or an unknown name is refused when update_poses returns, not after the workers
    (8.7-11.2 s it took)."""
    slow.ready().result(timeout=LONG)
    running = slow.plan_cell(seed=25)
    wait_for(lambda: slow.stats().busy == 1, "the worker to take the request")
    for update, match in (({"high2": [10.0, 0, 0, 0, 0, 0]}, "joint_1 = 10.00000"),
                          ({"high2": [0.0, 0.0]}, "expected 6 joint values"),
                          ({"hihg2": [0.0] * 6}, "did you mean 'high2'")):
        future = slow.update_poses(update)
        assert future.done()
        with pytest.raises(PoseError, match=match):
            future.result(timeout=0)
    assert running.cancel()
    future = slow.update_poses({"high2": [10.0, 0, 0, 0, 0, 0]})  # just after a cancel
    assert future.done() and isinstance(future.exception(timeout=0), PoseError)


def test_ready_waits_for_the_warm_spare(slow: RuntimePlanner) -> None:
    # Issue 28: ready() was done before the spare had loaded, so a fresh plan right
    # after a cancel waited for a new worker to load (3.6-4.0 s against 1.06 s).
    slow.ready().result(timeout=LONG)
    spares = slow.stats().spares
    assert len(spares) == 1  # no waiting here: ready() means the spare is loaded
    future = slow.plan_cell(seed=23)
    wait_for(lambda: slow.stats().busy == 1, "the worker to take the request")
    assert future.cancel()
    # The spare's own pid in the slot proves it took over (no new worker loaded); how
    # soon is benchmarks/runtime_recovery.py's figure, not a wall-time bound here (a
    # 5 s bound failed once in a full suite on 2 busy cores).
    wait_for(lambda: slow.stats().pids == spares, "the spare to take over")
    # The new spare loads behind it (a few seconds): ready() waits for it again.
    slow.ready().result(timeout=LONG)
    after = slow.stats()
    assert len(after.spares) == 1 and after.spares != spares


def test_timeout_answers_at_its_deadline_and_keeps_the_cache(slow: RuntimePlanner) -> None:
    cached = slow.plan_route("phase1").result(timeout=LONG)
    wait_for(lambda: idle(slow), "the planner to be idle")
    before = slow.stats()
    t0 = time.perf_counter()
    with pytest.raises(PlannerTimeout, match="0.2 s timeout") as info:
        slow.plan_cell(seed=31, timeout=0.2).result(timeout=LONG)
    took = time.perf_counter() - t0
    assert info.value.status == "timeout"
    # benchmarks/runtime_recovery.py measures the overshoot (milliseconds).
    assert 0.2 <= took < 0.2 + CACHED, f"a 0.2 s timeout answered after {took:.3f} s"
    traj, took = timed(slow.plan_route("phase1"))
    assert_same(traj, cached)
    assert took < CACHED
    assert slow.stats().timed_out == before.timed_out + 1
    wait_for(lambda: slow.stats().killed == before.killed + 1, "the worker to be stopped")


def test_a_waiting_caller_times_its_request_out_itself(slow: RuntimePlanner,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The thread blocked in ``result()`` fails the request at its deadline itself (one
    scheduler wake-up, not the deadline thread's and then its own): here the deadline
    thread never hears of the request, and the answer still comes at the deadline."""
    from safepath.runtime import _job

    wait_for(lambda: idle(slow), "the planner to be idle")
    before = slow.stats()
    monkeypatch.setattr(_job.Deadlines, "add", lambda self, job: None)
    t0 = time.perf_counter()
    with pytest.raises(PlannerTimeout, match="0.1 s timeout"):
        slow.plan_cell(seed=37, timeout=0.1).result(timeout=LONG)
    took = time.perf_counter() - t0
    assert 0.1 <= took < 0.1 + CACHED, f"a 0.1 s timeout answered after {took:.3f} s"
    assert slow.stats().timed_out == before.timed_out + 1
    wait_for(lambda: slow.stats().killed == before.killed + 1, "the worker to be stopped")


def test_a_queued_request_times_out_without_a_worker(slow: RuntimePlanner) -> None:
    wait_for(lambda: idle(slow), "the planner to be idle")
    before = slow.stats()
    busy = slow.plan_cell(seed=34)
    wait_for(lambda: slow.stats().busy == 1, "the worker to take the request")
    t0 = time.perf_counter()
    with pytest.raises(PlannerTimeout, match="route 'phase1' not planned within the 0.05 s"):
        slow.plan_route("phase1", seed=35, timeout=0.05).result(timeout=LONG)
    assert time.perf_counter() - t0 < 0.05 + CACHED
    busy.result(timeout=LONG)  # the running request was not disturbed
    wait_for(lambda: slow.stats().skipped == before.skipped + 1, "the skip")
    after = slow.stats()
    assert after.killed == before.killed and after.pids == before.pids


def test_a_killed_worker_is_a_typed_error_then_replaced(
        planner: RuntimePlanner, reference: dict[str, Trajectory]) -> None:
    future = planner.plan_cell(seed=41)
    wait_for(lambda: planner.stats().busy == 1, "the worker to take the request")
    pid = planner.stats().pids[0]
    assert pid is not None
    os.kill(pid, signal.SIGKILL)
    with pytest.raises(WorkerError, match="killed by SIGKILL") as info:
        future.result(timeout=LONG)
    assert info.value.pid == pid and info.value.exitcode == -signal.SIGKILL
    assert_same(planner.plan_route("phase1").result(timeout=LONG), reference["phase1"])
    assert planner.stats().crashed >= 1


# -- threads ---------------------------------------------------------------------------------
def test_four_threads_get_the_serial_results(blocked: RuntimePlanner,
                                             blocked_cell: Cell) -> None:
    jobs = [("phase1", 50), ("phase2_safe", 50), ("phase1", 51), ("phase2_safe", 51)]
    results: dict[int, dict[tuple[str, int], Trajectory]] = {}
    start = threading.Barrier(4)

    def client(k: int) -> None:
        start.wait()
        order = jobs[k:] + jobs[:k]  # every thread asks in a different order
        futures = {job: blocked.plan_route(job[0], seed=job[1]) for job in order}
        results[k] = {job: f.result(timeout=LONG) for job, f in futures.items()}

    threads = [threading.Thread(target=client, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(LONG)
    serial = {seed: in_process(blocked_cell, ["phase1", "phase2_safe"], seed)
              for seed in (50, 51)}
    assert sorted(results) == [0, 1, 2, 3]
    for trajs in results.values():
        assert sorted(trajs) == sorted(jobs)
        for (name, seed), traj in trajs.items():
            assert_same(traj, serial[seed][name])

    # A pose update reaches both workers before the requests made after it.
    high2 = blocked_cell.pose("high2")
    moved = high2.copy()
    moved[0] += 0.05  # a free pose a little further round
    blocked.update_poses({"high2": moved})
    later = [blocked.plan_route("phase1", seed=seed) for seed in (50, 51)]
    blocked.update_poses({"high2": high2})
    again = blocked.plan_route("phase1", seed=50)
    for future in later:
        q = future.result(timeout=LONG).q
        assert np.isclose(q, moved, atol=1e-9).all(axis=1).any()  # it goes through it
        assert not np.isclose(q, high2, atol=1e-9).all(axis=1).any()
    assert_same(again.result(timeout=LONG), serial[50]["phase1"])


def test_planning_does_not_stall_this_process(blocked: RuntimePlanner, slow: RuntimePlanner,
                                              planner: RuntimePlanner) -> None:
    # The blocked cell makes OMPL plan: in-process, that holds the interpreter lock for
    # most of 100 ms at a time (see benchmarks/runtime_heartbeat.py --detour high1 high2).
    # Measured once no spare of this module's planners is loading (on two cores, a
    # loading worker takes the CPU this process's heartbeat needs).
    for p in (blocked, slow, planner):
        wait_for(lambda p=p: len(p.stats().spares) == 1, "the spares to load")
    gaps: list[float] = []
    stop = threading.Event()

    def heartbeat() -> None:  # 100 Hz
        last = time.perf_counter()
        while not stop.is_set():
            time.sleep(0.01)
            now = time.perf_counter()
            gaps.append(now - last)
            last = now

    beat = threading.Thread(target=heartbeat)
    beat.start()
    try:
        # The cycle, new seeds (nothing comes from the workers' caches), for at least 1.5 s
        # of planning whatever the planner's speed.
        t0, k = time.perf_counter(), 0
        while k < 4 or time.perf_counter() - t0 < 1.5:
            blocked.plan_cell(seed=100 + k).result(timeout=LONG)
            k += 1
    finally:
        stop.set()
        beat.join()
    assert len(gaps) > 100
    assert max(gaps) < 0.1, f"heartbeat gap {max(gaps) * 1000:.1f} ms"
    assert np.percentile(gaps, 99) < 0.05, f"p99 gap {np.percentile(gaps, 99) * 1000:.1f} ms"


# -- life cycle ------------------------------------------------------------------------------
def _workers() -> set[int]:
    return {p.pid for p in multiprocessing.active_children()
            if p.name.startswith("safepath-runtime-worker") and p.pid is not None}


def test_close_reaps_the_workers_and_is_idempotent() -> None:
    p = RuntimePlanner(CELL_DIR)
    p.ready().result(timeout=LONG)
    pid = p.stats().pids[0]
    assert pid in _workers()
    queued = [p.plan_cell(seed=60), p.plan_route("phase1", seed=61)]
    p.close()
    p.close()
    assert p.closed and p.stats().pids == (None,)
    assert pid not in _workers()
    assert all(f.cancelled() for f in queued)
    with pytest.raises(WorkerError, match="closed"):
        p.plan_route("phase1").result(timeout=1.0)


def test_a_dropped_planner_finishes_its_requests_then_stops(
        reference: dict[str, Trajectory]) -> None:
    # What the ROS node does: plan, keep only the futures.
    before = _workers()
    p = RuntimePlanner(CELL_DIR)
    futures = [p.plan_route(name) for name in ("phase1", "phase2_safe")]
    del p
    gc.collect()
    assert_same(futures[0].result(timeout=LONG), reference["phase1"])
    assert_same(futures[1].result(timeout=LONG), reference["phase2_safe"])
    wait_for(lambda: not (_workers() - before), "the dropped planner's worker to exit")


def test_worker_log_records_reach_the_callers_loggers(caplog: pytest.LogCaptureFixture
                                                      ) -> None:
    caplog.set_level(logging.DEBUG, logger="safepath")
    with RuntimePlanner(CELL_DIR) as p:
        p.plan_cell(seed=3).result(timeout=LONG)
    remote = [r for r in caplog.records if r.processName.startswith("safepath-runtime-worker")]
    assert any(r.name.startswith("safepath.planning.") for r in remote)
    assert any("ready in" in r.getMessage() for r in caplog.records
               if r.name == "safepath.runtime._launcher")


def test_invalid_arguments_raise_at_once(planner: RuntimePlanner) -> None:
    with pytest.raises(SafepathError, match="timeout"):
        planner.plan_route("phase1", timeout=0)
    with pytest.raises(SafepathError, match="seed"):
        planner.plan_route("phase1", seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(PoseError):
        planner.update_poses([1, 2, 3])  # type: ignore[arg-type]
    with pytest.raises(SafepathError, match="workers"):
        RuntimePlanner(CELL_DIR, workers=0)
    with pytest.raises(SafepathError, match="start_method"):
        RuntimePlanner(CELL_DIR, start_method="fork")  # type: ignore[arg-type]
    with pytest.raises(SafepathError, match="spare"):
        RuntimePlanner(CELL_DIR, spare=2)  # type: ignore[arg-type]
