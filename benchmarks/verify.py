"""Cost of the independent release check (``StagedVerifier.verify``) on the bundled cell.

Records every verification one warm :func:`safepath.plan_cell` of the quality-check cell
makes (its three routes), then replays them:

* with the verifier, ``--runs`` times: its wall time per plan (minimum and median),
  the grid samples, the samples where FCL judged or measured a pair, the FCL pair
  checks, and the pair bounds its conservative layer evaluated;
* with the brute-force check the verifier stands for (written here): every grid sample
  placed with pinocchio and every pair judged with FCL, once, on the first
  ``--dense-calls`` verifications (all by default), with the verifier's time on the same
  calls, and whether both found the same (no failure; the verifier's clearance within
  half a resolution above the dense one).

Timings fluctuate on a shared machine: both are measured in the same run, with the
load average printed. Aim: the verifier at <= 10 ms per warm plan of the cell.

Run: ``.venv/bin/python benchmarks/verify.py [--runs 20] [--dense-calls N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import fcl
import numpy as np
import pinocchio as pin

from safepath import load_cell, plan_cell
from safepath.verify import FclVerifier, StagedVerifier, VerifyResult

CELL_DIR = Path(__file__).resolve().parents[1] / "scenes" / "quality_check_cell"
#: Aim for the verifier's time per warm plan of the cell [s].
AIM = 0.010


@dataclass(frozen=True)
class Call:
    """One verification made while planning: the verifier, its trajectory and the knot
    where each of its stages starts."""

    verifier: StagedVerifier
    t: np.ndarray
    q: np.ndarray
    starts: list[int]


def record_calls() -> list[Call]:
    """The verifications of one warm plan of the cell (after a first, cold plan)."""
    cell = load_cell(CELL_DIR)
    plan_cell(cell)
    calls: list[Call] = []
    original = StagedVerifier.verify

    def recording(self: StagedVerifier, t: np.ndarray, q: np.ndarray, starts: list[int],
                  **kwargs: object) -> VerifyResult:
        calls.append(Call(self, t, q, list(starts)))
        return original(self, t, q, starts, **kwargs)  # type: ignore[arg-type]

    with mock.patch.object(StagedVerifier, "verify", recording):
        plan_cell(cell)
    return calls


def replay(calls: Sequence[Call]) -> tuple[float, list[VerifyResult]]:
    """Wall time of the verifier on the calls [s], and its results."""
    start = time.perf_counter()
    results = [c.verifier.verify(c.t, c.q, c.starts) for c in calls]
    return time.perf_counter() - start, results


def dense(call: Call) -> tuple[bool, float]:
    """Brute force: every grid sample of each stage's stretch placed with pinocchio,
    every pair judged with FCL (against the stage verifier's own pair list and what each
    pair must keep).

    Returns:
        Whether a sample fails, and the smallest robot-environment distance [m].
    """
    ends = [*call.starts[1:], len(call.q) - 1]
    failed, clearance = False, np.inf
    for v, a, b in zip(call.verifier.verifiers, call.starts, ends, strict=True):
        stage_failed, stage_clearance = _dense_stretch(v, np.asarray(call.q[a:b + 1]))
        failed, clearance = failed or stage_failed, min(clearance, stage_clearance)
    return failed, clearance


def _dense_stretch(v: FclVerifier, q: np.ndarray) -> tuple[bool, float]:
    """:func:`dense` on one stage's stretch ``q`` with its verifier ``v``."""
    grid = v.grid(q)
    model = v.robot.model
    data = model.createData()
    request = fcl.DistanceRequest()
    clearance = np.inf
    movers, environment = v.movers, v.environment
    for s in range(grid.samples):
        pin.forwardKinematics(model, data, grid.state(q, s))
        for body in movers:
            T = data.oMi[body.joint].homogeneous @ body.T
            body.fcl.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
        for pair in v.pairs:
            o1 = movers[pair.first].fcl
            o2 = (environment if pair.environment else movers)[pair.second].fcl
            if pair.allowed_depth > 0.0:
                result = fcl.CollisionResult()
                request_c = fcl.CollisionRequest(enable_contact=True, num_max_contacts=4)
                if fcl.collide(o1, o2, request_c, result) and max(
                        c.penetration_depth for c in result.contacts) > pair.allowed_depth:
                    return True, clearance
                continue
            d = fcl.distance(o1, o2, request, fcl.DistanceResult())
            if d < pair.keep or (d <= 0.0 and fcl.collide(  # its margin, or zero
                    o1, o2, fcl.CollisionRequest(), fcl.CollisionResult())):
                return True, clearance
            if pair.environment:
                clearance = min(clearance, d)
    return False, clearance


def load_average() -> str:
    """The 1-minute load average and the core count."""
    if not hasattr(os, "getloadavg"):
        return "load average unavailable"
    return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print its figures; returns the exit status (0)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="replays of the verifier")
    parser.add_argument("--dense-calls", type=int, default=None,
                        help="verifications replayed by brute force (default: all)")
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    calls = record_calls()
    replay(calls)  # warm
    times, results = [], []
    for _ in range(args.runs):
        seconds, results = replay(calls)
        times.append(seconds)
    samples = sum(r.samples for r in results)
    checked = sum(r.checked for r in results)
    print(f"The release check on one warm plan_cell of {CELL_DIR.name} (3 routes): "
          f"{len(calls)} verifications, {samples} grid samples; {load_average()}")
    best, median = min(times), statistics.median(times)
    print(f"  verifier: {best * 1e3:.1f} ms per plan (median {median * 1e3:.1f} ms over "
          f"{args.runs} runs); aim <= {AIM * 1e3:.0f} ms: {'met' if best <= AIM else 'NOT met'}")
    print(f"  samples judged or measured by FCL: {checked} of {samples} "
          f"({sum(r.pair_checks for r in results)} FCL pair checks); the others certified "
          f"by {sum(r.bound_checks for r in results)} bounds of the conservative layer")
    chosen = calls[:args.dense_calls] if args.dense_calls is not None else calls
    start = time.perf_counter()
    verdicts = [dense(c) for c in chosen]
    brute = time.perf_counter() - start
    seconds, mine = replay(chosen)
    same = all(not failed
               and dmin - 1e-9 <= r.min_clearance  # FCL at one sample, placed its way
               <= dmin + c.verifier.verifiers[0].resolution / 2 + 1e-9
               for (failed, dmin), r, c in zip(verdicts, mine, chosen, strict=True))
    print(f"  brute force (every sample, every pair, FCL) on {len(chosen)} of them: "
          f"{brute * 1e3:.0f} ms, the verifier {seconds * 1e3:.1f} ms on the same "
          f"({brute / seconds:.0f}x); same verdicts and clearances: {'yes' if same else 'NO'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
