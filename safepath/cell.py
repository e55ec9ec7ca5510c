"""A cell: a robot, its scene and its taught poses, loaded from one scene folder."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .collision import CheckOptions, CollisionChecker, StateReport
from .errors import ConfigError, PoseError
from .poses import load_poses
from .robot import Robot, load_robot
from .scene import Scene, load_scene

__all__ = ["Cell", "PoseCheck", "load_cell", "check_poses"]


@dataclass
class Cell:
    """A robot in its scene, with its taught poses.

    Attributes:
        robot: The robot the scene includes.
        scene: The surroundings.
        poses: Taught poses by name [rad].
        folder: The scene folder.
        poses_path: The poses file.
    """

    robot: Robot
    scene: Scene
    poses: dict[str, np.ndarray]
    folder: Path
    poses_path: Path
    _local: threading.local = field(default_factory=threading.local, repr=False,
                                    compare=False)

    def cache(self, key: Any) -> dict[Any, Any]:
        """A per-thread dictionary for objects built from this cell (collision checkers
        are not thread-safe, so each thread gets its own), one per ``key``."""
        caches: dict[Any, dict[Any, Any]] | None = getattr(self._local, "caches", None)
        if caches is None:
            caches = self._local.caches = {}
        return caches.setdefault(key, {})

    def pose(self, name: str) -> np.ndarray:
        """The taught pose ``name``.

        Raises:
            PoseError: No pose of that name (lists the known ones).
        """
        if name not in self.poses:
            raise PoseError(f"unknown pose '{name}' (known: {', '.join(self.poses)})",
                            path=self.poses_path, key=name)
        return self.poses[name]

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

    The robot is looked up by name, or as a path relative to the scene folder.

    Raises:
        SafepathError: Any malformed or inconsistent file (typed, names file and key).
    """
    folder = Path(folder)
    if not folder.exists():
        raise ConfigError("scene folder not found", path=folder)
    scene = load_scene(folder)
    if scene.path is not None:
        folder = scene.path.parent
    relative = folder / scene.robot
    robot = load_robot(relative if relative.is_dir() else scene.robot)
    poses_path = folder / "poses.yaml"
    poses = load_poses(poses_path, robot) if poses_path.exists() else {}
    if scene.grasp is not None:
        for name in scene.grasp.poses:
            if name not in poses:
                raise ConfigError(f"unknown pose '{name}' (known: {', '.join(poses)})",
                                  path=scene.path, key="grasp.poses")
        _check_fits(robot, scene)
    for i, contact in enumerate(scene.allowed_contacts):
        for name in contact.at:
            if name not in poses:
                raise ConfigError(f"unknown pose '{name}' (known: {', '.join(poses)})",
                                  path=scene.path, key=f"allowed_contacts[{i}].at")
    return Cell(robot=robot, scene=scene, poses=poses, folder=folder, poses_path=poses_path)


def _check_fits(robot: Robot, scene: Scene) -> None:
    if scene.grasp is None:
        return
    obj = scene.objects[scene.grasp.object]
    if robot.tool is None:
        raise ConfigError(f"robot '{robot.name}' has no tool to hold '{obj.name}'",
                          path=scene.path, key="grasp")
    width = 2 * obj.shape.size[0] if obj.shape.kind in ("cylinder", "sphere", "capsule") \
        else min(obj.shape.size[:2])
    tool = robot.tool
    if not (tool.closed_width < width < tool.open_width):
        raise ConfigError(
            f"'{obj.name}' is {width * 1000:.1f} mm wide; {tool.name} grips objects between "
            f"{tool.closed_width * 1000:.1f} and {tool.open_width * 1000:.1f} mm",
            path=scene.path, key=f"objects.{obj.name}")


def check_poses(cell: Cell, options: CheckOptions | None = None) -> list[PoseCheck]:
    """Check every taught pose, with the gripper empty and, where the scene says the
    object may be held there, holding it (with that pose's allowed contacts)."""
    out = []
    empty_checkers: dict[str, CollisionChecker] = {}
    for name, q in cell.poses.items():
        checker = empty_checkers.setdefault(name, cell.checker(at=name, options=options))
        out.append(PoseCheck(name, False, checker.check(q)))
        if cell.scene.grasp is not None and name in cell.scene.grasp.poses:
            held = cell.checker(held=True, at=name, options=options)
            out.append(PoseCheck(name, True, held.check(q)))
    return out
