"""Timing: time-optimal, jerk-limited timing of joint paths under the robot's limits.

The layer after collision-checked paths and before the release check: a joint polyline
becomes a cubic spline (:func:`spline_path`; the spline in ``_spline``, blended corners
with continuous curvature in ``_blend``). A straight move is timed by the closed-form
jerk-limited S-curve (``_scurve``); on any other path, TOPP-RA finds the time-optimal
timing under joint velocity and acceleration limits that vary along it (``_path_limits``;
our numba kernel, ``_topp``), its jerk is limited by two moving averages (``_smooth``;
optionally the steps' limits held as far around each step as the averages reach),
knots whose excess would take more than a small stretch are tightened and timed again,
and what is left is removed by stretching time (:func:`time_path`, in
:mod:`.path_timing`). No released knot exceeds a limit.

Depends on the robot and its limits only: nothing here imports collision checking,
planning or the release check.
"""

from __future__ import annotations

from ._path_limits import PathLimits, PathSpline, path_limits
from ._spline import CubicPath
from .path_timing import (
    RETIME_ABOVE,
    RETRY_ABOVE,
    TimedPiece,
    TimingOptions,
    rest_to_rest_time,
    spline_path,
    stretch_knots,
    time_path,
)

__all__ = [
    "RETIME_ABOVE",
    "RETRY_ABOVE",
    "CubicPath",
    "PathLimits",
    "PathSpline",
    "TimedPiece",
    "TimingOptions",
    "path_limits",
    "rest_to_rest_time",
    "spline_path",
    "stretch_knots",
    "time_path",
]
