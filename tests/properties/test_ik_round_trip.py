"""Property: inverse kinematics finds the TCP pose forward kinematics gives.

For random joint states of each bundled robot, the TCP pose (forward kinematics) is
solved by :func:`safepath.kinematics.solve_ik` from a start near the state (every joint
moved by up to ``START_OFFSET``, kept in the limits):

* anywhere in the limits, an answer it returns is inside the limits and puts the TCP on
  the target within the solver's tolerances (position [m], orientation [rad]); where it
  finds none it raises ``IKError``, never returning a wrong answer;
* away from the limits and from singular states, it finds one. (Damped least squares,
  clipped to the limits, may not converge within its iterations at a singular state,
  e.g. the UR5's elbow folded at -pi, or at a target with a joint on its limit, e.g. the
  Panda's shoulder at its lower limit: hypothesis finds both.)
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from safepath import IKError, LineOptions, Robot, load_robot
from safepath.kinematics import solve_ik

from .strategies import bounded, in_limits

ROBOTS = ["ned3pro", "gen3_lite", "panda", "ur5"]
#: Largest offset of the start from the state, per joint [rad].
START_OFFSET = 0.1
#: "Away from the limits": every joint at least this far inside them [rad].
LIMIT_CLEARANCE = 0.05
#: "Away from singular states": the TCP Jacobian's smallest singular value at least this.
MIN_SINGULAR_VALUE = 0.02
OPTIONS = LineOptions()


@cache
def _robot(name: str) -> Robot:
    return load_robot(name)


def _starts(robot: Robot) -> st.SearchStrategy[tuple[float, ...]]:
    return st.tuples(*[st.floats(-START_OFFSET, START_OFFSET)] * robot.dof)


def _solve(robot: Robot, q: np.ndarray, offset: tuple[float, ...]) -> np.ndarray:
    """IK of the TCP pose at ``q`` from the start ``q + offset``; asserts that an answer
    is inside the limits and on the target within the tolerances."""
    T_world_tcp = robot.frame_pose(q)
    q_init = np.clip(q + np.array(offset), robot.lower, robot.upper)
    answer = solve_ik(robot, T_world_tcp, q_init, options=OPTIONS)
    assert np.all(answer >= robot.lower) and np.all(answer <= robot.upper)
    reached = robot.frame_pose(answer)
    position_error = np.linalg.norm(reached.translation - T_world_tcp.translation)
    orientation_error = np.linalg.norm(pin.log3(reached.rotation.T @ T_world_tcp.rotation))
    assert position_error < OPTIONS.position_tolerance
    assert orientation_error < OPTIONS.orientation_tolerance
    return answer


def _smallest_singular_value(robot: Robot, q: np.ndarray) -> float:
    data = robot.model.createData()
    J = pin.computeFrameJacobian(robot.model, data, q, robot.tcp_frame_id, pin.LOCAL)
    return float(np.linalg.svd(J, compute_uv=False)[-1])


@pytest.mark.parametrize("name", ROBOTS)
def test_ik_round_trips_away_from_limits_and_singular_states(name: str) -> None:
    robot = _robot(name)

    @bounded(40)
    @given(q=in_limits(robot, LIMIT_CLEARANCE), offset=_starts(robot))
    def round_trip(q: np.ndarray, offset: tuple[float, ...]) -> None:
        assume(_smallest_singular_value(robot, q) >= MIN_SINGULAR_VALUE)
        _solve(robot, q, offset)

    round_trip()


@pytest.mark.parametrize("name", ROBOTS)
def test_ik_never_returns_a_wrong_answer(name: str) -> None:
    robot = _robot(name)

    @bounded(30)
    @given(q=in_limits(robot), offset=_starts(robot))
    def answer_or_error(q: np.ndarray, offset: tuple[float, ...]) -> None:
        try:
            _solve(robot, q, offset)
        except IKError:
            pass

    answer_or_error()
