"""pyroboplan (Pinocchio + coal; educational, pure Python) in its own venv.

API as installed (pyroboplan 1.3.1, pin 4.0.0): the robot is a Pinocchio model and
geometry model (``pinocchio.buildModelsFromUrdf``); obstacles are ``GeometryObject``s
on the universe joint, the held object one on the TCP frame's joint, and the pairs to
check are the collision model's collision pairs. Planning follows the library's own
recipe with its documented defaults: ``RRTPlanner(model, collision_model,
RRTPlannerOptions(rng_seed=seed))`` (unidirectional RRT, ``max_step_size=0.05`` rad
edge checks, ``max_connection_dist=inf``, no goal bias, ``max_planning_time=10`` s),
then ``shortcut_path`` (``max_iters=100``, ``max_step_size=0.05``), then
``TrapezoidalVelocityTrajectory(path, qd_max, qdd_max)`` (pyroboplan has no TOPP-RA
wrapper: its trapezoid stops at every waypoint; it takes the robot's velocity and
acceleration limits), sampled every ``sample_period``.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET

import coal
import numpy as np
import pinocchio as pin
from _common import Timer, load_job, run_problems, time_checks, write_result
from pyroboplan.core.utils import check_collisions_at_state
from pyroboplan.planning.path_shortcutting import shortcut_path
from pyroboplan.planning.rrt import RRTPlanner, RRTPlannerOptions
from pyroboplan.trajectory.trapezoidal_velocity import TrapezoidalVelocityTrajectory

try:
    from importlib.metadata import version as _version

    VERSION = _version("pyroboplan")
except Exception:  # metadata missing is not fatal
    VERSION = "?"


def _geometry(spec: dict) -> object:
    if spec["kind"] == "box":
        return coal.Box(*spec["size"])
    if spec["kind"] == "cylinder":
        return coal.Cylinder(spec["size"][0], spec["size"][1])
    if spec["kind"] == "sphere":
        return coal.Sphere(spec["size"][0])
    raise ValueError(f"unsupported shape {spec['kind']}")


def _srdf_pairs(path: str) -> set[frozenset[str]]:
    root = ET.parse(path).getroot()
    return {frozenset((e.get("link1"), e.get("link2"))) for e in root.iter("disable_collisions")}


def build_models(robot: dict, world: dict) -> tuple[pin.Model, pin.GeometryModel]:
    """Robot (locked joints removed), obstacles and held object, with the pairs to check."""
    model, cmodel, _ = pin.buildModelsFromUrdf(robot["urdf"],
                                               package_dirs=robot["package_dirs"])
    if robot["fixed"]:
        q_ref = pin.neutral(model)
        lock = []
        for name, value in robot["fixed"].items():
            jid = model.getJointId(name)
            q_ref[model.joints[jid].idx_q] = value
            lock.append(jid)
        model, cmodel = pin.buildReducedModel(model, cmodel, lock, q_ref)
    n_robot = len(cmodel.geometryObjects)
    link = [model.frames[g.parentFrame].name for g in cmodel.geometryObjects]
    joint = [int(g.parentJoint) for g in cmodel.geometryObjects]
    kind = ["robot"] * n_robot
    for obs in world["obstacles"]:
        T = np.asarray(obs["T"])
        cmodel.addGeometryObject(pin.GeometryObject(obs["name"], 0, 0, pin.SE3(T[:3, :3], T[:3, 3]),
                                                    _geometry(obs)))
        link.append(obs["name"])
        joint.append(0)
        kind.append("obstacle")
    if world["attached"] is not None:
        att = world["attached"]
        fid = model.getFrameId(robot["tcp_link"])
        frame = model.frames[fid]
        T = np.asarray(att["T_link_object"])
        M = frame.placement * pin.SE3(T[:3, :3], T[:3, 3])
        cmodel.addGeometryObject(pin.GeometryObject(att["name"], int(frame.parentJoint), fid,
                                                    M, _geometry(att)))
        link.append(att["name"])
        joint.append(int(frame.parentJoint))
        kind.append("attached")
    disabled = _srdf_pairs(robot["srdf"])
    allowed = {frozenset(p) for p in world["allowed"]}
    touch = set(robot["touch_links"])
    base = set(robot["base_links"])
    for i in range(len(link)):
        for j in range(i + 1, len(link)):
            ki, kj = kind[i], kind[j]
            pair = frozenset((link[i], link[j]))
            if "obstacle" in (ki, kj):
                if ki == kj or pair & base or pair in allowed:
                    continue
            elif ki == kj == "robot":
                if link[i] == link[j] or joint[i] == joint[j] or pair in disabled:
                    continue
            else:  # attached object vs robot
                if pair & touch or joint[i] == joint[j]:
                    continue
            cmodel.addCollisionPair(pin.CollisionPair(i, j))
    return model, cmodel


def main() -> None:
    job, out = load_job()
    robot = job["robot"]
    worlds: dict[str, tuple] = {}
    vmax = np.asarray(robot["velocity_limits"])
    amax = np.asarray(robot["acceleration_limits"])

    def world(name: str) -> tuple:
        if name not in worlds:
            model, cmodel = build_models(robot, job["worlds"][name])
            worlds[name] = (model, cmodel, model.createData(), cmodel.createData())
        return worlds[name]

    def solve(problem: dict) -> dict:
        model, cmodel, data, cdata = world(problem["world"])
        q0, q1 = np.asarray(problem["start"]), np.asarray(problem["goal"])
        options = RRTPlannerOptions(rng_seed=int(problem["seed"]))
        with Timer() as t_plan:
            path = RRTPlanner(model, cmodel, options=options).plan(q0, q1)
        if not path:
            return {"ok": False, "error": "RRTPlanner returned no path",
                    "plan_seconds": t_plan.seconds, "total_seconds": t_plan.seconds}
        with Timer() as t_smooth:
            path = shortcut_path(model, cmodel, path)
        with Timer() as t_time:
            traj = TrapezoidalVelocityTrajectory(np.asarray(path).T, vmax, amax)
            t, q, _, _ = traj.generate(job["sample_period"])
        return {"ok": True, "error": None, "plan_seconds": t_plan.seconds,
                "smooth_seconds": t_smooth.seconds, "timing_seconds": t_time.seconds,
                "total_seconds": t_plan.seconds + t_smooth.seconds + t_time.seconds,
                "duration": float(t[-1]), "waypoints": len(path), "t": t, "q": q.T,
                "own_check_colliding_samples": sum(
                    bool(check_collisions_at_state(model, cmodel, x, data, cdata))
                    for x in q.T)}

    t0 = time.perf_counter()
    problems = run_problems(job, solve)
    model, cmodel, data, cdata = world(job["check"]["world"])
    checks = time_checks(job["check"]["states"],
                         lambda q: check_collisions_at_state(model, cmodel, q, data, cdata))
    write_result(out, {
        "peer": "pyroboplan", "version": VERSION,
        "settings": {"planner": "RRTPlannerOptions() defaults (RRT, max_step_size 0.05, "
                                "max_planning_time 10 s) + rng_seed; shortcut_path defaults "
                                "(100 iterations); TrapezoidalVelocityTrajectory (stops at "
                                "every waypoint)",
                     "limits": "robot velocity/acceleration limits (qd_max, qdd_max)",
                     "collision": "coal via pinocchio.computeCollisions, URDF collision "
                                  "geometry as given",
                     "seed": "RRTPlannerOptions(rng_seed=problem seed) (np.random.seed)"},
        "checks": checks, "problems": problems, "wall_seconds": time.perf_counter() - t0})


if __name__ == "__main__":
    main()
