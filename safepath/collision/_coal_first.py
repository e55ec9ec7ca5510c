"""The first query coal answers in a process, made the same in every process.

Measured (coal 3.0.3, this machine): which GJK query a process makes first changes the
last bits of every later distance in that process. After a pouring-cell plan whose first
query was a broad-phase collision check, the distances of the quality-check cell's
executed states came out up to 3.8e-11 m (1e-9 relative) from those of a fresh process;
a process whose first query was a plain box-box distance answered as a fresh one, however
it went on. Which state coal keeps from its first query is not traced (not in its Python
face). Determinism is a promise of the library (a seed gives the same result in any
process, thread or sweep worker), so this package makes that first query itself, once,
when it is imported: two unit boxes half a metre apart.
"""

from __future__ import annotations

__all__ = ["settle"]


def settle() -> None:
    """Make coal's first query of this process (see the module doc): called once, by
    the import of :mod:`safepath.collision`."""
    import coal
    import numpy as np

    apart = coal.Transform3s()
    apart.setTranslation(np.array([0.5, 0.0, 0.0]))
    coal.distance(coal.Box(0.1, 0.1, 0.1), coal.Transform3s(), coal.Box(0.1, 0.1, 0.1), apart,
                  coal.DistanceRequest(), coal.DistanceResult())
