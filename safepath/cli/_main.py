"""The ``safepath`` command line.

Every command turns a :class:`~safepath.errors.SafepathError` into one line on
standard error: exit status 2 for bad input (an ``InputError``), 1 for no safe result (a
pose in collision, a route that cannot be planned, timed or verified within its
margins and limits).
"""

from __future__ import annotations

import argparse
import logging
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import InputError, PlanningError, SafepathError, TimingError, VerificationError

if TYPE_CHECKING:
    from ..cell import Cell

__all__ = ["main"]

EXIT_UNSAFE = 1
EXIT_ERROR = 2
#: Errors that say no safe result exists (exit 1), unless they are bad input.
_NO_SAFE_RESULT = (PlanningError, TimingError, VerificationError)


def _fmt_pair(pair: tuple[str, str] | None) -> str:
    return "-" if pair is None else f"{pair[0]} / {pair[1]}"


def _say_unfinished_save(path: Path | None) -> None:
    """Warn on standard error when a save of the poses file stopped after its log line
    and before its rename: the poses checked are those before that save."""
    from ..files._io import leftover_temporaries

    if path is None or not leftover_temporaries(path):
        return
    from ..view.store import unfinished_save

    entry = unfinished_save(path)
    if entry is not None:
        print(f"safepath check: warning: {path}: a save logged at {entry.get('time')} by "
              f"{entry.get('client')} did not finish (its process stopped before replacing "
              "the file): these are the poses before it; `safepath view` finishes it",
              file=sys.stderr)


def cmd_check(args: argparse.Namespace) -> int:
    """Check every taught pose of a cell."""
    from ..cell import iter_pose_checks, load_cell
    from ..collision import CheckOptions

    cell = load_cell(args.scene)
    _say_unfinished_save(cell.poses_path)
    options = CheckOptions(margin=args.margin)
    grasped = cell.scene.grasp.object if cell.scene.grasp else "object"
    print(f"cell {cell.scene.name}: robot {cell.robot.name}, {len(cell.poses)} poses, "
          f"margin {cell.scene.margin * 1000 if args.margin is None else args.margin * 1000:.0f}"
          " mm")
    header = (f"{'pose':<10} {'gripper':<8} {'limits':<7} {'free':<5} {'clearance[mm]':>13} "
              f"{'margin':<7} pair")
    print(header)
    print("-" * len(header))
    unsafe = low = count = 0
    for row in iter_pose_checks(cell, options):  # printed as checked: nothing kept
        count += 1
        rep = row.report
        unsafe += not rep.valid
        low += rep.valid and not rep.margin_ok
        pair = rep.collisions[0] if rep.collisions else (
            rep.margin_violations[0][0] if rep.margin_violations else rep.closest_pair)
        margin = "ok" if rep.margin_ok else "LOW"
        limits = "ok" if rep.within_limits else "OUT"
        free = "yes" if not rep.collisions else "NO"
        print(f"{row.pose:<10} {(grasped if row.held else 'empty'):<8} {limits:<7} {free:<5}"
              f" {rep.clearance * 1000:>13.1f} {margin:<7} {_fmt_pair(pair)}")
        if rep.limit_violation:
            print(f"{'':<10} {rep.limit_violation}")
        if len(rep.collisions) > 1:
            print(f"{'':<10} also colliding: "
                  + ", ".join(_fmt_pair(p) for p in rep.collisions[1:]))
    print(f"{count - unsafe}/{count} states valid, {low} below margin")
    unreachable = _check_routes(cell)
    if unsafe or unreachable or (low and args.strict):
        return EXIT_UNSAFE
    return 0


def _check_routes(cell: Cell) -> int:
    """Print what ``routes.yaml`` holds and one line per target inverse kinematics does
    not reach (named by route and step, as ``plan`` would refuse it); how many."""
    from ..planning.reach import check_targets

    if cell.folder is None or not (cell.folder / "routes.yaml").is_file():
        return 0
    routes = cell.route_table()  # a malformed routes.yaml: a ConfigError, exit 2
    steps = sum(len(r.steps) for r in routes.values())
    print(f"routes.yaml: {len(routes)} routes, {steps} steps valid "
          f"({', '.join(routes)})")
    unreachable = check_targets(cell, routes, path=cell.folder / "routes.yaml")
    for target in unreachable:
        print(f"unreachable: {target.error}")
    return len(unreachable)


def cmd_robot_pairs(args: argparse.Namespace) -> int:
    """Regenerate a robot folder's allowed self-collision pairs, and name the file in its
    robot.yaml if it does not yet (or say how, with --no-wire)."""
    from ..collision import wire_allowed_pairs, write_allowed_pairs
    from ..description.robot_folder import load_robot

    bare = Path(args.robot).suffix.lower() == ".urdf"
    robot = None if bare else load_robot(args.robot)
    target = None if robot is None else robot.allowed_collisions_path
    if robot is None or target is None or robot.source is None \
            or robot.source.name != "robot.yaml":
        raise SafepathError(
            f"'{args.robot}' is not a robot folder (no robot.yaml), so there is no file to "
            "write the pairs into and none would read it; adjacent links are skipped "
            "already. Make a robot folder (robot.yaml next to the URDF, see "
            "docs/your_own_robot_and_cell.md), then run this on it")
    stats = write_allowed_pairs(robot, target, samples=args.samples, seed=args.seed)
    counts: dict[str, int] = {}
    for s in stats:
        counts[s.reason] = counts.get(s.reason, 0) + 1
    print(f"wrote {target}: " + ", ".join(f"{v} {k}" for k, v in sorted(counts.items())))
    line = f"allowed_collisions: {target.name}"
    if wire_allowed_pairs(robot.source, target, write=not args.no_wire):
        print(f"added `{line}` to {robot.source}" if not args.no_wire else
              f"not read yet: add `{line}` to {robot.source}")
    return 0


def cmd_build_kernels(args: argparse.Namespace) -> int:
    """Compile the numba kernels ahead of time (see :mod:`safepath._aot`)."""
    from .._aot import cache_root
    from .._aot.build import build
    from .._aot.table import ENTRIES

    try:
        result = build(force=args.force)
    except ImportError as exc:  # a numba without pycc: the JIT kernels still work
        raise SafepathError(f"cannot compile the kernels ahead of time ({exc}); numba "
                            "compiles them on first use instead") from exc
    except OSError as exc:
        raise SafepathError(f"cannot write the kernel build to {cache_root()}: {exc}") from exc
    if result.fresh:
        print(f"built {len(ENTRIES)} kernels in {result.seconds:.0f} s: {result.path}")
    else:
        print(f"kernels up to date: {result.path}")
    # A new process loads the build just made, so the bundled cells' parts are made
    # where they are kept (safepath.cli._prepare); a failure there is the cells' own.
    done = subprocess.run([sys.executable, "-m", "safepath.cli._prepare"],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        lines = (done.stderr.strip() or "no output").splitlines()
        raise SafepathError(f"kernels built, but preparing the bundled cells failed: {lines[-1]}")
    print(f"prepared the bundled cells' first plans: {done.stdout.strip()}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``safepath``."""
    parser = argparse.ArgumentParser(prog="safepath", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("check", help="check every taught pose of a cell")
    p.add_argument("scene", help="scene folder (e.g. scenes/quality_check_cell)")
    p.add_argument("--margin", type=float, default=None, help="safety margin [m]")
    p.add_argument("--strict", action="store_true", help="exit 1 when a margin is not kept")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("robot-pairs", help="regenerate a robot's allowed self-collision pairs")
    p.add_argument("robot", help="robot folder or name (e.g. robots/ned3pro)")
    p.add_argument("--samples", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-wire", action="store_true",
                   help="do not add `allowed_collisions:` to robot.yaml (say how instead)")
    p.set_defaults(func=cmd_robot_pairs)

    p = sub.add_parser("build-kernels",
                       help="compile the numba kernels ahead of time (a new process then "
                            "plans without numba)")
    p.add_argument("--force", action="store_true", help="rebuild even if up to date")
    p.set_defaults(func=cmd_build_kernels)

    for register in _EXTRA:
        register(sub)
    return parser


#: Commands added by other modules (plan, view): functions that add a subparser.
_EXTRA: list[Callable[[argparse._SubParsersAction], None]] = []


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``safepath`` command.

    Args:
        argv: The command's arguments; None for this process's own command line
            (``sys.argv``: the ``safepath`` script, ``python -m safepath.cli``), which
            ends when this returns (see :func:`_leave_to_the_os`).
    """
    try:
        return _run(argv)
    finally:
        if argv is None:
            _leave_to_the_os()


def _leave_to_the_os() -> None:
    """Spare the ending process the collector's walk over everything it made.

    At exit the interpreter runs full collections over every object still alive (the
    modules, numpy's and pinocchio's objects, the cell, its checkers and kernels),
    though the process frees all of its memory at once: a few tens of milliseconds of a
    ``safepath plan`` process. :func:`gc.freeze` moves them out of the collector's sight
    first. Exit handlers, stream flushes, and the finalizers of objects freed by reference
    counting still run; objects kept only by reference cycles are left to the operating
    system (the commands close their files and pools themselves).

    Not after OMPL has been loaded: its nanobind bindings count the instances still alive
    when the interpreter ends and print every one as a leak (hundreds of lines on stderr).
    """
    import gc

    if "ompl" in sys.modules:
        return
    gc.freeze()


def _run(argv: Sequence[str] | None) -> int:
    """Parse ``argv`` (None: ``sys.argv``), run its command, return the exit status."""
    _load_extra(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except SafepathError as exc:
        print(f"safepath {args.command}: error: {exc}", file=sys.stderr)
        # Bad input is 2; a route that cannot be planned, timed or verified safely (a
        # collision, a margin not kept, an unreachable target) is no safe result: 1,
        # as 'check' says of a pose in collision.
        return EXIT_ERROR if isinstance(exc, InputError) or not isinstance(
            exc, _NO_SAFE_RESULT) else EXIT_UNSAFE
    except KeyboardInterrupt:
        print(f"safepath {args.command}: interrupted", file=sys.stderr)
        return 130


#: The modules that add the other commands, by command.
_EXTRA_MODULES = {"plan": "safepath.cli._plan", "view": "safepath.view.cli",
                  "sim": "safepath.sim.cli", "teach": "safepath.cli._teach"}
#: The commands defined in this module.
_OWN_COMMANDS = ("check", "robot-pairs", "build-kernels")


def _load_extra(argv: Sequence[str] | None = None) -> None:
    """Register the commands of other modules: with ``argv``, only the module of the
    command it names (importing ``safepath.sim`` alone costs a plan process tens of
    milliseconds); without, or when it names no known command (``--help``, a typo), all
    of them, so that help and errors list every command."""
    import importlib

    command = next((a for a in argv if not a.startswith("-")), None) if argv else None
    if command in _OWN_COMMANDS:
        names: tuple[str, ...] = ()
    elif command in _EXTRA_MODULES:
        names = (_EXTRA_MODULES[command],)
    else:
        names = tuple(_EXTRA_MODULES.values())
    for name in names:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.startswith("safepath"):
                continue
            raise
        register = getattr(module, "register", None)
        if register is not None and register not in _EXTRA:
            _EXTRA.append(register)

