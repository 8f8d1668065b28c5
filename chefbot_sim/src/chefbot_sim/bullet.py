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
GROUP_ALL = 0xFFFF
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
    """A pybullet world with one robot.

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
        self._get_joint_states = self._c.getJointStates
        self._get_base_pose = self._c.getBasePositionAndOrientation
        self._get_base_velocity = self._c.getBaseVelocity
        self._get_link_state = self._c.getLinkState
        self._base_from_inertial: tuple | None = None
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
        self.robot: int | None = None
        self._joints: dict[str, int] = {}
        self._links: dict[str, int] = {}
        self.bodies: dict[str, int] = {}
        self._fixed: dict[str, tuple[str, np.ndarray]] = {}

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

    # ------------------------------------------------------------ robot
    def load_robot(self, urdf_xml: str, pose: Pose2D, base_friction: float = 0.0,
                   wheel_contact_correction: float = WHEEL_CONTACT_CORRECTION, z: float = 0.0) -> None:
        """Load the robot from a URDF string with its root (``base_footprint``) at ``pose``,
        ``z`` m above the world origin (the height of the surface it stands on).

        Inertia comes from the URDF.  Fixed links are merged into their parent
        body (3× faster physics); their frames stay available by name through
        :meth:`frame_pose`, computed from the URDF's fixed joints.  Links without
        ``<inertial>`` (pure frames such as ``camera_depth_optical_frame``) get a
        negligible mass instead of pybullet's default 1 kg.  The merged base gets
        ``base_friction``: the book's casters are frictionless balls, and the
        wheels carry the robot's traction.  Collision cylinders of links on
        continuous joints (the wheels) shrink by ``wheel_contact_correction`` m
        so that they roll with the URDF radius (see WHEEL_CONTACT_CORRECTION).
        """
        if self.robot is not None:
            raise BulletError("a robot is loaded already")
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
        self._fixed = _fixed_joint_tree(root)
        fd, path = tempfile.mkstemp(prefix="chefbot_", suffix=".urdf")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(ET.tostring(root))
            with self.no_rendering(), _quiet_stdout():  # pybullet prints every merged link
                self.robot = self._c.loadURDF(
                    path, basePosition=(pose.x, pose.y, float(z)),
                    baseOrientation=self._c.getQuaternionFromEuler((0, 0, pose.yaw)),
                    flags=pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_MERGE_FIXED_LINKS)
        except pybullet.error as e:
            raise BulletError(f"pybullet could not load the robot URDF: {e}") from e
        finally:
            os.unlink(path)
        c, r = self._c, self.robot
        self._links = {c.getBodyInfo(r)[0].decode(): -1}
        self._joints = {}
        for j in range(c.getNumJoints(r)):
            info = c.getJointInfo(r, j)
            self._joints[info[1].decode()] = j
            self._links[info[12].decode()] = j
        c.changeDynamics(r, -1, lateralFriction=base_friction, rollingFriction=0.0, spinningFriction=0.0)
        for idx in self._links.values():
            c.setCollisionFilterGroupMask(r, idx, GROUP_ROBOT, GROUP_ALL)
        # pybullet's default velocity motors hold every joint still: release them
        for j in self.movable_joints().values():
            c.setJointMotorControl2(r, j, pybullet.VELOCITY_CONTROL, targetVelocity=0.0, force=0.0)

    def frame(self, name: str) -> tuple[int, np.ndarray]:
        """A robot frame by URDF link name: (pybullet link index, 4×4 fixed offset
        from that body link's frame).  BulletError names a missing frame."""
        self._need_robot()
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

    def _need_robot(self) -> int:
        if self.robot is None:
            raise BulletError("no robot loaded")
        return self.robot

    def joint(self, name: str) -> int:
        """Index of the robot joint ``name`` (BulletError names a missing one)."""
        self._need_robot()
        try:
            return self._joints[name]
        except KeyError:
            raise BulletError(f"robot has no joint '{name}' (has: {', '.join(sorted(self._joints))})") from None

    def movable_joints(self) -> dict[str, int]:
        """Non-fixed joints of the robot, name → index, in index order."""
        r = self._need_robot()
        return {n: j for n, j in self._joints.items()
                if self._c.getJointInfo(r, j)[2] != pybullet.JOINT_FIXED}

    def set_joint_velocities(self, joints: Sequence[int], velocities: Sequence[float],
                             max_torque: float | Sequence[float]) -> None:
        """Velocity-control motors: target rad/s, torque limit N·m (one for all, or one per joint)."""
        forces = [float(max_torque)] * len(joints) if isinstance(max_torque, (int, float)) else list(max_torque)
        self._c.setJointMotorControlArray(self._need_robot(), list(joints), pybullet.VELOCITY_CONTROL,
                                          targetVelocities=list(velocities), forces=forces)

    def joint_states(self, joints: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """Positions (rad) and velocities (rad/s) of the given joints."""
        st = self._get_joint_states(self._need_robot(), list(joints))
        return np.array([s[0] for s in st]), np.array([s[1] for s in st])

    def base_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Root link position (m), quaternion, linear (m/s) and angular (rad/s)
        velocity, all in the world frame.

        The root is ``base_footprint``: pybullet's base frame is the root's
        inertial frame, so the URDF link frame is recovered here.
        """
        r = self._need_robot()
        c = self._c
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
        st = self._get_link_state(self._need_robot(), link, computeForwardKinematics=True)
        return np.array(st[4]), np.array(st[5])

    def teleport(self, pose: Pose2D, z: float = 0.0) -> None:
        """Put the robot's root at ``pose``, ``z`` m up (at rest, wheels stopped)."""
        r = self._need_robot()
        c = self._c
        inertial_pos, inertial_orn = c.getDynamicsInfo(r, -1)[3:5]
        q = c.getQuaternionFromEuler((0.0, 0.0, pose.yaw))
        p, q2 = c.multiplyTransforms((pose.x, pose.y, z), q, inertial_pos, inertial_orn)
        c.resetBasePositionAndOrientation(r, p, q2)
        c.resetBaseVelocity(r, (0, 0, 0), (0, 0, 0))
        for j in self.movable_joints().values():
            pos = c.getJointState(r, j)[0]
            c.resetJointState(r, j, pos, 0.0)

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
    def cast_rays(self, origins: np.ndarray, ends: np.ndarray, floor: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Cast rays from ``origins`` to ``ends`` ((N, 3) world, m) against the world
        (and the floor when ``floor``), never the robot, in one ``rayTestBatch``.
        Returns hit fractions in [0, 1] (1 = no hit) and the hit body ids (-1 = none)."""
        mask = GROUP_WORLD | GROUP_FLOOR if floor else GROUP_WORLD
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
        (H, W) in m (``inf`` where nothing is within ``far``).
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

    def robot_contacts(self) -> list[tuple[str, int, np.ndarray]]:
        """Contacts of the robot with anything but what it stands on (the floor, or the
        top of a platform: contacts whose normal is within ~45° of vertical):
        (robot link name, other body id, world contact point m)."""
        r = self._need_robot()
        names = {v: k for k, v in self._links.items()}
        out = []
        for cp in self._c.getContactPoints(bodyA=r):
            if cp[2] == self.floor or cp[2] == r or abs(cp[7][2]) > SUPPORT_NORMAL_Z:
                continue
            out.append((names.get(cp[3], str(cp[3])), cp[2], np.array(cp[5])))
        return out

    def body_name(self, body: int) -> str:
        """Name of a loaded body id ("floor", or the id as text when unknown)."""
        for k, v in self.bodies.items():
            if v == body:
                return k
        return "floor" if body == self.floor else str(body)


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
