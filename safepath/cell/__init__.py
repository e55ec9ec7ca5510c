"""A cell: a robot folder, a scene and the user's files (poses, routes, TCP targets).

:func:`load_cell` reads a cell folder (``scene.yaml``, ``poses.yaml``, ``routes.yaml``)
into a :class:`Cell`, and :func:`check_poses` checks its taught poses. The files' own
readers: :mod:`.poses`, :mod:`.routes` (with the pour steps, :mod:`.pour_steps`),
:mod:`.tcp_targets` and :mod:`.scene_yaml`.
"""

from ._cell import Cell, PoseCheck, check_poses, load_cell, prepare_robot

__all__ = ["Cell", "PoseCheck", "load_cell", "check_poses", "prepare_robot"]
