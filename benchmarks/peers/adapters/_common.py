"""Shared by the adapters: read a job, time things, write the result.

Runs inside each peer's own venv, so it needs numpy and the standard library only.

A job (JSON) holds ``robot`` (URDF, SRDF, joint names, limits, TCP link, links that
never check against the environment), ``worlds`` (obstacles as boxes/cylinders with 4x4
world poses, an object attached to the TCP link, pairs not to check), ``problems``
(id, world, start, goal, seed), ``check`` (a world and joint vectors for the
collision-checks-per-second figure) and ``sample_period`` [s].

A result (JSON) holds ``peer``, ``version``, ``settings`` (what was used, defaults
named), ``checks`` (count, seconds, colliding) and per problem: ``ok``, ``error``,
``plan_seconds`` (path search, with the peer's own simplification where it cannot be
separated), ``smooth_seconds``, ``timing_seconds``, ``total_seconds``, ``duration``
[s], ``waypoints``, and the timed path ``t`` [s], ``q`` [rad] sampled every
``sample_period``.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["load_job", "write_result", "Timer", "run_problems", "time_checks",
           "quat_wxyz"]


def load_job() -> tuple[dict[str, Any], str]:
    """The job (from argv[1]) and the result path (argv[2])."""
    if len(sys.argv) != 3:
        raise SystemExit(f"usage: {sys.argv[0]} JOB.json RESULT.json")
    with open(sys.argv[1]) as f:
        return json.load(f), sys.argv[2]


def write_result(path: str, result: dict[str, Any]) -> None:
    """Write the result JSON."""
    with open(path, "w") as f:
        json.dump(result, f, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))


class Timer:
    """``with Timer() as t: ...``; then ``t.seconds``."""

    def __enter__(self) -> Timer:
        self._t0 = time.perf_counter()
        self.seconds = 0.0
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds = time.perf_counter() - self._t0


def run_problems(job: dict[str, Any], solve: Callable[[dict[str, Any]], dict[str, Any]]
                 ) -> list[dict[str, Any]]:
    """Call ``solve(problem)`` for every problem; an exception is a failed problem.

    The first problem is solved once untimed before (warm-up: lazy imports, caches).
    """
    if job["problems"]:
        try:
            solve(job["problems"][0])
        except Exception:  # the timed run reports it
            pass
    out = []
    for problem in job["problems"]:
        try:
            res = solve(problem)
        except Exception as exc:  # the peer's own failure, whatever its type
            res = {"ok": False, "error": f"{type(exc).__name__}: {exc}"[:500],
                   "trace": traceback.format_exc()[-1500:]}
        res["id"] = problem["id"]
        for key in ("t", "q"):
            if key in res and res[key] is not None:
                res[key] = np.asarray(res[key], dtype=float).tolist()
        out.append(res)
        print(f"[{job.get('peer', '?')}] {problem['id']}: "
              f"{'ok' if res.get('ok') else 'FAIL ' + str(res.get('error'))[:120]}",
              file=sys.stderr, flush=True)
    return out


def time_checks(states: list[list[float]], check: Callable[[np.ndarray], bool], *,
                repeats: int = 3) -> dict[str, Any]:
    """Time single-state collision checks; ``check(q)`` returns True when colliding.

    Three passes over the states; the fastest counts (the machine is shared).
    """
    qs = [np.asarray(q, dtype=float) for q in states]
    check(qs[0])  # warm-up (first call may build caches)
    passes = []
    for _ in range(repeats):
        colliding = 0
        t0 = time.perf_counter()
        for q in qs:
            colliding += bool(check(q))
        passes.append(time.perf_counter() - t0)
    seconds = min(passes)
    return {"count": len(qs), "seconds": seconds, "passes": passes, "colliding": colliding,
            "per_second": len(qs) / seconds if seconds > 0 else None}


def quat_wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
             (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q)
