"""Batch planning of many cells as a sweep task (:mod:`safepath.sweeps`).

"Does a changed fixture break any of 200 cells?": :class:`PlanCellsTask` plans one cell
folder per seed (the seed is the folder's index in the task's list) with
:func:`~safepath.planning.route_planner.plan_cell`, which times and verifies every route.
A cell that plans reports each route's motion time and the verified clearance; a cell
that does not is a failed seed whose error is the exception's one-line text (the route,
the routes file, the step and the reason a :class:`~safepath.errors.PlanningError`
names), with the command that plans that folder alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..errors import InputError, SafepathError
from .options import PlanOptions

if TYPE_CHECKING:  # the sweep runner loads only for a sweep, not with safepath.planning
    from ..sweeps import TaskResult

__all__ = ["PlanCellsTask"]


@dataclass(frozen=True)
class PlanCellsTask:
    """Plan the cell folder ``folders[seed]`` for each seed.

    Attributes:
        folders: The cells' folders (paths every worker can read); seeds index them.
        options: The planning options of every cell.
        replay_command: The command that plans one folder, ``{folder}`` in its place.
    """

    folders: tuple[str, ...]
    options: PlanOptions = field(default_factory=PlanOptions)
    replay_command: str = "safepath plan {folder}"

    def __call__(self, seed: int) -> TaskResult:
        """Plan, time and verify every route of cell ``folders[seed]``.

        Raises:
            InputError: A seed that indexes no folder.
        """
        from ..cell import load_cell
        from ..sweeps import TaskResult
        from .route_planner import plan_cell

        folder = self._folder(seed)
        try:
            routes = plan_cell(load_cell(folder), self.options)
        except SafepathError as exc:  # the cell's failure is the seed's result
            text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            return TaskResult(error=f"{type(exc).__name__}: {text}")
        figures: dict[str, float | tuple[float, ...]] = {
            "motion_time": tuple(float(traj.duration) for traj in routes.values()),
            "cell_motion_time": float(sum(traj.duration for traj in routes.values())),
            "min_clearance": 1000 * min(float(traj.info["min_clearance"])
                                        for traj in routes.values())}
        figures |= {f"route.{name}": float(traj.duration) for name, traj in routes.items()}
        return TaskResult(figures=figures, checks={"planned": True})

    def _folder(self, seed: int) -> str:
        if not 0 <= seed < len(self.folders):
            raise InputError(f"expected a seed in 0..{len(self.folders) - 1} (one per cell "
                             f"folder), got {seed}", key="seed")
        return self.folders[seed]

    def identity(self) -> dict[str, Any]:
        """The cells and the planning options."""
        return {"kind": "plan cells", "folders": list(self.folders),
                "options": repr(self.options)}

    def labels(self) -> dict[str, str]:
        """The report's words (a route's motion time keeps its ``route.<name>`` key)."""
        return {"planned": "cells planned, timed and verified",
                "motion_time": "motion time of a route [s]",
                "cell_motion_time": "motion time of a cell's routes [s]",
                "min_clearance": "smallest verified clearance of a cell [mm]"}

    def replay(self, seed: int) -> str:
        """The command that plans this seed's folder alone."""
        return self.replay_command.format(folder=self._folder(seed))
