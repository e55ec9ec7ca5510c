"""The two problem sets of the peer benchmark, as plain data every planner can read.

1. ``cell``: the bundled quality-check cell (Ned3 Pro). Every motion step of every route
   becomes a joint-space problem from the joint vector where the step starts to the
   joint goal safepath resolves for it (taught pose, offset or ``up`` target by
   safepath's IK), in the world of that step (the vial held or resting where the route
   left it, the contacts the scene allows on that step). safepath itself plans the
   routes with its full pipeline (lines as TCP lines, blending, margins); the peers plan
   the same steps as free joint moves. That is the simplification.
2. ``panda``: Franka Panda (example-robot-data) on a table with a few boxes;
   ``panda_problems.json`` holds the start/goal pairs (generated once with a fixed seed:
   both states valid, the straight joint segment between them in collision).

``python benchmarks/peers/problems.py`` regenerates ``panda_problems.json``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["PANDA_PROBLEMS", "CellStep", "generate_panda_problems", "write_panda_cell",
           "cell_steps", "robot_spec", "world_spec", "random_states"]

HERE = Path(__file__).resolve().parent
PANDA_PROBLEMS = HERE / "panda_problems.json"

#: The Panda world: a table (top at z = 0, the robot base on it) and boxes in front of
#: the robot; a pillar splits the workspace into a left and a right half.
PANDA_OBSTACLES: list[dict[str, Any]] = [
    {"name": "table", "size": [1.40, 1.60, 0.05], "xyz": [0.35, 0.0, -0.025]},
    {"name": "pillar", "size": [0.10, 0.10, 0.70], "xyz": [0.50, 0.0, 0.35]},
    {"name": "crossbar", "size": [0.10, 0.90, 0.06], "xyz": [0.50, 0.0, 0.73]},
    {"name": "box_left", "size": [0.20, 0.16, 0.20], "xyz": [0.55, 0.40, 0.10]},
    {"name": "box_right", "size": [0.20, 0.16, 0.14], "xyz": [0.50, -0.42, 0.07]},
    {"name": "back_wall", "size": [0.05, 1.60, 0.60], "xyz": [-0.35, 0.0, 0.30]},
]
#: Where start and goal TCPs are drawn: left or right of the pillar, above the table.
_REGIONS = {
    "left": ((0.30, 0.12, 0.10), (0.75, 0.60, 0.65)),
    "right": ((0.30, -0.60, 0.10), (0.75, -0.12, 0.65)),
}


def _scene_yaml(name: str, robot: str, obstacles: Iterable[Mapping[str, Any]],
                margin: float) -> str:
    lines = [f"name: {name}", f"robot: {robot}", f"margin: {margin}", "objects:"]
    for o in obstacles:
        lines += [f"  {o['name']}:", "    shape: box",
                  f"    size: {list(map(float, o['size']))}",
                  f"    xyz: {list(map(float, o['xyz']))}",
                  f"    rpy: {list(map(float, o.get('rpy', [0.0, 0.0, 0.0])))}"]
    return "\n".join(lines) + "\n"


def write_panda_cell(problems: Mapping[str, Any], folder: Path) -> Path:
    """Write the Panda problem set as a safepath scene folder (scene, poses, routes).

    One route per problem (``p00`` ...), from its start pose to its goal by one free
    ``move``. The scene margin is 0, so every planner sees the same free space; the
    fingers are closed (locked at 0), as every adapter holds them.
    """
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scene.yaml").write_text(
        _scene_yaml("panda_table", "panda", problems["obstacles"], 0.0)
        + "locked_joints:\n  panda_finger_joint1: 0.0\n")
    poses = ["poses:"]
    routes = ["routes:"]
    for p in problems["problems"]:
        pid = p["id"]
        poses.append(f"  {pid}_start: {[float(v) for v in p['start']]}")
        poses.append(f"  {pid}_goal: {[float(v) for v in p['goal']]}")
        routes += [f"  {pid}:", f"    start: {pid}_start", "    steps:",
                   f"      - move: {pid}_goal"]
    (folder / "poses.yaml").write_text("\n".join(poses) + "\n")
    (folder / "routes.yaml").write_text("\n".join(routes) + "\n")
    return folder


def generate_panda_problems(*, seed: int = 20240, count: int = 24) -> dict[str, Any]:
    """Draw ``count`` start/goal pairs for the Panda world.

    Each start and goal is a uniformly drawn joint vector whose TCP lies in one of the
    two regions beside the pillar (start and goal on opposite sides), valid under
    safepath's checker (margin 0), and the straight joint segment between them collides.
    """
    import tempfile

    import safepath

    with tempfile.TemporaryDirectory() as tmp:
        cell = safepath.load_cell(write_panda_cell({"obstacles": PANDA_OBSTACLES,
                                                    "problems": []}, Path(tmp)))
        robot = cell.robot
        checker = safepath.CollisionChecker(robot, cell.scene,
                                            options=safepath.CheckOptions())
        rng = np.random.default_rng(seed)

        def draw(region: str) -> np.ndarray:
            lo, hi = (np.asarray(v) for v in _REGIONS[region])
            while True:
                q = np.round(rng.uniform(robot.lower, robot.upper), 6)
                p = robot.tcp_position(q)
                if np.all(p >= lo) and np.all(p <= hi) and checker.is_valid(q):
                    return q

        out = []
        while len(out) < count:
            side = ("left", "right") if len(out) % 2 == 0 else ("right", "left")
            q0, q1 = draw(side[0]), draw(side[1])
            if checker.segment_is_valid(q0, q1):
                continue
            out.append({"id": f"p{len(out):02d}", "start": q0.tolist(), "goal": q1.tolist(),
                        "seed": len(out)})
    return {"robot": "panda", "seed": seed, "tcp_regions": _REGIONS,
            "note": "start/goal TCPs on opposite sides of the pillar; both valid and the "
                    "straight joint segment in collision (safepath checker, margin 0, "
                    "resolution 2 mm)",
            "obstacles": PANDA_OBSTACLES, "problems": out}


@dataclass
class CellStep:
    """One motion step of the cell as a joint-space problem.

    Attributes:
        route: Route name.
        index: Step index in the route.
        label: Step label (``2 move high2``).
        kind: ``move`` or ``line`` (the peers plan both as free joint moves).
        start: Joint vector where the step starts [rad].
        goal: Joint goal safepath resolves for it [rad].
        world: Key of the world state of the step.
        held: Held object, or None.
        resting: Placements (4x4) of resting movable objects.
        allowed: Allowed contacts on this step.
    """

    route: str
    index: int
    label: str
    kind: str
    start: np.ndarray
    goal: np.ndarray
    world: str
    held: str | None
    resting: dict[str, np.ndarray]
    allowed: tuple


def cell_steps(cell: Any) -> list[CellStep]:
    """Every motion step of every route of the cell, in route order, with its world."""
    import safepath
    from safepath.kinematics import LineOptions, solve_ik
    from safepath.planning.route_planner import initial_world, route_order

    routes = safepath.load_routes(cell.folder, poses=list(cell.poses),
                                  objects=list(cell.scene.objects))
    scene, robot = cell.scene, cell.robot
    worlds: dict[str, Any] = {}
    world_keys: dict[tuple, str] = {}
    out: list[CellStep] = []
    for name in route_order(routes):
        route = routes[name]
        world = worlds[route.after].copy() if route.after else initial_world(cell)
        q = cell.pose(route.start)
        pose_name: str | None = route.start
        labels = route.labels()
        for i, step in enumerate(route.steps):
            if step.is_motion:
                target = step.target
                if target.exact_pose is not None:
                    goal, goal_name = cell.pose(target.exact_pose), target.exact_pose
                else:
                    seed = cell.pose(target.pose) if target.pose is not None else q
                    T = robot.frame_pose(seed)
                    T.translation = T.translation + np.asarray(target.offset)
                    goal = solve_ik(robot, T, seed, options=LineOptions(), step=labels[i])
                    goal_name = None
                allowed = (scene.contacts_at(pose_name) + scene.contacts_at(goal_name)
                           if step.kind == "line" else ())
                key = (world.key(), allowed)
                wname = world_keys.setdefault(key, f"w{len(world_keys)}")
                out.append(CellStep(name, i, labels[i], step.kind, q.copy(), goal.copy(),
                                    wname, world.held,
                                    {k: v.copy() for k, v in world.resting.items()}, allowed))
                q, pose_name = goal, goal_name
            else:
                obj = step.object or scene.grasp.object
                T = robot.frame_pose(q).homogeneous @ scene.grasp.T_tcp_object
                world = world.copy()
                if step.kind == "close":
                    world.held = obj
                    world.resting.pop(obj, None)
                elif world.held == obj:
                    world.held = None
                    world.resting[obj] = T
        worlds[name] = world
    return out


def _shape(kind: str, size: tuple[float, ...]) -> dict[str, Any]:
    return {"kind": kind, "size": [float(v) for v in size]}


def robot_spec(robot: Any, urdf: Path, srdf: Path, *, all_joints: list[str],
               fixed: Mapping[str, float], package_dirs: list[str]) -> dict[str, Any]:
    """What an adapter needs to know about the robot (JSON-ready).

    ``all_joints`` are the URDF's movable joints in order; ``fixed`` the ones locked
    (Panda fingers) with their value.
    """
    model = robot.model
    tcp = model.frames[robot.tcp_frame_id]
    tcp_joint = int(tcp.parentJoint)
    links_on_tcp_joint = sorted({robot.model.frames[g.parentFrame].name
                                 for g in robot.collision_model.geometryObjects
                                 if int(g.parentJoint) == tcp_joint})
    base_links = sorted({robot.model.frames[g.parentFrame].name
                         for g in robot.collision_model.geometryObjects
                         if int(g.parentJoint) == 0})
    contact = list(robot.tool.contact_links) if robot.tool else []
    return {
        "name": robot.name, "urdf": str(urdf), "srdf": str(srdf),
        "package_dirs": package_dirs, "joint_names": list(robot.joint_names),
        "all_joint_names": all_joints, "fixed": dict(fixed),
        "tcp_link": tcp.name, "T_joint_tcp": tcp.placement.homogeneous.tolist(),
        "base_links": base_links,
        "touch_links": sorted(set(contact) | set(links_on_tcp_joint)),
        "lower": robot.lower.tolist(), "upper": robot.upper.tolist(),
        "velocity_limits": robot.velocity_limits.tolist(),
        "acceleration_limits": robot.acceleration_limits.tolist(),
    }


def world_spec(robot: Any, scene: Any, *, held: str | None = None,
               resting: Mapping[str, np.ndarray] | None = None,
               allowed: Iterable[Any] = ()) -> dict[str, Any]:
    """One world state for the adapters: obstacles (boxes and cylinders with 4x4 world
    poses), the held object (attached to the TCP link), and the pairs not to check
    (allowed contacts, expanded from ``gripper`` to the tool's contact links)."""
    from safepath.model.scene import GRIPPER

    obstacles = []
    for obj in scene.objects.values():
        T = obj.T_world_object
        if obj.movable:
            if obj.name == held:
                continue
            T = (resting or {}).get(obj.name, obj.T_world_object)
            if T is None:
                continue
        obstacles.append({"name": obj.name, **_shape(obj.shape.kind, obj.shape.size),
                          "T": np.asarray(T).tolist()})
    attached = None
    if held is not None:
        obj = scene.objects[held]
        attached = {"name": held, **_shape(obj.shape.kind, obj.shape.size),
                    "T_link_object": scene.grasp.T_tcp_object.tolist()}
    contact = list(robot.tool.contact_links) if robot.tool else []
    pairs = set()
    for c in allowed:
        a_side = contact if c.between[0] == GRIPPER else [c.between[0]]
        b_side = contact if c.between[1] == GRIPPER else [c.between[1]]
        pairs |= {(a, b) for a in a_side for b in b_side}
    return {"obstacles": obstacles, "attached": attached,
            "allowed": [list(p) for p in sorted(pairs)]}


def random_states(robot: Any, count: int, seed: int) -> np.ndarray:
    """Uniform joint vectors within the limits (for the checks-per-second figure)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.lower, robot.upper, size=(count, robot.dof))


if __name__ == "__main__":
    data = generate_panda_problems()
    # One obstacle / problem per line: small diffs when regenerated.
    head = {k: v for k, v in data.items() if k not in ("obstacles", "problems")}
    text = "{\n" + "".join(f" {json.dumps(k)}: {json.dumps(v)},\n" for k, v in head.items())
    for key in ("obstacles", "problems"):
        rows = ",\n".join("  " + json.dumps(row) for row in data[key])
        text += f' "{key}": [\n{rows}\n ]' + (",\n" if key == "obstacles" else "\n}\n")
    PANDA_PROBLEMS.write_text(text)
    print(f"wrote {len(data['problems'])} problems to {PANDA_PROBLEMS}")
