"""A cell: a robot folder, a scene and the user's files (poses, routes, TCP targets).

:func:`load_cell` reads a cell folder (``scene.yaml``, ``poses.yaml``, ``routes.yaml``)
into a :class:`Cell`, and :func:`check_poses` checks its taught poses. The files' own
readers: :mod:`.poses`, :mod:`.routes` (with the pour steps, :mod:`.pour_steps`),
:mod:`.tcp_targets` and :mod:`.scene_yaml`.
"""

from ._cell import Cell, PoseCheck, check_poses, iter_pose_checks, load_cell, prepare_robot
from .poses import dump_poses, load_poses, save_poses
from .routes import Route, Step, Target, load_routes
from .scene_yaml import load_scene

__all__ = ["Cell", "PoseCheck", "Route", "Step", "Target", "check_poses", "dump_poses",
           "iter_pose_checks",
           "load_cell", "load_poses", "load_routes", "load_scene", "prepare_robot",
           "save_poses"]
