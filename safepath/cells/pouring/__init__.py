"""The pouring cell's gravimetric pour: the scale's reading stops the cup's tilt.

The motions themselves (a tilt about a point, a circle of the TCP, routes' ``tilt`` and
``circle`` steps) are the library's (:mod:`safepath.planning.pour`); this package is what
the pouring cell does with them:

* :mod:`.cup`: a cup that empties over its lip (its spill angle rises as it empties).
* :mod:`.flow`: the flow model and the simulated scale, the simulated pour stopped on its
  reading, the stop and return upright.
* :mod:`.stop_decision`: when to stop for a cup that empties (a grid of flow gains fitted
  to the readings).
* :mod:`.commands`: the controller's options, commands and report.
* :mod:`.parts`: the controller's collaborators (the mass predictor, the stop and return).
* :mod:`.controller`: :class:`~.controller.PourController`, the pour's state machine,
  ROS-free (stamped ``/weight`` readings and goal results in, goals out).
* :mod:`.setup`: the controller built from the pour node's parameters.
* :mod:`.dry_run`: the controller run on a simulated cell and scale.
"""

from .commands import PourControllerOptions, PourReport, SendArmGoal, SendGripperGoal
from .controller import PourController, PourState

__all__ = ["PourController", "PourControllerOptions", "PourReport", "PourState", "SendArmGoal",
           "SendGripperGoal"]
