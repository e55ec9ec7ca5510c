"""The world a route plans in: what the gripper holds, where the other objects rest,
and the checkers and verifiers built for each such state."""

from __future__ import annotations

import threading
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from ..cell import Cell
from ..collision import CheckOptions, CollisionChecker
from ..model.scene import AllowedContact
from ..verify import FclVerifier, StagedVerifier
from .options import PlanOptions

__all__ = ["WorldState", "CheckerCache", "initial_world"]

T = TypeVar("T")


@dataclass
class WorldState:
    """Which object the gripper holds and where the others rest.

    Attributes:
        held: Held object, or None.
        resting: World placement (4x4) of movable objects that are not held.
    """

    held: str | None = None
    resting: dict[str, np.ndarray] = field(default_factory=dict)

    def copy(self) -> WorldState:
        """An independent copy."""
        return WorldState(self.held, {k: v.copy() for k, v in self.resting.items()})

    def key(self) -> tuple:
        """Hashable identity of the state."""
        return (self.held, tuple(sorted((k, v.round(9).tobytes())
                                        for k, v in self.resting.items())))


def initial_world(cell: Cell) -> WorldState:
    """The scene's world: nothing held, movable objects at their scene placement."""
    return WorldState(None, {o.name: o.T_world_object.copy()
                             for o in cell.scene.objects.values() if o.movable})


@dataclass
class _Made:
    """The checkers and verifiers made for one cell, thread and check options, by world
    state and allowed contacts."""

    checkers: dict[tuple, CollisionChecker] = field(default_factory=dict)
    verifiers: dict[tuple, FclVerifier] = field(default_factory=dict)
    staged: dict[tuple, StagedVerifier] = field(default_factory=dict)


class _PerThread(threading.local):
    def __init__(self) -> None:
        self.made: dict[CheckOptions, _Made] = {}


#: What was made per cell (kept while the cell lives) and thread: collision checkers are
#: not thread-safe, so each thread gets its own.
_MADE: weakref.WeakKeyDictionary[Cell, _PerThread] = weakref.WeakKeyDictionary()
_MADE_LOCK = threading.Lock()


class CheckerCache:
    """Checkers and verifiers, built once per world state and allowed-contact set.

    What it builds is kept per cell and thread, so that planning the same cell again, as
    a node or a review session does, does not rebuild them; they depend on the world
    state and the allowed contacts (the keys), never on the taught poses. A cell made
    anew (``dataclasses.replace``, unpickled in a worker) starts with none.
    """

    def __init__(self, cell: Cell, options: PlanOptions, *,
                 verified_in: Cell | None = None) -> None:
        self.cell = cell
        self.options = options
        #: The cell whose scene the verifiers check against (default: ``cell``): a plan
        #: may keep more clearance than the release check requires.
        self.verified_in = cell if verified_in is None else verified_in
        with _MADE_LOCK:
            per_thread = _MADE.get(cell)
            if per_thread is None:
                per_thread = _MADE[cell] = _PerThread()
        made = per_thread.made.setdefault(options.check, _Made())
        self._checkers = made.checkers
        self._verifiers = made.verifiers
        self._staged = made.staged

    def made(self) -> tuple[dict[tuple, CollisionChecker], dict[tuple, FclVerifier]]:
        """The checkers and verifiers made so far (in this thread, for these check
        options), by (world state key, allowed contacts): copies, for inspection."""
        return dict(self._checkers), dict(self._verifiers)

    def checker(self, world: WorldState, allowed: tuple[AllowedContact, ...]) -> CollisionChecker:
        """The collision checker of ``world`` with the contacts ``allowed``."""
        state = world.key()
        key = (state, allowed)
        if key not in self._checkers:
            # Another one of the same world state gives its geometry and layer tables.
            base = _of_state(self._checkers, state)
            self._checkers[key] = base.with_allowed(allowed) if base is not None else \
                CollisionChecker(self.cell.robot, self.cell.scene, held=world.held,
                                 resting=world.resting, allowed=allowed,
                                 options=self.options.check)
        return self._checkers[key]

    def verifier(self, world: WorldState, allowed: tuple[AllowedContact, ...]) -> FclVerifier:
        """The independent verifier of ``world`` with the contacts ``allowed``."""
        state = world.key()
        key = (state, allowed)
        if key not in self._verifiers:
            opts = self.options.check
            base = _of_state(self._verifiers, state)
            self._verifiers[key] = base.with_allowed(allowed) if base is not None else \
                FclVerifier(self.verified_in.robot, self.verified_in.scene, held=world.held,
                            resting=dict(world.resting), allowed=allowed,
                            resolution=opts.resolution, margin=opts.margin,
                            enforce_margin=opts.enforce_margin)
        return self._verifiers[key]

    def stages(self, world: WorldState, allowed: Sequence[tuple[AllowedContact, ...]]
               ) -> StagedVerifier:
        """The verifiers of ``world`` with each of the contacts ``allowed``, as one check
        of a trajectory that goes through them in this order."""
        key = (world.key(), tuple(allowed))
        if key not in self._staged:
            self._staged[key] = StagedVerifier([self.verifier(world, a) for a in allowed])
        return self._staged[key]


def _of_state(made: dict[tuple, T], state: tuple) -> T | None:
    """The first of ``made`` (by world state and allowed contacts) of world ``state``."""
    return next((value for (s, _), value in made.items() if s == state), None)
