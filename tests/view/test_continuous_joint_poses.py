"""The review session edits a continuous joint's angle beyond +-pi (issue 36, point 1): on
example-robot-data's Kinova Jaco, whose base joint ``j2s6s200_joint_1`` is continuous,
an edited pose of 4.5 rad is valid, saved and read back as 4.5 rad; a bounded joint
beyond its limit is still refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import safepath
from safepath import Cell, Scene, SceneObject, Shape, load_poses, placement
from safepath.view import ReviewSession, ViewOptions

Q_UP = np.array([2.9, 3.5, 2.0, 0.3, 2.5, 3.0])


def test_a_continuous_joint_is_edited_and_saved_beyond_pi(tmp_path: Path) -> None:
    robot = safepath.load_robot("kinova")
    floor = SceneObject("floor", Shape("box", (2.0, 2.0, 0.02)), placement((0, 0, -0.011)))
    path = tmp_path / "poses.yaml"
    cell = Cell(robot, Scene(name="floor", robot="kinova", objects=[floor]),
                {"up": Q_UP, "turned": Q_UP + np.array([0.0, 0, 0, 1.0, 0, 0])},
                poses_path=path)
    session = ReviewSession(cell, options=ViewOptions(port=0, plan_on_start=False,
                                                      replan_on_save=False)).start()
    try:
        session.edit_pose("turned")
        q = Q_UP.copy()
        q[0] = 4.5  # beyond +pi: the same placement as 4.5 - 2 pi
        status = session.set_joints(q)
        assert status.valid, status.summary()
        assert session.save_poses() == path
        assert load_poses(path, robot)["turned"][0] == 4.5
        bounded = q.copy()
        bounded[1] = 6.0  # j2s6s200_joint_2 stops at 5.46 rad
        assert not session.set_joints(bounded).valid
    finally:
        session.stop()
