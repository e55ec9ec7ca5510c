"""How a trajectory controller joins two points: one object per way, named as
``controller.yaml`` names it.

ros2_control's ``joint_trajectory_controller`` (``trajectory.cpp``,
``interpolate_between_points``) joins two points per joint with a **quintic** polynomial
when points carry positions, velocities and accelerations, a **cubic** when they carry
positions and velocities, a **linear** ramp when they carry positions only.
:class:`Interpolation` owns one of these joins: the polynomial's coefficients, its
values at times, the peaks of the executed motion between points, and which point fields
the controller reads (a goal for a cubic controller carries no accelerations).
:data:`QUINTIC`, :data:`CUBIC` and :data:`LINEAR` are the instances;
:func:`interpolation_named` looks one up by its ``controller.yaml`` name.

Quintic peaks run in the compiled kernel :mod:`safepath.model._joinkernel`; the others
(rarer) in numpy, with the same bounds.

Adding an interpolation: an instance here (its ``order`` and ``fields``) and its
coefficients in :meth:`Interpolation.coefficients`; everything else reads the object.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ._sampling import SAMPLE_SLACK

__all__ = ["Interpolation", "QUINTIC", "CUBIC", "LINEAR", "INTERPOLATIONS",
           "interpolation_named", "as_interpolation"]


@dataclass(frozen=True)
class Interpolation:
    """One way a controller joins two points, per joint.

    Attributes:
        name: Its ``controller.yaml`` name (``quintic``, ``cubic``, ``linear``).
        order: Degree of the polynomial between two points.
        fields: The point fields the controller reads (``positions``, ``velocities``,
            ``accelerations``); goals carry these and no others.
    """

    name: str
    order: int
    fields: tuple[str, ...]

    def __str__(self) -> str:
        return self.name

    @property
    def uses_velocities(self) -> bool:
        """Whether points carry velocities for this join."""
        return "velocities" in self.fields

    @property
    def uses_accelerations(self) -> bool:
        """Whether points carry accelerations for this join (a cubic ignores them)."""
        return "accelerations" in self.fields

    def coefficients(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                     k: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per interval and joint, the polynomial's coefficients ``c0..c5`` (N-1, dof, 6)
        in the time from the interval's start [s], and the intervals' lengths (N-1,) [s].

        With ``k`` (interval indices, (M,)), those of the intervals ``k`` only (M, dof, 6)
        and (M,): the same numbers as rows ``k`` of the whole (every operation is
        element-wise), without computing every interval when a few are sampled.
        """
        if k is None:
            T = np.diff(t)[:, None]  # noqa: N806
            p0, p1 = q[:-1], q[1:]
        else:
            T = (t[k + 1] - t[k])[:, None]  # noqa: N806
            p0, p1 = q[k], q[k + 1]
        c = np.zeros((T.shape[0], q.shape[1], 6))
        c[..., 0] = p0
        if self.order == 1:
            c[..., 1] = (p1 - p0) / T
            return c, T[:, 0]
        v0, v1 = (qd[:-1], qd[1:]) if k is None else (qd[k], qd[k + 1])
        c[..., 1] = v0
        if self.order == 3:
            h = p1 - p0
            c[..., 2] = (3 * h - (2 * v0 + v1) * T) / T ** 2
            c[..., 3] = (-2 * h + (v0 + v1) * T) / T ** 3
            return c, T[:, 0]
        a0, a1 = (qdd[:-1], qdd[1:]) if k is None else (qdd[k], qdd[k + 1])
        c[..., 2] = a0 / 2
        h = p1 - p0 - v0 * T - a0 * T * T / 2
        dv = v1 - v0 - a0 * T
        da = a1 - a0
        c[..., 3] = (10 * h - 4 * dv * T + da * T * T / 2) / T ** 3
        c[..., 4] = (-15 * h + 7 * dv * T - da * T * T) / T ** 4
        c[..., 5] = (6 * h - 3 * dv * T + da * T * T / 2) / T ** 5
        return c, T[:, 0]

    def evaluate(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                 k: np.ndarray, tau: np.ndarray) -> list[np.ndarray]:
        """Position, velocity, acceleration and jerk on intervals ``k`` (M,) at ``tau``
        (M, 1) [s] after each interval's start (each (M, dof))."""
        if k.size < t.size - 1:  # fewer samples than intervals (a controller's step, say)
            ck = self.coefficients(t, q, qd, qdd, k)[0]
        else:
            ck = self.coefficients(t, q, qd, qdd)[0][k]
        return [polynomial(ck, tau, nu) for nu in range(4)]

    def states(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
               times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration of the join of points ``(t, q, qd, qdd)``
        (at least two) at ``times`` [s], clamped to the ends; each (len(times), dof).
        Compiled for quintics (equal to :func:`safepath.model.execution.join` to rounding)."""
        if self.order == 5:
            from ._joinkernel import sample

            return sample(t, q, qd, qdd, times)
        t = np.asarray(t, dtype=float)
        times = np.clip(np.atleast_1d(np.asarray(times, dtype=float)), t[0], t[-1])
        k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 2)
        p, v, a, _ = self.evaluate(t, q, qd, qdd, k, (times - t[k])[:, None])
        return p, v, a

    def peaks(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
              rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per interval and joint: bound of ``|v|`` [rad/s], exact max ``|a|`` [rad/s^2] and
        ``|j|`` [rad/s^3] of the joined motion (N-1, dof) each; ``rate`` [Hz] is the least
        number of speed samples per second where the speed may peak inside."""
        if self.order == 5:
            from ._joinkernel import peaks

            return peaks(t, q, qd, qdd, rate)
        c, T = self.coefficients(np.asarray(t, dtype=float), q, qd, qdd)  # noqa: N806
        return interval_peaks(c, T, rate)

    def ratios(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
               rate: float, row: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
               jmax: np.ndarray, *, exact_from: float = 0.0, at: np.ndarray | None = None
               ) -> np.ndarray:
        """Per interval, the largest speed, acceleration and jerk ratio over the joints of
        the joined motion (:meth:`peaks`) to the limits in row ``row[k]`` (N-1,) of
        ``vmax`` [rad/s], ``amax`` [rad/s^2], ``jmax`` [rad/s^3] (rows, dof): the rows of
        one array (3, N-1), NaN on every interval next to a point that is not finite
        (whatever the interpolation's sums make of it). Compiled for quintics, in one pass.

        A caller that needs the ratios only where they reach ``exact_from`` lets the
        quintic's pass skip the exact peaks below it: every ratio of ``exact_from`` or
        more is exact; a smaller speed or acceleration ratio may instead be a bound of it
        that is still below ``exact_from``. With ``at``, only the intervals it lists
        (each (len(at),)).

        Raises:
            ValueError: An interval of ``at`` that the points do not have.
        """
        if at is not None:
            at = np.asarray(at, dtype=np.int64)
            if at.size and not (0 <= at.min() and at.max() < len(t) - 1):
                raise ValueError(f"at: intervals 0 .. {len(t) - 2}, got {at.min()} .. "
                                 f"{at.max()}")
        if self.order == 5:
            from ._joinkernel import ratios

            return ratios(t, q, qd, qdd, rate, row, vmax, amax, jmax, exact_from, at)
        peaks = self.peaks(t, q, qd, qdd, rate)
        # numpy reduces a short last axis slowly; across the long one it is ~10x faster.
        out = np.stack([np.max(np.ascontiguousarray((x / lim[row]).T), axis=0)
                        for x, lim in zip(peaks, (vmax, amax, jmax), strict=True)])
        finite = np.isfinite(t) & np.isfinite(q).all(axis=1) & np.isfinite(qd).all(axis=1) \
            & np.isfinite(qdd).all(axis=1)
        if not finite.all():
            out[:, ~(finite[:-1] & finite[1:])] = np.nan
        return out if at is None else out[:, at]


#: Position, velocity and acceleration matched at both points.
QUINTIC = Interpolation("quintic", 5, ("positions", "velocities", "accelerations"))
#: Position and velocity matched at both points (accelerations are not sent).
CUBIC = Interpolation("cubic", 3, ("positions", "velocities"))
#: Positions only, joined by a straight ramp.
LINEAR = Interpolation("linear", 1, ("positions",))
_BY_NAME = {i.name: i for i in (QUINTIC, CUBIC, LINEAR)}
#: The ways a controller joins points, as ``controller.yaml`` names them.
INTERPOLATIONS: tuple[str, ...] = tuple(_BY_NAME)


def interpolation_named(name: object, *, path: str | Path | None = None,
                        key: str = "interpolation") -> Interpolation:
    """The interpolation ``controller.yaml`` (or a trajectory file) names ``name``.

    Raises:
        ConfigError: Not a known name, naming ``path`` and ``key``.
    """
    found = _BY_NAME.get(name) if isinstance(name, str) else None
    if found is None:
        raise ConfigError(f"expected one of {list(INTERPOLATIONS)}, got {name!r}",
                          path=path, key=key)
    return found


def as_interpolation(value: Interpolation | str) -> Interpolation:
    """``value`` as an :class:`Interpolation` (a name is looked up).

    Raises:
        ConfigError: An unknown name.
    """
    return value if isinstance(value, Interpolation) else interpolation_named(value)


#: ``_FACTORS[nu][k]``: the factor of ``c_k`` in the ``nu``-th derivative, k! / (k - nu)!.
_FACTORS = tuple(tuple(float(np.prod(np.arange(k - nu + 1, k + 1))) if nu else 1.0
                       for k in range(6)) for nu in range(6))


def polynomial(c: np.ndarray, tau: np.ndarray, nu: int) -> np.ndarray:
    """The ``nu``-th derivative of the polynomials ``c`` (..., 6) at ``tau`` (broadcast)."""
    out = np.zeros(np.broadcast_shapes(c.shape[:-1], tau.shape))
    factors = _FACTORS[nu]
    for k in range(5, nu - 1, -1):
        out = out * tau + factors[k] * c[..., k]
    return out


def interval_peaks(c: np.ndarray, T: np.ndarray, rate: float  # noqa: N803
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per interval and joint: bound of |v|, exact max |a| and |j| (N-1, dof) each."""
    Tc = T[:, None]  # noqa: N806
    # Jerk: a quadratic; its extremes at the ends and at its vertex.
    j0 = 6.0 * c[..., 3]
    j1 = j0 + Tc * (24.0 * c[..., 4] + 60.0 * c[..., 5] * Tc)
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = -c[..., 4] * 24.0 / (120.0 * c[..., 5])
    inside = np.isfinite(vertex) & (vertex > 0) & (vertex < Tc)
    jv = np.where(inside, polynomial(c, np.where(inside, vertex, 0.0), 3), 0.0)
    j_peak = np.maximum(np.maximum(np.abs(j0), np.abs(j1)), np.abs(jv))
    # Acceleration: a cubic; its extremes at the ends and where the jerk vanishes.
    a_cands = [2.0 * c[..., 2], polynomial(c, Tc, 2)]
    qa, qb, qc = 60.0 * c[..., 5], 24.0 * c[..., 4], 6.0 * c[..., 3]
    disc = qb * qb - 4.0 * qa * qc
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
        roots = [(-qb + sq) / (2.0 * qa), (-qb - sq) / (2.0 * qa),
                 np.where(qb != 0.0, -qc / qb, np.nan)]
    for r, valid in zip(roots, (disc >= 0, disc >= 0, qa == 0), strict=True):
        ok = valid & np.isfinite(r) & (r > 0) & (r < Tc)
        if ok.any():
            a_cands.append(np.where(ok, polynomial(c, np.where(ok, r, 0.0), 2), a_cands[0]))
    a_all = np.stack(a_cands)
    a_peak = np.abs(a_all).max(axis=0)
    # Speed: where the acceleration keeps its sign the speed is monotone and peaks at an
    # end; elsewhere it is sampled at >= rate per second (at least 4 samples), and a peak
    # between samples dt apart adds at most |jerk| dt^2 / 8 (the acceleration vanishes).
    v_peak = np.maximum(np.abs(c[..., 1]), np.abs(polynomial(c, Tc, 1)))
    turns = (a_all.min(axis=0) < 0.0) & (a_all.max(axis=0) > 0.0)
    if turns.any():
        k, joint = np.nonzero(turns)
        ck, Tk = c[k, joint], T[k]  # noqa: N806
        m = max(4, int(np.ceil(float(Tk.max()) * rate - SAMPLE_SLACK)) + 1)
        tau = Tk[:, None] * np.linspace(0.0, 1.0, m)[None, :]
        sampled = np.abs(polynomial(ck[:, None, :], tau, 1)).max(axis=1)
        v_peak[k, joint] = np.maximum(v_peak[k, joint],
                                      sampled + j_peak[k, joint] * (Tk / (m - 1)) ** 2 / 8.0)
    return v_peak, a_peak, j_peak
