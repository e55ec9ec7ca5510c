"""``safepath teach``: a taught pose from a TCP target, written to the cell's poses file.

The joint vector comes from :meth:`safepath.cell._cell.Cell.pose_from_tcp` (inverse kinematics
started at ``--near``); it is checked as ``safepath check`` checks a taught pose (limits,
collision-free with the gripper empty, the allowed contacts of its name) and only then
written, with :func:`safepath.cell.poses.save_poses` (atomically, the previous file kept as
``poses.yaml~``, comments and the other poses' text kept). A pose in collision is exit 1
and nothing is written; bad input is exit 2.
"""

from __future__ import annotations

import argparse

__all__ = ["register", "cmd_teach"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``teach`` to the ``safepath`` command line."""
    p = sub.add_parser("teach", help="teach a pose from a TCP target (IK) and write it to "
                                     "the cell's poses.yaml")
    p.add_argument("scene", help="scene folder (e.g. scenes/quality_check_cell)")
    p.add_argument("name", help="the pose's name")
    p.add_argument("--position", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"),
                   help="TCP position in the world frame [m]")
    p.add_argument("--orientation", type=float, nargs=4, default=None,
                   metavar=("QX", "QY", "QZ", "QW"),
                   help="TCP orientation, a unit quaternion (default: the TCP's at --near)")
    p.add_argument("--near", required=True,
                   help="the taught pose the inverse kinematics starts from")
    p.add_argument("--replace", action="store_true", help="replace a pose of that name")
    p.set_defaults(func=cmd_teach)


def cmd_teach(args: argparse.Namespace) -> int:
    """Solve, check, and write the pose; print where it put the TCP."""
    from ..cell import load_cell
    from ..cell.poses import POSE_NAME, save_poses
    from ..errors import ConfigError, PoseError

    cell = load_cell(args.scene)
    name = str(args.name)
    if not POSE_NAME.match(name):
        raise PoseError(f"'{name}' is not a valid pose name", key="name")
    if name in cell.poses and not args.replace:
        raise ConfigError(f"the cell has a pose '{name}' already: --replace replaces it",
                          path=cell.poses_file(), key=name)
    q = cell.pose_from_tcp(args.position, args.orientation, near=args.near)
    report = cell.checker(at=name).check(q)
    values = ", ".join(f"{v:.6f}" for v in q)
    if not report.valid:
        pairs = ", ".join(f"{a} / {b}" for a, b in report.collisions)
        print(f"safepath teach: pose '{name}' [{values}] is in collision ({pairs}): "
              "not written")
        return 1
    poses = {**cell.poses, name: q}
    save_poses(cell.poses_file(), poses, cell.robot)
    tcp = ", ".join(f"{v:.4f}" for v in cell.robot.tcp_position(q))
    clearance = ""
    if report.closest_pair:
        margin = "" if report.margin_ok else " (below its margin)"
        clearance = (f", clearance {report.clearance * 1000:.1f} mm{margin} "
                     f"({' / '.join(report.closest_pair)})")
    print(f"taught '{name}': [{values}] rad, TCP at {tcp} m{clearance}; written to "
          f"{cell.poses_file()}")
    return 0
