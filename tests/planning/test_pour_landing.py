"""Where a pour can spill (issue 35, point 5): the whole opening of the cup, whenever it is
tipped past its spill angle, over the bowl's opening inside its wall.

The pouring cell's cup (a 70 x 100 mm cylinder, open at the top, spill angle 45 deg in
the scene) tilts about its lip 35 mm beside the bowl's axis (radius 70 mm, a 3 mm wall
in the scene). The rim's reach is measured here on the released samples, at 3600
points, independently of the check.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from safepath import Cell, ConfigError, load_cell, load_scene
from safepath.cell.pour_steps import Tilt
from safepath.cell.routes import Route, Step
from safepath.errors import PourLandingError
from safepath.planning import WorldState, plan_route

POURING = Path(__file__).resolve().parents[2] / "scenes" / "pouring_cell"
LIP = (0.035, 0.04, 0.0)  # the tilt's pivot in the TCP frame, as routes.yaml has it


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_cell(POURING)


def _tilt(degrees: float) -> Route:
    """A tilt of the held cup about its lip, from the pour point, into the bowl."""
    return Route(f"tilt{degrees:.0f}", "above_bowl", (
        Step("tilt", None, pour=Tilt(LIP, axis=(-1, 0, 0), angle=math.radians(degrees)),
             max_angular_speed=0.3491, into="bowl"),))


def _rim(cell: Cell, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per state: the cup's tilt from the vertical [rad] and its rim's largest distance
    from the bowl's axis [m] (3600 points of the rim)."""
    cup = cell.scene.objects["cup"]
    radius, length = cup.shape.size
    phi = np.linspace(0.0, 2 * math.pi, 3600, endpoint=False)
    rim = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, length / 2),
                    np.ones_like(phi)])
    axis = cell.scene.objects["bowl"].T_world_object[:2, 3]
    assert cell.scene.grasp is not None
    tilt, reach = [], []
    for qk in q:
        T = cell.robot.frame_pose(qk).homogeneous @ cell.scene.grasp.T_tcp_object
        tilt.append(math.acos(np.clip(T[2, 2], -1.0, 1.0)))
        p = T @ rim
        reach.append(np.hypot(p[0] - axis[0], p[1] - axis[1]).max())
    return np.array(tilt), np.array(reach)


def test_a_tilt_to_170_deg_is_refused(cell: Cell) -> None:
    """Tipped to 170 deg the opening faces down and its rim swings 104 mm from the axis
    of a bowl whose opening ends 67 mm from it: refused (it planned with exit 0 and
    "lands in 'bowl'" when only the lip was followed)."""
    with pytest.raises(PourLandingError, match="can spill outside 'bowl'") as info:
        plan_route(cell, _tilt(170.0), world=WorldState(held="cup"))
    err = info.value
    assert err.step == "0 tilt 170.0deg" and err.receptacle == "bowl"
    assert err.limit == pytest.approx(0.067)
    assert 0.100 < err.distance < 0.106 and err.overshoot == pytest.approx(
        err.distance - err.limit)
    assert "67.0 mm" in str(err) and f"{err.distance * 1000:.1f} mm" in str(err)


def test_a_tilt_to_115_deg_lands_inside_the_wall(cell: Cell) -> None:
    """The bundled slow pour's 115 deg: past the 45 deg spill angle the rim reaches
    65 mm from the axis, inside the 67 mm the wall leaves; released, with figures that
    say so."""
    traj = plan_route(cell, _tilt(115.0), world=WorldState(held="cup"))
    tilt, reach = _rim(cell, traj.q)
    past = tilt > math.radians(45.0)
    assert past.sum() > 100 and 0.064 < reach[past].max() < 0.067
    land = traj.info["pours"]["0 tilt 115.0deg"]["landing"]
    assert land["into"] == "bowl" and land["spill_angle"] == pytest.approx(0.7854)
    assert 0.067 - reach[past].max() - 5e-4 < land["margin"] <= 0.067 - reach[past].max()
    dt = np.diff(traj.t, append=traj.t[-1])
    assert land["pouring_time"] == pytest.approx(dt[past].sum(), abs=0.01)


def test_the_wall_comes_from_the_scene(cell: Cell) -> None:
    """The same 115 deg tilt into a bowl with 6 mm walls: its opening ends 64 mm from the
    axis, the rim reaches 65 mm: refused. With no wall given, the default (5 mm) holds."""
    bowl = cell.scene.objects["bowl"]
    for wall, limit in ((0.006, 0.064), (None, 0.065)):
        scene = dataclasses.replace(cell.scene, objects={
            **cell.scene.objects, "bowl": dataclasses.replace(bowl, wall=wall)})
        thick = Cell(cell.robot, scene, dict(cell.poses))
        with pytest.raises(PourLandingError) as info:
            plan_route(thick, _tilt(115.0), world=WorldState(held="cup"))
        assert info.value.limit == pytest.approx(limit)


def test_the_spill_angle_gates_the_check(cell: Cell) -> None:
    """Below its spill angle nothing pours: a 40 deg tilt is released with no landing
    margin, whatever the rim does."""
    traj = plan_route(cell, _tilt(40.0), world=WorldState(held="cup"))
    land = traj.info["pours"]["0 tilt 40.0deg"]["landing"]
    assert land["margin"] is None and land["pouring_time"] == 0.0


@pytest.mark.parametrize(("key", "value"), [("wall", -0.001), ("spill_angle", 4.0),
                                            ("wall", "thick")])
def test_bad_wall_or_spill_angle_is_refused_naming_the_key(tmp_path: Path, key: str,
                                                           value: object) -> None:
    text = (POURING / "scene.yaml").read_text()
    text = text.replace("    wall: 0.003\n", "") if key == "wall" else \
        text.replace("    spill_angle: 0.7854\n", "")
    obj = "bowl" if key == "wall" else "cup"
    text = text.replace(f"  {obj}:\n", f"  {obj}:\n    {key}: {value}\n", 1)
    (tmp_path / "scene.yaml").write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scene(tmp_path / "scene.yaml")
    assert info.value.key == f"objects.{obj}.{key}"
    assert info.value.path == tmp_path / "scene.yaml"
