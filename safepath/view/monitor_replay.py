"""Replay of a monitor run in the browser: observed points, protective zone, decisions.

Reads a bag written by :class:`safepath.monitor.ros.MonitorRecorder` and shows, at any
time of the run: the robot (its recorded ``/joint_states``), the cell, the points of the
last observation delivered by then, the protective zone (a sphere of radius ``S_p``
about the closest observed element, coloured by the decision: green continue, yellow
slow or resume, red stop or re-plan), the true obstacle when the bag has it
(simulations), and the decisions over time (separation against protective distance,
speed scale). A time slider scrubs; Play runs it at its own pace.

Command line::

    python -m safepath.view.monitor_replay out/run --scene scenes/quality_check_cell
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..cell import Cell, load_cell
from ..errors import SafepathError
from ..monitor.ros import MonitorRun, read_monitor_bag

__all__ = ["MonitorReplay", "serve_replay", "main"]

_COLORS = {"continue": (40, 180, 60), "slow": (240, 190, 20), "resume": (240, 190, 20),
           "stop": (230, 30, 30), "replan": (230, 30, 30)}


class MonitorReplay:
    """The replay's scene and controls on one viser server.

    Args:
        server: The viser server.
        cell: The cell the run happened in.
        run: The recorded run.
    """

    def __init__(self, server: Any, cell: Cell, run: MonitorRun) -> None:
        from .scene_nodes import CellNodes, RobotNodes, configure_lighting

        if len(run.joint_times) == 0:
            raise SafepathError("the bag has no /joint_states: nothing to replay")
        self.server, self.cell, self.run = server, cell, run
        configure_lighting(server)
        self.cell_nodes = CellNodes(server, cell.scene)
        self.robot_nodes = RobotNodes(server, cell.robot)
        self.t0 = float(min(run.joint_times[0], run.observation_times[0]
                            if len(run.observation_times) else np.inf))
        self.t1 = float(run.joint_times[-1])
        self._decision_t = np.array([d["time"] for d in run.decisions])
        gui = server.gui
        self.status = gui.add_markdown("")
        self.slider = gui.add_slider("Time [s]", min=0.0, max=max(self.t1 - self.t0, 1e-3),
                                     step=0.004, initial_value=0.0)
        self.play = gui.add_button("Play")
        self.pause_button = gui.add_button("Pause")
        self.plot = gui.add_uplot(
            self._plot_data(),
            ({"label": "t [s]"},
             {"label": "separation [m]", "stroke": "#2a9d8f", "width": 2},
             {"label": "protective distance [m]", "stroke": "#e63946", "dash": (6.0, 4.0)},
             {"label": "speed scale", "stroke": "#264653", "width": 1.5}),
            title="Decisions over time", aspect=1.6)
        self.points = server.scene.add_point_cloud(
            "/monitor/points", points=np.zeros((1, 3), dtype=np.float32),
            colors=(255, 120, 0), point_size=0.012)
        self.zone = server.scene.add_icosphere("/monitor/zone", radius=1.0,
                                               color=(40, 180, 60), opacity=0.25,
                                               visible=False)
        self.truth = server.scene.add_icosphere("/monitor/truth", radius=0.05,
                                                color=(120, 120, 255), opacity=0.6,
                                                visible=bool(run.truth))
        self.slider.on_update(lambda _: self.show(self.t0 + float(self.slider.value)))
        self.play.on_click(lambda _: self._start_playing())
        self.pause_button.on_click(lambda _: self.pause())
        self._playing = False
        self.show(self.t0)

    def _plot_data(self) -> tuple[np.ndarray, ...]:
        d = self.run.decisions
        t = self._decision_t - self.t0 if len(d) else np.zeros(1)
        sep = np.array([x["separation_kept"] if x["separation_kept"] is not None else np.nan
                        for x in d]) if d else np.zeros(1)
        sp = np.array([x["protective_distance"] for x in d]) if d else np.zeros(1)
        scale = np.array([x["scale"] for x in d]) if d else np.zeros(1)
        return (t, np.minimum(sep, 3.0), sp, scale)

    def decision_at(self, t: float) -> dict[str, Any] | None:
        """The last decision taken at or before time ``t`` [s]."""
        k = int(np.searchsorted(self._decision_t, t, side="right")) - 1
        return self.run.decisions[k] if k >= 0 else None

    def show(self, t: float) -> None:
        """Draw the run at time ``t`` [s] (bag clock)."""
        run = self.run
        q = np.array([np.interp(t, run.joint_times, run.joint_positions[:, j])
                      for j in range(run.joint_positions.shape[1])])
        k = int(np.searchsorted(run.observation_times, t, side="right")) - 1
        d = self.decision_at(t)
        with self.server.atomic():
            self.robot_nodes.update(q)
            if k >= 0 and len(run.observations[k]):
                self.points.points = run.observations[k].astype(np.float32)
                self.points.visible = True
            else:
                self.points.visible = False
            if d is not None and d.get("closest") is not None:
                self.zone.position = tuple(d["closest"][:3])
                self.zone.scale = max(float(d["protective_distance"]), 1e-3)
                self.zone.color = _COLORS.get(d["kind"], (200, 200, 200))
                self.zone.visible = True
            else:
                self.zone.visible = False
            if run.truth:
                times = np.array([x[0] for x in run.truth])
                i = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
                self.truth.position = tuple(run.truth[i][1])
                self.truth.scale = run.truth[i][2] / 0.05
        self.status.content = self._status(t, d)

    @staticmethod
    def _status(t: float, d: dict[str, Any] | None) -> str:
        if d is None:
            return f"t = {t:.3f} s, no decision yet"

        def mm(v: float | None) -> str:
            return "beyond range" if v is None else f"{v * 1000:.0f} mm"

        return (f"t = {t:.3f} s: **{d['kind']}** (scale {d['scale']:.2f}), "
                f"separation {mm(d['separation_now'])}, protective distance "
                f"{d['protective_distance'] * 1000:.0f} mm. {d['reason']}")

    @property
    def playing(self) -> bool:
        """Whether the replay is playing (Play pressed, not paused nor at its end)."""
        return self._playing

    def pause(self) -> None:
        """Stop playing (the slider stays where it is)."""
        self._playing = False

    def _start_playing(self) -> None:
        if self._playing:
            return
        self._playing = True

        def loop() -> None:
            start, t_from = time.monotonic(), float(self.slider.value)
            while self._playing:
                t = t_from + time.monotonic() - start
                if t > self.t1 - self.t0:
                    break
                self.slider.value = t
                time.sleep(0.04)
            self._playing = False

        threading.Thread(target=loop, daemon=True).start()


def serve_replay(bag: str | Path, scene: str | Path, *, host: str = "127.0.0.1",
                 port: int = 8080) -> tuple[Any, MonitorReplay]:
    """Start a viser server showing the run of ``bag`` in the cell of ``scene``.

    Raises:
        SafepathError: A bad bag or scene.
    """
    import viser

    cell = load_cell(scene)
    run = read_monitor_bag(bag)
    server = viser.ViserServer(host=host, port=port)
    return server, MonitorReplay(server, cell, run)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m safepath.view.monitor_replay BAG --scene FOLDER [--host] [--port]``."""
    parser = argparse.ArgumentParser(prog="python -m safepath.view.monitor_replay",
                                     description="Replay a monitor bag in the browser.")
    parser.add_argument("bag")
    parser.add_argument("--scene", default="scenes/quality_check_cell")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8080)
    args = parser.parse_args(argv)
    try:
        server, _ = serve_replay(args.bag, args.scene, host=args.host, port=args.port)
    except SafepathError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"replay at http://{args.host}:{server.get_port()} (Ctrl-C to stop)")
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    sys.exit(main())
