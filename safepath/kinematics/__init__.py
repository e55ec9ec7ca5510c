"""Kinematics of the arm: inverse kinematics (damped least squares) and its numba kernel.

Below the cell and the planner in the layers: loading a cell's TCP pose targets
(:mod:`safepath.cell.tcp_targets`) and planning Cartesian lines
(:mod:`safepath.planning.cartesian`) both solve IK here. Importing this package imports
neither numba nor the kernel (:mod:`._ik_kernel`, imported by the first Cartesian line).
"""

from .ik import LineOptions, solve_ik

__all__ = ["LineOptions", "solve_ik"]
