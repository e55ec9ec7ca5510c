"""The quality-check cell's surroundings: the conveyor with its IR sensor, and the test zone.

Both are kinematic models driven by a ``numpy.random.Generator`` (never global state):

* :class:`Conveyor`: vials are put on the belt's far end at random intervals
  (exponential, mean ``arrival_interval``), ride at ``belt_speed`` while the belt runs,
  keep ``spacing`` between them (centre to centre; a vial is put on only when the last
  one has ridden ``spacing`` away), and stop at the IR sensor at the belt's end (under the
  robot's ``grip`` pose). The conveyor stops itself while a vial stands at the sensor
  (otherwise the vial would be pushed off the end), whatever it was told.
* :class:`VerdictService`: the test zone's answer to a verdict request: the vial's true
  class after a random latency, or, with stated probabilities, no answer at all (a
  time-out for the controller) or a malformed one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Conveyor", "Vial", "VerdictService", "VerdictAnswer"]


@dataclass
class Vial:
    """A vial on its way through the cell.

    Attributes:
        number: Arrival order, from 1.
        unsafe: Its true class.
        arrived: When it was put on the belt [s].
        position: Distance travelled along the belt [m] (the sensor at ``length``).
        picked: When the robot took it off the belt [s] (None: not yet).
        placed: Where it ended up (``packaging`` / ``reject``) and when [s].
    """

    number: int
    unsafe: bool
    arrived: float
    position: float = 0.0
    picked: float | None = None
    placed: tuple[str, float] | None = None


@dataclass
class Conveyor:
    """The conveyor (see the module docstring).

    Attributes:
        length: Distance from where vials are put on to the sensor [m].
        belt_speed: Belt speed [m/s].
        spacing: Least distance between two vials' centres [m].
        arrival_interval: Mean time between two vials put on the belt [s].
        p_unsafe: Probability that a vial is unsafe.
    """

    length: float
    belt_speed: float
    spacing: float
    arrival_interval: float
    p_unsafe: float
    rng: np.random.Generator = field(repr=False)
    commanded: bool = False
    vials: list[Vial] = field(default_factory=list)        # on the belt, front first
    arrived: list[Vial] = field(default_factory=list)      # every vial so far
    next_arrival: float = 0.0
    stopped_time: float = 0.0

    def __post_init__(self) -> None:
        self.next_arrival = float(self.rng.exponential(self.arrival_interval))

    @property
    def sensor(self) -> bool:
        """The IR sensor: a vial stands at the belt's end."""
        return bool(self.vials) and self.vials[0].position >= self.length - 1e-9

    @property
    def running(self) -> bool:
        """Whether the belt moves: commanded, and no vial waiting at the sensor."""
        return self.commanded and not self.sensor

    def advance(self, now: float, dt: float) -> None:
        """Move the belt by ``dt`` [s] up to ``now`` and put on the vials that arrive."""
        if not self.running:
            self.stopped_time += dt
        else:
            front = self.length
            for vial in self.vials:
                vial.position = min(vial.position + self.belt_speed * dt, front)
                front = vial.position - self.spacing
        while self.next_arrival <= now:
            last = self.vials[-1].position if self.vials else math.inf
            if last >= self.spacing:  # room at the far end; else the operator waits
                vial = Vial(len(self.arrived) + 1, bool(self.rng.random() < self.p_unsafe),
                            self.next_arrival)
                self.vials.append(vial)
                self.arrived.append(vial)
            self.next_arrival += float(self.rng.exponential(self.arrival_interval))

    def queued(self) -> tuple[float, ...]:
        """Where the vials behind the sensor stand: each one's distance [m] behind the
        sensor, front first (the vial at the sensor, if any, not included)."""
        return tuple(self.length - v.position for v in self.vials
                     if v.position < self.length - 1e-9)

    def pick(self, now: float) -> Vial | None:
        """The robot takes the vial at the sensor off the belt (None: there is none)."""
        if not self.sensor:
            return None
        vial = self.vials.pop(0)
        vial.picked = now
        return vial


@dataclass(frozen=True)
class VerdictAnswer:
    """The test zone's answer: ``text`` (None: no answer) after ``latency`` [s]."""

    text: str | None
    latency: float


@dataclass(frozen=True, kw_only=True)
class VerdictService:
    """The test zone's verdict service.

    Attributes:
        latency: Answer latency, uniform in [low, high] [s].
        p_timeout: Probability of no answer at all.
        p_malformed: Probability of a malformed answer.
        period: The brief's way: the answer is only read at the next of the test zone's
            publications every ``period`` [s] (None: a service answers each request).
    """

    latency: tuple[float, float] = (0.2, 1.5)
    p_timeout: float = 0.05
    p_malformed: float = 0.05
    period: float | None = None

    @property
    def longest_answer(self) -> float:
        """The longest time from a request to its answer [s]: the longest inference, plus a
        whole ``period`` when the answer waits for the next publication (it is read at the
        first publication after the inference, less than a period after it)."""
        return float(self.latency[1]) + (self.period or 0.0)

    def answer(self, vial: Vial | None, now: float, rng: np.random.Generator) -> VerdictAnswer:
        """The answer to a request made at ``now`` about ``vial``."""
        low, high = self.latency
        latency = float(rng.uniform(low, high))
        if self.period is not None:  # read at the next publication after the inference
            latency = math.ceil((now + latency) / self.period) * self.period - now
        draw = float(rng.random())
        if draw < self.p_timeout:
            return VerdictAnswer(None, latency)
        if draw < self.p_timeout + self.p_malformed:
            return VerdictAnswer(str(rng.choice(["SAFE", "", "vial: safe", "0.93"])), latency)
        truth = vial is not None and not vial.unsafe
        return VerdictAnswer("safe" if truth else "unsafe", latency)
