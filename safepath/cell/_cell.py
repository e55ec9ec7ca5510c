"""A cell: a robot, its scene, its taught poses and its routes.

Built in Python (``Cell(robot, scene, poses, routes=...)``) or loaded from a scene folder
(:func:`load_cell`); both are validated the same way when the cell is made.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import KW_ONLY, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..collision import CheckOptions, CollisionChecker, StateReport
from ..description.robot_folder import load_robot
from ..errors import ConfigError, PoseError, unknown_name
from ..files._io import check_names
from ..files._paths import SCENES_DIR
from ..model.robot import Robot
from ..model.scene import Scene
from ..model.tool import check_tool
from .poses import POSE_NAME, load_poses
from .routes import Route, check_routes, load_cycle, load_routes
from .scene_yaml import load_scene

__all__ = ["Cell", "PoseCheck", "load_cell", "check_poses", "iter_pose_checks",
           "prepare_robot"]


@dataclass(eq=False, repr=False)
class Cell:
    """A robot in its scene, with its taught poses and routes.

    Everything is checked when the cell is made, whether in Python or by
    :func:`load_cell`: the robot is the one the scene includes, every pose against the
    robot (joint count, finite, inside the limits), the scene's grasp and allowed contacts
    against the poses and the tool, the routes against the poses and objects. A scene
    with its own tool (:attr:`Scene.tool`) gives it to the cell's robot:
    :attr:`robot` is then a copy of the robot given, holding that tool.

    Attributes:
        robot: The robot the scene includes.
        scene: The surroundings.
        poses: Taught poses by name [rad] (any sequences; kept as numpy arrays).
        routes: Routes by name, or None: ``routes.yaml`` of :attr:`folder`, if any.
        folder: The scene folder, or None for a cell built in Python.
        poses_path: The poses file, or None for a cell built in Python.

    Raises:
        PoseError: A pose with a bad name, the wrong joint count, a non-finite value or a
            value outside the joint limits.
        ConfigError: A robot that is not the scene's, a grasp or contact at an unknown
            pose, a grasp without a tool, an object the tool cannot hold, a route naming
            an unknown pose or object.
    """

    robot: Robot
    scene: Scene
    poses: dict[str, np.ndarray]
    _: KW_ONLY
    routes: Mapping[str, Route] | None = None
    folder: Path | None = None
    poses_path: Path | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.robot, Robot):
            raise ConfigError(f"expected a safepath.Robot, got {type(self.robot).__name__}",
                              key="robot")
        if not isinstance(self.scene, Scene):
            raise ConfigError(f"expected a safepath.Scene, got {type(self.scene).__name__}",
                              key="scene")
        if not isinstance(self.poses, Mapping):
            raise PoseError(f"expected a mapping of pose names to joint vectors, got "
                            f"{type(self.poses).__name__}", path=self.poses_path, key="poses")
        self.folder = None if self.folder is None else Path(self.folder)
        self.poses_path = None if self.poses_path is None else Path(self.poses_path)
        _check_robot_is_the_scenes(self.robot, self.scene)
        if self.scene.tool is not None and self.scene.tool != self.robot.tool:
            check_tool(self.scene.tool, self.robot.model, path=self.scene.path)
            self.robot = self.robot.with_tool(self.scene.tool)
        self.poses = poses = _valid_poses(self.poses, self.robot, self.poses_path)
        _check_scene_against(self.robot, self.scene, poses)
        if self.routes is not None:
            self.routes = check_routes(self.routes, poses=list(poses),
                                       objects=list(self.scene.objects))

    def scene_folder(self) -> Path:
        """The scene folder (for what needs files: re-planning in another process).

        Raises:
            ConfigError: The cell was built in Python, without a folder.
        """
        if self.folder is None:
            raise ConfigError("the cell was built in Python: it has no scene folder",
                              key="folder")
        return self.folder

    def poses_file(self) -> Path:
        """The poses file (for what reads or saves it: the review session).

        Raises:
            ConfigError: The cell was built in Python, without a poses file.
        """
        if self.poses_path is None:
            raise ConfigError("the cell was built in Python: it has no poses file",
                              key="poses_path")
        return self.poses_path

    def __repr__(self) -> str:
        where = f", folder={str(self.folder)!r}" if self.folder is not None else ""
        return (f"Cell({self.scene.name!r}, robot={self.robot.name!r}, "
                f"{len(self.poses)} poses{where})")

    def route_table(self) -> dict[str, Route]:
        """The cell's routes: those it was given, else ``routes.yaml`` of its folder.

        Raises:
            ConfigError: No routes given and no ``routes.yaml`` (or a malformed one).
        """
        if self.routes is not None:
            return dict(self.routes)
        if self.folder is None:
            raise ConfigError("the cell has no routes (give Cell(..., routes=...))",
                              key="routes")
        self._check_poses_file()
        return load_routes(self.folder, poses=list(self.poses),
                           objects=list(self.scene.objects))

    def cycle(self) -> list[str] | None:
        """The order one cycle of the cell runs its routes in: the ``cycle`` of
        ``routes.yaml`` (checked against the routes), or None when there is none (routes
        given in Python, or a file without one).

        Raises:
            ConfigError: A malformed or inconsistent ``cycle`` (names file and key).
        """
        if self.routes is not None or self.folder is None:
            return None
        return load_cycle(self.folder, self.route_table())

    def pose(self, name: str) -> np.ndarray:
        """The taught pose ``name``.

        Raises:
            PoseError: No pose of that name (lists the known ones).
        """
        if name not in self.poses:
            self._check_poses_file()
            raise PoseError(unknown_name("pose", name, self.poses), path=self.poses_path,
                            key=name)
        return self.poses[name]

    def pose_from_tcp(self, position: Any, orientation: Any = None, *, near: str,
                      frame: str | None = None) -> np.ndarray:
        """Teach a pose by its TCP: the joint vector [rad] that puts the TCP (or
        ``frame``, rigidly attached to it) at ``position``, found by inverse kinematics
        started at the taught pose ``near`` (deterministic: the solution on its branch).

        Args:
            position: World position [m] (x, y, z).
            orientation: World orientation as a unit quaternion (x, y, z, w); None keeps
                the TCP's orientation at ``near``.
            near: The taught pose the solve starts from.
            frame: A robot frame moving rigidly with the TCP to place instead of it.

        Raises:
            PoseError: ``near`` is no taught pose, or no solution within the joint limits
                from it (out of reach, or at a joint limit).
            ConfigError: A malformed position or orientation (key ``position`` or
                ``orientation``), or a frame that does not move with the TCP.
        """
        import pinocchio as pin

        from .tcp_targets import CartesianTarget, solve_target

        q0 = self.pose(near)
        if orientation is None:
            orientation = tuple(float(v) for v in
                                pin.Quaternion(self.robot.frame_pose(q0).rotation).coeffs())
        try:
            target = CartesianTarget(tuple(np.asarray(position, dtype=float).reshape(-1)),
                                     tuple(np.asarray(orientation, dtype=float).reshape(-1)),
                                     frame)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"expected numbers: {exc}", key="position") from None
        q = solve_target(self.robot, target, q0, key="position")
        return self.robot.as_joint_vector(q, name="position")

    def _check_poses_file(self) -> None:
        """Refuse to look a pose up in a poses file that does not exist, naming it."""
        if not self.poses and self.poses_path is not None and not self.poses_path.exists():
            raise PoseError("file not found: the cell has no taught poses (write them "
                            "there, see docs/your_own_robot_and_cell.md)",
                            path=self.poses_path)

    def checker(self, *, held: bool = False, at: str | None = None,
                options: CheckOptions | None = None) -> CollisionChecker:
        """A collision checker for this cell.

        Args:
            held: Whether the gripper holds the scene's graspable object.
            at: Taught pose whose allowed contacts apply (see the scene).
            options: Resolution and margin.
        """
        obj = None
        if held:
            if self.scene.grasp is None:
                raise ConfigError("the scene defines no grasp", path=self.scene.path,
                                  key="grasp")
            obj = self.scene.grasp.object
        return CollisionChecker(self.robot, self.scene, held=obj,
                                allowed=self.scene.contacts_at(at), options=options)


@dataclass(frozen=True)
class PoseCheck:
    """The check of one taught pose in one gripper state.

    Attributes:
        pose: Pose name.
        held: Whether the gripper held the object.
        report: The checker's report.
    """

    pose: str
    held: bool
    report: StateReport


def load_cell(folder: str | Path) -> Cell:
    """Load ``scene.yaml`` and ``poses.yaml`` from a scene folder, and the robot it names.

    Args:
        folder: A scene folder, or the name of a bundled one (``"quality_check_cell"``,
            found from any working directory, also in an installed library).

    The robot is looked up by name, or as a path relative to the scene folder. Routes
    (``routes.yaml``) are read when they are needed (:meth:`Cell.route_table`).

    Raises:
        SafepathError: Any malformed or inconsistent file (typed, names file and key).
    """
    folder = Path(folder)
    if not folder.exists():
        bundled = SCENES_DIR / str(folder)
        if len(folder.parts) == 1 and (bundled / "scene.yaml").is_file():
            folder = bundled
        else:
            names = sorted(p.parent.name for p in SCENES_DIR.glob("*/scene.yaml"))
            hint = unknown_name("scene", str(folder), names).split(" (", 1)[1]
            raise ConfigError(f"scene folder not found ({hint}", path=folder)
    scene = load_scene(folder)
    if scene.path is not None:
        folder = scene.path.parent
    relative = folder / scene.robot
    try:
        robot = load_robot(relative if relative.exists() else scene.robot,
                           locked_joints=scene.locked_joints)
    except ConfigError as exc:
        if exc.path is not None or not (exc.key or "").startswith("locked_joints"):
            raise
        raise ConfigError(exc.reason, path=scene.path, key=exc.key) from None
    poses_path = folder / "poses.yaml"
    poses = load_poses(poses_path, robot) if poses_path.exists() else {}
    cell = Cell(robot, scene, poses, folder=folder, poses_path=poses_path)
    _load_planning_code()
    prepare_robot(robot)
    return cell


def _load_planning_code() -> None:
    """Load what every plan of a cell runs, once per process: the release check's
    library (python-fcl, 5-8 ms) and the kernels compiled ahead of time
    (:func:`safepath._aot.load_planning_kernels`), so that a loaded cell's first plan
    pays for planning, not for loading code."""
    import fcl  # noqa: F401

    from .. import _aot

    _aot.load_planning_kernels()


def prepare_robot(robot: Robot) -> None:
    """Make what every collision checker and release verifier of ``robot`` takes from
    the robot alone (sphere fits and hull tables, read from the disk cache where a
    process made them before; the verifier's shapes; reach per joint: ~4 ms for the
    Ned3 Pro), as preparing the robot's geometry is part of loading it: a loaded cell's
    first plan pays for planning. Planners make the same when first needed for a robot
    built in Python.

    A robot the release verifier cannot check (:func:`safepath.verify.unverifiable`)
    still loads, to be viewed, edited and checked pose by pose; planning refuses it,
    naming the geometry or joint (as for a cell built in Python), so its verifier's part
    is not made here."""
    from .. import collision, verify

    collision.prepare_checkers(robot)
    if not verify.unverifiable(robot):
        verify.prepare_verifiers(robot)


def _check_scene_against(robot: Robot, scene: Scene, poses: Mapping[str, np.ndarray]) -> None:
    """The scene's grasp and allowed contacts name known poses; the tool fits the object."""
    if scene.grasp is not None:
        check_names(scene.grasp.poses, poses, path=scene.path, key="grasp.poses", what="pose")
        _check_fits(robot, scene)
    for i, contact in enumerate(scene.allowed_contacts):
        check_names(contact.at, poses, path=scene.path, key=f"allowed_contacts[{i}].at",
                    what="pose")


def _check_robot_is_the_scenes(robot: Robot, scene: Scene) -> None:
    """The robot is the one ``scene.robot`` names: by its name, or by the folder, file or
    example-robot-data name it was loaded from."""
    given = Path(scene.robot)
    asked = {given.name, given.stem} | ({given.parent.name} if given.name == "robot.yaml"
                                        else set())
    known = {robot.name}
    if robot.reference is not None:
        ref = Path(robot.reference)
        known |= {ref.name, ref.stem} | ({ref.parent.name} if ref.name == "robot.yaml"
                                         else set())
    if not asked & known:
        raise ConfigError(f"the scene includes robot '{scene.robot}' but the cell's robot is "
                          f"'{robot.name}' (loaded from {robot.reference or 'Python'})",
                          path=scene.path, key="robot")


def _valid_poses(given: Mapping[Any, Any], robot: Robot, path: Path | None
                 ) -> dict[str, np.ndarray]:
    """Pose name to joint vector, every name and vector checked (joint vectors that are
    already in-limit float vectors are checked all at once and kept).

    Raises:
        PoseError: A bad name, or a vector of the wrong length, not finite or outside
            the limits (the first in order, as :meth:`Robot.as_joint_vector` says).
    """
    vectors = list(given.values())
    if all(isinstance(q, np.ndarray) and q.dtype == np.float64 and q.shape == (robot.dof,)
           for q in vectors) and all(isinstance(n, str) and POSE_NAME.match(n) for n in given):
        Q = np.array(vectors).reshape(len(vectors), robot.dof)  # noqa: N806
        if np.all(np.isfinite(Q) & (Q >= robot.lower) & (Q <= robot.upper)):
            return dict(given)
    poses: dict[str, np.ndarray] = {}
    for name, q in given.items():  # in order: the first bad name or vector is named
        if not isinstance(name, str) or not POSE_NAME.match(name):
            raise PoseError(f"'{name}' is not a valid pose name", path=path, key=str(name))
        poses[name] = robot.as_joint_vector(q, name=name, path=path)
    return poses


def _check_fits(robot: Robot, scene: Scene) -> None:
    if scene.grasp is None:
        return
    obj = scene.objects[scene.grasp.object]
    if robot.tool is None:
        raise ConfigError(
            f"robot '{robot.name}' has no tool to hold '{obj.name}': give the links that "
            "touch a held object in scene.yaml or robot.yaml (tool: {contact_links: "
            "[...]}), or load_robot(..., tool=ToolSpec(contact_links=(...)))",
            path=scene.path, key="grasp")
    tool = robot.tool
    if tool.open_width is None or tool.closed_width is None:
        return  # the tool gives no widths: nothing to check the object against
    width = 2 * obj.shape.size[0] if obj.shape.kind in ("cylinder", "sphere", "capsule") \
        else min(obj.shape.size[:2])
    if not (tool.closed_width < width < tool.open_width):
        raise ConfigError(
            f"'{obj.name}' is {width * 1000:.1f} mm wide; {tool.name} grips objects between "
            f"{tool.closed_width * 1000:.1f} and {tool.open_width * 1000:.1f} mm",
            path=scene.path, key=f"objects.{obj.name}")


def check_poses(cell: Cell, options: CheckOptions | None = None) -> list[PoseCheck]:
    """Check every taught pose, with the gripper empty and, where the scene says the
    object may be held there, holding it (with that pose's allowed contacts)."""
    return list(iter_pose_checks(cell, options))


def iter_pose_checks(cell: Cell, options: CheckOptions | None = None) -> Iterator[PoseCheck]:
    """:func:`check_poses` one check at a time, in the same order (nothing kept: a file
    of many poses is reported while it is checked)."""
    # One checker per gripper state and set of allowed contacts, not per pose: poses
    # that share them share it; the sphere layer classifies each checker's poses in one
    # call, and coal is asked for collisions only where it cannot prove a pose free.
    names = list(cell.poses)
    grasp = cell.scene.grasp
    states = [(False, n) for n in names]
    if grasp is not None:
        states = [s for n in names for s in ((False, n), (True, n))[:1 + (n in grasp.poses)]]
    keys = [_checker_key(cell, held, name) for held, name in states]
    Q = np.array([cell.poses[name] for _, name in states], dtype=float)  # noqa: N806
    Q = Q.reshape(len(states), cell.robot.dof)  # noqa: N806
    checkers: dict[tuple[bool, tuple[int, ...]], CollisionChecker] = {}
    free = np.zeros(len(states), dtype=bool)
    for key in dict.fromkeys(keys):
        rows = [i for i, k in enumerate(keys) if k == key]
        checkers[key] = cell.checker(held=key[0], at=states[rows[0]][1], options=options)
        free[rows] = checkers[key].proven_free(Q[rows])
    del Q
    for i, ((held, name), key) in enumerate(zip(states, keys, strict=True)):
        yield PoseCheck(name, held, checkers[key].check(cell.poses[name], free=bool(free[i])))


def _checker_key(cell: Cell, held: bool, name: str) -> tuple[bool, tuple[int, ...]]:
    """The gripper state and the allowed contacts (their indices) of a pose."""
    contacts = cell.scene.allowed_contacts
    return held, tuple(i for i, c in enumerate(contacts) if name in c.at)
