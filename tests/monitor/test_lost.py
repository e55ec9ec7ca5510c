"""A body that held the robot back and then vanished from every sensor where it stood
(:mod:`safepath.monitor.lost`), in closed loop on the bundled cell's phase 1: a sphere
seen by the test camera walks toward the arm's path; the camera then sees nothing (the
sphere below its detection capability, as in the live-safety suite's seed 7311), or sees
the sphere walk away, or see it again where it stood and then leave."""

from __future__ import annotations

import numpy as np

from safepath import Cell
from safepath.monitor import Cloud, Decision, Monitor
from safepath.monitor.lost import SPREAD, TRACK, LostBodies
from safepath.monitor.simulation import MovingSphere, camera_cloud

from .conftest import CAMERA, Phase1, make_monitor

RADIUS = 0.05
PERIOD = 1 / 30


def _cloud(t: float, center: np.ndarray | None, rng: np.random.Generator) -> Cloud:
    if center is None:  # nothing in view: an empty frame
        return Cloud(t, "cam", np.zeros((0, 3)))
    P = camera_cloud(MovingSphere(np.zeros(1), center[None], RADIUS), t, CAMERA, 300, rng)  # noqa: N806
    return Cloud(t, "cam", P + rng.normal(0.0, 0.003, P.shape))


def _stopped_by_a_sphere(cell: Cell, phase1: Phase1) -> tuple[Monitor, np.ndarray, float,
                                                                 np.random.Generator]:
    """The first motion of phase 1 followed; a sphere walks (0.5 m/s) to a spot 12 cm
    beside the path ahead until the monitor stops the arm and it has come to rest."""
    traj, held = phase1.motions[0]
    m = make_monitor(cell, replan_after=0.6)
    m.follow(traj, start=0.0, held=held)
    k = traj.t.size // 2
    spot = cell.robot.tcp_position(traj.q[k]) + [0.0, 0.12, 0.0]
    center, rng, t = spot + [0.5, 0.0, 0.0], np.random.default_rng(3), 0.0
    still = None
    while still is None or t - still < 0.3:
        step = spot - center
        n = float(np.linalg.norm(step))
        center = spot.copy() if n < 0.5 * PERIOD else center + step / n * 0.5 * PERIOD
        d = m.observe(_cloud(t, center, rng), t)
        if d.kind == "stop" and m.state_at(t)[1] == 0.0 and still is None:
            still = t
        t = round(t + PERIOD, 9)
        assert t < 8.0, "the sphere never stopped the arm"
    return m, center, t, rng


def _run(m: Monitor, t: float, seconds: float, where: object, rng: np.random.Generator
         ) -> tuple[list[Decision], float]:
    out = []
    end = t + seconds
    while t < end:
        center = where(t) if callable(where) else where
        out.append(m.observe(_cloud(t, center, rng), t))
        t = round(t + PERIOD, 9)
    return out, t


def test_a_body_that_vanishes_where_it_stood_keeps_the_arm_stopped(
        cell: Cell, phase1: Phase1) -> None:
    # Without the rule the empty frames read as a clear area: a resume after hold_time.
    m, center, t, rng = _stopped_by_a_sphere(cell, phase1)
    decisions, t = _run(m, t, 4 * m.options.hold_time, None, rng)
    kinds = [d.kind for d in decisions]
    assert set(kinds) <= {"stop", "replan"} and m.state_at(t)[1] == 0.0
    lost = [d for d in decisions if "vanished from every sensor" in d.reason]
    assert len(lost) == 1  # said once, at the first empty frame
    assert lost[0] is decisions[0]
    # Kept as seen: at rest, so a re-plan goes around where it was last seen.
    asked = [d.replan for d in decisions if d.replan is not None]
    assert len(asked) == 1
    body = asked[0]
    assert body.body_center is not None and body.body_size is not None
    assert np.all(np.abs(body.body_center - center) <= RADIUS + 0.02)
    # The operator's reset forgets it: the area reads clear, the arm resumes.
    m.reset()
    decisions, t = _run(m, t, 2 * m.options.hold_time, None, rng)
    assert "resume" in [d.kind for d in decisions]


def test_a_body_seen_walking_away_is_not_kept(cell: Cell, phase1: Phase1) -> None:
    # It leaves in view at 1.6 m/s, out of the camera's field (empty frames) 1 m on.
    m, center, t, rng = _stopped_by_a_sphere(cell, phase1)
    t0 = t

    def away(now: float) -> np.ndarray | None:
        x = center + [1.6 * (now - t0), 0.0, 0.0]
        return None if now - t0 > 1.0 / 1.6 else x

    decisions, t = _run(m, t, 3 * m.options.hold_time, away, rng)
    assert "resume" in [d.kind for d in decisions]
    assert not any("vanished" in d.reason for d in decisions)


def test_a_lost_body_seen_again_where_it_stood_is_the_sensors_business(
        cell: Cell, phase1: Phase1) -> None:
    m, center, t, rng = _stopped_by_a_sphere(cell, phase1)
    decisions, t = _run(m, t, 0.5, None, rng)  # lost
    assert "vanished from every sensor" in decisions[0].reason
    decisions, t = _run(m, t, 0.3, center, rng)  # seen again where it stood
    assert all(d.kind in ("stop", "replan") for d in decisions)
    t0 = t
    decisions, t = _run(m, t, 3 * m.options.hold_time,
                        lambda now: center + [1.0 * (now - t0), 0.0, 0.0], rng)  # walks off
    assert "resume" in [d.kind for d in decisions]
    assert not any("vanished" in d.reason for d in decisions)


def test_the_reach_of_a_body_grows_at_walking_speed_and_once_lost_for_a_while() -> None:
    lost = LostBodies(speed=1.6, link=0.1)
    body = np.array([[0.0, 0.0, 0.5, 0.02]])
    lost.seen([1.0], body, body[0])
    far = np.array([[1.5, 0.0, 0.5, 0.02]])
    E, note = lost.fill(far, [1.05])  # 1.5 m away, 50 ms on: not where it could have been
    assert lost.lost and "vanished" in note and len(E) == 2
    assert np.array_equal(E[1], body[0])
    E, note = lost.fill(far, [1.1])  # still lost, said once
    assert lost.lost and note == "" and len(E) == 2
    other = np.array([[5.0, 5.0, 5.0, 0.1]])
    lost.seen([1.2], other, other[0])  # while lost, what holds the robot back is its own
    # Lost with a reach of 0.1 + SPREAD + 1.6 * 0.05 m, grown for TRACK more: no farther.
    reach = 0.1 + SPREAD + 1.6 * 0.05 + 1.6 * TRACK
    beyond = np.array([[reach + 0.04 + 0.01, 0.0, 0.5, 0.02]])
    E, note = lost.fill(beyond, [3.0])
    assert lost.lost and len(E) == 2
    within = np.array([[reach + 0.04 - 0.01, 0.0, 0.5, 0.02]])
    E, note = lost.fill(within, [3.1])  # seen near where it vanished: in view again
    assert not lost.lost and len(E) == 1
    E, note = lost.fill(far, [3.2])  # nothing held back any more
    assert len(E) == 1 and note == ""
    # A silent sensor: nothing is judged (empty stamps), the robot stops for the silence.
    lost.seen([4.0], body, body[0])
    E, note = lost.fill(far, [])
    assert not lost.lost and len(E) == 1
    # Not lost yet after a second without every sensor speaking: found wherever it could
    # have walked since it was seen.
    E, note = lost.fill(np.array([[2.0, 0.0, 0.5, 0.02]]), [5.0])
    assert not lost.lost and len(E) == 1
    # A body user code declares (Obstacles) is gone when it no longer declares it.
    lost.seen([6.0], body, body[0], declared=body)
    E, note = lost.fill(far, [6.1])
    assert not lost.lost and len(E) == 1
