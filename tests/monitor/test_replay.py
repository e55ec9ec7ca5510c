"""The replay of a recorded monitor run in the review page (a real viser server)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safepath import Cell
from safepath.errors import RosError
from safepath.monitor.ros import MonitorRecorder, read_monitor_bag
from safepath.monitor.simulation import MovingSphere, simulate
from safepath.view.monitor_replay import MonitorReplay, main

from .conftest import CAMERA, Phase1, make_monitor


@pytest.fixture(scope="module")
def bag(cell: Cell, phase1: Phase1, tmp_path_factory: pytest.TempPathFactory) -> Path:
    monitor = make_monitor(cell, hold_time=0.3)
    recorder = MonitorRecorder(monitor.options, cell.robot.joint_names)
    target = np.array([0.33, 0.30, 0.30])
    obstacle = MovingSphere.approach(target + [0.8, 0, 0], target, 1.6, 0.2, 0.7, leave_at=1.2)
    simulate(monitor, list(phase1.motions), obstacle, sensor="cam", sensor_pose=CAMERA,
             until=3.0, recorder=recorder)
    return recorder.write(tmp_path_factory.mktemp("bags") / "run")


def test_replay_shows_points_zone_and_decisions(cell: Cell, bag: Path) -> None:
    import viser

    run = read_monitor_bag(bag)
    server = viser.ViserServer(host="127.0.0.1", port=0)
    try:
        replay = MonitorReplay(server, cell, run)
        stops = [d for d in run.decisions if d["kind"] == "stop" and d["closest"]]
        assert stops
        d = stops[0]
        replay.show(d["time"])
        assert "**stop**" in replay.status.content
        assert replay.zone.visible and replay.zone.color == (230, 30, 30)
        assert replay.zone.scale == pytest.approx(d["protective_distance"])
        np.testing.assert_allclose(replay.zone.position, d["closest"][:3], atol=1e-6)
        k = int(np.searchsorted(run.observation_times, d["time"], side="right")) - 1
        # (viser keeps positions as float16)
        np.testing.assert_allclose(replay.points.points, run.observations[k], atol=1e-3)
        # Scrubbing with the slider moves the robot to its recorded state.
        replay.slider.value = 2.5
        replay.show(replay.t0 + 2.5)
        assert replay.decision_at(replay.t0 + 2.5)["time"] <= replay.t0 + 2.5
        t_plot = replay.plot.data[0]
        assert len(t_plot) == len(run.decisions)
    finally:
        server.stop()


def test_replay_command_line_refuses_a_bad_bag(tmp_path: Path, capsys: pytest.CaptureFixture
                                               ) -> None:
    assert main([str(tmp_path / "missing"), "--port", "0"]) == 2
    assert "error:" in capsys.readouterr().err
    with pytest.raises(RosError):
        read_monitor_bag(tmp_path / "missing")
