"""The brief's way of moving, for comparison: every route step rest to rest on its own.

The brief's node sends one arm command per taught pose and waits for each to finish, so
the arm stops at every pose. :func:`stop_and_go` turns a verified route into that motion:
the same path (the route's own knots), cut where its steps meet, each piece timed rest
to rest by safepath's timing (:func:`safepath.timing.time_path`) at the step's
speed scale and TCP speed limit, the gripper events kept between the same pieces. It is
the motion of ``safepath plan``'s stop-and-go column, as a trajectory the twin can run.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..model.trajectory import GripperEvent, Trajectory

if TYPE_CHECKING:
    from ..cell import Cell

__all__ = ["stop_and_go"]


def _step_number(label: str) -> int:
    head = label.split(" ", 1)[0]
    return int(head) if head.isdigit() else -1


def _pieces(traj: Trajectory) -> list[tuple[int, int]]:
    """Knot index ranges ``[a, b]`` of ``traj`` between its step changes and events."""
    cuts = {0, traj.t.size - 1}
    cuts.update(int(k) for k in np.flatnonzero(np.diff(traj.step_index)) + 1)
    for event in traj.events:
        cuts.add(int(np.argmin(np.abs(traj.t - event.time))))
    ordered = sorted(cuts)
    return [(a, b) for a, b in zip(ordered[:-1], ordered[1:], strict=True) if b > a]


def stop_and_go(cell: Cell, traj: Trajectory) -> Trajectory:
    """``traj``'s path, stopping where each of its steps ends (see the module docstring).

    Raises:
        TimingError: A piece cannot be timed.
    """
    from ..timing import TimingOptions, spline_path, time_path

    steps = cell.route_table()[traj.route].steps if traj.route else ()
    options = TimingOptions()
    ts, qs, qds, qdds, idx = [np.zeros(1)], [traj.q[:1]], [np.zeros((1, traj.dof))], \
        [np.zeros((1, traj.dof))], [traj.step_index[:1]]
    clock = 0.0
    event_times: dict[int, float] = {}
    events_at = {int(np.argmin(np.abs(traj.t - e.time))): e for e in traj.events}
    if 0 in events_at:
        event_times[0] = 0.0
    for a, b in _pieces(traj):
        label = traj.steps[traj.step_index[a + 1]] if traj.steps else ""
        n = _step_number(label)
        step = steps[n] if 0 <= n < len(steps) else None
        waypoints = traj.q[a:b + 1]
        keep = np.concatenate([[True], np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
                               > 1e-9])
        waypoints = waypoints[keep]
        if len(waypoints) >= 2:
            path, s_way, _ = spline_path(list(waypoints), options.spacing)
            segments = len(waypoints) - 1
            piece = time_path(cell.robot, path, s_way,
                              scales=[step.speed if step else 1.0] * segments,
                              tcp_speeds=[step.tcp_speed if step else None] * segments,
                              options=options, step=label)
            ts.append(clock + piece.t[1:])
            qs.append(piece.q[1:])
            qds.append(piece.qd[1:])
            qdds.append(piece.qdd[1:])
            idx.append(np.full(piece.t.size - 1, traj.step_index[a + 1]))
            qs[-1][-1] = traj.q[b]  # end exactly where the route's step ends
            clock += float(piece.t[-1])
        if b in events_at:
            event_times[b] = clock
    events = tuple(replace(e, time=event_times[k]) for k, e in events_at.items()
                   if isinstance(e, GripperEvent))
    info = {**traj.info, "stop_and_go": True}
    return Trajectory(traj.joint_names, np.concatenate(ts), np.vstack(qs), np.vstack(qds),
                      np.vstack(qdds), np.concatenate(idx), traj.steps, events, traj.robot,
                      traj.route, info, traj.limits, traj.interpolation)
