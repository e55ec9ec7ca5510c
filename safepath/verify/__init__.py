"""The release check: an independent re-check of timed trajectories with python-fcl.

Nothing leaves safepath that this package has not checked, and it checks with code of
its own: it shares nothing with the planner's collision checker
(:mod:`safepath.collision`) but the *data* (the robot's joints and collision geometry,
the scene, the allowed contacts). It derives its own pairs, computes its own forward
kinematics (``_kernel``), its own conservative distance bounds (``_distance``, ``_bounds``)
and lets FCL, not coal, judge every sample those bounds cannot clear
(:class:`FclVerifier`, :class:`StagedVerifier`). This is the one deliberate duplicate of
the planner's geometry in safepath: a fault in the planner's kernels (its sphere layer,
its GJK, its kinematics) cannot also hide a collision from the check that releases the
trajectory. Keep it so: nothing here imports :mod:`safepath.collision` or
:mod:`safepath.planning` (tests/test_import_contracts.py checks it).

Its face: :class:`FclVerifier`, :class:`StagedVerifier`, :class:`VerifyResult`, what a
verifier shows of itself (:class:`CheckedPair`, :class:`Body`, :class:`Grid`,
:class:`StateBounds`),
:func:`check_verifiable` (refuses, before planning, what it cannot check; :func:`unverifiable`
lists it),
:func:`prepare_verifiers` (what every verifier of a robot takes from it alone) and
:func:`fcl_shape`.
"""

from __future__ import annotations

from ._bodies import Body, check_verifiable, fcl_shape, prepare_verifiers, unverifiable
from ._bounds import Grid
from .verifier import CheckedPair, FclVerifier, StagedVerifier, StateBounds, VerifyResult

__all__ = [
    "Body",
    "CheckedPair",
    "FclVerifier",
    "Grid",
    "StagedVerifier",
    "StateBounds",
    "VerifyResult",
    "check_verifiable",
    "fcl_shape",
    "prepare_verifiers",
    "unverifiable",
]
