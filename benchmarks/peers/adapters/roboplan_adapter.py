"""roboplan (C++ on Pinocchio + coal, TOPP-RA, viser) in its own venv.

API as installed (roboplan 0.7.0): ``Scene(name, loadUrdfSceneDescription(urdf,
package_paths))``; ``importSrdf`` (disabled pairs), ``importJointLimitsFromConfig``
(velocity and acceleration limits, roboplan's YAML layout), ``addGroup``; obstacles with
``addBoxGeometry`` / ``addCylinderGeometry`` on the ``universe`` frame, the held object
on the TCP frame; ``setCollisions(pairs, False)`` for pairs not to check. Planning
with the documented defaults: ``RRT(scene, RRTOptions(group_name=...))`` (plain RRT,
``max_nodes=1000``, ``max_connection_distance=3.0``, ``collision_check_step_size=0.05``
with bisection, ``goal_biasing_probability=0.15``, no time limit), ``setRngSeed``;
``PathShortcutter(scene, PathShortcuttingOptions(group_name=..., seed=...))``
(100 iterations, step 0.05); ``PathParameterizerTOPPRA(scene, group).generate(path,
TOPPRAOptions(dt=sample_period))`` (default ``Hermite`` spline mode: zero velocity at
every waypoint, exactly on the path).
"""

from __future__ import annotations

import os
import tempfile
import time
import xml.etree.ElementTree as ET

import numpy as np
from _common import Timer, load_job, run_problems, time_checks, write_result
from roboplan.core import (
    Box,
    Cylinder,
    JointConfiguration,
    PathShortcutter,
    PathShortcuttingOptions,
    Scene,
    Sphere,
    loadJointLimitsConfig,
    loadUrdfSceneDescription,
)
from roboplan.rrt import RRT, RRTOptions
from roboplan.toppra import PathParameterizerTOPPRA, TOPPRAOptions

try:
    from importlib.metadata import version as _version

    VERSION = _version("roboplan")
except Exception:  # metadata missing is not fatal
    VERSION = "?"

GROUP = "arm"
COLOR = np.array([0.5, 0.5, 0.5, 1.0])


def _add(scene: Scene, spec: dict, frame: str, T: np.ndarray) -> None:
    T = np.asfortranarray(np.asarray(T, dtype=float))
    if spec["kind"] == "box":
        scene.addBoxGeometry(spec["name"], frame, Box(*spec["size"]), T, COLOR)
    elif spec["kind"] == "cylinder":
        scene.addCylinderGeometry(spec["name"], frame, Cylinder(*spec["size"]), T, COLOR)
    elif spec["kind"] == "sphere":
        scene.addSphereGeometry(spec["name"], frame, Sphere(spec["size"][0]), T, COLOR)
    else:
        raise ValueError(f"unsupported shape {spec['kind']}")


def _limits_yaml(robot: dict, folder: str) -> str:
    path = os.path.join(folder, f"{robot['name']}_limits.yaml")
    with open(path, "w") as f:
        f.write("joint_limits:\n")
        for name, v, a in zip(robot["joint_names"], robot["velocity_limits"],
                              robot["acceleration_limits"], strict=True):
            f.write(f"  {name}:\n    max_velocity: [{v}]\n    max_acceleration: [{a}]\n")
    return path


def build_scene(robot: dict, world: dict, folder: str) -> Scene:
    """The robot, its limits and group, the world's objects and the pairs not checked."""
    scene = Scene("bench", loadUrdfSceneDescription(robot["urdf"], robot["package_dirs"]))
    with open(robot["srdf"]) as f:
        scene.importSrdf(f.read())
    scene.importJointLimitsFromConfig(loadJointLimitsConfig(_limits_yaml(robot, folder)))
    scene.addGroup(GROUP, robot["joint_names"])
    full = scene.getCurrentJointPositions().copy()
    for name, value in robot["fixed"].items():
        index = scene.getJointPositionIndices([name])
        if len(index):  # a mimic joint has none: it follows its leader
            full[index[0]] = value
    scene.setJointPositions(full)
    obstacles = [o["name"] for o in world["obstacles"]]
    for obs in world["obstacles"]:
        _add(scene, obs, "universe", np.asarray(obs["T"]))
    off: list[tuple[str, str]] = []
    if world["attached"] is not None:
        att = world["attached"]
        # roboplan places geometry relative to the parent *joint* of the frame named
        # (checked: the TCP-relative pose put the vial inside the wrist).
        T = np.asarray(robot["T_joint_tcp"]) @ np.asarray(att["T_link_object"])
        _add(scene, att, robot["tcp_link"], T)
        off += [(att["name"], link) for link in robot["touch_links"]]
    off += [(a, b) for i, a in enumerate(obstacles) for b in obstacles[i + 1:]]
    off += [(link, o) for link in robot["base_links"] for o in obstacles]
    off += [(a, b) for a, b in world["allowed"]]
    scene.setCollisions(off, False)
    return scene


def _srdf_check(path: str) -> int:
    return sum(1 for _ in ET.parse(path).getroot().iter("disable_collisions"))


def main() -> None:
    job, out = load_job()
    robot = job["robot"]
    folder = tempfile.mkdtemp(prefix="roboplan_bench_")
    scenes: dict[str, Scene] = {}
    names = robot["joint_names"]

    def scene_of(name: str) -> Scene:
        if name not in scenes:
            scenes[name] = build_scene(robot, job["worlds"][name], folder)
        return scenes[name]

    def solve(problem: dict) -> dict:
        scene = scene_of(problem["world"])
        seed = int(problem["seed"])
        rrt = RRT(scene, RRTOptions(group_name=GROUP))
        rrt.setRngSeed(seed)
        start = JointConfiguration(names, np.asarray(problem["start"], dtype=float))
        goal = JointConfiguration(names, np.asarray(problem["goal"], dtype=float))
        with Timer() as t_plan:
            path = rrt.plan(start, goal)
        if path is None or len(path.positions) < 2:
            return {"ok": False, "error": "RRT returned no path",
                    "plan_seconds": t_plan.seconds, "total_seconds": t_plan.seconds}
        with Timer() as t_smooth:
            path = PathShortcutter(scene, PathShortcuttingOptions(group_name=GROUP, seed=seed)
                                   ).shortcut(path)
        with Timer() as t_time:
            traj = PathParameterizerTOPPRA(scene, GROUP).generate(
                path, TOPPRAOptions(dt=job["sample_period"]))
        t = np.asarray(traj.times, dtype=float)
        q = np.asarray(traj.positions, dtype=float)
        full = scene.getCurrentJointPositions().copy()
        idx = scene.getJointPositionIndices(names)
        own = 0
        for x in q:
            full[idx] = x
            own += bool(scene.hasCollisions(full))
        return {"ok": True, "error": None, "plan_seconds": t_plan.seconds,
                "smooth_seconds": t_smooth.seconds, "timing_seconds": t_time.seconds,
                "total_seconds": t_plan.seconds + t_smooth.seconds + t_time.seconds,
                "duration": float(t[-1] - t[0]), "waypoints": len(path.positions),
                "t": t - t[0], "q": q, "own_check_colliding_samples": own}

    t0 = time.perf_counter()
    problems = run_problems(job, solve)
    check_scene = scene_of(job["check"]["world"])
    full = check_scene.getCurrentJointPositions().copy()
    idx = check_scene.getJointPositionIndices(names)

    def colliding(q: np.ndarray) -> bool:
        full[idx] = q
        return bool(check_scene.hasCollisions(full))

    checks = time_checks(job["check"]["states"], colliding)
    write_result(out, {
        "peer": "roboplan", "version": VERSION,
        "settings": {"planner": "RRTOptions() defaults (plain RRT, max_nodes 1000, "
                                "max_connection_distance 3.0, collision_check_step_size "
                                "0.05 with bisection, goal bias 0.15, no time limit) + "
                                "setRngSeed; PathShortcutter defaults (100 iterations); "
                                "PathParameterizerTOPPRA, TOPPRAOptions() defaults (Hermite)",
                     "limits": "robot velocity/acceleration limits via "
                               "importJointLimitsFromConfig",
                     "collision": "coal (roboplan Scene), URDF collision geometry as given",
                     "srdf_disabled_pairs": _srdf_check(robot["srdf"]),
                     "seed": "RRT.setRngSeed / PathShortcuttingOptions.seed = problem seed"},
        "checks": checks, "problems": problems, "wall_seconds": time.perf_counter() - t0})


if __name__ == "__main__":
    main()
