"""Commands the bundled cells' controllers share: cancel an overdue goal, the cell stopped.

The cells' state machines (:mod:`safepath.cells.quality_check`, :mod:`safepath.cells.pouring`)
return their decisions as commands for the ROS node to carry out; these two mean the same
in every cell, so they live here, in the library, and each cell adds its own.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CancelGoal", "Fault"]


@dataclass(frozen=True)
class CancelGoal:
    """Cancel a goal that is overdue."""

    goal_id: int


@dataclass(frozen=True)
class Fault:
    """The cell stopped: no further motion (the quality-check controller also stops the
    conveyor, until its ``reset()``)."""

    reason: str
