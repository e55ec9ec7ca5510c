"""The twin: the cells' own controllers closed loop on simulated robot dynamics (MuJoCo).

* :mod:`~safepath.sim.model`: the robot's MuJoCo model, generated from its own
  description, with position servos (:class:`ServoGains`);
* :mod:`~safepath.sim.arm` / :mod:`~safepath.sim.twin`: the simulated
  ``FollowJointTrajectory`` controller and gripper, physics at 1 kHz, one clock
  (:class:`RobotTwin`);
* :mod:`~safepath.sim.quality_check`: the quality-check cell closed loop
  (:func:`run_quality_check`); :mod:`~safepath.sim.pouring`: the pouring cell closed loop
  (:func:`run_pouring`); :mod:`~safepath.sim.sweep` many runs on a process pool,
  :mod:`~safepath.sim.bag` a run's ROS 2 bag; :mod:`~safepath.sim.sweep_tasks` the runs as
  tasks of a resumable sweep (:mod:`safepath.sweeps`: local pool or Ray, with a report);
* :mod:`~safepath.sim.monitor_loop`: the monitor node's core closed loop.

MuJoCo is imported only when a model is built, so importing this package stays light.
"""

from __future__ import annotations

from .model import RobotModel, ServoGains, build_robot_model
from .pouring import PouringParams, PouringRun, run_pouring
from .quality_check import QualityCheckParams, QualityCheckRun, run_quality_check
from .sweep import run_many
from .twin import RobotTwin, TwinOptions

__all__ = [
    "PouringParams",
    "PouringRun",
    "QualityCheckParams",
    "QualityCheckRun",
    "RobotModel",
    "RobotTwin",
    "ServoGains",
    "TwinOptions",
    "build_robot_model",
    "run_many",
    "run_pouring",
    "run_quality_check",
]
