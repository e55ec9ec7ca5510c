"""TOPPRA constraints whose joint limits vary along the path (one value per gridpoint).

Imported lazily by :mod:`safepath.planning.timing` (toppra is a heavy import).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import toppra.constraint as constraint
from toppra.constraint import DiscretizationType
from toppra.constraint.linear_constraint import canlinear_colloc_to_interpolate

__all__ = ["VaryingVelocity", "VaryingAcceleration"]


class VaryingVelocity(constraint.LinearConstraint):  # type: ignore[misc]
    """Joint velocity limits per gridpoint, as bounds on the squared path speed.

    Args:
        vlim: Limits [rad/s], shape (gridpoints, dof), symmetric.
    """

    def __init__(self, vlim: np.ndarray) -> None:
        super().__init__()
        self.vlim = vlim
        self.dof = vlim.shape[1]

    def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *args: object,
                                  **kwargs: object) -> tuple:
        qs = np.abs(path(gridpoints, 1))
        with np.errstate(divide="ignore"):
            sd = np.where(qs > 1e-12, self.vlim / np.maximum(qs, 1e-300), np.inf)
        xmax = np.min(sd, axis=1) ** 2
        xbound = np.stack([np.zeros_like(xmax), np.minimum(xmax, 1e12)], axis=1)
        return None, None, None, None, None, None, xbound


class VaryingAcceleration(constraint.LinearConstraint):  # type: ignore[misc]
    """Joint acceleration limits per gridpoint (interpolation discretisation).

    Args:
        alim: Limits [rad/s^2], shape (gridpoints, dof), symmetric.
    """

    def __init__(self, alim: np.ndarray) -> None:
        super().__init__()
        self.alim = alim
        self.dof = alim.shape[1]
        self.identical = False
        self.set_discretization_type(DiscretizationType.Interpolation)

    def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *args: object,
                                  **kwargs: object) -> tuple:
        ps = path(gridpoints, 1)
        pss = path(gridpoints, 2)
        dof, n = self.dof, len(gridpoints)
        F = np.zeros((n, 2 * dof, dof))
        g = np.zeros((n, 2 * dof))
        F[:, :dof, :] = np.eye(dof)
        F[:, dof:, :] = -np.eye(dof)
        g[:, :dof] = self.alim
        g[:, dof:] = self.alim
        return canlinear_colloc_to_interpolate(ps, pss, np.zeros_like(ps), F, g, None, None,
                                               gridpoints, identical=False)
