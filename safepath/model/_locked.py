"""Locked joints: URDF joints that a motion holds still (fingers, a gripper), set by the user.

A robot description may move more joints than safepath plans for: the Gen3 Lite's and the
Panda's fingers, for instance. Those joints are *locked*: held at a value for the whole
motion. Their value is the user's to give (``load_robot(..., locked_joints=...)`` or a
cell's ``locked_joints``) and is never guessed:

* a number places the joint (and the joints that mimic it) there; the collision geometry
  of the links it moves is where those links really are;
* ``"travel"`` (also what an unset joint gets) covers the joint's whole travel: the
  geometry of each link it moves is replaced by one convex shape enclosing every place the
  link takes between the joint's limits, so a path declared free stays free whatever the
  fingers do during it.

Travel shapes are exact enclosures: the link's shape is sampled at ``TRAVEL_SAMPLES`` joint
values and the hull of the samples is grown (Minkowski sum with a cube) by a bound on how
far a point can leave the chord between two samples (``h^2/8`` times twice the largest
second difference seen on a four times finer grid).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigError
from .shapes import from_coal

__all__ = ["TRAVEL", "LockedJoint", "lock_joints", "read_mimics"]

#: The value that asks for the whole travel of a locked joint.
TRAVEL = "travel"
#: Joint values at which a link is placed to build its travel shape.
TRAVEL_SAMPLES = 48


@dataclass(frozen=True)
class LockedJoint:
    """A joint held still during motions.

    Attributes:
        name: Joint name (as in the URDF).
        value: Its position [rad or m], or None when the geometry covers its whole travel.
        lower: Lower position limit [rad or m].
        upper: Upper position limit [rad or m].
        follows: For a mimic joint, (driving joint, multiplier, offset); None otherwise.
    """

    name: str
    value: float | None
    lower: float
    upper: float
    follows: tuple[str, float, float] | None = None


def read_mimics(urdf: Path | str | None) -> dict[str, tuple[str, float, float]]:
    """``{joint: (driving joint, multiplier, offset)}`` from a URDF's ``<mimic>`` tags."""
    if urdf is None or not Path(urdf).is_file():
        return {}
    try:
        root = ET.parse(urdf).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"malformed URDF ({exc})", path=Path(urdf)) from None
    out = {}
    for joint in root.iter("joint"):
        mimic = joint.find("mimic")
        if mimic is not None and joint.get("name"):
            out[str(joint.get("name"))] = (str(mimic.get("joint")),
                                           float(mimic.get("multiplier", 1.0)),
                                           float(mimic.get("offset", 0.0)))
    return out


def lock_joints(model: pin.Model, geoms: Sequence[pin.GeometryModel], arm_joints: Sequence[str],
                values: Mapping[str, Any] | None, *, mimics: Mapping[str, tuple[str, float, float]],
                path: Path | None = None, key: str = "locked_joints",
                ) -> tuple[pin.Model, list[pin.GeometryModel], tuple[LockedJoint, ...]]:
    """Reduce ``model`` to ``arm_joints``, holding every other joint as the user says.

    Args:
        model: The full model (every URDF joint movable).
        geoms: Geometry models of ``model`` (collision first); the first gets travel shapes.
        arm_joints: Joints kept movable.
        values: ``{joint: value [rad or m] or "travel"}`` for driving locked joints; a
            joint that is not given covers its travel. Mimic joints follow their driver.
        mimics: The URDF's mimic relations (:func:`read_mimics`).
        path: File named in errors.
        key: Key named in errors.

    Raises:
        ConfigError: An unknown joint, a mimic or arm joint given a value, a value that
            is not a number or ``"travel"``, or one outside the joint's limits.
    """
    names = list(model.names[1:])
    locked_names = [n for n in names if n not in set(arm_joints)]
    given = dict(values or {})
    for name, raw in given.items():
        if name not in names:
            raise ConfigError(f"no joint {name!r}; locked joints: {locked_names}", path=path,
                              key=f"{key}.{name}")
        if name in arm_joints:
            raise ConfigError(f"{name} is planned, not locked", path=path, key=f"{key}.{name}")
        if name in mimics:
            raise ConfigError(f"{name} follows {mimics[name][0]} (URDF mimic): set that joint",
                              path=path, key=f"{key}.{name}")
        if raw != TRAVEL and (isinstance(raw, bool) or not isinstance(raw, int | float)):
            raise ConfigError(f"expected a number or {TRAVEL!r}, got {raw!r}", path=path,
                              key=f"{key}.{name}")
    q = pin.neutral(model)
    travel: list[str] = []
    locked: list[LockedJoint] = []
    for name in locked_names:
        jid = model.getJointId(name)
        if model.joints[jid].nq != 1:
            raise ConfigError(f"{name} is not a 1-DoF joint and cannot be locked", path=path,
                              key=key)
        iq = model.joints[jid].idx_q
        lo, hi = float(model.lowerPositionLimit[iq]), float(model.upperPositionLimit[iq])
        follows = mimics.get(name)
        raw = given.get(follows[0] if follows else name, TRAVEL)
        if raw == TRAVEL:
            travel.append(name)
            locked.append(LockedJoint(name, None, lo, hi, follows))
            q[iq] = 0.5 * (lo + hi)
            continue
        value = float(raw) * follows[1] + follows[2] if follows else float(raw)
        if not math.isfinite(value) or not lo - 1e-12 <= value <= hi + 1e-12:
            raise ConfigError(f"{name} = {value:g} is outside its limits [{lo:g}, {hi:g}]",
                              path=path, key=f"{key}.{follows[0] if follows else name}")
        q[iq] = value
        locked.append(LockedJoint(name, value, lo, hi, follows))
    if not locked:
        return model, list(geoms), ()
    geoms = list(geoms)
    if travel:
        _cover_travel(model, geoms[0], q, travel, mimics)
    reduced, reduced_geoms = _reduce(model, geoms, locked_names, q, path=path, key=key)
    return reduced, reduced_geoms, tuple(locked)


def _reduce(model: pin.Model, geoms: Sequence[pin.GeometryModel], locked: Sequence[str],
            q: np.ndarray, *, path: Path | None, key: str
            ) -> tuple[pin.Model, list[pin.GeometryModel]]:
    """Pinocchio's reduced model with ``locked`` held at ``q``; its errors re-raised."""
    try:
        reduced, reduced_geoms = pin.buildReducedModel(
            model, list(geoms), [model.getJointId(n) for n in locked], q)
    except (ValueError, RuntimeError) as exc:  # Pinocchio's, e.g. a link named as a joint
        raise ConfigError(f"Pinocchio cannot lock joints {list(locked)} "
                          f"({str(exc).splitlines()[0]})", path=path, key=key) from None
    return reduced, list(reduced_geoms)


def _cover_travel(model: pin.Model, geom: pin.GeometryModel, q: np.ndarray,
                  travel: Sequence[str], mimics: Mapping[str, tuple[str, float, float]]) -> None:
    """Replace the shapes moved by ``travel`` joints by hulls over their whole travel."""
    import coal

    ids = {n: model.getJointId(n) for n in travel}
    data = model.createData()
    for gi, g in enumerate(geom.geometryObjects):
        movers = [n for n in travel if _is_ancestor(model, ids[n], g.parentJoint)]
        if not movers:
            continue
        drivers = {mimics[n][0] if n in mimics else n for n in movers}
        if len(drivers) > 1:
            raise ConfigError(f"link {model.frames[g.parentFrame].name} is moved by independent "
                              f"locked joints {sorted(drivers)}: give their values",
                              key="locked_joints")
        driver = drivers.pop()
        djoint = model.joints[model.getJointId(driver)]
        dlo = float(model.lowerPositionLimit[djoint.idx_q])
        dhi = float(model.upperPositionLimit[djoint.idx_q])
        # The first unmoved ancestor of the shape: its frame stays put while the joints move.
        anchor = g.parentJoint
        while any(_is_ancestor(model, ids[n], anchor) for n in movers):
            anchor = model.parents[anchor]
        local = _enclosing_points(g.geometry)

        def cloud(s: np.ndarray, g: Any = g, anchor: int = anchor, local: np.ndarray = local,
                  movers: list[str] = movers, dlo: float = dlo, dhi: float = dhi) -> np.ndarray:
            out = []
            for fraction in s:
                qq = q.copy()
                value = dlo + fraction * (dhi - dlo)
                for name in movers:
                    m = mimics.get(name)
                    qq[model.joints[ids[name]].idx_q] = value * m[1] + m[2] if m else value
                pin.forwardKinematics(model, data, qq)
                T = data.oMi[anchor].actInv(data.oMi[g.parentJoint]) * g.placement
                out.append(local @ T.rotation.T + T.translation)
            return np.asarray(out)  # (samples, points, 3)

        fine = cloud(np.linspace(0.0, 1.0, 4 * (TRAVEL_SAMPLES - 1) + 1))
        second = float(np.linalg.norm(fine[2:] - 2 * fine[1:-1] + fine[:-2], axis=2).max())
        # |p''| <= second / h_f^2 (h_f: fine step); a chord of the coarse grid (h = 4 h_f)
        # stays within |p''| h^2 / 8 = 2 second of the curve; doubled for safety.
        margin = 4.0 * second + 1e-6
        pts = fine[::4].reshape(-1, 3)
        cube = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        grown = (pts[:, None, :] + margin * cube[None, :, :]).reshape(-1, 3)
        from scipy.spatial import ConvexHull

        points = coal.StdVec_Vec3s()
        for point in grown[ConvexHull(grown).vertices]:
            points.append(point)
        shape = coal.Convex.convexHull(points, False, "")
        new = pin.GeometryObject(g.name, anchor, g.parentFrame, pin.SE3.Identity(), shape)
        new.meshColor = g.meshColor
        geom.geometryObjects[gi] = new


def _is_ancestor(model: pin.Model, a: int, j: int) -> bool:
    while j > 0:
        if j == a:
            return True
        j = model.parents[j]
    return False


def _enclosing_points(shape: Any) -> np.ndarray:
    """Points whose hull encloses ``shape`` (in the shape's frame): a kind of the shape
    table says which; a hull's or mesh's own points."""
    import coal

    primitive = from_coal(shape)
    if primitive is not None:
        kind, half = primitive
        return kind.enclosing_points(half)
    if isinstance(shape, coal.ConvexBase):
        return np.asarray(shape.points(), dtype=float)
    if isinstance(shape, coal.BVHModelBase):
        return np.asarray(shape.vertices(), dtype=float)
    raise ConfigError(f"cannot cover the travel of a {type(shape).__name__} shape")
