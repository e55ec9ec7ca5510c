"""The one table of kernels compiled ahead of time, with their exact signatures.

Every numba kernel that planning calls from Python (``plan_cell``, ``plan_route``, the
runtime planner's workers), and the monitor's, is listed here once, by its export name:
the module and function that define it and the types of its arguments and result, in
numba's notation. The argument types are exactly what the callers pass (C-contiguous,
writeable arrays of these dtypes, Python or numpy scalars of these kinds); a call that
passes anything else runs the numba-compiled (JIT) kernel instead, and under
``SAFEPATH_AOT_STRICT=1`` (the test suite) raises, so that a caller drifting from its
signature fails in the tests, never in a user's plan. ``tests/test_aot.py`` compiles
every entry with numba from these argument types and checks the result type against
the table, and replays recorded real calls through the guards.

Changing a kernel's arguments means changing its row here (the ahead-of-time module is
then stale and is rebuilt by ``safepath build-kernels``; until then numba's JIT runs).
Importing this module imports neither numba nor a kernel module.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["Entry", "ENTRIES", "Kind", "MODULES", "PLANNING_MODULES"]

#: A type in numba's notation, or a tuple of them (a tuple argument, tuples nested).
Kind = str | tuple["Kind", ...]

#: Arrays: C-contiguous float64, int64 and bool arrays of 1 to 4 dimensions.
F1, F2, F3, F4 = "f8[::1]", "f8[:, ::1]", "f8[:, :, ::1]", "f8[:, :, :, ::1]"
I1, I2, B1, B2 = "i8[::1]", "i8[:, ::1]", "b1[::1]", "b1[:, ::1]"
#: Scalars.
FLOAT, INT, BOOL = "f8", "i8", "b1"


class Entry(NamedTuple):
    """One exported kernel.

    Attributes:
        module: The module that defines it (``safepath.collision._kernels``).
        function: Its name there.
        args: The argument types (a tuple of types for a tuple argument).
        result: The result type (``void``: none).
    """

    module: str
    function: str
    args: tuple[Kind, ...]
    result: str


_FAST = "safepath.collision._kernels"
#: The sphere layer's helper kernels, the accessors they read their buffers through, and
#: the constants those compile in (the buffers' layout).
_FAST_PARTS = ("safepath.collision._placement", "safepath.collision._pair_tests",
               "safepath.collision._gjk", "safepath.collision._records",
               "safepath.collision._layout")
#: The sphere layer's per-pair distance bounds (the checker's clearance and report).
_BOUNDS = "safepath.collision._bounds"
_VERIFY = "safepath.verify._kernel"
_VERIFY_DISTANCE = "safepath.verify._distance"
#: The records the release check's walk reads (no kernel: its source shapes the build).
_VERIFY_RECORDS = "safepath.verify._records"
_IK = "safepath.kinematics._ik_kernel"
_TOPP = "safepath.timing._topp_kernels"
_MONITOR = "safepath.monitor._kernels"
#: The shape table, whose kind codes the sphere layer's and the monitor's kernels compile in.
_SHAPES = "safepath.model.shapes"
#: Each kind's geometry, inlined into the sphere layer's and the monitor's kernels.
_PRIMITIVES = "safepath.model._primitives"
_JOIN = "safepath.model._joinkernel"
#: The planner's one forward kinematics (the sphere layer's and the lines' IK's) and the
#: joint table's columns it compiles in.
_FK = ("safepath.model._fk_kernel", "safepath.model._joint_table")
#: A placed shape of the verifier: a tuple of 17 floats (its record's fields, in order).
_SHAPE = "UniTuple(f8, 17)"
#: The verifier's hull tables: vertices, neighbour starts, neighbour rows, climbs' starts.
_HULLS = (F2, I1, I1, I1)

#: Every exported kernel, by export name.
ENTRIES: dict[str, Entry] = {
    # The sphere layer (safepath.collision.SphereLayer, safepath.collision.CollisionChecker).
    "fast_classify": Entry(_FAST, "classify", (F1, F1, I1), INT),
    "fast_classify_many": Entry(_FAST, "classify_many", (F2, F1, I1, I1), "void"),
    "fast_certify_polyline": Entry(_FAST, "certify_polyline",
                                   (F2, I1, I1, I1, F1, I1, I1, I1, INT), "UniTuple(i8, 5)"),
    "fast_certify_segment": Entry(_FAST, "certify_segment", (F1, F1, F1, I1, BOOL, BOOL, I1),
                                  "UniTuple(i8, 5)"),
    "fast_pair_bounds": Entry(_BOUNDS, "pair_bounds", (F2, F1, I1, F1, B1, F2), "void"),
    # The release check's bounds (safepath.verify._bounds).
    "verify_certify": Entry(
        _VERIFY, "certify",
        (I1, I1, I1, F1,  # todo, its stretches, theta
         (F2, F2, F2, F2, F2, I1, F1),  # grid
         (I1, F3, I1, F2, I1, I1, F3, I1),  # kin
         (B2, F4),  # cache
         (I1, I1, B1, F2, B1, B2),  # pairs
         (F2, F3, _HULLS),  # world
         (F2, F1, I1, F1),  # memory
         (FLOAT, FLOAT, FLOAT, FLOAT),  # params
         (I1, F1, F1, F2, F2, I1, I1, I1, F1),  # scratch and outputs
         INT, INT),  # where to start
        "UniTuple(i8, 3)"),
    "verify_grid": Entry(_VERIFY, "grid", (F2, F2, FLOAT), f"Tuple(({I1}, {F1}, {F2}, {F2}))"),
    "verify_body_poses": Entry(_VERIFY, "body_poses",
                               (F2, (I1, F3, I1, F2, I1, I1, F3, I1), INT, F3), "void"),
    "verify_axis_bound": Entry(_VERIFY_DISTANCE, "axis_bound_entry", (_SHAPE, _SHAPE, _HULLS),
                               "UniTuple(f8, 4)"),
    "verify_gjk_bound": Entry(_VERIFY_DISTANCE, "gjk_bound_entry",
                              (_SHAPE, _SHAPE, _HULLS, FLOAT, FLOAT, FLOAT, FLOAT, BOOL, F2,
                               F2, I1),
                              "UniTuple(f8, 5)"),
    # Inverse kinematics of Cartesian lines (safepath.planning.cartesian, on the kernel of
    # safepath.kinematics).
    "ik_line_path": Entry(_IK, "line_path", (F2, I2, F1, F2, F1, F1, F1, F1, F1, F1, INT, F2),
                          "Tuple((i8, i8, i8, f8))"),
    "ik_solve": Entry(_IK, "solve", (F2, I2, F1, F2, F1, F1, F1, F1, F1, INT), INT),
    "ik_tcp_pose": Entry(_IK, "tcp_pose", (F2, I2, F1, F1, F2, F1), "void"),
    "ik_tcp_jacobian": Entry(_IK, "tcp_jacobian", (F2, I2, F1, F1, F2), "void"),
    "ik_log6": Entry(_IK, "log6", (F2, F1, F1), "void"),
    "ik_jlog6": Entry(_IK, "jlog6", (F2, F1, F2), "void"),
    # The TCP's positions and speeds (safepath.Robot.tcp_positions, tcp_speeds).
    "model_tcp_motion": Entry(_FK[0], "tcp_motion",
                              (F2, I2, F1, F2, F2, BOOL, F3, F2, F1, F2, F1), "void"),
    # The monitor (safepath.monitor: separation bounds, speed profiles).
    "monitor_bucket": Entry(_MONITOR, "bucket", (F2, FLOAT),
                            f"Tuple(({F2}, {F2}, {I1}, {F2}, {I1}))"),
    "monitor_prefix_separation": Entry(
        _MONITOR, "prefix_separation",
        (F3, F1, I1, F3, INT, INT, F2, F2, I1, F2, I1, FLOAT, F1, I1), "void"),
    "monitor_near_robot": Entry(_MONITOR, "near_robot",
                                (F3, F1, I1, F3, INT, INT, F2, FLOAT, B1), "void"),
    "monitor_scene_distance": Entry(_MONITOR, "scene_distance",
                                    (F2, I1, F3, F2, F1, FLOAT, F1), "void"),
    "monitor_march": Entry(_MONITOR, "march", (F1, F2, F2, F1, FLOAT, FLOAT, FLOAT, F1, F1, F1),
                           "Tuple((i8, i8, b1))"),
    "monitor_linked_cells": Entry(_MONITOR, "linked_cells", (I1, I1, INT, INT, B1), "void"),
    # TOPP-RA's two passes, the spline solve, the smoothed knots, the jerk window
    # (safepath.timing._topp_kernels).
    "topp_backward": Entry(_TOPP, "backward", (F1, F1, F2, F2, F2, F1, F1, F1), INT),
    "topp_forward": Entry(_TOPP, "forward", (F1, F1, F2, F2, F2, F1, F1, F1, F1), "void"),
    "topp_tighten": Entry(_TOPP, "tighten", (I1, I1, F1, F1, F1, F1, F1, F1), "void"),
    "topp_jet": Entry(_TOPP, "jet", (F1, F3, F1, F2, F2, F2), "void"),
    "topp_evaluate": Entry(_TOPP, "evaluate", (F1, F1, F1, F1, F1, F1, F1, F1), "void"),
    "topp_tridiagonal": Entry(_TOPP, "tridiagonal", (F1, F1, F1, F2), INT),
    "topp_knots": Entry(_TOPP, "knots", (F1, F1, F1, F1, F1, F1, F1, FLOAT, FLOAT, F1, F3, F1,
                                          F1, F1, F2, F2, F2), "void"),
    "topp_jerk_rows": Entry(_TOPP, "jerk_rows", (F1, F1, F1, F1, FLOAT, F1, F2, F1, F2, F2, F1,
                                                 F2), "void"),
    "topp_jerk_shift": Entry(_TOPP, "jerk_shift", (F2, FLOAT), INT),
    "topp_fill_grid": Entry(_TOPP, "fill_grid", (F1, I1, F1), "void"),
    "topp_grid_peaks": Entry(_TOPP, "grid_peaks", (F1, F1, F3, F2, F1, F1, F1, F1), "void"),
    "topp_acceleration_rows": Entry(_TOPP, "acceleration_rows", (F1, F2, F2, F2, F2, F2, F2),
                                    "void"),
    # The peaks of a controller's quintic join (safepath.model._joinkernel).
    "join_peaks": Entry(_JOIN, "_peaks", (F1, F2, F2, F2, FLOAT, F2, F2, F2), "void"),
    "join_sample": Entry(_JOIN, "_sample", (F1, F2, F2, F2, F1, F2, F2, F2), "void"),
    "join_ratios": Entry(_JOIN, "_ratios", (F1, F2, F2, F2, FLOAT, I1, I1, F2, F2, F2, FLOAT, F1,
                                             F1, F1),
                         "void"),
    "join_screen": Entry(_JOIN, "_screen", (F1, F2, F2, F2, FLOAT, I1, F2, F2, F2, FLOAT, F1,
                                             F1, F1, F3), "void"),
}

#: The modules whose source the ahead-of-time module is compiled from: it is used only
#: while all of them are unchanged. Every kernel compiled through :func:`safepath._aot.njit`
#: lives in one of them (tests/test_aot.py checks it); the cup's (a simulated scale, not
#: on a planning path) uses numba directly.
MODULES: tuple[str, ...] = (_FAST, *_FAST_PARTS, _BOUNDS, *_FK, _VERIFY, _VERIFY_DISTANCE,
                            _VERIFY_RECORDS, _IK, _TOPP, _JOIN, _MONITOR, _SHAPES,
                            _PRIMITIVES)
#: Those a plan calls (all but the monitor's).
PLANNING_MODULES: tuple[str, ...] = (_FAST, *_FAST_PARTS, _BOUNDS, *_FK, _VERIFY,
                                     _VERIFY_DISTANCE, _VERIFY_RECORDS, _IK, _TOPP, _JOIN,
                                     _SHAPES, _PRIMITIVES)
