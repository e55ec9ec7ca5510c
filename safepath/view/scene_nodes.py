"""Drawing a cell in a viser scene: the robot's geometry, the cell's objects, the
taught poses as TCP frames, and planned TCP paths coloured by clearance.

One scene node per geometry: each is placed in the world frame from Pinocchio's
forward kinematics, so a frame of the review costs one position and one orientation
update per geometry (sent together inside ``server.atomic()`` by the caller).
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pinocchio as pin
import viser

from ..model.robot import Robot
from ..model.scene import Scene
from ..model.shapes import SHAPES, from_coal
from .analysis import GREEN, RED, YELLOW

__all__ = ["Rgb", "Scope", "RobotStyle", "HIGHLIGHT", "LEVEL_COLORS", "ShapeNode",
           "RobotNodes", "CellNodes", "PoseFrames", "draw_path", "pose_of",
           "configure_lighting"]

log = logging.getLogger(__name__)

Rgb = tuple[int, int, int]
#: Where nodes are added: the server (every page) or one client (that page only; a
#: client's node shadows the server's node of the same name).
Scope = viser.ViserServer | viser.ClientHandle
RobotStyle = Literal["collision", "visual"]

#: Colour of geometry in collision.
HIGHLIGHT: Rgb = (235, 20, 20)
#: Path colours by safety level.
LEVEL_COLORS: dict[int, Rgb] = {GREEN: (40, 180, 60), YELLOW: (240, 190, 20), RED: (230, 30, 30)}
# One colour per link in the collision style (cycled); none of them is red.
_LINK_PALETTE: tuple[Rgb, ...] = (
    (90, 110, 140), (70, 140, 200), (110, 180, 230), (60, 160, 150), (120, 200, 170),
    (150, 130, 210), (190, 160, 230), (100, 100, 110), (200, 200, 120), (170, 120, 60),
)


def configure_lighting(server: viser.ViserServer) -> None:
    """Plain lights instead of viser's HDR environment map.

    Pre-filtering the environment map takes seconds in a browser without a GPU
    (software WebGL: remote desktops, CI), before the first frame; a hemisphere light
    lights flat-shaded primitives as well.
    """
    server.scene.configure_environment_map(None)
    server.scene.add_light_hemisphere("/lights/sky", sky_color=(255, 255, 255),
                                      ground_color=(120, 120, 130), intensity=2.0,
                                      position=(0.0, 0.0, 1.0))


def pose_of(T: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(wxyz, position)`` of a 4x4 transform or ``pin.SE3`` (viser's convention)."""
    if isinstance(T, pin.SE3):
        R, p = T.rotation, T.translation
    else:
        T = np.asarray(T, dtype=float)
        R, p = T[:3, :3], T[:3, 3]
    x, y, z, w = pin.Quaternion(np.asarray(R)).coeffs()
    return np.array([w, x, y, z]), np.array(p, dtype=float)


def _to_rgb(color: Iterable[float]) -> Rgb:
    c = [float(v) for v in color][:3]
    return (int(round(255 * c[0])), int(round(255 * c[1])), int(round(255 * c[2])))


@dataclass
class ShapeNode:
    """One drawn shape: the node that is placed and coloured.

    Attributes:
        name: The thing it draws (link or object name).
        root: Its scene node (a triangle mesh).
        color: Normal colour.
    """

    name: str
    root: Any
    color: Rgb
    _shown: Rgb | None = None

    def place(self, T: Any) -> None:
        """Put the shape at ``T`` (world frame)."""
        wxyz, position = pose_of(T)
        self.root.wxyz = wxyz
        self.root.position = position

    @property
    def shown_color(self) -> Rgb | None:
        """The colour the shape is painted now (None: never painted)."""
        return self._shown

    def paint(self, color: Rgb) -> None:
        """Colour the shape (no message when unchanged)."""
        if color != self._shown:
            self.root.color = color
            self._shown = color


def add_shape(server: Scope, path: str, name: str, kind: str,
              size: tuple[float, ...], color: Rgb, *, opacity: float | None = None
              ) -> ShapeNode | None:
    """Add a shape of the shape table (``kind``, ``size`` [m] as in
    :class:`~safepath.model.scene.Shape`), centred on its frame, as the triangle mesh of
    its table row.

    Returns None for a kind the table does not have.
    """
    row = SHAPES.get(kind)
    if row is None:
        return None
    vertices, faces = row.mesh(row.half(size))
    return add_mesh(server, path, name, vertices, faces, color, opacity=opacity)


#: Meshes with more triangles than this are not drawn (a visual model's meshes can have
#: hundreds of thousands; the collision model's convex hulls have hundreds).
MAX_MESH_TRIANGLES = 50_000


def add_mesh(server: Scope, path: str, name: str, vertices: np.ndarray, faces: np.ndarray,
             color: Rgb, *, opacity: float | None = None) -> ShapeNode:
    """Add a triangle mesh (vertices [m] in its frame, faces as vertex indices)."""
    node = server.scene.add_mesh_simple(path, vertices=np.asarray(vertices, dtype=np.float32),
                                        faces=np.asarray(faces, dtype=np.int32), color=color,
                                        opacity=opacity)
    return ShapeNode(name, node, color, color)


def coal_mesh(geometry: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``(vertices [m], faces)`` of a coal convex hull or triangle mesh (the meshes of
    example-robot-data's arms), or None for anything else or a mesh too big to draw."""
    import coal

    if isinstance(geometry, coal.Convex):
        count, vertices, face = geometry.num_polygons, geometry.points(), geometry.polygons
    elif isinstance(geometry, coal.BVHModelBase):
        count, vertices, face = geometry.num_tris, geometry.vertices(), geometry.tri_indices
    elif isinstance(geometry, coal.ConvexBase):
        return _hull_mesh(np.asarray(geometry.points(), dtype=float).reshape(-1, 3))
    else:
        return None
    if not 0 < count <= MAX_MESH_TRIANGLES:
        return None
    faces = np.array([[face(i)[k] for k in range(3)] for i in range(count)], dtype=np.int32)
    return np.asarray(vertices, dtype=np.float32), faces


def _hull_mesh(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of a ``coal.ConvexBase`` that keeps only its points (the
    fingers' whole-travel hulls of :mod:`safepath.model._locked`): every point a vertex, the
    faces the triangles of the points' convex hull, turned outwards."""
    from scipy.spatial import ConvexHull

    faces = np.asarray(ConvexHull(points).simplices, dtype=np.int32)
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - points.mean(axis=0)) < 0
    faces[inward] = faces[inward][:, ::-1]
    return points.astype(np.float32), faces


def coal_shape(geometry: Any) -> tuple[str, tuple[float, ...]] | None:
    """``(kind, size)`` of a coal primitive (see :class:`~safepath.model.scene.Shape`)."""
    primitive = from_coal(geometry)
    if primitive is None:
        return None
    kind, half = primitive
    return kind.name, kind.size(half)


class RobotNodes:
    """The robot's geometry, one node per geometry object, in two styles.

    ``collision``: the collision model, one colour per link. ``visual``: the URDF's
    visual model with its materials. Only the shown style is updated.
    """

    def __init__(self, server: Scope, robot: Robot, *, prefix: str = "/robot",
                 style: RobotStyle = "collision") -> None:
        self.robot = robot
        self._data = robot.model.createData()
        self._q: np.ndarray | None = None
        self._visible = True
        # Per style: the geometry model, its data, the drawn nodes and their indices.
        self._sets: dict[str, tuple[pin.GeometryModel, pin.GeometryData, list[ShapeNode],
                                    list[int]]] = {}
        links = list(robot.link_names)
        palette = {link: _LINK_PALETTE[i % len(_LINK_PALETTE)] for i, link in enumerate(links)}
        models: dict[str, pin.GeometryModel | None] = {
            "collision": robot.collision_model, "visual": robot.visual_model}
        for which, gmodel in models.items():
            if gmodel is None:
                continue
            nodes: list[ShapeNode] = []
            indices: list[int] = []
            for i, geom in enumerate(gmodel.geometryObjects):
                link = str(robot.model.frames[geom.parentFrame].name)
                color = (palette.get(link, _LINK_PALETTE[0]) if which == "collision"
                         else _to_rgb(geom.meshColor))
                path = f"{prefix}/{which}/{i:02d}_{geom.name}"
                shape = coal_shape(geom.geometry)
                mesh = coal_mesh(geom.geometry) if shape is None else None
                if shape is not None:
                    node = add_shape(server, path, link, shape[0], shape[1], color)
                elif mesh is not None:
                    node = add_mesh(server, path, link, mesh[0], mesh[1], color)
                else:
                    log.warning("%s geometry %s: shape %s not drawn", which, geom.name,
                                type(geom.geometry).__name__)
                    continue
                if node is not None:
                    node.root.visible = which == style
                    nodes.append(node)
                    indices.append(i)
            self._sets[which] = (gmodel, pin.GeometryData(gmodel), nodes, indices)
        self.style: RobotStyle = style if style in self._sets else "collision"
        self._highlighted: frozenset[str] = frozenset()

    @property
    def nodes(self) -> list[ShapeNode]:
        """Nodes of the shown style."""
        return self._sets[self.style][2]

    def all_nodes(self) -> list[ShapeNode]:
        """Nodes of every style."""
        return [node for _, _, nodes, _ in self._sets.values() for node in nodes]

    def update(self, q: np.ndarray) -> None:
        """Place the shown style's geometry at joint vector ``q`` [rad]."""
        self._q = np.array(q, dtype=float)
        gmodel, gdata, nodes, indices = self._sets[self.style]
        pin.forwardKinematics(self.robot.model, self._data, self._q)
        pin.updateGeometryPlacements(self.robot.model, self._data, gmodel, gdata)
        for node, i in zip(nodes, indices, strict=True):
            node.place(gdata.oMg[i])

    def highlight(self, links: Collection[str]) -> None:
        """Colour the geometry of ``links`` red, the rest in its own colour."""
        self._highlighted = frozenset(links)
        for node in self.nodes:
            node.paint(HIGHLIGHT if node.name in self._highlighted else node.color)

    def set_style(self, style: RobotStyle) -> None:
        """Show the ``collision`` or ``visual`` geometry."""
        if style not in self._sets or style == self.style:
            return
        for node in self.nodes:
            node.root.visible = False
        self.style = style
        for node in self.nodes:
            node.root.visible = self._visible
        if self._q is not None:
            self.update(self._q)
        self.highlight(self._highlighted)

    def set_visible(self, visible: bool) -> None:
        """Show or hide the robot."""
        self._visible = visible
        for node in self.nodes:
            node.root.visible = visible


class CellNodes:
    """The cell's objects; movable ones are placed by :meth:`place`."""

    def __init__(self, server: Scope, scene: Scene, *, prefix: str = "/cell"
                 ) -> None:
        self.nodes: dict[str, ShapeNode] = {}
        for obj in scene.objects.values():
            node = add_shape(server, f"{prefix}/{obj.name}", obj.name, obj.shape.kind,
                             obj.shape.size, _to_rgb(obj.color))
            if node is None:  # pragma: no cover - the scene only has drawable kinds
                continue
            node.place(obj.T_world_object)
            self.nodes[obj.name] = node

    def place(self, name: str, T_world_object: np.ndarray | None) -> None:
        """Put a movable object at ``T_world_object``; None hides it."""
        node = self.nodes[name]
        node.root.visible = T_world_object is not None
        if T_world_object is not None:
            node.place(T_world_object)

    def highlight(self, names: Collection[str]) -> None:
        """Colour the objects ``names`` red, the rest in their own colour."""
        for name, node in self.nodes.items():
            node.paint(HIGHLIGHT if name in names else node.color)


class PoseFrames:
    """Every taught pose as a labelled TCP frame."""

    def __init__(self, server: Scope, robot: Robot,
                 poses: Mapping[str, np.ndarray], *, prefix: str = "/poses") -> None:
        self._server = server
        self._robot = robot
        self._prefix = prefix
        self.frames: dict[str, Any] = {}
        self._visible = True
        for name, q in poses.items():
            self.set(name, q)

    def set(self, name: str, q: np.ndarray) -> None:
        """Show pose ``name`` at joint vector ``q`` [rad]."""
        wxyz, position = pose_of(self._robot.frame_pose(np.asarray(q, dtype=float)))
        frame = self.frames.get(name)
        if frame is None:
            frame = self._server.scene.add_frame(
                f"{self._prefix}/{name}", axes_length=0.04, axes_radius=0.002,
                origin_radius=0.005, wxyz=wxyz, position=position, visible=self._visible)
            self._server.scene.add_label(f"{self._prefix}/{name}/label", name,
                                         position=(0.0, 0.0, 0.0), anchor="bottom-left")
            self.frames[name] = frame
        else:
            frame.wxyz = wxyz
            frame.position = position

    def remove(self, name: str) -> None:
        """Remove the frame of pose ``name`` (a page's own: the shared one shows again)."""
        frame = self.frames.pop(name, None)
        if frame is not None:
            frame.remove()

    def set_visible(self, visible: bool) -> None:
        """Show or hide the frames."""
        self._visible = visible
        for frame in self.frames.values():
            frame.visible = visible


def draw_path(server: viser.ViserServer, path: str, tcp: np.ndarray, level: np.ndarray, *,
              visible: bool = True) -> Any:
    """Draw a TCP polyline, each segment coloured by the worse level of its ends."""
    tcp = np.asarray(tcp, dtype=float)
    if tcp.shape[0] < 2:
        tcp = np.vstack([tcp, tcp])
        level = np.concatenate([level, level])
    points = np.stack([tcp[:-1], tcp[1:]], axis=1)
    seg_level = np.maximum(level[:-1], level[1:])
    table = np.array([LEVEL_COLORS[k] for k in (GREEN, YELLOW, RED)], dtype=np.uint8)
    colors = np.repeat(table[seg_level][:, None, :], 2, axis=1)
    return server.scene.add_line_segments(path, points, colors, thickness=3.0,
                                          thickness_units="screen", visible=visible)


#: Direction from the cell's centre to the first view's camera (front right, above).
VIEW_DIRECTION = np.array([0.48, -0.74, 0.6]) / np.linalg.norm([0.48, -0.74, 0.6])


def cell_framing(cell: Any) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The first view's camera position and look-at point [m]: the box holding every
    frame of the robot at each taught pose and every scene object within the robot's
    reach (a table larger than the reach is cut to it), seen from
    :data:`VIEW_DIRECTION` at a distance that fits it."""
    robot = cell.robot
    data = robot.model.createData()
    frames = []
    for q in [*cell.poses.values(), np.clip(np.zeros(robot.dof), robot.lower, robot.upper)]:
        pin.framesForwardKinematics(robot.model, data, np.asarray(q, dtype=float))
        frames.append(np.array([f.translation for f in data.oMf]))
    points = np.vstack(frames)
    base = points[0]  # the universe frame: where the robot stands
    reach = float(np.linalg.norm(points - base, axis=1).max()) + 0.1
    lo, hi = points.min(axis=0), points.max(axis=0)
    for obj in cell.scene.objects.values():
        c, r = obj.T_world_object[:3, 3], obj.shape.bounding_radius()
        o_lo, o_hi = np.maximum(c - r, base - reach), np.minimum(c + r, base + reach)
        if np.all(o_lo <= o_hi):
            lo, hi = np.minimum(lo, o_lo), np.maximum(hi, o_hi)
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 0.2)
    eye = center + VIEW_DIRECTION * 1.5 * radius
    return (tuple(float(v) for v in eye),  # type: ignore[return-value]
            tuple(float(v) for v in center))
