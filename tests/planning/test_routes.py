"""Routes as data, and every way a route can fail: typed errors, never a partial result.

Parsing errors name the file and the dotted key; planning errors name the step and the
evidence (the colliding pair, where the line fails, the planner status).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from safepath import (
    ConfigError,
    IKError,
    PlannerOptions,
    PlannerTimeout,
    PlanningError,
    PlanOptions,
    Route,
    Step,
    Target,
    load_cell,
    load_routes,
    plan_cell,
    plan_route,
)
from safepath.cell import Cell
from safepath.planning.route_planner import route_order

from .conftest import BUNDLED

POSES = ["grip", "high1", "high2", "low1", "safe", "unsafe"]
OBJECTS = ["vial", "table"]


def _write_routes(tmp_path: Path, routes: dict[str, Any]) -> Path:
    path = tmp_path / "routes.yaml"
    path.write_text(yaml.safe_dump({"routes": routes}, sort_keys=False))
    return path


def _load(tmp_path: Path, routes: dict[str, Any]) -> dict[str, Route]:
    return load_routes(_write_routes(tmp_path, routes), poses=POSES, objects=OBJECTS)


def _scene_copy(tmp_path: Path, edit: Any) -> Path:
    """A copy of the bundled cell whose scene.yaml is changed by ``edit(data)``."""
    folder = tmp_path / "cell"
    shutil.copytree(BUNDLED, folder)
    data = yaml.safe_load((folder / "scene.yaml").read_text())
    edit(data)
    (folder / "scene.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return folder


# -- the bundled routes ------------------------------------------------------------------
def test_bundled_routes_load_as_written(bundled_cell: Cell) -> None:
    routes = load_routes(BUNDLED, poses=list(bundled_cell.poses),
                         objects=list(bundled_cell.scene.objects))
    assert list(routes) == ["phase1", "phase2_safe", "phase2_unsafe"]
    p1, safe = routes["phase1"], routes["phase2_safe"]
    assert p1.start == "grip" and p1.after is None
    assert [s.kind for s in p1.steps] == ["close", "line", "line", "move", "line", "open",
                                          "line"]
    assert p1.steps[0].object == "vial" and p1.steps[0].stop
    assert p1.steps[1].target == Target(None, (0.0, 0.0, 0.10))  # {up: 0.10}: straight up
    assert p1.steps[2].speed == 0.5 and p1.steps[2].tcp_speed == 0.25
    assert p1.steps[3].speed == 1.0 and p1.steps[3].tcp_speed is None
    assert safe.after == "phase1" and safe.start == "high2"
    assert safe.steps[3].target == Target("safe", (0.0, 0.0, 0.05))
    assert safe.steps[3].target.exact_pose is None
    assert safe.steps[6].target == Target(None, (0.0, 0.0, 0.05))  # {up: 0.05}
    via = safe.steps[7]  # via: high2 is a move that never stops
    assert via.kind == "move" and not via.stop and via.target == Target("high2")
    assert via.via and not safe.steps[3].via
    assert p1.labels()[3] == "3 move high2"
    assert safe.labels()[7:9] == ["7 via high2", "8 via high1"]  # named as written
    assert route_order({k: routes[k] for k in reversed(list(routes))})[0] == "phase1"


def test_plan_cell_names_a_missing_or_circular_after(bundled_cell: Cell) -> None:
    """Routes given to plan_cell directly: a route that follows one not given, or routes
    that follow each other, are a ConfigError naming the key (not a bare KeyError or a
    RecursionError), before anything is planned."""
    import dataclasses

    from safepath.planning import plan_cell

    routes = load_routes(BUNDLED, poses=list(bundled_cell.poses),
                         objects=list(bundled_cell.scene.objects))
    with pytest.raises(ConfigError, match="phase1") as missing:
        plan_cell(bundled_cell, routes={"phase2_safe": routes["phase2_safe"]})
    assert missing.value.key == "routes.phase2_safe.after"
    looped = {"phase1": dataclasses.replace(routes["phase1"], after="phase2_safe"),
              "phase2_safe": routes["phase2_safe"]}
    with pytest.raises(ConfigError, match="cycle"):
        plan_cell(bundled_cell, routes=looped)


def test_step_shorthands(tmp_path: Path) -> None:
    routes = _load(tmp_path, {"r": {"start": "high1", "steps": [
        "close", {"move": "high2", "stop": True}, "open", {"via": {"pose": "low1"}}]}})
    steps = routes["r"].steps
    assert [s.kind for s in steps] == ["close", "move", "open", "move"]
    assert steps[0].object is None and steps[1].stop and not steps[3].stop


# -- parsing errors: file and key ------------------------------------------------------------
@pytest.mark.parametrize(("routes", "key", "words"), [
    ({"r": {"start": "high1", "steps": [{"line": "high2"}, {"move": "nowhere"}]}},
     "routes.r.steps[1].move", "unknown pose 'nowhere'"),
    ({"r": {"start": "high1", "steps": [{"move": {"pose": "nope", "offset": [0, 0, 1]}}]}},
     "routes.r.steps[0].move.pose", "unknown pose 'nope'"),
    ({"r": {"start": "nowhere", "steps": [{"move": "high2"}]}},
     "routes.r.start", "unknown pose"),
    ({"r": {"start": "high1", "steps": [{"jump": "high2"}]}},
     "routes.r.steps[0]", "exactly one of"),
    ({"r": {"start": "high1", "steps": [{"move": "high2", "line": "low1"}]}},
     "routes.r.steps[0]", "exactly one of"),
    ({"r": {"start": "high1", "steps": [{"move": "high2", "speed": 1.5}]}},
     "routes.r.steps[0].speed", "at most 1"),
    ({"r": {"start": "high1", "steps": [{"move": "high2", "speed": 0}]}},
     "routes.r.steps[0].speed", ""),
    ({"r": {"start": "high1", "steps": [{"move": "high2", "tcp_speed": -1}]}},
     "routes.r.steps[0].tcp_speed", ""),
    ({"r": {"start": "high1", "steps": [{"move": "high2", "fast": True}]}},
     "routes.r.steps[0].fast", "unknown key"),
    ({"r": {"start": "high1", "steps": [{"via": "high2", "stop": True}]}},
     "routes.r.steps[0].stop", "never stops"),
    ({"r": {"start": "high1", "steps": [{"close": "spoon"}]}},
     "routes.r.steps[0].close", "unknown object 'spoon'"),
    ({"r": {"start": "high1", "steps": [{"move": {"pose": "low1", "offset": [0, 0]}}]}},
     "routes.r.steps[0].move.offset", ""),
    ({"r": {"start": "high1", "steps": []}}, "routes.r.steps", "non-empty"),
    ({"a": {"start": "high1", "after": "b", "steps": [{"move": "high2"}]},
      "b": {"start": "high2", "after": "a", "steps": [{"move": "high1"}]}},
     "routes.a.after", "cycle"),
    ({"a": {"start": "high1", "after": "a", "steps": [{"move": "high2"}]}},
     "routes.a.after", "cycle"),
    ({"a": {"start": "high1", "after": "zz", "steps": [{"move": "high2"}]}},
     "routes.a.after", "unknown route 'zz'"),
])
def test_bad_routes_name_file_and_key(tmp_path: Path, routes: dict[str, Any], key: str,
                                      words: str) -> None:
    path = _write_routes(tmp_path, routes)
    with pytest.raises(ConfigError) as info:
        load_routes(path, poses=POSES, objects=OBJECTS)
    assert info.value.key == key
    assert info.value.path == path
    assert words in info.value.reason
    assert str(path) in str(info.value) and key in str(info.value)


def test_missing_routes_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError):
        load_routes(tmp_path, poses=POSES, objects=OBJECTS)
    (tmp_path / "routes.yaml").write_text("routes: {}\n")
    with pytest.raises(ConfigError) as info:
        load_routes(tmp_path, poses=POSES, objects=OBJECTS)
    assert info.value.key == "routes"


# -- planning failures ---------------------------------------------------------------------
def _route(start: str, *steps: Step) -> Route:
    return Route("test", start, tuple(steps))


def test_start_in_collision_names_the_pair(bundled_cell: Cell) -> None:
    # At grip the open jaws straddle the vial; a free move (no allowed contact) may not
    # start there.
    with pytest.raises(PlanningError) as info:
        plan_route(bundled_cell, _route("grip", Step("move", Target("high1"))))
    err = info.value
    assert err.step == "0 move high1"
    assert "start state is invalid" in str(err)
    assert "vial" in str(err) and ("mors_1" in str(err) or "mors_2" in str(err))


def test_goal_in_collision_names_the_pair(bundled_cell: Cell) -> None:
    with pytest.raises(PlanningError) as info:
        plan_route(bundled_cell, _route("high1", Step("move", Target("grip"))))
    assert "goal state is invalid" in str(info.value)
    assert "vial" in str(info.value)
    assert info.value.step == "0 move grip"


def test_unreachable_line_target_raises_ik_error(bundled_cell: Cell) -> None:
    target = Target("high1", (1.0, 0.0, 0.0))  # 1 m beyond high1: out of reach
    with pytest.raises(IKError) as info:
        plan_route(bundled_cell, _route("high1", Step("line", target)))
    err = info.value
    assert 0.0 < err.fraction <= 1.0
    expected = bundled_cell.robot.tcp_position(bundled_cell.pose("high1")) + [1.0, 0.0, 0.0]
    np.testing.assert_allclose(np.asarray(err.position), expected, atol=1e-9)
    assert err.step == "0 line high1+1.000,+0.000,+0.000"


def test_a_line_through_an_object_raises(bundled_cell: Cell) -> None:
    """Straight down from high1 by 30 cm: through the conveyor."""
    with pytest.raises(IKError) as info:
        plan_route(bundled_cell, _route("high1", Step("line", Target(None, (0, 0, -0.3)))))
    err = info.value
    # The first state refused keeps less than the 10 mm margin (before the contact).
    assert "below its margin of 10 mm (no contact)" in str(err) and "qc_conveyor" in str(err)
    assert 0.5 < err.fraction < 1.0
    # Where it fails: on the vertical line, below the conveyor's top plus the margin.
    start = bundled_cell.robot.tcp_position(bundled_cell.pose("high1"))
    position = np.asarray(err.position)
    np.testing.assert_allclose(position[:2], start[:2], atol=1e-4)
    assert position[2] < 0.065 + 0.010 + 0.03


def test_close_far_from_the_object_raises(bundled_cell: Cell) -> None:
    with pytest.raises(PlanningError, match="mm from the gripper") as info:
        plan_route(bundled_cell, _route("high1", Step("close", None, "vial", stop=True),
                                        Step("move", Target("high2"))))
    assert info.value.step == "0 close vial"


def test_object_too_wide_for_the_gripper(tmp_path: Path) -> None:
    def widen(data: dict[str, Any]) -> None:
        data["objects"]["vial"]["radius"] = 0.03

    folder = _scene_copy(tmp_path, widen)
    with pytest.raises(ConfigError) as info:
        load_cell(folder)
    assert info.value.key == "objects.vial"
    assert info.value.path == folder / "scene.yaml"
    assert "60.0 mm" in str(info.value)


def _blocked_cell(tmp_path: Path) -> Cell:
    """A wall at 45 deg from 12 cm off the base axis outwards, and a ceiling just above
    the arm at high1 and high2: no way from high1 to high2 (RRTConnect finds none in 2 s
    over several seeds), yet both poses are valid with their margin."""
    angle, inner, length = math.pi / 4, 0.12, 1.5
    centre = inner + length / 2

    def add(data: dict[str, Any]) -> None:
        objects = data["objects"]
        objects["wall"] = {"shape": "box", "size": [length, 0.004, 2.0],
                           "xyz": [centre * math.cos(angle), centre * math.sin(angle), 0.5],
                           "rpy": [0.0, 0.0, angle]}
        objects["ceiling"] = {"shape": "box", "size": [2.0, 2.0, 0.01],
                              "xyz": [0.0, 0.0, 0.52]}

    return load_cell(_scene_copy(tmp_path, add))


def test_planner_time_out_is_typed(tmp_path: Path) -> None:
    cell = _blocked_cell(tmp_path)
    checker = cell.checker(held=False)
    assert checker.check(cell.pose("high1")).margin_ok
    assert checker.check(cell.pose("high2")).margin_ok
    options = PlanOptions(planner=PlannerOptions(time_limit=0.2))
    with pytest.raises(PlannerTimeout) as info:
        plan_route(cell, _route("high1", Step("move", Target("high2"))), options)
    err = info.value
    assert err.step == "0 move high2"
    assert err.status  # OMPL's status string is kept
    assert "0.2 s" in str(err)


def test_a_failed_route_fails_the_whole_cell(tmp_path: Path) -> None:
    """plan_cell returns every route or raises: no partial dictionary."""
    cell = _blocked_cell(tmp_path)
    routes = {"ok": _route("high2", Step("line", Target("low1"))),
              "blocked": Route("blocked", "high1", (Step("move", Target("high2")),))}
    options = PlanOptions(planner=PlannerOptions(time_limit=0.2))
    with pytest.raises(PlannerTimeout):
        plan_cell(cell, options, routes=routes)


def test_planner_options_are_validated() -> None:
    with pytest.raises(ConfigError, match="unknown planner"):
        PlannerOptions(planner="Dijkstra")
    with pytest.raises(ConfigError, match="time_limit"):
        PlannerOptions(time_limit=0.0)
