"""The quality-check cell's state machine: a vial seen on the conveyor, tested, then packed
or rejected.

The motions are the library's (the cell's routes, planned by :func:`safepath.plan_cell`;
their goals, :mod:`safepath.ros.goals`); this package is what the quality-check cell does
with them:

* :mod:`.commands`: the controller's options, the commands it returns and its cycle
  report (:class:`~safepath.ros.commands.CancelGoal` and
  :class:`~safepath.ros.commands.Fault` are the library's, shared with the other cells).
* :mod:`.controller`: :class:`~.controller.QualityCheckController`, the cell's state
  machine, ROS-free (sensor readings, verdicts and goal results in, goals out).
"""

from .commands import (
    ActuateGripper,
    Command,
    ControllerOptions,
    CycleReport,
    MoveArm,
    RequestVerdict,
    SetConveyor,
)
from .controller import CellState, QualityCheckController

__all__ = ["ActuateGripper", "CellState", "Command", "ControllerOptions", "CycleReport",
           "MoveArm", "QualityCheckController", "RequestVerdict", "SetConveyor"]
