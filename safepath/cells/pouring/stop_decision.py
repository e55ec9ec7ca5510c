"""The gravimetric controller for a cup that empties (:class:`~safepath.cells.pouring.cup.Cup`).

It knows the cup (geometry, fill, repose, flow exponent), the scale's latency and the fall
time, and its own stop-and-return motions (:func:`plan_stops`: the real braking and the
planned returns at events along the tilt), but not the flow gain. At every reading it
picks, on a grid of gains (:data:`GAINS`), the one whose predicted readings fit the
readings so far best (least squares), predicts with it the final mass if it stopped
there (what left the cup by then, what the stop and the return still pour, interpolated
between the events) and stops when that reaches the target.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .cup import Cup

__all__ = ["GAINS", "StopTable", "plan_stops", "decide", "Delays"]


class Delays(Protocol):
    """What :func:`decide` reads of the flow model (``flow.FlowModel``), so that
    this module imports nothing of the module that calls it."""

    @property
    def cup(self) -> Cup | None:
        """The cup that empties."""

    @property
    def latency(self) -> float:
        """Scale reading delay [s]."""

    @property
    def fall_time(self) -> float:
        """Time from the lip to the bowl [s]."""

#: The controller's grid of flow gains [g/s/rad^1.5] (log-spaced).
GAINS = np.geomspace(5.0, 5000.0, 48)


@dataclass(frozen=True)
class StopTable:
    """The controller's model of its own stops: the tilt history of the stop and the
    return upright from events along the pour motion.

    Attributes:
        events: Event times on the motion [s] (increasing).
        histories: Per event, (times from the event [s], tilts [rad]).
    """

    events: np.ndarray
    histories: tuple[tuple[np.ndarray, np.ndarray], ...]


StopFn = Callable[[float], tuple[np.ndarray, np.ndarray, float]]


def plan_stops(stop: StopFn, tilt_of_t: Callable[[float], float], duration: float,
               cup: Cup, *, samples: int = 12) -> StopTable:
    """The stop and return at ``samples`` events from where the cup starts to spill to
    the motion's end (the real braking and planned returns of ``stop``)."""
    times = np.linspace(0.0, duration, 800)
    tilts = np.array([tilt_of_t(float(t)) for t in times])
    spill = cup.spill_angle(cup.fill)
    first = float(times[np.argmax(tilts > spill)]) if (tilts > spill).any() else duration
    events = np.linspace(first, duration * 0.999, samples)
    histories = tuple((h[0], h[1]) for h in (stop(float(e)) for e in events))
    return StopTable(events, histories)


def decide(model: Delays, t_motion: np.ndarray, tilt_motion: np.ndarray,
           readings: np.ndarray, stops: StopTable, target: float
           ) -> tuple[float | None, float]:
    """The controller on the motion's readings.

    Args:
        model: Its cup, latency and fall time (not its gain).
        t_motion: Times of the pour motion [s].
        tilt_motion: Its tilt at those times [rad].
        readings: (time [s], reading [g]) of the scale during the motion.
        stops: The controller's stops.
        target: Mass to pour [g].

    Returns:
        The time of the first reading at which the best-fitting gain predicts a final
        mass >= ``target`` if it stopped there (None: never), and that gain.
    """
    cup = model.cup
    assert cup is not None  # FlowModel.cup: the caller dispatches on it
    out = cup.pour(t_motion, tilt_motion, GAINS)  # (G, N) what left the cup
    seen = np.array([np.interp(readings[:, 0] - model.latency - model.fall_time, t_motion, o,
                               left=0.0) for o in out])
    sse = np.cumsum((seen - readings[None, :, 1]) ** 2, axis=1)
    # Final mass per gain and event: what left the cup by the event, and what the stop
    # and the return (then resting upright) still pour.
    final = np.empty((GAINS.size, stops.events.size))
    for j, (event, (th, tilt)) in enumerate(zip(stops.events, stops.histories, strict=True)):
        left = np.array([np.interp(event, t_motion, o) for o in out])
        tail = np.append(th, th[-1] + 2.0)
        more = cup.pour(tail, np.append(tilt, tilt[-1]), GAINS, content=cup.fill - left)
        final[:, j] = left + more[:, -1]
    for k in range(len(readings)):
        g = int(np.argmin(sse[:, k]))
        tk = float(readings[k, 0])
        if tk < stops.events[0]:
            continue
        if float(np.interp(tk, stops.events, final[g])) >= target:
            return tk, float(GAINS[g])
    return None, float(GAINS[int(np.argmin(sse[:, -1]))])
