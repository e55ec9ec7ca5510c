"""mplib (OMPL + FCL + Pinocchio + TOPP-RA) in its own venv (numpy < 2).

API as installed (mplib 0.2.1): ``mplib.Planner(urdf, move_group, srdf=...,
joint_vel_limits=..., joint_acc_limits=...)``; obstacles are ``FCLObject``s added to
``planner.planning_world``; the held object is attached to the TCP link with
``planning_world.attach_object(name, geometry, art_name, link_id, pose, touch_links)``;
pairs not to check go into the allowed-collision matrix. ``planner.plan_qpos`` is
called with its documented defaults (RRTConnect, ``planning_time=1`` s, ``rrt_range=0.1``,
``simplify=True``, ``fix_joint_limits=True``) except ``time_step``, which only sets how
densely the TOPP-RA result is sampled (the benchmark's sample period instead of 0.1 s,
so that the re-check sees the timed path itself). ``mplib.set_global_seed`` seeds OMPL
per problem. Limits: the robot's joint velocity and acceleration limits (mplib's own
default is 1 rad/s and 1 rad/s^2).
"""

from __future__ import annotations

import os
import re
import tempfile
import time

import mplib
import numpy as np
from _common import Timer, load_job, quat_wxyz, run_problems, time_checks, write_result
from mplib.collision_detection import fcl

try:
    from importlib.metadata import version as _version

    VERSION = _version("mplib")
except Exception:  # metadata missing is not fatal
    VERSION = "?"


def _pose(T: list) -> mplib.Pose:
    T = np.asarray(T, dtype=float)
    return mplib.Pose(T[:3, 3], quat_wxyz(T[:3, :3]))


def _geometry(spec: dict) -> object:
    if spec["kind"] == "box":
        return fcl.Box(*spec["size"])
    if spec["kind"] == "cylinder":
        return fcl.Cylinder(spec["size"][0], spec["size"][1])
    if spec["kind"] == "sphere":
        return fcl.Sphere(spec["size"][0])
    raise ValueError(f"unsupported shape {spec['kind']}")


def _relative_urdf(urdf: str) -> str:
    """A copy of the URDF in a temp dir, with mesh paths relative to the copy
    (mplib resolves every mesh path, even an absolute one, against the URDF's folder)."""
    folder = tempfile.mkdtemp(prefix="mplib_bench_")
    text = open(urdf).read()
    text = re.sub(r'filename="(/[^"]+)"',
                  lambda m: f'filename="{os.path.relpath(m.group(1), folder)}"', text)
    path = os.path.join(folder, os.path.basename(urdf))
    with open(path, "w") as f:
        f.write(text)
    return path


class _World:
    """One mplib planner per world state."""

    def __init__(self, robot: dict, world: dict) -> None:
        self.planner = mplib.Planner(urdf=_relative_urdf(robot["urdf"]), srdf=robot["srdf"],
                                     move_group=robot["tcp_link"],
                                     joint_vel_limits=robot["velocity_limits"],
                                     joint_acc_limits=robot["acceleration_limits"])
        p = self.planner
        names = p.user_joint_names
        self.full = np.zeros(len(names))
        for name, value in robot["fixed"].items():
            self.full[names.index(name)] = value
        self.arm = [names.index(n) for n in robot["joint_names"]]
        pw = p.planning_world
        for obs in world["obstacles"]:
            pw.add_object(fcl.FCLObject(obs["name"], _pose(obs["T"]),
                                        [fcl.CollisionObject(_geometry(obs))],
                                        [mplib.Pose()]))
        if world["attached"] is not None:
            att = world["attached"]
            link_id = p.user_link_names.index(robot["tcp_link"])
            pw.attach_object(att["name"], _geometry(att), p.robot.get_name(), link_id,
                             _pose(att["T_link_object"]), robot["touch_links"])
        acm = pw.get_allowed_collision_matrix()
        for a, b in world["allowed"]:
            acm.set_entry(a, b, True)
        for link in robot["base_links"]:
            for obs in world["obstacles"]:
                acm.set_entry(link, obs["name"], True)

    def qpos(self, q_arm: list) -> np.ndarray:
        q = self.full.copy()
        q[self.arm] = q_arm
        return q

    def colliding(self, q_arm: np.ndarray) -> bool:
        self.planner.robot.set_qpos(self.qpos(q_arm), True)
        return bool(self.planner.planning_world.is_state_colliding())


def main() -> None:
    job, out = load_job()
    robot = job["robot"]
    worlds: dict[str, _World] = {}

    def world(name: str) -> _World:
        if name not in worlds:
            worlds[name] = _World(robot, job["worlds"][name])
        return worlds[name]

    def solve(problem: dict) -> dict:
        w = world(problem["world"])
        planner = w.planner
        topp = {"seconds": 0.0}
        original = planner.TOPP

        def timed_topp(*args: object, **kwargs: object) -> object:
            with Timer() as t:
                result = original(*args, **kwargs)
            topp["seconds"] = t.seconds
            return result

        planner.TOPP = timed_topp  # measure TOPP-RA inside plan_qpos, unchanged
        mplib.set_global_seed(int(problem["seed"]))
        start = w.qpos(problem["start"])
        with Timer() as total:
            res = planner.plan_qpos([w.qpos(problem["goal"])], start,
                                    time_step=job["sample_period"])
        planner.TOPP = original
        if res["status"] != "Success":
            return {"ok": False, "error": str(res["status"]), "total_seconds": total.seconds}
        t = np.asarray(res["time"], dtype=float)
        q = np.asarray(res["position"], dtype=float)
        return {"ok": True, "error": None, "plan_seconds": total.seconds - topp["seconds"],
                "timing_seconds": topp["seconds"], "total_seconds": total.seconds,
                "duration": float(res["duration"]), "t": t, "q": q,
                "own_check_colliding_samples": sum(w.colliding(x) for x in q)}

    t0 = time.perf_counter()
    problems = run_problems(job, solve)
    check_world = world(job["check"]["world"])
    checks = time_checks(job["check"]["states"], check_world.colliding)
    write_result(out, {
        "peer": "mplib", "version": VERSION,
        "settings": {"planner": "Planner.plan_qpos defaults: OMPL RRTConnect, planning_time "
                                "1 s, rrt_range 0.1, simplify True; TOPP-RA "
                                "(ParametrizeConstAccel) through a cubic spline of the "
                                "waypoints",
                     "limits": "robot velocity/acceleration limits passed as "
                               "joint_vel_limits / joint_acc_limits",
                     "collision": "FCL, URDF collision geometry as given (use_convex False)",
                     "seed": "mplib.set_global_seed(problem seed)"},
        "checks": checks, "problems": problems, "wall_seconds": time.perf_counter() - t0})


if __name__ == "__main__":
    main()
