"""Speed and separation monitoring: keep moving safely when the world changes.

ROS-free core: observations (laser scans, point clouds, obstacles from user code) in,
a decision out every time (continue, slow, stop, resume, re-plan), with the rest of the
path re-timed (never re-shaped) as a replacement trajectory within the robot's limits.
The ROS 2 wiring (message conversion, bag recording) is in :mod:`safepath.monitor.ros`.

It is not a certified safety function: ``docs/monitor.md`` states its safety model and its limits.
"""

from __future__ import annotations

from .monitor import Decision, Monitor, ReplanRequest
from .observations import Cloud, Counts, ObservationError, Obstacles, Scan
from .options import MonitorOptions

__all__ = [
    "Cloud",
    "Counts",
    "Decision",
    "Monitor",
    "MonitorOptions",
    "ObservationError",
    "Obstacles",
    "ReplanRequest",
    "Scan",
]
