"""Worlds for the ChefBot simulator: our YAML format, Gazebo SDF import, table poses.

Pure Python (numpy + PyYAML), no pybullet and no ROS: the simulator facade,
the map rasteriser, the demo, the GUI and the tests all read worlds through
this module.

Units: metres, radians.  The world frame is the ``map`` frame of the demo.

Our YAML format (see the package README for the full description)::

    name: hotel
    objects:
      - {name: wall_n, shape: box, size: [15.4, 0.2, 1.0], pose: [4.5, 6.1, 0.0]}
      - {name: pillar, shape: cylinder, radius: 0.2, height: 1.0, pose: [4.5, 4.5]}
      - {name: ball, shape: sphere, radius: 0.15, pose: [3, 0, 0.75, 0], colour: [1, 0, 0]}

``pose`` is ``[x, y]``, ``[x, y, yaw]`` or ``[x, y, z, yaw]`` where ``z`` is the
height of the object's *bottom* above the floor (default 0: standing on the
floor).  Internally every :class:`Shape` stores its *centre* and roll/pitch/yaw,
which is also what SDF import produces.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from chefbot_description.model import rpy_matrix  # URDF/SDF fixed-axis convention, one implementation

SHAPES = ("box", "cylinder", "sphere")
DEFAULT_COLOUR = (0.75, 0.75, 0.75, 1.0)
# SDF models that stand for the floor and the light; the simulator has its own floor.
IGNORED_SDF_MODELS = ("ground_plane", "sun")


class WorldError(ValueError):
    """A world file is invalid; the message names the file and the element."""


@dataclass(frozen=True)
class Shape:
    """One static primitive obstacle.

    ``size`` is ``(sx, sy, sz)`` full extents for a box, ``(radius, height)`` for a
    cylinder (axis along the shape's z), ``(radius,)`` for a sphere; metres.
    ``position`` is the centre (m) and ``rpy`` the orientation (rad) in the world frame.
    """

    name: str
    kind: str
    size: tuple[float, ...]
    position: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    colour: tuple[float, float, float, float] = DEFAULT_COLOUR

    @property
    def yaw(self) -> float:
        """Heading (rad) of the shape about z."""
        return self.rpy[2]

    def rotation(self) -> np.ndarray:
        """3×3 rotation matrix from shape frame to world frame."""
        return rpy_matrix(*self.rpy)

    def half_extents(self) -> np.ndarray:
        """Half extents of the shape's own bounding box in its frame (m)."""
        if self.kind == "box":
            return np.asarray(self.size, float) / 2.0
        if self.kind == "cylinder":
            r, h = self.size
            return np.array([r, r, h / 2.0])
        r = self.size[0]
        return np.array([r, r, r])

    def z_range(self) -> tuple[float, float]:
        """Lowest and highest world z (m) of the shape's oriented bounding box."""
        ext = np.abs(self.rotation()) @ self.half_extents()
        return self.position[2] - ext[2], self.position[2] + ext[2]

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounding box (min xyz, max xyz), m."""
        ext = np.abs(self.rotation()) @ self.half_extents()
        c = np.asarray(self.position, float)
        return c - ext, c + ext

    def contains(self, points: np.ndarray, grow_xy: float = 0.0) -> np.ndarray:
        """Which of the world points ``(N, 3)`` lie inside the shape.

        ``grow_xy`` enlarges the shape by that many metres in its own x and y
        (used by the rasteriser to count a cell touched by an edge as occupied).
        """
        local = (np.asarray(points, float) - np.asarray(self.position)) @ self.rotation()
        if self.kind == "box":
            half = np.asarray(self.size, float) / 2.0 + np.array([grow_xy, grow_xy, 0.0])
            return np.all(np.abs(local) <= half, axis=1)
        if self.kind == "cylinder":
            r, h = self.size
            radial = np.hypot(local[:, 0], local[:, 1])
            return (radial <= r + grow_xy) & (np.abs(local[:, 2]) <= h / 2.0)
        r = self.size[0]
        return np.linalg.norm(local, axis=1) <= r + grow_xy

    def distance_xy(self, x: float, y: float) -> float:
        """Horizontal distance (m) from the point to the shape's footprint (0 inside).

        Boxes and cylinders are taken as upright prisms (roll = pitch = 0), which
        holds for every shape our worlds and the book's hotel contain.
        """
        dx, dy = x - self.position[0], y - self.position[1]
        if self.kind == "box":
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            lx, ly = c * dx + s * dy, -s * dx + c * dy
            qx = max(abs(lx) - self.size[0] / 2.0, 0.0)
            qy = max(abs(ly) - self.size[1] / 2.0, 0.0)
            return math.hypot(qx, qy)
        return max(math.hypot(dx, dy) - self.size[0], 0.0)


@dataclass
class World:
    """A set of static shapes; ``source`` is the file it came from (for messages)."""

    name: str
    shapes: list[Shape] = field(default_factory=list)
    source: str = "<memory>"

    def shape(self, name: str) -> Shape:
        """The shape named ``name`` (KeyError if none)."""
        for s in self.shapes:
            if s.name == name:
                return s
        raise KeyError(name)

    def shapes_in_band(self, z_low: float, z_high: float) -> list[Shape]:
        """Shapes whose vertical extent overlaps ``[z_low, z_high]`` (m)."""
        out = []
        for s in self.shapes:
            lo, hi = s.z_range()
            if hi >= z_low and lo <= z_high:
                out.append(s)
        return out

    def clearance(self, x: float, y: float, z_low: float = 0.02, z_high: float = 1.0) -> float:
        """Horizontal distance (m) from (x, y) to the nearest shape in the height band."""
        d = [s.distance_xy(x, y) for s in self.shapes_in_band(z_low, z_high)]
        return min(d) if d else math.inf

    def surface_height(self, x: float, y: float) -> float:
        """Height (m) of the surface at (x, y) a robot spawned there stands on (see :func:`surface_height`)."""
        return surface_height(self.shapes, x, y)

    def bounds_xy(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all shapes, m; zeros for an empty world."""
        if not self.shapes:
            return 0.0, 0.0, 0.0, 0.0
        lo = np.min([s.aabb()[0] for s in self.shapes], axis=0)
        hi = np.max([s.aabb()[1] for s in self.shapes], axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


STEP_TOLERANCE = 0.01  # m: a shape whose bottom is this close to a surface stands on it


def surface_height(shapes: list[Shape], x: float, y: float) -> float:
    """Height (m) of what a robot placed at (x, y) stands on: the floor (0) or the top
    of the shapes under that point that rest on it, stacked (a stage, a box on a stage).

    A shape counts when its footprint contains (x, y) and its bottom is within
    :data:`STEP_TOLERANCE` of the surface found so far, so an overhang (a shelf
    whose bottom is above the surface) does not lift the robot onto its top.
    Footprints are taken as upright prisms (see :meth:`Shape.distance_xy`).
    """
    under = sorted((s.z_range() for s in shapes if s.distance_xy(x, y) <= 0.0), key=lambda r: r[0])
    surface = 0.0
    for lo, hi in under:   # by bottom height: each one can only rest on those before it
        if lo <= surface + STEP_TOLERANCE:
            surface = max(surface, hi)
    return surface


# ------------------------------------------------------------------ rotations
def matrix_to_rpy(m: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`rpy_matrix` (pitch in [-pi/2, pi/2])."""
    pitch = math.asin(max(-1.0, min(1.0, -m[2, 0])))
    if abs(m[2, 0]) < 1.0 - 1e-9:
        roll = math.atan2(m[2, 1], m[2, 2])
        yaw = math.atan2(m[1, 0], m[0, 0])
    else:  # gimbal lock: put everything into yaw
        roll = 0.0
        yaw = math.atan2(-m[0, 1], m[1, 1])
    return roll, pitch, yaw


# ------------------------------------------------------------------ loading
def load_world(path: str | Path) -> World:
    """Load a world from our YAML format (``.yaml``/``.yml``) or a Gazebo SDF
    world (``.world``/``.sdf``).  Raises :class:`WorldError` on any problem."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise WorldError(f"{path}: cannot read world file: {e.strerror}") from e
    if path.suffix.lower() in (".world", ".sdf", ".xml"):
        return parse_sdf(text, str(path))
    return parse_yaml_world(text, str(path))


def parse_yaml_world(text: str, source: str = "<string>") -> World:
    """Parse our YAML world format (see module docstring)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise WorldError(f"{source}: invalid YAML: {e}") from e
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise WorldError(f"{source}: top level must be a mapping with 'objects', got {type(data).__name__}")
    unknown = set(data) - {"name", "objects", "description"}
    if unknown:
        raise WorldError(f"{source}: unknown top-level key(s) {sorted(unknown)}")
    objects = data.get("objects") or []
    if not isinstance(objects, list):
        raise WorldError(f"{source}: 'objects' must be a list")
    world = World(name=str(data.get("name", Path(source).stem)), source=source)
    seen: set[str] = set()
    for i, obj in enumerate(objects):
        shape = parse_object(obj, f"{source}: objects[{i}]", default_name=f"object_{i}")
        if shape.name in seen:
            raise WorldError(f"{source}: objects[{i}]: duplicate name '{shape.name}'")
        seen.add(shape.name)
        world.shapes.append(shape)
    return world


_OBJECT_KEYS = {"name", "shape", "size", "radius", "height", "pose", "colour", "color"}


def parse_object(obj: Any, where: str, default_name: str = "object") -> Shape:
    """Parse one object mapping of our YAML format into a :class:`Shape`.

    ``where`` prefixes error messages (file and element).  Also used by the sim
    node's spawn topic, which takes one object in this format.
    """
    if not isinstance(obj, dict):
        raise WorldError(f"{where}: an object must be a mapping, got {obj!r}")
    name = str(obj.get("name", default_name))
    where = f"{where} ('{name}')"
    unknown = set(obj) - _OBJECT_KEYS
    if unknown:
        raise WorldError(f"{where}: unknown key(s) {sorted(unknown)}")
    if "shape" not in obj:
        raise WorldError(f"{where}: missing field 'shape' (one of {', '.join(SHAPES)})")
    kind = obj["shape"]
    if kind not in SHAPES:
        raise WorldError(f"{where}: unknown shape {kind!r} (expected one of {', '.join(SHAPES)})")
    if kind == "box":
        if "size" not in obj:
            raise WorldError(f"{where}: missing field 'size' ([x, y, z] in m)")
        size = _numbers(obj["size"], 3, 3, f"{where}: size")
        height = size[2]
    elif kind == "cylinder":
        size = (_positive(obj, "radius", where), _positive(obj, "height", where))
        height = size[1]
    else:
        size = (_positive(obj, "radius", where),)
        height = 2.0 * size[0]
    if any(v <= 0 for v in size):
        raise WorldError(f"{where}: sizes must be positive, got {list(size)}")
    if "pose" not in obj:
        raise WorldError(f"{where}: missing field 'pose' ([x, y], [x, y, yaw] or [x, y, z, yaw])")
    pose = _numbers(obj["pose"], 2, 4, f"{where}: pose")
    x, y = pose[0], pose[1]
    z_bottom, yaw = 0.0, 0.0
    if len(pose) == 3:
        yaw = pose[2]
    elif len(pose) == 4:
        z_bottom, yaw = pose[2], pose[3]
    colour = obj.get("colour", obj.get("color"))
    rgba = DEFAULT_COLOUR if colour is None else _colour(colour, f"{where}: colour")
    return Shape(name, kind, tuple(size), (x, y, z_bottom + height / 2.0), (0.0, 0.0, yaw), rgba)


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise WorldError(f"{where}: expected a number, got {v!r}")
    f = float(v)
    if not math.isfinite(f):
        raise WorldError(f"{where}: expected a finite number, got {v!r}")
    return f


def _numbers(v: Any, n_min: int, n_max: int, where: str) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or not n_min <= len(v) <= n_max:
        want = f"{n_min}" if n_min == n_max else f"{n_min} to {n_max}"
        raise WorldError(f"{where}: expected a list of {want} numbers, got {v!r}")
    return tuple(_number(x, where) for x in v)


def _positive(obj: dict, key: str, where: str) -> float:
    if key not in obj:
        raise WorldError(f"{where}: missing field '{key}' (m)")
    v = _number(obj[key], f"{where}: {key}")
    if v <= 0:
        raise WorldError(f"{where}: {key} must be positive, got {v}")
    return v


def _colour(v: Any, where: str) -> tuple[float, float, float, float]:
    c = _numbers(v, 3, 4, where)
    if any(x < 0 or x > 1 for x in c):
        raise WorldError(f"{where}: colour components must be in [0, 1], got {list(c)}")
    return (c[0], c[1], c[2], c[3] if len(c) == 4 else 1.0)


# ------------------------------------------------------------------ SDF import
def _floats(text: str | None, n: int, where: str) -> list[float]:
    parts = (text or "").split()
    if len(parts) != n:
        raise WorldError(f"{where}: expected {n} numbers, got {text!r}")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise WorldError(f"{where}: expected {n} numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in vals):
        raise WorldError(f"{where}: expected finite numbers, got {text!r}")
    return vals


def _sdf_pose(elem: ET.Element | None, where: str) -> np.ndarray:
    """4×4 transform of an SDF ``<pose>`` child of ``elem`` (identity if absent)."""
    t = np.eye(4)
    if elem is None:
        return t
    p = elem.find("pose")
    if p is None:
        return t
    x, y, z, r, pi, ya = _floats(p.text, 6, f"{where}/pose")
    t[:3, :3] = rpy_matrix(r, pi, ya)
    t[:3, 3] = (x, y, z)
    return t


def _sdf_colour(link: ET.Element) -> tuple[float, float, float, float]:
    for tag in ("visual/material/diffuse", "visual/material/ambient"):
        e = link.find(tag)
        if e is not None and e.text:
            try:
                vals = [float(v) for v in e.text.split()]
            except ValueError:
                continue
            if len(vals) in (3, 4):
                vals = [min(max(v, 0.0), 1.0) for v in vals]
                return (vals[0], vals[1], vals[2], vals[3] if len(vals) == 4 else 1.0)
    return DEFAULT_COLOUR


def parse_sdf(text: str, source: str = "<string>") -> World:
    """Import a Gazebo SDF world made of primitive shapes.

    Every ``<collision>`` with a box, cylinder or sphere geometry becomes a static
    :class:`Shape`; planes and the ``ground_plane``/``sun`` models are skipped
    (the simulator has its own floor).  A ``<state>`` block, as Gazebo writes it
    on save, overrides model poses, gives the model ``<scale>`` (applied to the
    geometry and to link/collision offsets in the model frame) and the links'
    world poses.  All models are treated as static.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise WorldError(f"{source}: invalid XML: {e}") from e
    world_el = root if root.tag == "world" else root.find("world")
    if world_el is None:
        raise WorldError(f"{source}: no <world> element")
    wname = world_el.get("name", Path(source).stem)
    state_models: dict[str, ET.Element] = {}
    for state in world_el.findall("state"):
        for m in state.findall("model"):
            state_models[m.get("name", "")] = m
    world = World(name=wname, source=source)
    for inc in world_el.findall("include"):
        uri = (inc.findtext("uri") or "").strip()
        if not any(uri.endswith(n) for n in IGNORED_SDF_MODELS):
            raise WorldError(f"{source}: <include> of '{uri}': only primitive-shape models "
                             "written inline are supported (ground_plane and sun are ignored)")
    names: set[str] = set()
    for model in world_el.findall("model"):
        mname = model.get("name")
        if not mname:
            raise WorldError(f"{source}: <model> without a name attribute")
        if mname in IGNORED_SDF_MODELS:
            continue
        where = f"{source}: model '{mname}'"
        st = state_models.get(mname)
        model_tf = _sdf_pose(st if st is not None and st.find("pose") is not None else model, where)
        scale = np.ones(3)
        if st is not None and st.find("scale") is not None:
            scale = np.array(_floats(st.findtext("scale"), 3, f"{where}/state/scale"))
            if np.any(scale <= 0):
                raise WorldError(f"{where}/state/scale: scale must be positive, got {scale.tolist()}")
        links = model.findall("link")
        if model.find("model") is not None:
            raise WorldError(f"{where}: nested models are not supported")
        for link in links:
            lname = link.get("name", "link")
            lwhere = f"{where} / link '{lname}'"
            st_link = st.find(f"link[@name='{lname}']") if st is not None else None
            if st_link is not None and st_link.find("pose") is not None:
                # Gazebo's <state> gives link poses in the world frame
                link_tf = _sdf_pose(st_link, lwhere + " (state)")
            else:
                rel = _sdf_pose(link, lwhere)
                rel[:3, 3] *= scale
                link_tf = model_tf @ rel
            colour = _sdf_colour(link)
            for k, col in enumerate(link.findall("collision")):
                cname = col.get("name", f"collision_{k}")
                cwhere = f"{lwhere} / collision '{cname}'"
                rel = _sdf_pose(col, cwhere)
                rel[:3, 3] *= scale
                tf = link_tf @ rel
                shape = _sdf_geometry(col.find("geometry"), scale, cwhere)
                if shape is None:
                    continue
                kind, size = shape
                sname = mname if len(links) == 1 and len(link.findall("collision")) == 1 \
                    else f"{mname}/{lname}/{cname}"
                if sname in names:
                    raise WorldError(f"{cwhere}: duplicate name '{sname}'")
                names.add(sname)
                world.shapes.append(Shape(sname, kind, size, tuple(float(v) for v in tf[:3, 3]),
                                          matrix_to_rpy(tf[:3, :3]), colour))
    return world


def _sdf_geometry(geom: ET.Element | None, scale: np.ndarray, where: str) -> tuple[str, tuple] | None:
    if geom is None or len(geom) == 0:
        raise WorldError(f"{where}: missing <geometry>")
    g = geom[0]
    gw = f"{where} / geometry <{g.tag}>"
    if g.tag == "plane":
        return None
    if g.tag == "box":
        size = np.array(_floats(g.findtext("size"), 3, f"{gw}/size")) * scale
        if np.any(size <= 0):
            raise WorldError(f"{gw}: size must be positive, got {size.tolist()}")
        return "box", tuple(float(v) for v in size)
    if g.tag == "cylinder":
        r = _floats(g.findtext("radius"), 1, f"{gw}/radius")[0] * max(scale[0], scale[1])
        h = _floats(g.findtext("length"), 1, f"{gw}/length")[0] * scale[2]
        if r <= 0 or h <= 0:
            raise WorldError(f"{gw}: radius and length must be positive, got {r}, {h}")
        return "cylinder", (float(r), float(h))
    if g.tag == "sphere":
        r = _floats(g.findtext("radius"), 1, f"{gw}/radius")[0] * float(np.max(scale))
        if r <= 0:
            raise WorldError(f"{gw}: radius must be positive, got {r}")
        return "sphere", (float(r),)
    raise WorldError(f"{gw}: unsupported geometry (only box, cylinder, sphere, plane)")
