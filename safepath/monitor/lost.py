"""A body that held the robot back and then vanished from every sensor where it stood.

A sensor has a detection capability: a body lower than the scan's plane and narrower than
the camera's spacing of rays where it stands is seen while it walks (some ray catches it
now and then) and not at all once it stops between the rays. A body does not vanish, so
the monitor does not take such a place as clear: it keeps the body where it was last seen.

* **Seen**: at every decision that stops or slows the robot for a body, its elements as
  the newest observations show them (:func:`~safepath.monitor.parked.blocking_body`) and
  the oldest of those observations' stamps are kept.
* **Lost**: at a later observation with every sensor speaking, no element lies within
  ``link`` plus :data:`SPREAD` plus how far a body walks at ``speed`` in the time since of
  where it was seen: it went nowhere the sensors could see. Its last elements are then
  added to every observation, as observed, until an element is seen within that reach,
  grown at ``speed`` for at most :data:`TRACK` more (the body is in view again near where
  it vanished: the sensors' own elements decide from then on), or the monitor is reset.
  The robot stays stopped or slowed for it, and, once it is at rest, a re-plan goes
  around it as around any parked body.

A body that walks away is seen on its way (from one observation to the next, within the
reach); one that leaves the sensors' fields of view was no longer holding the robot back
there. The cost of the rule is a body that vanished and is really gone: the robot waits,
or goes around where it was, until the place is seen occupied and then empty again, or an
operator resets the monitor.
"""

from __future__ import annotations

import numpy as np

from .parked import extent

__all__ = ["TRACK", "SPREAD", "LostBodies"]

#: Longest time [s] over which the reach of a lost body grows (at ``speed``) after it was
#: lost: an element farther away is another body, not that one.
TRACK = 0.25
#: How far apart [m] two observations may show a body's elements nearest the robot when
#: it has not moved: a sensor's rays fall on another part of it (the live-safety suite's
#: 1 m tall cylinders, seen from above, gave a single element near the floor in one camera
#: frame and none within 0.23 m of it in the next). A body is lost only when nothing at
#: all is seen this close to where it was, beyond where it could have walked.
SPREAD = 0.5


class LostBodies:
    """The body that held the robot back at the latest decision, and whether it is lost.

    Args:
        speed: How fast a body walks [m/s] (the monitor's ``approach_speed``).
        link: Elements closer than this belong to one body [m] (``replan_cluster``).
    """

    def __init__(self, speed: float, link: float) -> None:
        self.speed = speed
        self.link = link
        self._stamp = -np.inf
        self._body = np.zeros((0, 4))
        self.lost = False
        self._lost_at = self._reach = 0.0  # when it was lost, and how far it could be then

    def clear(self) -> None:
        """Forget the body (the monitor was reset)."""
        self._body, self.lost = np.zeros((0, 4)), False

    def seen(self, stamps: list[float], body: np.ndarray | None, closest: np.ndarray | None,
             declared: np.ndarray | None = None) -> None:
        """The body (n, 4: x, y, z, radius) [m] of the element ``closest``
        (:func:`~safepath.monitor.parked.blocking_body`) holds the robot back in the
        observations of ``stamps`` [s] (those its elements may come from; the oldest
        counts); None: nothing holds it back at this decision (what was kept stays). A
        lost body's own elements (added by :meth:`fill`) do not see it again, and a body
        user code declares (``closest`` among ``declared``, the elements of
        :class:`~safepath.monitor.observations.Obstacles`) is not kept: it is gone when
        no longer declared."""
        if self.lost or not stamps or body is None or closest is None or not len(body):
            return
        if declared is not None and len(declared) and \
                bool(np.any(np.all(declared[:, :4] == np.asarray(closest)[:4], axis=1))):
            self._body = np.zeros((0, 4))
            return
        self._stamp = min(stamps)
        self._body = np.array(body[:, :4], dtype=float)

    def fill(self, elements: np.ndarray, stamps: list[float]) -> tuple[np.ndarray, str]:
        """The elements (n, 4) of the observations of ``stamps`` [s] (one per sensor;
        empty: a sensor is silent, nothing is judged), with the lost body's added (see
        the module doc), and what was lost at this observation, in words ("": nothing
        new)."""
        stamp = max(stamps, default=-np.inf)
        if not len(self._body) or not stamps or (not self.lost and stamp <= self._stamp):
            return elements, ""  # nothing held back, or no observation since the sighting
        if self.lost:  # found again only near where it vanished
            reach = self._reach + self.speed * min(stamp - self._lost_at, TRACK)
        else:  # wherever it could have walked since it was seen, or been seen otherwise
            reach = self.link + SPREAD + self.speed * (stamp - self._stamp)
        if len(elements):  # the gap to its box (elements' radii included): O(elements)
            lo, hi = extent(self._body)
            outside = np.maximum(np.maximum(lo - elements[:, :3], elements[:, :3] - hi), 0.0)
            if float(np.min(np.linalg.norm(outside, axis=1) - elements[:, 3])) <= reach:
                self.clear()  # in view (again): the sensors decide
                return elements, ""
        note = ""
        if not self.lost:
            self.lost, self._lost_at, self._reach = True, stamp, reach
            centre = self._body[:, :3].mean(axis=0)
            note = (f"a body vanished from every sensor at ({centre[0]:.2f}, "
                    f"{centre[1]:.2f}, {centre[2]:.2f}) m, no element within "
                    f"{1000 * reach:.0f} mm of where it was seen {stamp - self._stamp:.3f} s "
                    "before: kept there as seen")
        return np.vstack([elements, self._body]) if len(elements) else self._body.copy(), note
