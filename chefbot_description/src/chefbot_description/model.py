"""Read the ChefBot URDF: links, joints, frame poses and the simulation block.

Pure Python (``xml.etree`` + numpy), no rospy: the simulator, the tests and
tools import this module to get the robot's geometry from the *generated*
URDF (the string on ``robot_description``) instead of re-typing constants.

Units everywhere are SI: metres, kilograms, seconds, radians, hertz,
newton-metres.

Typical use::

    xml = expand_xacro()                      # or rospy.get_param("robot_description")
    robot = parse_urdf(xml)
    wheels = wheel_geometry(robot)            # radius 0.045, separation 0.30
    sim = load_sim_params(xml)                # the <chefbot_sim> block
    pose = frame_transform(robot, "camera_depth_optical_frame")  # 4x4 in base_footprint
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PACKAGE_NAME = "chefbot_description"
SIM_ELEMENT = "chefbot_sim"
SIM_VERSION = "1"

# The frame tree contract (ARCHITECTURE.md): child frame -> parent frame.
FRAME_TREE: Mapping[str, str] = {
    "base_link": "base_footprint",
    "wheel_left_link": "base_link",
    "wheel_right_link": "base_link",
    "caster_front_link": "base_link",
    "caster_back_link": "base_link",
    "plate_bottom_link": "base_link",
    "plate_middle_link": "base_link",
    "plate_top_link": "base_link",
    "camera_link": "base_link",
    "camera_depth_frame": "camera_link",
    "camera_depth_optical_frame": "camera_depth_frame",
    "camera_rgb_frame": "camera_link",
    "camera_rgb_optical_frame": "camera_rgb_frame",
    "gyro_link": "base_link",
    "ultrasonic_link": "base_link",
    "cliff_left_link": "base_link",
    "cliff_front_link": "base_link",
    "cliff_right_link": "base_link",
}
# Frames that are pure coordinate frames (no body, no inertial).
VIRTUAL_FRAMES = frozenset({"base_footprint", "camera_depth_frame", "camera_depth_optical_frame",
                            "camera_rgb_frame", "camera_rgb_optical_frame",
                            "cliff_left_link", "cliff_front_link", "cliff_right_link"})

# Mass and inertia given by urdf_for_physics() to links that have no inertial
# (pure frames). pybullet would otherwise invent 1 kg for each of them.
NEGLIGIBLE_MASS = 1e-5  # kg
NEGLIGIBLE_INERTIA = 1e-9  # kg*m^2


# ----------------------------------------------------------------- files
def package_path() -> Path:
    """Directory of the chefbot_description package (source or install share)."""
    try:
        import rospkg  # lazily: rospkg is only needed when the package is installed elsewhere

        return Path(rospkg.RosPack().get_path(PACKAGE_NAME))
    except Exception:  # noqa: BLE001 - any rospkg failure: fall back to the source tree
        return Path(__file__).resolve().parents[2]


def default_model_path() -> Path:
    """The main model, ``urdf/chefbot.xacro``."""
    return package_path() / "urdf" / "chefbot.xacro"


class XacroError(RuntimeError):
    """xacro could not expand a model; the message carries xacro's own error text."""


def expand_xacro(path: os.PathLike | str | None = None,
                 args: Mapping[str, str] | None = None,
                 timeout: float = 60.0) -> str:
    """Run the ``xacro`` command and return the URDF XML string.

    :param path: xacro file, default :func:`default_model_path`.
    :param args: xacro arguments, e.g. ``{"camera": "astra"}``.
    :param timeout: seconds before giving up on xacro.
    :raises XacroError: xacro missing, failed, or printed warnings; the message
        includes xacro's stderr.
    """
    path = Path(path) if path is not None else default_model_path()
    exe = shutil.which("xacro")
    if exe is None:
        raise XacroError("the 'xacro' command is not on PATH (run inside tools/with_env.sh)")
    cmd = [exe, str(path)] + [f"{k}:={v}" for k, v in (args or {}).items()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    if proc.returncode != 0:
        raise XacroError(f"xacro failed on {path} (exit {proc.returncode}): {proc.stderr.strip()}")
    return proc.stdout


# ----------------------------------------------------------------- URDF model
@dataclass(frozen=True)
class Inertial:
    """Mass (kg), centre of mass pose in the link frame (m, rad) and inertia (kg*m^2)."""

    mass: float
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    inertia: np.ndarray = field(compare=False)  # 3x3, about the COM, in the inertial frame


@dataclass(frozen=True)
class Geometry:
    """One collision or visual primitive: ``kind`` is box/cylinder/sphere/mesh.

    ``size`` holds (x, y, z) for a box, (radius, length) for a cylinder,
    (radius,) for a sphere, () for a mesh. Pose in the link frame (m, rad).
    """

    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]


@dataclass(frozen=True)
class Link:
    """A URDF link: inertial, collision and visual geometry."""

    name: str
    inertial: Inertial | None
    collisions: tuple[Geometry, ...]
    visuals: tuple[Geometry, ...]


@dataclass(frozen=True)
class Joint:
    """A URDF joint; origin is the child frame in the parent frame (m, rad)."""

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    effort: float | None = None  # N*m (revolute/continuous)
    velocity: float | None = None  # rad/s


@dataclass(frozen=True)
class RobotModel:
    """A parsed URDF: links and joints by name."""

    name: str
    links: Mapping[str, Link]
    joints: Mapping[str, Joint]

    @property
    def root(self) -> str:
        """The one link that is no joint's child."""
        children = {j.child for j in self.joints.values()}
        roots = [n for n in self.links if n not in children]
        if len(roots) != 1:
            raise ValueError(f"URDF must have exactly one root link, found {sorted(roots)}")
        return roots[0]

    def parent_joint(self, link: str) -> Joint | None:
        """The joint whose child is ``link`` (None for the root)."""
        if link not in self.links:
            raise KeyError(f"no link named {link!r} in the URDF")
        for joint in self.joints.values():
            if joint.child == link:
                return joint
        return None

    def edges(self) -> set[tuple[str, str]]:
        """The frame tree as a set of (parent, child) link names."""
        return {(j.parent, j.child) for j in self.joints.values()}


def _floats(text: str | None, n: int, what: str, default: Sequence[float] | None = None) -> tuple:
    if text is None:
        if default is None:
            raise ValueError(f"{what}: missing")
        return tuple(float(v) for v in default)
    parts = text.split()
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        raise ValueError(f"{what}: {text!r} is not {n} numbers") from None
    if len(values) != n:
        raise ValueError(f"{what}: {text!r} is not {n} numbers")
    return values


def _origin(elem: ET.Element, what: str) -> tuple[tuple, tuple]:
    origin = elem.find("origin")
    if origin is None:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    return (_floats(origin.get("xyz"), 3, f"{what} origin xyz", (0, 0, 0)),
            _floats(origin.get("rpy"), 3, f"{what} origin rpy", (0, 0, 0)))


def _geometry(elem: ET.Element, what: str) -> Geometry:
    xyz, rpy = _origin(elem, what)
    geom = elem.find("geometry")
    if geom is None or len(geom) != 1:
        raise ValueError(f"{what}: needs exactly one shape inside <geometry>")
    shape = geom[0]
    if shape.tag == "box":
        size = _floats(shape.get("size"), 3, f"{what} box size")
    elif shape.tag == "cylinder":
        size = (_floats(shape.get("radius"), 1, f"{what} cylinder radius")[0],
                _floats(shape.get("length"), 1, f"{what} cylinder length")[0])
    elif shape.tag == "sphere":
        size = _floats(shape.get("radius"), 1, f"{what} sphere radius")
    elif shape.tag == "mesh":
        size = ()
    else:
        raise ValueError(f"{what}: unknown geometry <{shape.tag}>")
    return Geometry(shape.tag, size, xyz, rpy)


def _inertial(elem: ET.Element, what: str) -> Inertial:
    xyz, rpy = _origin(elem, what)
    mass_elem = elem.find("mass")
    if mass_elem is None:
        raise ValueError(f"{what}: <inertial> without <mass>")
    mass = _floats(mass_elem.get("value"), 1, f"{what} mass")[0]
    inertia_elem = elem.find("inertia")
    if inertia_elem is None:
        raise ValueError(f"{what}: <inertial> without <inertia>")
    names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {n: _floats(inertia_elem.get(n), 1, f"{what} inertia {n}")[0] for n in names}
    tensor = np.array([[v["ixx"], v["ixy"], v["ixz"]],
                       [v["ixy"], v["iyy"], v["iyz"]],
                       [v["ixz"], v["iyz"], v["izz"]]])
    return Inertial(mass, xyz, rpy, tensor)


def _root_element(urdf_xml: str) -> ET.Element:
    try:
        root = ET.fromstring(urdf_xml)
    except ET.ParseError as exc:
        raise ValueError(f"robot description is not well-formed XML: {exc}") from None
    if root.tag != "robot":
        raise ValueError(f"robot description root element is <{root.tag}>, expected <robot>")
    return root


def parse_urdf(urdf_xml: str) -> RobotModel:
    """Parse a URDF string into links and joints (no xacro: expand first).

    :raises ValueError: malformed XML, missing attributes or dangling links,
        with the link/joint named in the message.
    """
    root = _root_element(urdf_xml)
    links: dict[str, Link] = {}
    for elem in root.findall("link"):
        name = elem.get("name")
        if not name:
            raise ValueError("<link> without a name")
        if name in links:
            raise ValueError(f"link {name!r} defined twice")
        what = f"link {name!r}"
        inertial = elem.find("inertial")
        links[name] = Link(
            name=name,
            inertial=_inertial(inertial, what) if inertial is not None else None,
            collisions=tuple(_geometry(c, f"{what} collision") for c in elem.findall("collision")),
            visuals=tuple(_geometry(c, f"{what} visual") for c in elem.findall("visual")),
        )
    joints: dict[str, Joint] = {}
    for elem in root.findall("joint"):
        name = elem.get("name")
        if not name:
            raise ValueError("<joint> without a name")
        what = f"joint {name!r}"
        parent, child = elem.find("parent"), elem.find("child")
        if parent is None or child is None or not parent.get("link") or not child.get("link"):
            raise ValueError(f"{what}: needs <parent link=...> and <child link=...>")
        for end in (parent.get("link"), child.get("link")):
            if end not in links:
                raise ValueError(f"{what}: refers to unknown link {end!r}")
        xyz, rpy = _origin(elem, what)
        axis_elem = elem.find("axis")
        axis = _floats(axis_elem.get("xyz") if axis_elem is not None else None, 3, f"{what} axis", (1, 0, 0))
        limit = elem.find("limit")
        effort = velocity = None
        if limit is not None:
            effort = float(limit.get("effort")) if limit.get("effort") is not None else None
            velocity = float(limit.get("velocity")) if limit.get("velocity") is not None else None
        joints[name] = Joint(name, elem.get("type", ""), parent.get("link"), child.get("link"),
                             xyz, rpy, axis, effort, velocity)
    return RobotModel(root.get("name", ""), links, joints)


# ----------------------------------------------------------------- kinematics
def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw (rad) as a 3x3 rotation: Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def pose_matrix(xyz: Sequence[float], rpy: Sequence[float]) -> np.ndarray:
    """4x4 homogeneous transform from a translation (m) and URDF rpy (rad)."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(*rpy)
    t[:3, 3] = xyz
    return t


def frame_transform(model: RobotModel, frame: str, base: str | None = None) -> np.ndarray:
    """Pose of ``frame`` in ``base`` (default the root) with all joints at zero, 4x4.

    ``base`` must be an ancestor of ``frame``.
    """
    base = base or model.root
    t = np.eye(4)
    link = frame
    while link != base:
        joint = model.parent_joint(link)
        if joint is None:
            raise ValueError(f"{base!r} is not an ancestor of {frame!r} in the URDF")
        t = pose_matrix(joint.xyz, joint.rpy) @ t
        link = joint.parent
    return t


# ----------------------------------------------------------------- derived data
@dataclass(frozen=True)
class WheelGeometry:
    """Drive wheel geometry read from the URDF (m)."""

    radius: float
    width: float
    separation: float  # distance between the wheel centres (track)


def wheel_geometry(model: RobotModel, left_joint: str = "wheel_left_joint",
                   right_joint: str = "wheel_right_joint") -> WheelGeometry:
    """Wheel radius/width from the wheel collision cylinder, separation from the joints."""
    for name in (left_joint, right_joint):
        if name not in model.joints:
            raise ValueError(f"URDF has no joint {name!r}")
    left, right = model.joints[left_joint], model.joints[right_joint]
    cylinders = [g for g in model.links[left.child].collisions if g.kind == "cylinder"]
    if not cylinders:
        raise ValueError(f"link {left.child!r} has no collision cylinder to take the wheel radius from")
    p_left = frame_transform(model, left.child)[:3, 3]
    p_right = frame_transform(model, right.child)[:3, 3]
    return WheelGeometry(radius=cylinders[0].size[0], width=cylinders[0].size[1],
                         separation=float(np.linalg.norm(p_left - p_right)))


def total_mass(model: RobotModel) -> float:
    """Sum of all link masses (kg)."""
    return sum(link.inertial.mass for link in model.links.values() if link.inertial is not None)


def urdf_for_physics(urdf_xml: str, mass: float = NEGLIGIBLE_MASS,
                     inertia: float = NEGLIGIBLE_INERTIA) -> str:
    """Return the URDF with a negligible ``<inertial>`` on every link that has none.

    Pure frames (base_footprint, camera imager and optical frames) carry no
    inertial in the model, which is right for ROS, but pybullet's loader gives
    such links 1 kg each. Load the result of this function instead (and pass
    ``URDF_USE_INERTIA_FROM_FILE``, else pybullet recomputes inertia from the
    collision shapes).
    """
    root = _root_element(urdf_xml)
    for link in root.findall("link"):
        if link.find("inertial") is None:
            inertial = ET.SubElement(link, "inertial")
            ET.SubElement(inertial, "mass", value=repr(mass))
            ET.SubElement(inertial, "inertia", ixx=repr(inertia), ixy="0", ixz="0",
                          iyy=repr(inertia), iyz="0", izz=repr(inertia))
    return ET.tostring(root, encoding="unicode")


# ----------------------------------------------------------------- sim block
@dataclass(frozen=True)
class DriveParams:
    """Differential-drive plugin (book: chefbot.gazebo.xacro's kobuki-style plugin)."""

    left_joint: str
    right_joint: str
    wheel_separation: float  # m
    wheel_diameter: float  # m
    torque: float  # N*m, maximum wheel torque of the plugin
    command_timeout: float  # s, wheels stop when cmd_vel is older
    update_rate: float  # Hz, odometry/tf publishing
    odom_frame: str
    base_frame: str

    @property
    def wheel_radius(self) -> float:
        """m."""
        return self.wheel_diameter / 2.0


@dataclass(frozen=True)
class DepthCameraParams:
    """Simulated depth + RGB camera (both images rendered with the same intrinsics)."""

    link: str
    depth_frame: str
    rgb_frame: str
    width: int  # px
    height: int  # px
    horizontal_fov: float  # rad
    update_rate: float  # Hz
    min_range: float  # m
    max_range: float  # m
    point_cloud_cutoff: float  # m, points nearer than this are dropped
    noise_stddev: float  # m, Gaussian depth noise

    @property
    def vertical_fov(self) -> float:
        """rad, for square pixels."""
        return 2.0 * math.atan(math.tan(self.horizontal_fov / 2.0) * self.height / self.width)

    @property
    def focal_length(self) -> float:
        """Pinhole focal length fx = fy in pixels."""
        return (self.width / 2.0) / math.tan(self.horizontal_fov / 2.0)


@dataclass(frozen=True)
class ImuParams:
    """Simulated IMU: frame, rate (Hz) and noise."""

    frame: str
    update_rate: float  # Hz
    gyro_noise_stddev: float  # rad/s
    accel_noise_stddev: float  # m/s^2

    @property
    def gyro_noise_variance(self) -> float:
        """(rad/s)^2, for sensor_msgs/Imu angular_velocity_covariance."""
        return self.gyro_noise_stddev ** 2


@dataclass(frozen=True)
class RangeSensorParams:
    """A cone range sensor (the HC-SR04); beam along the frame's +x."""

    frame: str
    min_range: float  # m
    max_range: float  # m
    field_of_view: float  # rad, full cone angle
    update_rate: float  # Hz
    noise_stddev: float  # m


@dataclass(frozen=True)
class CliffSensorParams:
    """A downward range sensor with no URDF link: its pose is given on ``parent``.

    The beam runs along the sensor's +x axis (pitch pi/2 points it at the floor).
    """

    name: str
    parent: str
    xyz: tuple[float, float, float]  # m, in parent
    rpy: tuple[float, float, float]  # rad, in parent
    min_range: float  # m
    max_range: float  # m
    field_of_view: float  # rad, full cone angle
    update_rate: float  # Hz

    def pose(self) -> np.ndarray:
        """4x4 pose of the sensor in ``parent``."""
        return pose_matrix(self.xyz, self.rpy)


@dataclass(frozen=True)
class BumperParams:
    """Simulated bumper: the link whose contacts count."""

    link: str  # contacts of this link with the world count as a bump


@dataclass(frozen=True)
class SimParams:
    """Everything in the ``<chefbot_sim>`` block."""

    drive: DriveParams
    depth_camera: DepthCameraParams
    imu: ImuParams
    ultrasonic: RangeSensorParams
    cliffs: tuple[CliffSensorParams, ...]
    bumper: BumperParams


def _number(kind: type, positive: bool = True, allow_zero: bool = False) -> Callable[[str, str], float]:
    def convert(text: str, what: str):
        try:
            value = kind(text)
        except ValueError:
            raise ValueError(f"{what}={text!r} is not a valid {kind.__name__}") from None
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{what}={text!r} must be finite")
        if positive and (value < 0 or (value == 0 and not allow_zero)):
            raise ValueError(f"{what}={text!r} must be {'>= 0' if allow_zero else '> 0'}")
        return value
    return convert


def _name(text: str, what: str) -> str:
    if not text.strip():
        raise ValueError(f"{what} is empty")
    return text


def _vector(text: str, what: str) -> tuple:
    try:
        return _floats(text, 3, what)
    except ValueError:
        raise ValueError(f"{what}={text!r} is not 3 numbers") from None


_POS = _number(float)
_NONNEG = _number(float, allow_zero=True)
_INT = _number(int)

# element -> attribute -> converter. Every attribute is required; others are rejected.
_SIM_SCHEMA: dict[str, dict[str, Callable[[str, str], object]]] = {
    "diff_drive": dict(left_joint=_name, right_joint=_name, wheel_separation=_POS, wheel_diameter=_POS,
                       torque=_POS, command_timeout=_POS, update_rate=_POS, odom_frame=_name,
                       base_frame=_name),
    "depth_camera": dict(link=_name, depth_frame=_name, rgb_frame=_name, width=_INT, height=_INT,
                         horizontal_fov=_POS, update_rate=_POS, min_range=_POS, max_range=_POS,
                         point_cloud_cutoff=_NONNEG, noise_stddev=_NONNEG),
    "imu": dict(frame=_name, update_rate=_POS, gyro_noise_stddev=_NONNEG, accel_noise_stddev=_NONNEG),
    "ultrasonic": dict(frame=_name, min_range=_POS, max_range=_POS, field_of_view=_POS,
                       update_rate=_POS, noise_stddev=_NONNEG),
    "cliff": dict(name=_name, parent=_name, xyz=_vector, rpy=_vector, min_range=_POS, max_range=_POS,
                  field_of_view=_POS, update_rate=_POS),
    "bumper": dict(link=_name),
}
_SINGLE = ("diff_drive", "depth_camera", "imu", "ultrasonic", "bumper")


def _read_element(elem: ET.Element) -> dict[str, object]:
    schema = _SIM_SCHEMA[elem.tag]
    where = f"<{SIM_ELEMENT}>/<{elem.tag}{' name=' + repr(elem.get('name')) if elem.get('name') else ''}>"
    unknown = sorted(set(elem.attrib) - set(schema))
    if unknown:
        raise ValueError(f"{where}: unknown attribute(s) {', '.join(unknown)}")
    values: dict[str, object] = {}
    for attr, convert in schema.items():
        text = elem.get(attr)
        if text is None:
            raise ValueError(f"{where}: missing attribute '{attr}'")
        values[attr] = convert(text, f"{where} {attr}")
    if "min_range" in values and values["min_range"] >= values["max_range"]:
        raise ValueError(f"{where}: min_range {values['min_range']} must be below max_range {values['max_range']}")
    return values


def load_sim_params(urdf_xml: str) -> SimParams:
    """Read the ``<chefbot_sim>`` block of a URDF string.

    Checks that every element and attribute is present and valid and that the
    joints, links and frames it names exist in the same URDF.

    :raises ValueError: naming the element and attribute that is missing,
        unknown or invalid.
    """
    root = _root_element(urdf_xml)
    blocks = root.findall(SIM_ELEMENT)
    if len(blocks) != 1:
        raise ValueError(f"robot description must contain exactly one <{SIM_ELEMENT}> element, "
                         f"found {len(blocks)} (was the model expanded with sim_params:=false?)")
    block = blocks[0]
    if block.get("version") != SIM_VERSION:
        raise ValueError(f"<{SIM_ELEMENT}> version={block.get('version')!r}, this reader understands "
                         f"version={SIM_VERSION!r}")
    found: dict[str, list[dict[str, object]]] = {tag: [] for tag in _SIM_SCHEMA}
    for elem in block:
        if elem.tag not in _SIM_SCHEMA:
            raise ValueError(f"<{SIM_ELEMENT}>: unknown element <{elem.tag}> "
                             f"(known: {', '.join(sorted(_SIM_SCHEMA))})")
        found[elem.tag].append(_read_element(elem))
    for tag in _SINGLE:
        if len(found[tag]) != 1:
            raise ValueError(f"<{SIM_ELEMENT}> needs exactly one <{tag}>, found {len(found[tag])}")
    if not found["cliff"]:
        raise ValueError(f"<{SIM_ELEMENT}> needs at least one <cliff>")

    links = {e.get("name") for e in root.findall("link")}
    joints = {e.get("name") for e in root.findall("joint")}

    def need(kind: str, names: set, value: object, where: str) -> None:
        if value not in names:
            raise ValueError(f"<{SIM_ELEMENT}>/<{where}> names {kind} {value!r}, which is not in the URDF")

    drive = found["diff_drive"][0]
    need("joint", joints, drive["left_joint"], "diff_drive")
    need("joint", joints, drive["right_joint"], "diff_drive")
    need("link", links, drive["base_frame"], "diff_drive")
    cam = found["depth_camera"][0]
    for key in ("link", "depth_frame", "rgb_frame"):
        need("link", links, cam[key], "depth_camera")
    if cam["horizontal_fov"] >= math.pi:
        raise ValueError(f"<{SIM_ELEMENT}>/<depth_camera> horizontal_fov {cam['horizontal_fov']} must be below pi")
    imu = found["imu"][0]
    need("link", links, imu["frame"], "imu")
    sonar = found["ultrasonic"][0]
    need("link", links, sonar["frame"], "ultrasonic")
    bumper = found["bumper"][0]
    need("link", links, bumper["link"], "bumper")
    cliffs = []
    for c in found["cliff"]:
        need("link", links, c["parent"], f"cliff name={c['name']!r}")
        cliffs.append(CliffSensorParams(**c))
    return SimParams(
        drive=DriveParams(**drive),
        depth_camera=DepthCameraParams(**cam),
        imu=ImuParams(**imu),
        ultrasonic=RangeSensorParams(**sonar),
        cliffs=tuple(cliffs),
        bumper=BumperParams(**bumper),
    )
