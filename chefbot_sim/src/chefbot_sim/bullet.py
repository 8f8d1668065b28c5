"""The pybullet facade: the ONLY module of the workspace that imports pybullet.

One :class:`BulletSim` owns one ``BulletClient`` (never the global pybullet
state), so several simulators can live in one process (tests do that).  It
knows bodies, joints and links by name and offers physics stepping, world and
robot loading, snapshots, teleporting, obstacle spawning and the raw sensor
geometry (rays, rendered images, contacts, link states).  Sensor models
(noise, rates, message layout) live in :mod:`chefbot_sim.sim`.

Units: metres, seconds, radians; quaternions are (x, y, z, w).
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from chefbot_common.geometry import Pose2D
from chefbot_description.model import rpy_matrix
from chefbot_sim.world import Shape, World

TIME_STEP = 1.0 / 240.0
# Constraint-solver iterations per step (pybullet's default is 50).  Measured in
# the hotel: 20 iterations cost ~25 % less per step; a 5 s drive ends within
# 4 mm of the 50-iteration run, and every accuracy test (distance, odometry,
# sensors) passes unchanged.
SOLVER_ITERATIONS = 20
# Collision groups: the world answers sensor rays, the robot does not (so the
# camera and the sonar never see the robot's own body); static bodies (world,
# floor) only pair with the robot, so static-static pairs never enter the
# broadphase (measured: the hotel's 56 shapes touching the floor and each
# other cost ~60 µs per physics step).  pybullet's rays belong to group 1.
GROUP_RAY = 1
GROUP_ROBOT = 2
GROUP_FLOOR = 4
GROUP_WORLD = 8
GROUP_ALL = 0x7FFFFFFF
# Several robots in one world: each also carries its own bit, from ROBOT_BIT0 up, so that
# its sensors' rays can hit the others' bodies but never its own.
ROBOT_BIT0 = 4
MAX_ROBOTS = 26
# pybullet turns a URDF cylinder into a convex hull with a collision margin;
# measured: such a 0.045 m wheel rolls like a 0.04625 m one (2.8 % more ground
# per turn than odometry assumes).  The physics copy of the wheel is shrunk by
# this much so the sim rolls with the URDF radius (implicit cylinders would be
# exact but slip on box floors).
WHEEL_CONTACT_CORRECTION = 0.00125  # m
FLOOR_HALF_SIZE = 100.0  # m: the floor spans 200 × 200 m around the origin
# A contact whose normal has a larger vertical component is the robot standing on
# something (a stage), not a bump (cos 45°).
SUPPORT_NORMAL_Z = 0.7


class BulletError(RuntimeError):
    """Facade misuse or a model the facade cannot load (names the culprit)."""


def display_problem() -> str | None:
    """Why pybullet's GUI could not open here (None = a display answers).

    pybullet's GUI ends the whole process with "cannot connect to X server"
    when the display is missing, so ask Xlib first (when libX11 is there).
    """
    disp = os.environ.get("DISPLAY")
    if not disp:
        return "DISPLAY is not set"
    try:
        x11 = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
    except OSError:
        return None  # cannot check without Xlib: let pybullet try
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    handle = x11.XOpenDisplay(disp.encode())
    if not handle:
        return f"cannot connect to the X server at DISPLAY={disp}"
    x11.XCloseDisplay(handle)
    return None


class BulletSim:
    """A pybullet world with its robots (:meth:`add_robot`; the first one's methods are on this
    class too, for a one-robot world).

    ``gui`` opens pybullet's own viewer; without a usable display that raises
    :class:`BulletError` saying so (instead of pybullet ending the process);
    ``time_step`` is the fixed physics step in s, ``solver_iterations`` the
    constraint solver's iterations per step.  Runs are
    deterministic: the same calls in the same order give the same results.
    """

    def __init__(self, gui: bool = False, time_step: float = TIME_STEP,
                 solver_iterations: int = SOLVER_ITERATIONS) -> None:
        self.gui = bool(gui)
        if self.gui:
            problem = display_problem()
            if problem:
                raise BulletError(f"gui:=true needs a display, but {problem}; run headless (gui:=false) "
                                  "or under a virtual display (xvfb-run)")
        self._c = BulletClient(connection_mode=pybullet.GUI if self.gui else pybullet.DIRECT)
        self.time_step = float(time_step)
        if int(solver_iterations) < 1:
            raise BulletError(f"solver_iterations must be >= 1, got {solver_iterations}")
        self._c.setPhysicsEngineParameter(fixedTimeStep=self.time_step, deterministicOverlappingPairs=1,
                                          numSolverIterations=int(solver_iterations))
        # hot calls bound once (BulletClient builds a partial on every attribute access)
        self._step = self._c.stepSimulation
        self._c.setGravity(0.0, 0.0, -9.81)
        if self.gui:
            self._c.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
        # The floor is a thin box, not a plane: a plane's AABB is infinite, so
        # every part of the robot's merged compound would be tested against it
        # each step (measured: 3x slower physics).
        half = (FLOOR_HALF_SIZE, FLOOR_HALF_SIZE, 0.05)
        self.floor = self._c.createMultiBody(
            0.0, self._c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half),
            self._c.createVisualShape(pybullet.GEOM_BOX, halfExtents=half), basePosition=(0.0, 0.0, -0.05))
        self._c.changeVisualShape(self.floor, -1, rgbaColor=(0.85, 0.85, 0.8, 1.0))
        # rays answer only when asked for the floor (cast_rays(floor=True): the cliff sensors)
        self._c.setCollisionFilterGroupMask(self.floor, -1, GROUP_FLOOR, GROUP_ROBOT | GROUP_RAY)
        self.robots: list[RobotBody] = []       # in load order
        self.robot: int | None = None             # the first robot's body id (one-robot API)
        self.body: RobotBody | None = None        # the first robot
        self.bodies: dict[str, int] = {}

    # ------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Disconnect; the object is unusable afterwards."""
        with contextlib.suppress(Exception):
            self._c.disconnect()

    def __enter__(self) -> BulletSim:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextlib.contextmanager
    def no_rendering(self) -> Iterator[None]:
        """Suspend the GUI's redraws while loading many bodies."""
        if self.gui:
            self._c.configureDebugVisualizer(pybullet.COV_ENABLE_RENDERING, 0)
        try:
            yield
        finally:
            if self.gui:
                self._c.configureDebugVisualizer(pybullet.COV_ENABLE_RENDERING, 1)

    # ------------------------------------------------------------ world
    def add_shape(self, shape: Shape) -> int:
        """Create ``shape`` as a static body; returns the body id."""
        if shape.name in self.bodies:
            raise BulletError(f"a body named '{shape.name}' exists already")
        c = self._c
        if shape.kind == "box":
            half = [v / 2.0 for v in shape.size]
            col = c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
            vis = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=shape.colour)
        elif shape.kind == "cylinder":
            r, h = shape.size
            col = c.createCollisionShape(pybullet.GEOM_CYLINDER, radius=r, height=h)
            vis = c.createVisualShape(pybullet.GEOM_CYLINDER, radius=r, length=h, rgbaColor=shape.colour)
        elif shape.kind == "sphere":
            col = c.createCollisionShape(pybullet.GEOM_SPHERE, radius=shape.size[0])
            vis = c.createVisualShape(pybullet.GEOM_SPHERE, radius=shape.size[0], rgbaColor=shape.colour)
        else:
            raise BulletError(f"shape '{shape.name}': unknown kind {shape.kind!r}")
        body = c.createMultiBody(0.0, col, vis, basePosition=shape.position,
                                 baseOrientation=c.getQuaternionFromEuler(shape.rpy))
        c.setCollisionFilterGroupMask(body, -1, GROUP_WORLD, GROUP_ROBOT | GROUP_RAY)
        self.bodies[shape.name] = body
        return body

    def load_world(self, world: World) -> None:
        """Add every shape of ``world`` as a static body."""
        with self.no_rendering():
            for s in world.shapes:
                self.add_shape(s)

    def remove_shape(self, name: str) -> None:
        """Remove a body added by :meth:`add_shape`."""
        if name not in self.bodies:
            raise BulletError(f"no body named '{name}'")
        self._c.removeBody(self.bodies.pop(name))

    # ------------------------------------------------------------ robots
    def load_robot(self, urdf_xml: str, pose: Pose2D, base_friction: float = 0.0,
                   wheel_contact_correction: float = WHEEL_CONTACT_CORRECTION, z: float = 0.0) -> RobotBody:
        """Load THE robot of a one-robot world (see :meth:`add_robot`); the robot methods of
        this class (:meth:`frame_pose`, :meth:`joint_states`, ...) act on it."""
        if self.robots:
            raise BulletError("a robot is loaded already")
        return self.add_robot(urdf_xml, pose, base_friction, wheel_contact_correction, z)

    def add_robot(self, urdf_xml: str, pose: Pose2D, base_friction: float = 0.0,
                  wheel_contact_correction: float = WHEEL_CONTACT_CORRECTION, z: float = 0.0,
                  name: str = "") -> RobotBody:
        """Load a robot from a URDF string with its root (``base_footprint``) at ``pose``,
        ``z`` m above the world origin (the height of the surface it stands on); returns its
        :class:`RobotBody`.  Several robots may share the world (up to :data:`MAX_ROBOTS`):
        each one's sensors see the others' bodies (never its own), and robots collide with
        each other, the world and the floor.  ``name`` (default ``robot<i>``) is what
        :meth:`body_name` answers for its body.

        Inertia comes from the URDF.  Fixed links are merged into their parent
        body (3× faster physics); their frames stay available by name through
        :meth:`RobotBody.frame_pose`, computed from the URDF's fixed joints.  Links without
        ``<inertial>`` (pure frames such as ``camera_depth_optical_frame``) get a
        negligible mass instead of pybullet's default 1 kg.  The merged base gets
        ``base_friction``: the book's casters are frictionless balls, and the
        wheels carry the robot's traction.  Collision cylinders of links on
        continuous joints (the wheels) shrink by ``wheel_contact_correction`` m
        so that they roll with the URDF radius (see WHEEL_CONTACT_CORRECTION).
        """
        if len(self.robots) >= MAX_ROBOTS:
            raise BulletError(f"at most {MAX_ROBOTS} robots share one world")
        name = name or f"robot{len(self.robots)}"
        if any(r.name == name for r in self.robots) or name in self.bodies or name == "floor":
            raise BulletError(f"a body named '{name}' exists already")
        try:
            root = ET.fromstring(urdf_xml)
        except ET.ParseError as e:
            raise BulletError(f"robot URDF is not valid XML: {e}") from e
        for link in root.findall("link"):
            if link.find("inertial") is None:
                inertial = ET.SubElement(link, "inertial")
                ET.SubElement(inertial, "mass", value="1e-5")
                ET.SubElement(inertial, "inertia", ixx="1e-9", iyy="1e-9", izz="1e-9", ixy="0", ixz="0", iyz="0")
        wheels = {j.find("child").get("link") for j in root.findall("joint")
                  if j.get("type") == "continuous" and j.find("child") is not None}
        for link in root.findall("link"):
            if link.get("name") in wheels:
                for cyl in link.findall("collision/geometry/cylinder"):
                    cyl.set("radius", repr(float(cyl.get("radius")) - wheel_contact_correction))
            elif "caster" in (link.get("name") or ""):
                # the casters shrink alike so the wheels still carry their share of the weight
                for sph in link.findall("collision/geometry/sphere"):
                    sph.set("radius", repr(float(sph.get("radius")) - wheel_contact_correction))
        fd, path = tempfile.mkstemp(prefix="chefbot_", suffix=".urdf")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(ET.tostring(root))
            with self.no_rendering(), _quiet_stdout():  # pybullet prints every merged link
                body = self._c.loadURDF(
                    path, basePosition=(pose.x, pose.y, float(z)),
                    baseOrientation=self._c.getQuaternionFromEuler((0, 0, pose.yaw)),
                    flags=pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_MERGE_FIXED_LINKS)
        except pybullet.error as e:
            raise BulletError(f"pybullet could not load the robot URDF: {e}") from e
        finally:
            os.unlink(path)
        robot = RobotBody(self, body, name, len(self.robots), _fixed_joint_tree(root), base_friction)
        self.robots.append(robot)
        if self.robot is None:
            self.robot, self.body = body, robot
        return robot

    def _primary(self) -> RobotBody:
        if self.body is None:
            raise BulletError("no robot loaded")
        return self.body

    # the one-robot API: the first robot loaded (RobotBody has the documentation)
    def frame(self, name: str) -> tuple[int, np.ndarray]:
        """The first robot's :meth:`RobotBody.frame`."""
        return self._primary().frame(name)

    def frame_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """The first robot's :meth:`RobotBody.frame_pose`."""
        return self._primary().frame_pose(name)

    def joint(self, name: str) -> int:
        """The first robot's :meth:`RobotBody.joint`."""
        return self._primary().joint(name)

    def movable_joints(self) -> dict[str, int]:
        """The first robot's :meth:`RobotBody.movable_joints`."""
        return self._primary().movable_joints()

    def set_joint_velocities(self, joints: Sequence[int], velocities: Sequence[float],
                             max_torque: float | Sequence[float]) -> None:
        """The first robot's :meth:`RobotBody.set_joint_velocities`."""
        self._primary().set_joint_velocities(joints, velocities, max_torque)

    def joint_states(self, joints: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """The first robot's :meth:`RobotBody.joint_states`."""
        return self._primary().joint_states(joints)

    def base_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The first robot's :meth:`RobotBody.base_state`."""
        return self._primary().base_state()

    def link_pose(self, link: int) -> tuple[np.ndarray, np.ndarray]:
        """The first robot's :meth:`RobotBody.link_pose`."""
        return self._primary().link_pose(link)

    def teleport(self, pose: Pose2D, z: float = 0.0) -> None:
        """The first robot's :meth:`RobotBody.teleport`."""
        self._primary().teleport(pose, z)

    def robot_contacts(self) -> list[tuple[str, int, np.ndarray]]:
        """The first robot's :meth:`RobotBody.contacts`."""
        return self._primary().contacts()

    # ------------------------------------------------------------ stepping, state
    def step(self, n: int = 1) -> None:
        """Advance physics by ``n`` fixed steps."""
        step = self._step
        for _ in range(n):
            step()

    def save_state(self) -> int:
        """Snapshot of the whole physics state (in memory); returns its id."""
        return self._c.saveState()

    def restore_state(self, state_id: int) -> None:
        """Restore a snapshot; the set of bodies must be the one at save time."""
        self._c.restoreState(stateId=state_id)

    def remove_state(self, state_id: int) -> None:
        """Free a snapshot taken with :meth:`save_state`."""
        self._c.removeState(state_id)

    # ------------------------------------------------------------ sensing
    def cast_rays(self, origins: np.ndarray, ends: np.ndarray, floor: bool = False,
                  robots: int = 0, world: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Cast rays from ``origins`` to ``ends`` ((N, 3) world, m) against the world's shapes
        (unless not ``world``) and the floor (when ``floor``) in one ``rayTestBatch``; robot
        bodies only where ``robots`` (a mask of :attr:`RobotBody.group_bit`) names them (by
        default none: a one-robot world's sensors never see their own robot).  Returns hit
        fractions in [0, 1] (1 = no hit) and the hit body ids (-1 = none)."""
        mask = (GROUP_WORLD if world else 0) | (GROUP_FLOOR if floor else 0) | int(robots)
        out = self._c.rayTestBatch(np.ascontiguousarray(origins, float), np.ascontiguousarray(ends, float),
                                   numThreads=0, collisionFilterMask=mask)
        ids = np.fromiter((h[0] for h in out), dtype=np.int64, count=len(out))
        frac = np.fromiter((h[2] for h in out), dtype=float, count=len(out))
        frac[ids < 0] = 1.0
        return frac, ids

    def render(self, width: int, height: int, eye: np.ndarray, rotation: np.ndarray,
               fy: float, near: float, far: float, rgb: bool) -> tuple[np.ndarray | None, np.ndarray]:
        """Render with TinyRenderer from a camera at ``eye`` whose optical frame
        (x right, y down, z forward) has world rotation ``rotation`` (3×3).

        ``fy`` is the focal length in pixels (square pixels).  Returns the RGB
        image (H, W, 3) uint8 when ``rgb`` and the depth along the optical axis
        (H, W) in m (``inf`` where nothing is within ``far``).  Every body is drawn,
        the other robots included.
        """
        fwd, down = rotation[:, 2], rotation[:, 1]
        view = self._c.computeViewMatrix(eye.tolist(), (eye + fwd).tolist(), (-down).tolist())
        fov_v = math.degrees(2.0 * math.atan(height / 2.0 / fy))
        proj = self._c.computeProjectionMatrixFOV(fov_v, width / height, near, far)
        flags = pybullet.ER_NO_SEGMENTATION_MASK
        _, _, px, zbuf, _ = self._c.getCameraImage(width, height, view, proj, renderer=pybullet.ER_TINY_RENDERER,
                                                   flags=flags, shadow=0)
        zbuf = np.asarray(zbuf, dtype=float).reshape(height, width)
        depth = far * near / (far - (far - near) * zbuf)
        depth[zbuf >= 1.0] = np.inf
        image = None
        if rgb:
            image = np.asarray(px, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()
        return image, depth

    def body_name(self, body: int) -> str:
        """Name of a loaded body id: a shape's or robot's name, "floor", or the id as text when unknown."""
        for k, v in self.bodies.items():
            if v == body:
                return k
        for r in self.robots:
            if r.id == body:
                return r.name
        return "floor" if body == self.floor else str(body)


class RobotBody:
    """One robot of a :class:`BulletSim` world: its joints, links and frames by URDF name,
    its motors, state, contacts, and rays that see everything but itself.  Made by
    :meth:`BulletSim.add_robot`."""

    def __init__(self, world: BulletSim, body: int, name: str, index: int,
                 fixed: dict[str, tuple[str, np.ndarray]], base_friction: float) -> None:
        self.world, self.id, self.name, self.index = world, body, name, index
        # own collision bit besides GROUP_ROBOT: the others' rays may name it, its own never do
        self.group_bit = 1 << (ROBOT_BIT0 + index)
        self._fixed = fixed
        self._base_from_inertial: tuple | None = None
        c = self._c = world._c
        self._get_joint_states = c.getJointStates
        self._get_base_pose = c.getBasePositionAndOrientation
        self._get_base_velocity = c.getBaseVelocity
        self._get_link_state = c.getLinkState
        self._links = {c.getBodyInfo(body)[0].decode(): -1}
        self._joints: dict[str, int] = {}
        for j in range(c.getNumJoints(body)):
            info = c.getJointInfo(body, j)
            self._joints[info[1].decode()] = j
            self._links[info[12].decode()] = j
        c.changeDynamics(body, -1, lateralFriction=base_friction, rollingFriction=0.0, spinningFriction=0.0)
        for idx in self._links.values():
            c.setCollisionFilterGroupMask(body, idx, GROUP_ROBOT | self.group_bit, GROUP_ALL)
        # pybullet's default velocity motors hold every joint still: release them
        for j in self.movable_joints().values():
            c.setJointMotorControl2(body, j, pybullet.VELOCITY_CONTROL, targetVelocity=0.0, force=0.0)

    def others_mask(self) -> int:
        """Collision bits of every other robot in the world (what this robot's rays may hit)."""
        mask = 0
        for r in self.world.robots:
            if r is not self:
                mask |= r.group_bit
        return mask

    def frame(self, name: str) -> tuple[int, np.ndarray]:
        """A robot frame by URDF link name: (pybullet link index, 4×4 fixed offset
        from that body link's frame).  BulletError names a missing frame."""
        offset = np.eye(4)
        cur = name
        while cur not in self._links:
            if cur not in self._fixed:
                raise BulletError(f"robot has no link '{name}'")
            parent, tf = self._fixed[cur]
            offset = tf @ offset
            cur = parent
        return self._links[cur], offset

    def frame_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (m) and 3×3 rotation of the robot frame ``name``."""
        link, offset = self.frame(name)
        p, q = self.link_pose(link)
        rot = np.array(self._c.getMatrixFromQuaternion(q)).reshape(3, 3)
        return p + rot @ offset[:3, 3], rot @ offset[:3, :3]

    def joint(self, name: str) -> int:
        """Index of the robot joint ``name`` (BulletError names a missing one)."""
        try:
            return self._joints[name]
        except KeyError:
            raise BulletError(f"robot has no joint '{name}' (has: {', '.join(sorted(self._joints))})") from None

    def movable_joints(self) -> dict[str, int]:
        """Non-fixed joints of the robot, name → index, in index order."""
        return {n: j for n, j in self._joints.items()
                if self._c.getJointInfo(self.id, j)[2] != pybullet.JOINT_FIXED}

    def set_joint_velocities(self, joints: Sequence[int], velocities: Sequence[float],
                             max_torque: float | Sequence[float]) -> None:
        """Velocity-control motors: target rad/s, torque limit N·m (one for all, or one per joint)."""
        forces = [float(max_torque)] * len(joints) if isinstance(max_torque, (int, float)) else list(max_torque)
        self._c.setJointMotorControlArray(self.id, list(joints), pybullet.VELOCITY_CONTROL,
                                          targetVelocities=list(velocities), forces=forces)

    def joint_states(self, joints: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """Positions (rad) and velocities (rad/s) of the given joints."""
        st = self._get_joint_states(self.id, list(joints))
        return np.array([s[0] for s in st]), np.array([s[1] for s in st])

    def base_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Root link position (m), quaternion, linear (m/s) and angular (rad/s)
        velocity, all in the world frame.

        The root is ``base_footprint``: pybullet's base frame is the root's
        inertial frame, so the URDF link frame is recovered here.
        """
        r, c = self.id, self._c
        pos, quat = self._get_base_pose(r)
        lin, ang = self._get_base_velocity(r)
        if self._base_from_inertial is None:  # constant once the robot is loaded
            inertial_pos, inertial_orn = c.getDynamicsInfo(r, -1)[3:5]
            self._base_from_inertial = c.invertTransform(inertial_pos, inertial_orn)
        pos, quat = c.multiplyTransforms(pos, quat, *self._base_from_inertial)
        return np.array(pos), np.array(quat), np.array(lin), np.array(ang)

    def link_pose(self, link: int) -> tuple[np.ndarray, np.ndarray]:
        """World position (m) and quaternion of a robot link's URDF frame."""
        if link == -1:
            p, q, _, _ = self.base_state()
            return p, q
        # the link frame is the joint frame: world link frame = URDF child link frame
        st = self._get_link_state(self.id, link, computeForwardKinematics=True)
        return np.array(st[4]), np.array(st[5])

    def teleport(self, pose: Pose2D, z: float = 0.0) -> None:
        """Put the robot's root at ``pose``, ``z`` m up (at rest, wheels stopped)."""
        r, c = self.id, self._c
        inertial_pos, inertial_orn = c.getDynamicsInfo(r, -1)[3:5]
        q = c.getQuaternionFromEuler((0.0, 0.0, pose.yaw))
        p, q2 = c.multiplyTransforms((pose.x, pose.y, z), q, inertial_pos, inertial_orn)
        c.resetBasePositionAndOrientation(r, p, q2)
        c.resetBaseVelocity(r, (0, 0, 0), (0, 0, 0))
        for j in self.movable_joints().values():
            pos = c.getJointState(r, j)[0]
            c.resetJointState(r, j, pos, 0.0)

    def cast_rays(self, origins: np.ndarray, ends: np.ndarray, floor: bool = False,
                  robots: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`BulletSim.cast_rays` from this robot's sensors: the world, the floor when
        ``floor``, the other robots when ``robots``, never this robot's own body."""
        return self.world.cast_rays(origins, ends, floor, self.others_mask() if robots else 0)

    def render(self, width: int, height: int, eye: np.ndarray, rotation: np.ndarray,
               fy: float, near: float, far: float, rgb: bool) -> tuple[np.ndarray | None, np.ndarray]:
        """:meth:`BulletSim.render` (for a camera on this robot)."""
        return self.world.render(width, height, eye, rotation, fy, near, far, rgb)

    def touches(self, other: RobotBody, margin: float = 0.0) -> bool:
        """Whether this robot's body is within ``margin`` m of ``other``'s (or inside it)."""
        return bool(self._c.getClosestPoints(self.id, other.id, float(margin)))

    def contacts(self) -> list[tuple[str, int, np.ndarray]]:
        """Contacts of the robot with anything but what it stands on (the floor, or the
        top of a platform: contacts whose normal is within ~45° of vertical), other robots
        included: (robot link name, other body id, world contact point m)."""
        r = self.id
        names = {v: k for k, v in self._links.items()}
        out = []
        for cp in self._c.getContactPoints(bodyA=r):
            if cp[2] == self.world.floor or cp[2] == r or abs(cp[7][2]) > SUPPORT_NORMAL_Z:
                continue
            out.append((names.get(cp[3], str(cp[3])), cp[2], np.array(cp[5])))
        return out


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence C-level writes to fd 1 (pybullet's URDF loader chatter) for a moment."""
    try:
        saved = os.dup(1)
    except OSError:  # no stdout at all
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _origin(el: ET.Element | None) -> np.ndarray:
    t = np.eye(4)
    if el is None:
        return t
    xyz = [float(v) for v in el.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in el.get("rpy", "0 0 0").split()]
    t[:3, :3] = rpy_matrix(*rpy)
    t[:3, 3] = xyz
    return t


def _fixed_joint_tree(root: ET.Element) -> dict[str, tuple[str, np.ndarray]]:
    """child link → (parent link, 4×4 child-in-parent) for every fixed URDF joint."""
    out = {}
    for j in root.findall("joint"):
        if j.get("type") == "fixed":
            parent, child = j.find("parent"), j.find("child")
            if parent is not None and child is not None:
                out[child.get("link")] = (parent.get("link"), _origin(j.find("origin")))
    return out
