"""The pour node's parameters (examples/ros2/pour_params.yaml) build a working pour: the
tilt and the pick and place routes planned on the real cell, run closed loop on the
simulated scale, gripper goals from robots/gen3_lite/controller.yaml."""

from __future__ import annotations

import math
import py_compile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from safepath.cells.pouring.controller import PourState, SendArmGoal, SendGripperGoal
from safepath.cells.pouring.dry_run import PourSim, commands_of
from safepath.cells.pouring.flow import FlowModel
from safepath.cells.pouring.setup import PourParameters, PourSetup, build_pour
from safepath.errors import InputError, TrajectoryError
from safepath.model.trajectory import Trajectory
from safepath.ros.goals import follow_joint_trajectory_goal, split_at_gripper_events
from safepath.ros.gripper import gripper_command_goal

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "ros2"


def params_file() -> dict[str, Any]:
    text = (EXAMPLES / "pour_params.yaml").read_text()
    return dict(yaml.safe_load(text)["safepath_pour"]["ros__parameters"])


@pytest.fixture(scope="module")
def setup() -> PourSetup:
    values = params_file()
    values["scene"] = str(ROOT / values["scene"])
    return build_pour(PourParameters.from_mapping(values))


def test_params_file_pick_pour_place(setup: PourSetup) -> None:
    truth = FlowModel(gain=70.0, latency=0.1, seed=11)
    first = next(s for s in setup.before if isinstance(s, Trajectory))
    run = PourSim(setup.cell, truth).run(setup.controller, first.q[0], max_time=300.0,
                                        holding=False)
    assert not run.faults and setup.controller.state is PourState.DONE
    arm = [c.purpose for _, c in commands_of(run, SendArmGoal)]  # type: ignore[attr-defined]
    assert arm == ["route", "route", "pour", "stop", "return", "route", "route"]
    grips = [c.event for _, c in commands_of(run, SendGripperGoal)]  # type: ignore[attr-defined]
    assert [g.action for g in grips] == ["open", "close", "open"]
    # What the node sends for them: ros2_kortex's open and closed positions.
    assert [gripper_command_goal(setup.cell.robot, g.action, backend="rosbags").command.position
            for g in grips] == [0.0, 0.8, 0.0]
    assert abs(run.final_mass - 100.0) <= 3.5  # see test_pour_controller.POUR_TOLERANCE
    assert run.tilt[-1] < math.radians(5.0)  # the place route keeps the cup upright


def test_every_example_node_compiles(tmp_path: Path) -> None:
    nodes = sorted(EXAMPLES.glob("*.py"))
    assert "pour_node.py" in [n.name for n in nodes]
    for node in nodes:
        py_compile.compile(str(node), cfile=str(tmp_path / f"{node.stem}.pyc"), doraise=True)


def test_node_declares_every_parameter_of_the_file() -> None:
    source = (EXAMPLES / "pour_node.py").read_text()
    assert "dataclasses.fields(PourParameters)" in source
    assert set(params_file()) == {f for f in PourParameters.__dataclass_fields__}


@pytest.mark.parametrize(("change", "key", "words"), [
    ({"tilt_angel": 1.0}, "tilt_angel", "did you mean 'tilt_angle'"),
    ({"robot": None}, "robot", "non-empty string"),
    ({"tilt_axis": [0.0, 0.0]}, "tilt_axis", "3 finite numbers"),
    ({"tilt_axis": [0.0, 0.0, 0.0]}, "tilt_axis", "must not be zero"),
    ({"pivot_offset": [0.0, math.nan, 0.0]}, "pivot_offset", "3 finite numbers"),
    ({"target": -1.0}, "target", "> 0"),
    ({"scale_latency": True}, "scale_latency", "> 0"),
    ({"tilt_angle": 3.5}, "tilt_angle", "below pi"),
])
def test_bad_parameters_are_typed(change: dict[str, Any], key: str, words: str) -> None:
    values = {**params_file(), **change}
    with pytest.raises(InputError, match=words) as info:
        PourParameters.from_mapping(values)
    assert info.value.key == key


def test_missing_parameter_and_wrong_robot() -> None:
    values = params_file()
    del values["pour_pose"]
    with pytest.raises(InputError, match="missing") as info:
        PourParameters.from_mapping(values)
    assert info.value.key == "pour_pose"
    values = {**params_file(), "robot": "ned3pro", "scene": str(ROOT / "scenes/pouring_cell")}
    with pytest.raises(InputError, match="holds robot 'gen3_lite', not 'ned3pro'") as info:
        build_pour(PourParameters.from_mapping(values))
    assert info.value.key == "robot"


def test_bag_of_pick_pour_place_with_gripper_goals(setup: PourSetup, tmp_path: Path) -> None:
    """Pick (with its gripper events), the tilt until a stop, the stop, the return
    upright, place: one bag with every goal the node sends, read back."""
    from safepath.cells.pouring.parts import PourStopper
    from safepath.ros.bag import ARM_GOAL_TOPIC, GRIPPER_GOAL_TOPIC, read_bag, write_bag

    pick, place = setup.routes["pick_cup"], setup.routes["place_cup"]
    stopper = PourStopper(setup.cell, setup.tilt)
    stop = stopper.stop(15.0, 15.05)
    back = stopper.back(stop.info["s_rest"])
    sequence = [pick, stopper.until(stop), stop, back, place]
    start = 1_700_000_000 * 10**9
    bag = read_bag(write_bag(tmp_path / "pour", sequence, start_time_ns=start, goals=True))
    # The pick as a node runs it (one goal through its 'close' would never close the
    # gripper): a goal per motion between gripper events.
    with pytest.raises(TrajectoryError, match="'close'.*split_at_gripper_events"):
        follow_joint_trajectory_goal(pick)
    motions = [m for traj in sequence for m in split_at_gripper_events(traj)
               if isinstance(m, Trajectory)]
    arm = bag.on(ARM_GOAL_TOPIC)
    assert len(arm) == len(motions) == 2 + 3 + 2  # pick: open, close; the pour; place: open
    begins = np.cumsum([0] + [round(t.duration * 1e9) for t in sequence[:-1]])
    starts = np.cumsum([0] + [round(m.duration * 1e9) for m in motions[:-1]])
    assert np.abs(np.array([m.timestamp - start for m in arm]) - starts).max() <= 10
    assert [arm[k].timestamp - start for k in (2, 3, 4, 5)] == list(begins[1:5])
    for m, motion in zip(arm, motions, strict=True):
        pts = m.msg.trajectory.points
        np.testing.assert_array_equal(pts[-1].positions, motion.q[-1])
        assert m.msg.trajectory.joint_names == list(motion.joint_names)
    grip = bag.on(GRIPPER_GOAL_TOPIC)
    expected = [(begins[0] + round(e.time * 1e9), e.action) for e in pick.events] + \
        [(begins[4] + round(e.time * 1e9), e.action) for e in place.events]
    got = [(m.timestamp - start, "close" if m.msg.command.position == 0.8 else "open")
           for m in grip]
    assert [a for _, a in got] == [a for _, a in expected]
    assert np.abs(np.array([t for t, _ in got]) - [t for t, _ in expected]).max() <= 10
    assert [m.msg.command.position for m in grip] == [0.0, 0.8, 0.0]
