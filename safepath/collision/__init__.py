"""Collision checking: the robot (and what it holds) against itself and its scene.

The layer between robot & scene and planning. Its face:

* :class:`CollisionChecker` (:mod:`.checker`): one robot, scene and world state; states,
  clearance, margins, segments and polylines, with coal as the exact judge;
* :class:`CheckOptions`, :class:`LayerOptions` (:mod:`.options`) and the reports
  :class:`StateReport`, :class:`SegmentReport` (:mod:`.reports`);
* the sphere layer (:mod:`.layer`, fits in :mod:`.spheres`) that decides most states
  before coal, exactly, with its numba kernels (``_kernels``, ``_placement``,
  ``_pair_tests``, ``_gjk``; buffers laid out by ``_layout``, packed by ``_pack``, robot
  parts kept per robot and on disk by :mod:`safepath.files.derived`);
* the robot's allowed self pairs (:mod:`.allowed_pairs`) and what every checker of a
  robot takes from it alone (:mod:`.prepare`).

Importing this package imports neither numba nor a kernel: the kernels load on first use.
"""

from __future__ import annotations

from ._coal_first import settle as _settle
from .allowed_pairs import compute_allowed_pairs, wire_allowed_pairs, write_allowed_pairs
from .checker import CollisionChecker
from .layer import COLLIDES, FREE, OUTSIDE, UNSURE, SphereLayer
from .options import CheckOptions, LayerOptions
from .prepare import prepare_checkers, robot_part
from .reports import Pair, SegmentReport, StateReport

__all__ = [
    "COLLIDES",
    "FREE",
    "OUTSIDE",
    "UNSURE",
    "CheckOptions",
    "CollisionChecker",
    "LayerOptions",
    "Pair",
    "SegmentReport",
    "SphereLayer",
    "StateReport",
    "compute_allowed_pairs",
    "prepare_checkers",
    "robot_part",
    "wire_allowed_pairs",
    "write_allowed_pairs",
]

_settle()  # coal's first query, the same in every process (see ._coal_first)
