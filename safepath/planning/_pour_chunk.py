"""A route's pour steps (a ``tilt``, or a ``tilt`` and the ``circle`` after it) as one
rest-to-rest piece of the route, planned, timed, checked and verified by
:mod:`safepath.planning.pour` in the route's world, with the figures measured on its
released samples. It is how :func:`~safepath.planning.plan_cell` plans a route's pour
steps, so it is the library's, not the pouring cell's (:mod:`safepath.cells.pouring`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cell.pour_steps import Circle, Tilt
from ..errors import PlanningError
from ..timing import TimedPiece
from ..verify import VerifyResult
from .pour import (
    PourMotion,
    PourWorld,
    cup_axis_in_tcp,
    plan_barista,
    plan_tilt,
    tilt_curve,
    tilt_of,
)

if TYPE_CHECKING:
    from ..cell import Cell
    from ..cell.routes import Route
    from .options import PlanOptions
    from .world import CheckerCache, WorldState

__all__ = ["PourChunk", "plan_pour_chunk"]


@dataclass
class PourChunk:
    """The timed pour of a route.

    Attributes:
        piece: Its timed knots.
        steps_of_knots: The route step of each knot.
        result: The independent re-check's result.
        world: The world it moved in (unchanged by it).
        figures: What was measured on the released samples, per step label (JSON-able).
    """

    piece: TimedPiece
    steps_of_knots: list[int]
    result: VerifyResult
    world: WorldState
    figures: dict[str, dict[str, float]]

    @property
    def duration(self) -> float:
        """Its duration [s]."""
        return float(self.piece.t[-1])


def plan_pour_chunk(cell: Cell, route: Route, i: int, q: np.ndarray, world: WorldState,
                    options: PlanOptions, cache: CheckerCache, labels: list[str]
                    ) -> PourChunk:
    """Plan the tilt at step ``i`` of ``route`` from ``q`` [rad], with the circle of
    step ``i + 1`` if there is one, in ``world`` (its checker and verifier).

    Raises:
        PlanningError: Nothing is held (a tilt pours the held object), or the pour
            cannot be planned within its tolerances (see :func:`plan_tilt`).
        TimingError, VerificationError: As :func:`plan_tilt`.
    """
    step = route.steps[i]
    tilt = step.pour
    assert isinstance(tilt, Tilt)  # Step checks it
    nxt = route.steps[i + 1] if i + 1 < len(route.steps) else None
    circle = nxt if nxt is not None and nxt.kind == "circle" else None
    if world.held is None:
        raise PlanningError("a tilt pours from the held object, and the gripper holds "
                            "nothing here", step=labels[i])
    T0 = cell.robot.frame_pose(q).homogeneous
    R_goal = tilt.goal(T0[:3, :3])
    pivot = tilt.pivot_in_world(T0)
    assert step.max_angular_speed is not None
    opts = replace(options.pour, max_angular_speed=step.max_angular_speed,
                   speed=min(step.speed, circle.speed if circle else 1.0),
                   timing=replace(options.pour.timing,
                                  speed_scale=options.timing.speed_scale))
    names = (labels[i], labels[i + 1]) if circle else (labels[i],)
    pw = PourWorld(cache.checker(world, ()), cache.verifier(world, ()), names)
    if circle is not None:
        assert isinstance(circle.pour, Circle) and circle.tcp_speed is not None
        T1 = tilt_curve(T0, R_goal, pivot)(1.0)
        center = T1[:3, 3] + np.array([circle.pour.center[0], circle.pour.center[1], 0.0])
        motion = plan_barista(cell, q, R_goal, pivot, center, turns=circle.pour.turns,
                              options=replace(opts, tcp_speed=circle.tcp_speed), world=pw)
    else:
        motion = plan_tilt(cell, q, R_goal, pivot, options=opts, world=pw)
    tr = motion.trajectory
    piece = TimedPiece(tr.t, tr.q, tr.qd, tr.qdd, motion.s, np.asarray(tr.step_index))
    steps_of_knots = [i + int(k) for k in tr.step_index]
    target_tilt = tilt_of(R_goal, cup_axis_in_tcp(cell))
    figures = _figures(motion, names, step.max_angular_speed,
                       circle.tcp_speed if circle else None, target_tilt)
    return PourChunk(piece, steps_of_knots, motion.verify, world.copy(), figures)


def _figures(motion: PourMotion, names: tuple[str, ...], w_bound: float,
             v_bound: float | None, target_tilt: float) -> dict[str, dict[str, Any]]:
    """The pour's figures on its released samples [s, rad, rad/s, m, m/s]."""
    t, index = motion.trajectory.t, motion.trajectory.step_index
    out: dict[str, dict[str, Any]] = {}
    for k, name in enumerate(names):
        sel = index == k
        knots = np.flatnonzero(sel)
        row: dict[str, Any] = {
            "kind": "tilt" if k == 0 else "circle",
            "duration": float(t[knots[-1]] - t[max(knots[0] - 1, 0)]),
            "samples": int(sel.sum()),
            "orientation_error": float(motion.angle_error[sel].max()),
            "max_tcp_speed": float(motion.tcp_speed[sel].max()),
            "max_angular_speed": float(motion.angular_speed[sel].max()),
        }
        if k == 0:
            row.update(angular_speed_bound=w_bound,
                       path_error=float(motion.position_error[sel].max()),
                       final_tilt=float(motion.tilt[knots[-1]]),
                       target_tilt=target_tilt)
        else:
            row.update(tcp_speed_bound=v_bound,
                       circle_error=float(motion.position_error[sel].max()),
                       tilt_error=float(np.abs(motion.tilt[sel] - target_tilt).max()),
                       target_tilt=target_tilt)
        out[name] = row
    return out


def describe(figures: dict[str, dict[str, Any]]) -> list[str]:
    """One line per pour step of :attr:`PourChunk.figures` (for ``safepath plan``)."""
    lines = []
    for name, f in figures.items():
        if f["kind"] == "tilt":
            lines.append(
                f"{name}: {f['duration']:.2f} s to {math.degrees(f['final_tilt']):.2f} deg "
                f"(target {math.degrees(f['target_tilt']):.2f}); cup angular speed "
                f"<= {math.degrees(f['max_angular_speed']):.3f} deg/s (bound "
                f"{math.degrees(f['angular_speed_bound']):.3f}); path error "
                f"{f['path_error'] * 1000:.3f} mm, orientation error "
                f"{math.degrees(f['orientation_error']):.3f} deg; peak TCP speed "
                f"{f['max_tcp_speed']:.4f} m/s")
        else:
            lines.append(
                f"{name}: {f['duration']:.2f} s; TCP off the circle <= "
                f"{f['circle_error'] * 1000:.3f} mm, tilt error <= "
                f"{math.degrees(f['tilt_error']):.3f} deg (orientation error "
                f"{math.degrees(f['orientation_error']):.3f} deg); peak TCP speed "
                f"{f['max_tcp_speed']:.4f} m/s (limit {f['tcp_speed_bound']:.3f}); cup "
                f"angular speed <= {math.degrees(f['max_angular_speed']):.3f} deg/s")
        land = f.get("landing")
        if land is not None and land["margin"] is not None:
            spill = math.degrees(land["spill_angle"])
            lines[-1] += (f"; lands in '{land['into']}' (past the {spill:.0f} deg spill angle "
                          f"for {land['pouring_time']:.1f} s: the whole opening >= "
                          f"{land['margin'] * 1000:.1f} mm inside its wall, "
                          f">= {land['height'] * 1000:.0f} mm above it)")
        elif land is not None:
            lines[-1] += (f"; never past the {math.degrees(land['spill_angle']):.0f} deg spill "
                          "angle")
    return lines
