"""The ChefBot simulator core, without ROS.

Steps physics at a fixed 1/240 s and drives the wheels in one of two modes:

* ``plugin`` (Gazebo's kobuki-style drive plugin): cmd_vel → wheel speeds,
  0.6 s command timeout, odometry from the simulated wheel joint angles;
* ``firmware`` (firmware-in-the-loop): our LaunchPad firmware core on a
  pseudo-terminal, stepped every physics step on sim time, its motor duties
  through a DC-motor model, encoder edges back into it
  (:mod:`chefbot_sim.firmware_drive`); no cmd_vel and no odometry here
  (``robot_standalone.launch`` on the pty does that, as on the robot).

Sensor readings come at their configured rates, all on sim time.  :meth:`Simulator.step` returns the readings due as
:class:`Event` objects; the ROS node turns them into messages, the benchmark
throws them away.

Parameters come from the ``<chefbot_sim>`` block of the robot URDF
(``chefbot_description.model.load_sim_params``) plus :class:`SimOptions` for
what the URDF does not describe (publishing rates of ROS-side topics, the
depth method, the seed).  Units: m, s, rad, Hz.
"""
from __future__ import annotations

import math
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from chefbot_common.geometry import Pose2D, wrap_angle, yaw_from_quaternion
from chefbot_sim import battery, imu_model
from chefbot_sim.bullet import BulletError, BulletSim
from chefbot_sim.camera import RgbdRenderer, RgbFrame
from chefbot_sim.events import CliffData, Event, GroundTruthData, ImuData, LidarData, OdomData, UltrasonicData
from chefbot_sim.firmware_drive import DcMotor, FirmwareDrive, motor_from_joint_limits
from chefbot_sim.lidar import LidarConfig
from chefbot_sim.raycast import RayCaster
from chefbot_sim.wheel_noise import WheelNoise, measure_wheels, quantise
from chefbot_sim.world import Shape, World, surface_height
from chefbot_vision.cloud import Pinhole

ORIGIN = Pose2D(0.0, 0.0, 0.0)
BATTERY_STEPS = 24   # physics steps between battery updates (0.1 s of sim time)
ROBOT_REACH = 0.35   # m: bound on a robot body's extent from its base_footprint in the plane (ChefBot:
                     # 0.178 m base; a margin for other shapes): rays passing farther are not cast
SENSORS = ("clock", "joint_states", "ground_truth", "odom", "imu", "ultrasonic", "cliff", "depth", "rgb", "bumper",
           "lidar", "battery")
DRIVES = ("plugin", "firmware")


class SimConfigError(ValueError):
    """The robot description cannot drive the simulator (names what is missing)."""


@dataclass
class SimOptions:
    """Simulator settings not in the URDF.  Rates in Hz of sim time (0 = off)."""

    seed: int = 0                      # random generator seed of the sensor, IMU-drift and wheel noise (same
                                       # seed: the same noise)
    clock_rate: float = 100.0          # [Hz] /clock publishing, not the physics rate (>= 0)
    joint_state_rate: float = 50.0     # [Hz] joint_states, the wheels' angles and speeds (>= 0; 0: off)
    ground_truth_rate: float = 50.0    # [Hz] ground_truth/odom, the true pose and twist (>= 0; 0: off)
    bumper_rate: float = 20.0          # [Hz] bumper, std_msgs/Bool contact state (>= 0; 0: off)
    rgb_rate: float = 10.0             # [Hz] TinyRenderer, only while subscribed (chefbot_sim.camera; 0: off)
    rgb_width: int = 320               # [px] RGB image width (>= 1; camera_info has the matching intrinsics)
    rgb_height: int = 240              # [px] RGB image height (>= 1)
    registered_stride: int = 2         # px step of camera/depth_registered/points over the RGB image
    depth_band_rows: int = 10          # rows around the centre cast exactly (depth_to_scan's scan_height)
    depth_fill: str = "coarse"         # rows outside the band: coarse | full | none
    depth_coarse_stride: int = 8       # px between coarse samples outside the band
    sonar_rings: int = 2               # rings of 8 rays in the cone, plus the axis ray
    solver_iterations: int = 20        # pybullet constraint-solver iterations per physics step
    drive: str = "plugin"              # plugin | firmware
    pty_link: str = ""                 # firmware mode: symlink to the emulated LaunchPad's pty ('' = none)
    build_faults: str = ""             # firmware mode: wiring faults of the emulated robot, comma-separated
                                       # (chefbot_firmware.virtual_board.FAULT_NAMES, e.g. left_leads_swapped)
    battery_volts: float = 12.4        # firmware mode without battery_model: constant voltage the board measures (V)
    battery_model: bool = True         # the discharge model (battery.py): firmware mode, the board measures it;
                                       # plugin mode, it is published at battery_rate
    battery_chemistry: str = "sla"     # sla | lipo3s | nimh10 (open-circuit voltage curve)
    battery_capacity_ah: float = 10.0  # Ah (book: 12 V 10 Ah)
    battery_initial_soc: float = 0.9   # state of charge at start, 0..1
    battery_idle_current: float = 2.5  # A drawn besides the motors (NUC, camera, board)
    battery_rate: float = 1.0          # [Hz] plugin mode: the pack's state (battery_state) per second of sim time
                                       # (0 = none; firmware mode: launchpad_node publishes it from the board)
    charge_current: float = 5.0        # [A] into the pack while the robot stands still on its charger (a fleet
                                       # robot with a charger pose in the fleet file; 0 = no charging)
    charger_tolerance: float = 0.15    # [m] the robot is on its charger within this of the charger pose
    imu_relative_yaw: bool = True      # IMU yaw 0 at the start pose, as the real MPU6050's DMP
    imu_gyro_bias: float = imu_model.DEFAULT_GYRO_BIAS              # rad/s, z-gyro bias at start
    imu_gyro_bias_drift: float = imu_model.DEFAULT_GYRO_BIAS_DRIFT  # rad/s/sqrt(s), bias random walk
    odom_imu_heading: bool = False     # plugin mode: odometry heading from the IMU (its drifting DMP yaw) instead
                                       # of the wheel difference, as Kobuki's base driver does; the firmware
                                       # drive's counterpart is diff_tf's use_imu
    # wheel odometry errors (chefbot_sim.wheel_noise; 0 = perfect odometry); ground truth unaffected
    wheel_radius_error_left: float = 0.0   # fraction: real rolling radius / nominal - 1
    wheel_radius_error_right: float = 0.0  # fraction
    wheel_slip_stddev: float = 0.0         # m per sqrt(m) of wheel travel
    wheel_encoder_counts: int = 0          # [counts/rev] plugin mode: encoder counts per wheel turn the odometry
                                           # is quantised to (0 = none)
    # optional 2-D lidar (chefbot_sim.lidar; the model needs the xacro's lidar:=360|270 for its frame)
    lidar_fov: float = 0.0             # [deg] field of view centred on the laser frame's +x: 0 = no lidar, else
                                       # (0, 360] (360: a full circle); scan on topic 'scan'
    lidar_beams: int = 360             # beams per scan (>= 2)
    lidar_rate: float = 10.0           # [Hz] scans per second of sim time (> 0)
    lidar_range_min: float = 0.12      # [m] closer returns read -inf (REP 117; >= 0)
    lidar_range_max: float = 12.0      # [m] nothing within it reads +inf (REP 117; > lidar_range_min)
    lidar_noise: float = 0.01          # [m] standard deviation of the range noise (>= 0)
    lidar_frame: str = "laser"         # URDF link / tf frame of the scan plane (with the tf prefix, if any)
    time_step: float = 1.0 / 240.0

    def lidar_config(self) -> LidarConfig | None:
        """The lidar's settings from these options (None: no lidar)."""
        if self.lidar_fov == 0:
            return None
        return LidarConfig(self.lidar_fov, self.lidar_beams, self.lidar_rate, self.lidar_range_min,
                           self.lidar_range_max, self.lidar_noise, self.lidar_frame)

    def battery_config(self) -> battery.BatteryConfig:
        """The battery model's settings from these options."""
        return battery.BatteryConfig(chemistry=self.battery_chemistry, capacity_ah=self.battery_capacity_ah,
                                     initial_soc=self.battery_initial_soc, idle_current=self.battery_idle_current)

    def imu_drift_config(self) -> imu_model.ImuDriftConfig:
        """The IMU drift model's settings from these options."""
        return imu_model.ImuDriftConfig(self.imu_relative_yaw, self.imu_gyro_bias, self.imu_gyro_bias_drift)

    def validate(self) -> None:
        """Check the options; SimConfigError naming the first bad one."""
        if self.drive not in DRIVES:
            raise SimConfigError(f"drive must be one of {', '.join(DRIVES)}, got {self.drive!r}")
        if not (math.isfinite(self.battery_volts) and self.battery_volts >= 0):
            raise SimConfigError(f"battery_volts must be a finite number >= 0, got {self.battery_volts!r}")
        if self.build_faults.strip():
            if self.drive != "firmware":
                raise SimConfigError(f"build_faults ({self.build_faults!r}) needs drive:=firmware: the faults sit "
                                     "between the emulated board and the motors and encoders")
            try:
                self.faults()
            except ValueError as exc:
                raise SimConfigError(f"build_faults: {exc}") from None
        for name in ("battery_rate", "charge_current", "charger_tolerance"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise SimConfigError(f"{name} must be a finite number >= 0, got {v!r}")
        try:
            self.imu_drift_config()
            self.battery_config()
        except ValueError as exc:
            raise SimConfigError(str(exc)) from None
        if self.depth_fill not in ("coarse", "full", "none"):
            raise SimConfigError(f"depth_fill must be coarse, full or none, got {self.depth_fill!r}")
        for name in ("clock_rate", "joint_state_rate", "ground_truth_rate", "bumper_rate", "rgb_rate"):
            if getattr(self, name) < 0:
                raise SimConfigError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.solver_iterations < 1:
            raise SimConfigError(f"solver_iterations must be >= 1, got {self.solver_iterations}")
        if self.depth_band_rows < 1 or self.depth_coarse_stride < 1:
            raise SimConfigError("depth_band_rows and depth_coarse_stride must be >= 1")
        if self.rgb_width < 1 or self.rgb_height < 1:
            raise SimConfigError("rgb_width and rgb_height must be >= 1")
        if self.registered_stride < 1:
            raise SimConfigError(f"registered_stride must be >= 1, got {self.registered_stride}")
        try:
            self.wheel_noise.validate()
        except ValueError as e:
            raise SimConfigError(str(e)) from None
        if self.lidar_fov != 0:
            try:
                self.lidar_config().validate()
            except ValueError as e:
                raise SimConfigError(str(e)) from None

    def faults(self):
        """The firmware drive's :class:`chefbot_firmware.virtual_board.BuildFaults` (None: built right)."""
        names = [n.strip() for n in self.build_faults.split(",") if n.strip()]
        if not names:
            return None
        from chefbot_firmware.virtual_board import BuildFaults
        return BuildFaults.from_names(names)

    @property
    def wheel_noise(self) -> WheelNoise:
        """The wheel noise model's settings from these options."""
        return WheelNoise(self.wheel_radius_error_left, self.wheel_radius_error_right, self.wheel_slip_stddev,
                          self.wheel_encoder_counts)


@dataclass(frozen=True)
class CameraModel(Pinhole):
    """Pinhole intrinsics (chefbot_vision's Pinhole; ROS convention: integer pixel coordinates are pixel
    centres) with the simulator's helpers."""

    @classmethod
    def from_fov(cls, width: int, height: int, horizontal_fov: float) -> CameraModel:
        """A pinhole model of ``width`` x ``height`` px from its horizontal field of view (rad)."""
        f = (width / 2.0) / math.tan(horizontal_fov / 2.0)
        return cls(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    def rays(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Directions (N, 3) in the optical frame with z = 1, for every (row, col) pair
        of the grid ``rows × cols``, row-major."""
        vv, uu = np.meshgrid(rows, cols, indexing="ij")
        return np.stack([(uu.ravel() - self.cx) / self.fx, (vv.ravel() - self.cy) / self.fy,
                         np.ones(uu.size)], axis=1)

    def info(self) -> dict:
        """CameraInfo fields: K, P (row-major), D, distortion model."""
        k = [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
        p = [self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
        return {"width": self.width, "height": self.height, "K": k, "P": p, "D": [0.0] * 5,
                "distortion_model": "plumb_bob"}


def load_params(urdf_xml: str) -> Any:
    """The ``<chefbot_sim>`` block of the URDF via chefbot_description's reader."""
    try:
        from chefbot_description.model import load_sim_params
    except ImportError as e:  # pragma: no cover - the package is a dependency
        raise SimConfigError(f"chefbot_description.model is not importable: {e}") from e
    try:
        return load_sim_params(urdf_xml)
    except ValueError as e:
        raise SimConfigError(f"robot_description has no usable <chefbot_sim> block: {e}") from e


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """3 x 3 rotation matrix of an (x, y, z, w) quaternion."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of a rotation matrix (Shepperd's method, w >= 0)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    return -q if q[3] < 0 else q


@dataclass
class _State:
    """Everything outside pybullet that a snapshot must carry."""

    time: float = 0.0
    steps: int = 0
    due: dict[str, float] = field(default_factory=dict)
    cmd: tuple[float, float] = (0.0, 0.0)
    cmd_time: float = -math.inf
    wheel_target: tuple[float, float] = (0.0, 0.0)
    odom: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wheel_prev: tuple[float, float] | None = None
    wheel_speed: tuple[float, float] = (0.0, 0.0)
    imu_prev_vel: np.ndarray | None = None
    imu_drift: tuple = (0.0, 0.0, None, 0)   # imu_model.DriftState
    battery_soc: float = 1.0                 # state of charge 0..1 (battery.py)
    battery_current: float = 0.0             # A, last computed draw
    rng_state: dict | None = None
    wheel_true_prev: tuple[float, float] = (0.0, 0.0)   # true wheel angles at the last measurement
    wheel_measured: tuple[float, float] = (0.0, 0.0)    # what the encoders report (rad)
    wheel_rng_state: dict | None = None


class Simulator:
    """ChefBot in a world, plugin-mode drive, sensors on sim time.

    ``urdf_xml`` is the robot_description (with the ``<chefbot_sim>`` block),
    ``start`` the pose of base_footprint in the world frame.  The same seed and
    the same calls give the same run.
    """

    def __init__(self, urdf_xml: str, world: World, start: Pose2D = ORIGIN,
                 options: SimOptions | None = None, gui: bool = False, shared: BulletSim | None = None,
                 name: str = "") -> None:
        self.options = options or SimOptions()
        self.options.validate()
        self.params = load_params(urdf_xml)
        self.world = world
        self.start = start
        # shared: a world several robots live in (chefbot_sim.fleet.Fleet steps it; this object is one
        # robot in it, named ``name``); else this Simulator owns its world
        self.shared = shared is not None
        if shared is None:
            self.bullet = BulletSim(gui=gui, time_step=self.options.time_step,
                                    solver_iterations=self.options.solver_iterations)
            self.bullet.load_world(world)
        else:
            self.bullet = shared
        # the robot stands on whatever is under its start pose (a stage, a platform)
        try:
            self.body = self.bullet.add_robot(urdf_xml, start, z=world.surface_height(start.x, start.y), name=name)
        except BulletError:
            self._close_world()
            raise
        p = self.params
        self._wheels = [self.body.joint(p.drive.left_joint), self.body.joint(p.drive.right_joint)]
        self.joint_names = list(self.body.movable_joints())
        self._joint_idx = [self.body.movable_joints()[n] for n in self.joint_names]
        for name in (p.depth_camera.depth_frame, p.depth_camera.rgb_frame, p.imu.frame,
                     p.ultrasonic.frame, p.drive.base_frame, p.bumper.link):
            self.body.frame(name)  # fail now, naming the frame, not at the first reading
        self._build_cliffs()
        cam = p.depth_camera
        self.depth_camera = CameraModel.from_fov(cam.width, cam.height, cam.horizontal_fov)
        self.rgb_camera = CameraModel.from_fov(self.options.rgb_width, self.options.rgb_height, cam.horizontal_fov)
        # rendered images and clouds (chefbot_sim.camera); dense_depth: depth by rendering every pixel
        # instead of band + coarse rays (the node sets it while camera/depth/points is subscribed)
        self.rgbd = RgbdRenderer(self.body, self.rgb_camera, self.depth_camera, cam.rgb_frame,
                                 cam.depth_frame, cam.min_range, cam.max_range)
        self.dense_depth = False
        self.last_rgb: RgbFrame | None = None
        self._spawned: list[Shape] = []
        self._caster = RayCaster(world.shapes)
        self._build_depth_rays()
        self._sonar_dirs = self._cone(p.ultrasonic.field_of_view / 2.0, self.options.sonar_rings)
        self.lidar = self.options.lidar_config()
        if self.lidar is not None:
            try:
                self.body.frame(self.lidar.frame)
            except BulletError as e:
                self._close_world()
                raise SimConfigError(f"lidar_fov is {self.lidar.fov:g} but the robot has no frame "
                                     f"'{self.lidar.frame}' (expand the xacro with lidar:=360 or lidar:=270, "
                                     f"or set lidar_frame): {e}") from None
            self._lidar_dirs = self.lidar.directions()
        self.rates = {
            "clock": self.options.clock_rate, "joint_states": self.options.joint_state_rate,
            "ground_truth": self.options.ground_truth_rate, "odom": p.drive.update_rate,
            "imu": p.imu.update_rate, "ultrasonic": p.ultrasonic.update_rate,
            "cliff": max((c.update_rate for c in p.cliffs), default=0.0),
            "depth": cam.update_rate, "rgb": self.options.rgb_rate, "bumper": self.options.bumper_rate,
            "lidar": self.lidar.rate if self.lidar is not None else 0.0,
            "battery": self.options.battery_rate if self.options.battery_model and self.options.drive == "plugin"
            else 0.0,
        }
        self.drive = self.options.drive
        if self.drive == "firmware":
            # robot_standalone's diff_tf owns odom + tf; the sim must not compete
            self.rates["odom"] = 0.0
        self._odom_from_imu = self.options.odom_imu_heading and self.rates["odom"] > 0   # (the URDF has an IMU)
        self.enabled = {k: v > 0 for k, v in self.rates.items()}
        self.rng = np.random.default_rng(self.options.seed)
        self.s = _State(due={k: 1.0 / r if r > 0 else math.inf for k, r in self.rates.items()})
        self._next_due = min(self.s.due.values())
        self._imu_drift = self.options.imu_drift_config()
        self.s.imu_drift = imu_model.initial_state(self._imu_drift)
        self._battery = self.options.battery_config()
        self.charger: Pose2D | None = None     # its charger in the world (a fleet robot's, from the fleet file)
        self.s.battery_soc = self._battery.initial_soc
        self.s.wheel_prev = tuple(self.body.joint_states(self._wheels)[0])
        self.s.wheel_true_prev = self.s.wheel_measured = self.s.wheel_prev
        self.s.wheel_prev = tuple(quantise(a, self.options.wheel_encoder_counts) for a in self.s.wheel_prev)
        self.wheel_noise = self.options.wheel_noise
        self.wheel_rng = np.random.default_rng([self.options.seed, 1])   # own stream: other noise unchanged
        self._initial = None if self.shared else self.bullet.save_state()
        self.firmware: FirmwareDrive | None = None
        if self.drive == "firmware":
            try:
                self.motor = self._motor_model(urdf_xml)
                self.firmware = FirmwareDrive(self.options.pty_link, self.motor, self.s.wheel_prev,
                                              self._start_volts(), faults=self.options.faults())
            except Exception:
                self._close_world()
                raise

    # ------------------------------------------------------------ control
    @property
    def time(self) -> float:
        """Sim time in s."""
        return self.s.time

    def _motor_model(self, urdf_xml: str) -> DcMotor:
        """The wheel motors from the URDF's wheel joint limits (effort = stall
        torque N·m, velocity = free speed rad/s), else the book's Pololu 37D."""
        from chefbot_description.model import parse_urdf

        joint = parse_urdf(urdf_xml).joints.get(self.params.drive.left_joint)
        return motor_from_joint_limits(getattr(joint, "effort", None), getattr(joint, "velocity", None))

    def set_cmd_vel(self, v: float, w: float) -> None:
        """A cmd_vel (v m/s forward, w rad/s yaw rate), stamped now in sim time (plugin mode only)."""
        if self.firmware is not None:
            raise RuntimeError("set_cmd_vel: the drive is 'firmware' (cmd_vel goes through "
                               "robot_standalone.launch and the emulated LaunchPad)")
        self.s.cmd = (float(v), float(w))
        self.s.cmd_time = self.s.time

    def set_enabled(self, kind: str, on: bool) -> None:
        """Switch a reading on/off (the node switches off what nobody subscribes to).
        Readings with rate 0 (and ``odom`` in firmware mode) stay off."""
        if kind not in self.enabled:
            raise KeyError(kind)
        self.enabled[kind] = bool(on) and self.rates[kind] > 0

    def _firmware_motors(self) -> None:
        cmds = self.firmware.motor_commands(self.s.wheel_speed)
        self.body.set_joint_velocities(self._wheels, [c[0] for c in cmds], [c[1] for c in cmds])

    def _start_volts(self) -> float:
        if not self.options.battery_model:
            return self.options.battery_volts
        return battery.terminal_voltage(self._battery, self.s.battery_soc, self._battery.idle_current)

    def _discharge(self, dt: float) -> None:
        """Draw the current of the motors and the rest for ``dt`` s, less the charger's while the robot
        stands on its charger.  Firmware mode: the motors at the firmware's duties, and the board measures
        the pack's terminal voltage; plugin mode: each turning wheel's motor at its unloaded current (the
        plugin drive has no duty; an estimate)."""
        cfg = self._battery
        if self.firmware is not None:
            motor = self.motor
            motors = sum(battery.motor_current(cfg, d, motor.torque(d, w), motor.stall_torque)
                         for d, w in zip(self.firmware.duties(), self.s.wheel_speed, strict=True))
        else:
            motors = sum(cfg.motor_free_current for w in self.s.wheel_target if abs(w) > 1e-6)
        amps = cfg.idle_current + motors - (self.options.charge_current if self.on_charger() else 0.0)
        self.s.battery_soc = battery.discharge(cfg, self.s.battery_soc, amps, dt)
        self.s.battery_current = amps
        if self.firmware is not None:
            self.firmware.set_battery(battery.terminal_voltage(cfg, self.s.battery_soc, amps))

    def on_charger(self) -> bool:
        """Does the robot stand still on its charger (``charger``: a pose in the world, None = none)?"""
        if self.charger is None or self.options.charge_current <= 0:
            return False
        if any(abs(w) > 1e-6 for w in (self.s.wheel_target if self.firmware is None else self.firmware.duties())):
            return False
        pos = self.body.base_state()[0]
        return math.hypot(pos[0] - self.charger.x, pos[1] - self.charger.y) <= self.options.charger_tolerance

    @property
    def battery(self) -> tuple[float, float]:
        """(state of charge 0..1, current A; negative: charging) of the simulated pack (battery_model)."""
        return self.s.battery_soc, self.s.battery_current

    def _drive(self) -> None:
        d = self.params.drive
        v, w = self.s.cmd
        if self.s.time - self.s.cmd_time > d.command_timeout:
            v, w = 0.0, 0.0
        r = d.wheel_radius
        target = ((v - w * d.wheel_separation / 2.0) / r, (v + w * d.wheel_separation / 2.0) / r)
        if target != self.s.wheel_target:
            self.body.set_joint_velocities(self._wheels, target, d.torque)
            self.s.wheel_target = target

    # ------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> list[Event]:
        """Advance ``n`` physics steps; return the readings that fell due.  (A robot in a shared
        world is stepped by its :class:`chefbot_sim.fleet.Fleet`.)"""
        if self.shared:
            raise RuntimeError("step: this robot lives in a shared world; step the Fleet")
        events: list[Event] = []
        for _ in range(n):
            self.before_physics()
            self.bullet.step()
            self.after_physics(events)
        return events

    def before_physics(self) -> None:
        """Apply the drive's wheel commands for the coming physics step."""
        if self.firmware is None:
            self._drive()
        else:
            self._firmware_motors()

    def after_physics(self, events: list[Event]) -> None:
        """Count the physics step just taken; append the readings that fell due to ``events``."""
        dt = self.options.time_step
        fw = self.firmware
        self.s.steps += 1
        self.s.time = self.s.steps * dt
        if fw is not None:
            ang, vel = self.body.joint_states(self._wheels)
            self.s.wheel_speed = (float(vel[0]), float(vel[1]))
            fw.after_physics(self._measure_wheels(ang), self.s.time)
            if self.options.battery_model and self.s.steps % BATTERY_STEPS == 0:
                self._discharge(BATTERY_STEPS * dt)
        elif self.options.battery_model and self.s.steps % BATTERY_STEPS == 0:
            self._discharge(BATTERY_STEPS * dt)
        if self.s.time + 1e-9 < self._next_due:
            return  # most steps: no reading due
        for kind in SENSORS:
            rate = self.rates[kind]
            if rate <= 0 or self.s.time + 1e-9 < self.s.due[kind]:
                continue
            # stay on the rate's grid; only re-anchor if we fell behind
            self.s.due[kind] += 1.0 / rate
            if self.s.due[kind] <= self.s.time + 1e-9:
                self.s.due[kind] = self.s.time + 1.0 / rate
            if kind == "odom":  # integrate odometry even when nobody listens
                data = self._odom()
                if self.enabled[kind]:
                    events.append(Event(kind, self.s.time, data))
                continue
            if kind == "imu":
                data = self._imu()
                if fw is not None:
                    fw.set_imu(data["orientation"])
                if self.enabled[kind]:
                    events.append(Event(kind, self.s.time, data))
                continue
            if kind == "ultrasonic" and fw is not None:  # the board's HC-SR04 always measures
                data = self._sonar()
                fw.set_ultrasonic(data["range"])
                if self.enabled[kind]:
                    events.append(Event(kind, self.s.time, data))
                continue
            if self.enabled[kind]:
                events.append(Event(kind, self.s.time, self._read(kind)))
        self._next_due = min(self.s.due.values())

    def run(self, duration: float, on_event: Callable[[Event], None] | None = None) -> None:
        """Advance by ``duration`` s of sim time, passing each reading to ``on_event``."""
        n = int(round(duration / self.options.time_step))
        for _ in range(n):
            for e in self.step():
                if on_event is not None:
                    on_event(e)

    def _read(self, kind: str) -> Any:
        if kind == "clock":
            return self.s.time
        if kind == "joint_states":
            pos, vel = self.body.joint_states(self._joint_idx)
            return {"name": self.joint_names, "position": pos, "velocity": vel}
        if kind == "ground_truth":
            return self.ground_truth()
        if kind == "ultrasonic":
            return self._sonar()
        if kind == "cliff":
            return self.cliff()
        if kind == "depth":
            return self.depth_image()
        if kind == "rgb":
            return self.rgb_image()
        if kind == "lidar":
            return self.lidar_scan()
        if kind == "battery":
            cfg = self._battery
            return {"soc": self.s.battery_soc, "current": self.s.battery_current,
                    "volts": battery.terminal_voltage(cfg, self.s.battery_soc, max(self.s.battery_current, 0.0)),
                    "capacity_ah": cfg.capacity_ah, "charging": self.s.battery_current < 0}
        if kind == "bumper":
            contacts = self.body.contacts()
            return {"pressed": bool(contacts),
                    "bodies": sorted({self.bullet.body_name(c[1]) for c in contacts})}
        raise KeyError(kind)

    # ------------------------------------------------------------ readings
    def ground_truth(self) -> GroundTruthData:
        """base_footprint pose in the world frame and its twist in the base frame."""
        pos, quat, lin, ang = self.body.base_state()
        rot = quat_to_matrix(quat)
        return {"position": pos, "orientation": quat, "linear": rot.T @ lin, "angular": rot.T @ ang,
                "x": float(pos[0]), "y": float(pos[1]), "yaw": yaw_from_quaternion(*quat)}

    def _measure_wheels(self, true_angles) -> tuple[float, float]:
        """The wheel angles (rad) the encoders report now (see chefbot_sim.wheel_noise)."""
        now = (float(true_angles[0]), float(true_angles[1]))
        if self.wheel_noise.active:
            self.s.wheel_measured = measure_wheels(self.wheel_noise, self.wheel_rng, self.s.wheel_true_prev, now,
                                                   self.s.wheel_measured, self.params.drive.wheel_radius)
        else:
            self.s.wheel_measured = (self.s.wheel_measured[0] + now[0] - self.s.wheel_true_prev[0],
                                     self.s.wheel_measured[1] + now[1] - self.s.wheel_true_prev[1])
        self.s.wheel_true_prev = now
        return self.s.wheel_measured

    def _odom(self) -> OdomData:
        d = self.params.drive
        true_ang, vel = self.body.joint_states(self._wheels)
        counts = self.wheel_noise.encoder_counts
        ang = [quantise(a, counts) for a in self._measure_wheels(true_ang)]
        pl, pr = self.s.wheel_prev
        dl = (ang[0] - pl) * d.wheel_radius
        dr = (ang[1] - pr) * d.wheel_radius
        self.s.wheel_prev = (float(ang[0]), float(ang[1]))
        wn = self.wheel_noise
        vel = (vel[0] / (1.0 + wn.radius_error_left), vel[1] / (1.0 + wn.radius_error_right))
        ds, dth = (dl + dr) / 2.0, (dr - dl) / d.wheel_separation
        x, y, th = self.s.odom
        v = (vel[0] + vel[1]) / 2.0 * d.wheel_radius
        w = (vel[1] - vel[0]) * d.wheel_radius / d.wheel_separation
        if self._odom_from_imu:
            # the IMU's heading (0 at the start pose, drifting with the gyro bias as of its last sample)
            _, quat, _, ang = self.body.base_state()
            bias, drift = self.s.imu_drift[0], self.s.imu_drift[1]
            dth = wrap_angle(yaw_from_quaternion(*quat) - self.start.yaw + drift - th)
            w = float(ang[2]) + bias
        x += ds * math.cos(th + dth / 2.0)
        y += ds * math.sin(th + dth / 2.0)
        th = math.atan2(math.sin(th + dth), math.cos(th + dth))
        self.s.odom = (x, y, th)
        return {"x": x, "y": y, "yaw": th, "v": float(v), "w": float(w)}

    def _imu(self) -> ImuData:
        imu = self.params.imu
        pos, rot = self.body.frame_pose(imu.frame)
        _, _, lin, ang = self.body.base_state()
        prev = self.s.imu_prev_vel
        period = 1.0 / self.rates["imu"]
        acc_world = np.zeros(3) if prev is None else (lin - prev) / period
        self.s.imu_prev_vel = lin
        # an accelerometer at rest reads +g upwards
        acc = rot.T @ (acc_world + np.array([0.0, 0.0, 9.81]))
        gyro = rot.T @ ang
        gyro = gyro + self.rng.normal(0.0, imu.gyro_noise_stddev, 3) if imu.gyro_noise_stddev > 0 else gyro
        acc = acc + self.rng.normal(0.0, imu.accel_noise_stddev, 3) if imu.accel_noise_stddev > 0 else acc
        # the real DMP: heading relative to power-on, drifting with the gyro bias
        self.s.imu_drift = imu_model.advance(self.s.imu_drift, self.s.time, self._imu_drift, self.options.seed)
        quat, gyro = imu_model.apply(matrix_to_quat(rot), gyro, self.start.yaw, self.s.imu_drift, self._imu_drift)
        return {"orientation": quat, "angular_velocity": gyro, "linear_acceleration": acc,
                "gyro_variance": imu.gyro_noise_stddev ** 2, "accel_variance": imu.accel_noise_stddev ** 2}

    @staticmethod
    def _cone(half_angle: float, rings: int) -> np.ndarray:
        """Unit directions (frame +x axis) filling a cone: the axis + rings of 8 rays."""
        dirs = [np.array([1.0, 0.0, 0.0])]
        for k in range(1, rings + 1):
            a = half_angle * k / rings
            for j in range(8):
                phi = 2.0 * math.pi * j / 8
                dirs.append(np.array([math.cos(a), math.sin(a) * math.cos(phi), math.sin(a) * math.sin(phi)]))
        return np.array(dirs)

    def _sonar(self) -> UltrasonicData:
        """Range (m) of the nearest echo in the cone; +inf without an echo (REP 117)."""
        us = self.params.ultrasonic
        pos, rot = self.body.frame_pose(us.frame)
        # no floor echoes: the lower rays of the 15 degree cone would hit the
        # floor 0.8 m ahead, which the real HC-SR04 does not report
        dirs = self._sonar_dirs @ rot.T
        t = np.minimum(self._caster.cast(pos, dirs, us.max_range, floor=False),
                       self._robot_hits(pos, dirs, us.max_range))
        r = float(np.min(t))
        if math.isfinite(r):
            if us.noise_stddev > 0:
                r += float(self.rng.normal(0.0, us.noise_stddev))
            r = min(max(r, us.min_range), us.max_range)
        return {"range": r, "min_range": us.min_range, "max_range": us.max_range,
                "field_of_view": us.field_of_view}

    def _robot_hits(self, origin: np.ndarray, dirs: np.ndarray, max_t: float) -> np.ndarray:
        """For the ray-cast sensors (depth camera, sonar: the analytic caster sees only the
        static shapes): ``t`` of each ray ``origin + t·dir`` where it first hits another robot's
        body, ``inf`` elsewhere.  Only the rays that pass within ROBOT_REACH of another robot's
        centre (in the plane) are cast, with pybullet, against those robots' real collision shapes;
        alone in the world, or with the others out of sight, it costs next to nothing."""
        out = np.full(len(dirs), np.inf)
        others = [r for r in self.bullet.robots if r is not self.body]
        if not others:
            return out
        d2 = dirs[:, :2]
        near = np.zeros(len(dirs), bool)
        mask = 0
        for r in others:
            c = r.base_state()[0][:2] - origin[:2]
            along = d2 @ c                                   # t * |d|^2 at the closest approach
            dd = np.einsum("ij,ij->i", d2, d2)
            with np.errstate(divide="ignore", invalid="ignore"):
                closest = np.where(dd > 0, along / dd, 0.0)  # t of the closest approach to c
            closest = np.clip(closest, 0.0, max_t)
            gap = np.hypot(*(d2 * closest[:, None] - c).T)
            hit = gap <= ROBOT_REACH
            if hit.any():
                near |= hit
                mask |= r.group_bit
        if not mask:
            return out
        sel = np.flatnonzero(near)
        frac, _ = self.bullet.cast_rays(np.broadcast_to(origin, (len(sel), 3)), origin + dirs[sel] * max_t,
                                        robots=mask, world=False)
        out[sel] = np.where(frac < 1.0, frac * max_t, np.inf)
        return out

    def lidar_scan(self) -> LidarData:
        """One scan of the lidar: a ray per beam in the laser frame's x-y plane, one ``rayTestBatch``
        against every body of the world (spawned obstacles included) and the floor (which only a
        tilted robot sees), never the robot itself.  Ranges (m) per :meth:`LidarConfig.ranges`:
        noise, +inf = no return within range_max, -inf = closer than range_min (REP 117).

        The whole scan is taken at one instant (the sim time of the event): the sweep of a real
        spinning unit during its 0.1 s turn is not modelled, so ``time_increment`` is 0."""
        lid = self.lidar
        pos, rot = self.body.frame_pose(lid.frame)
        dirs = self._lidar_dirs @ rot.T
        frac, _ = self.body.cast_rays(np.broadcast_to(pos, dirs.shape), pos + dirs * lid.range_max, floor=True)
        dist = np.where(frac < 1.0, frac * lid.range_max, np.inf)
        return {"ranges": lid.ranges(dist, self.rng), "angle_min": lid.angle_min,
                "angle_increment": lid.angle_increment, "angle_max": lid.angle_max,
                "range_min": lid.range_min, "range_max": lid.range_max, "scan_time": 1.0 / lid.rate,
                "frame": lid.frame}

    def _build_cliffs(self) -> None:
        """Cliff sensors of the URDF block: per sensor its parent frame, beam origin and
        direction (+x of the sensor pose) in that frame, and limits (m)."""
        cliffs = self.params.cliffs
        self.cliff_frames = []   # what each Range is stamped with: the sensor's URDF frame
        for c in cliffs:
            self.body.frame(c.parent)
            # the sensor's frame carries its parent's tf prefix (xacro frame_prefix, e.g. 'chefbot1/')
            frame = c.parent[:c.parent.rfind("/") + 1] + f"{c.name}_link"
            try:
                self.body.frame(frame)
                self.cliff_frames.append(frame)
            except BulletError:   # a model without the frames (older URDF): the sensor's name
                self.cliff_frames.append(c.name)
        self._cliff_parents = sorted({c.parent for c in cliffs})
        self._cliff_parent_idx = np.array([self._cliff_parents.index(c.parent) for c in cliffs], dtype=int)
        poses = [c.pose() for c in cliffs]
        self._cliff_origin = np.array([t[:3, 3] for t in poses], float).reshape(-1, 3)
        self._cliff_dir = np.array([t[:3, 0] for t in poses], float).reshape(-1, 3)
        self._cliff_min = np.array([c.min_range for c in cliffs], float)
        self._cliff_max = np.array([c.max_range for c in cliffs], float)

    def cliff(self) -> CliffData:
        """Range (m) along each cliff sensor's beam to the floor or whatever is below, one
        ``rayTestBatch`` for all sensors; REP 117: +inf = nothing within max_range (a drop),
        -inf = closer than min_range.

        One ray per sensor, on the beam axis: the 5° cone is 3 mm wide at the 0.03 m
        the floor is away and 13 mm at max range, well under the robot's stopping
        distance, so a cone of rays would cost more and change nothing that matters.
        """
        frames = [self.body.frame_pose(name) for name in self._cliff_parents]
        pos = np.array([f[0] for f in frames])[self._cliff_parent_idx]
        rot = np.array([f[1] for f in frames])[self._cliff_parent_idx]
        origins = pos + np.einsum("nij,nj->ni", rot, self._cliff_origin)
        dirs = np.einsum("nij,nj->ni", rot, self._cliff_dir)
        frac, _ = self.body.cast_rays(origins, origins + dirs * self._cliff_max[:, None], floor=True)
        ranges = np.where(frac < 1.0, frac * self._cliff_max, np.inf)
        ranges[ranges < self._cliff_min] = -np.inf
        return {"names": [c.name for c in self.params.cliffs], "frames": self.cliff_frames, "range": ranges,
                "min_range": self._cliff_min, "max_range": self._cliff_max,
                "field_of_view": np.array([c.field_of_view for c in self.params.cliffs])}

    def _build_depth_rays(self) -> None:
        cam = self.depth_camera
        band = self.options.depth_band_rows
        # the rows depth_to_scan reads (depthimage_to_laserscan's offset = int(cy - scan_height / 2)):
        # one row off, its top row was coarse-filled from 2 rows higher and saw overhangs it must not
        first = max(0, int(cam.cy - band // 2))
        self._band_rows = np.arange(first, min(cam.height, first + band))
        mode = self.options.depth_fill
        stride = self.options.depth_coarse_stride
        if mode == "full":
            rows = np.arange(cam.height)
            self._depth_rows, self._depth_cols = rows, np.arange(cam.width)
            self._coarse = None
        else:
            self._depth_rows, self._depth_cols = self._band_rows, np.arange(cam.width)
            self._coarse = None
            if mode == "coarse":
                rows = np.arange(stride // 2, cam.height, stride)
                cols = np.arange(stride // 2, cam.width, stride)
                self._coarse = (rows, cols)
        self._dirs_exact = cam.rays(self._depth_rows, self._depth_cols)
        self._dirs_coarse = cam.rays(*self._coarse) if self._coarse is not None else None
        # one cast per frame for both sets (a cast has ~0.3 ms of fixed cost)
        self._dirs_all = (self._dirs_exact if self._dirs_coarse is None
                          else np.vstack([self._dirs_exact, self._dirs_coarse]))

    def depth_image(self) -> np.ndarray:
        """Depth (m, along the optical axis) as float32 (H, W); NaN = no reading.

        Rows of the scan band (``depth_band_rows`` around the centre) are exact
        per pixel; with ``depth_fill`` coarse, other pixels take the depth of the
        nearest coarse sample; with none they are NaN; with full every pixel is exact.
        """
        cam, p = self.depth_camera, self.params.depth_camera
        pos, rot = self.body.frame_pose(p.depth_frame)
        if self.dense_depth:
            # every pixel rendered (for the point clouds), but the scan band stays the exact
            # per-pixel ray cast, so depth_to_scan sees the same ranges either way (the
            # renderer's depth differs at object edges and shifted amcl's fit)
            img = self.rgbd.render_depth()
            dirs = self._dirs_exact
        else:
            img = np.full((cam.height, cam.width), np.nan, dtype=np.float32)
            dirs = self._dirs_all
        dirs_w = dirs @ rot.T
        t_all = np.minimum(self._caster.cast(pos, dirs_w, p.max_range), self._robot_hits(pos, dirs_w, p.max_range))
        n_exact = len(self._dirs_exact)
        t = t_all[:n_exact]
        img[self._depth_rows[0]:self._depth_rows[-1] + 1, :] = t.reshape(len(self._depth_rows), cam.width)
        if self.dense_depth:
            return self._depth_noise_and_range(img)
        if self._coarse is not None:
            rows, cols = self._coarse
            tc = t_all[n_exact:].reshape(len(rows), len(cols))
            stride = self.options.depth_coarse_stride
            ri = np.clip(np.arange(cam.height) // stride, 0, len(rows) - 1)
            ci = np.clip(np.arange(cam.width) // stride, 0, len(cols) - 1)
            fill = tc[ri][:, ci]
            mask = np.ones(cam.height, bool)
            mask[self._band_rows] = False
            img[mask] = fill[mask]
        return self._depth_noise_and_range(img)

    def _depth_noise_and_range(self, img: np.ndarray) -> np.ndarray:
        p = self.params.depth_camera
        if p.noise_stddev > 0:  # float32 normals: ~2x cheaper for 19 200 pixels
            img += self.rng.standard_normal(img.shape, dtype=np.float32) * np.float32(p.noise_stddev)
        img[~((img >= p.min_range) & (img <= p.max_range))] = np.nan
        return img

    def rgb_image(self) -> np.ndarray:
        """uint8 (H, W, 3) colour image from the RGB optical frame (TinyRenderer); the render's
        registered depth stays in ``last_rgb`` (for camera/depth_registered/points)."""
        self.last_rgb = self.rgbd.render_rgb()
        return self.last_rgb.image

    # ------------------------------------------------------------ world edits
    def _rebuild_caster(self) -> None:
        self._caster = RayCaster(self.world.shapes + self._spawned)

    def spawn(self, shape: Shape, add_body: bool = True) -> None:
        """Add a static obstacle (its name must be new).  In a shared world the Fleet adds the
        body once (``add_body``) and tells every robot's ray caster."""
        if any(s.name == shape.name for s in self.world.shapes + self._spawned):
            raise ValueError(f"an object named '{shape.name}' exists already")
        if add_body:
            self.bullet.add_shape(shape)
        self._spawned.append(shape)
        self._rebuild_caster()

    def remove(self, name: str, remove_body: bool = True) -> None:
        """Remove a spawned obstacle (``remove_body``: as in :meth:`spawn`)."""
        for s in self._spawned:
            if s.name == name:
                if remove_body:
                    self.bullet.remove_shape(name)
                self._spawned.remove(s)
                self._rebuild_caster()
                return
        raise ValueError(f"no spawned obstacle named '{name}'")

    @property
    def spawned(self) -> list[str]:
        """Names of the obstacles spawned since start, in order."""
        return [s.name for s in self._spawned]

    def _resync_wheels(self) -> None:
        """Wheel angles changed outside physics: no odometry, no encoder edges for that."""
        self.s.wheel_true_prev = tuple(float(a) for a in self.body.joint_states(self._wheels)[0])
        counts = self.wheel_noise.encoder_counts
        self.s.wheel_prev = tuple(quantise(a, counts) for a in self.s.wheel_measured)
        self.s.wheel_speed = (0.0, 0.0)
        if self.firmware is not None:
            self.firmware.resync(self.s.wheel_measured)

    def teleport(self, pose: Pose2D) -> None:
        """Put the robot at ``pose`` at rest, on the surface there (floor or platform top);
        odometry (and in firmware mode the encoder counts) keeps counting from where it was."""
        self.body.teleport(pose, z=surface_height(self.world.shapes + self._spawned, pose.x, pose.y))
        self._resync_wheels()
        self.s.imu_prev_vel = None
        self.s.cmd_time = -math.inf

    def reset(self) -> None:
        """Robot back to the start pose at rest, spawned obstacles removed,
        odometry zeroed.  Sim time keeps running forward (like Gazebo's
        reset_world), so ROS clients never see time jump back.  In a shared world only
        this robot goes back (the Fleet removes the obstacles)."""
        if self.shared:
            self.body.teleport(self.start, z=self.world.surface_height(self.start.x, self.start.y))
        else:
            for name in list(self.spawned):
                self.remove(name)
            self.bullet.restore_state(self._initial)
        self.s.wheel_target = (math.nan, math.nan)  # force re-applying the motors
        self.s.cmd = (0.0, 0.0)
        self.s.cmd_time = -math.inf
        self.s.odom = (0.0, 0.0, 0.0)
        self._resync_wheels()
        self.s.imu_prev_vel = None
        if self.firmware is None:
            self._drive()

    # ------------------------------------------------------------ snapshots
    def snapshot(self) -> tuple[int, _State, list[Shape]]:
        """Everything needed to continue identically later (physics + drive,
        odometry, schedules, noise generator).  Valid while the set of spawned
        obstacles is unchanged.  Not in firmware mode (the firmware core's state
        cannot be saved)."""
        if self.firmware is not None:
            raise RuntimeError("snapshot: not available in firmware mode (the firmware core has no snapshots)")
        if self.shared:
            raise RuntimeError("snapshot: not available for a robot in a shared world")
        st = _State(**{k: getattr(self.s, k) for k in self.s.__dataclass_fields__})
        st.due = dict(self.s.due)
        st.rng_state = self.rng.bit_generator.state
        st.wheel_rng_state = self.wheel_rng.bit_generator.state
        return self.bullet.save_state(), st, list(self._spawned)

    def restore(self, snap: tuple[int, _State, list[Shape]]) -> None:
        """Go back to a :meth:`snapshot` (same spawned obstacles required, else ValueError)."""
        state_id, st, spawned = snap
        if [s.name for s in spawned] != self.spawned:
            raise ValueError("snapshot was taken with different spawned obstacles")
        self.bullet.restore_state(state_id)
        self.s = _State(**{k: getattr(st, k) for k in st.__dataclass_fields__})
        self.s.due = dict(st.due)
        self._next_due = min(self.s.due.values())
        self.rng.bit_generator.state = st.rng_state
        self.wheel_rng.bit_generator.state = st.wheel_rng_state
        target = self.s.wheel_target
        self.body.set_joint_velocities(self._wheels, target, self.params.drive.torque)

    @property
    def pty_path(self) -> str | None:
        """Firmware mode: the emulated LaunchPad's pty (what launchpad_node opens)."""
        return self.firmware.pty_path if self.firmware is not None else None

    def close(self) -> None:
        """Free pybullet and, in firmware mode, unplug the pty (the symlink goes away)."""
        if self.firmware is not None:
            self.firmware.close()
            self.firmware = None
        self._close_world()

    def _close_world(self) -> None:
        if not self.shared:
            self.bullet.close()


class Pacer:
    """Holds the sim to ``real_time_factor`` × wall time (0 = as fast as possible).

    By default a sim that fell behind (a slow step, a loaded machine) catches up
    by running flat out until it is back on schedule.  With ``max_lag`` (s of
    wall time) it never runs ahead of ``real_time_factor`` instead: when it is
    more than ``max_lag`` behind, the schedule restarts from now.  Firmware
    mode needs that: a catch-up burst would hand the real-time driver several
    encoder lines at once, which it must treat as an impossible jump.
    """

    def __init__(self, real_time_factor: float, clock: Callable[[], float] = _time.monotonic,
                 max_lag: float | None = None) -> None:
        if real_time_factor < 0:
            raise ValueError(f"real_time_factor must be >= 0, got {real_time_factor}")
        if max_lag is not None and max_lag < 0:
            raise ValueError(f"max_lag must be >= 0, got {max_lag}")
        self.rtf = real_time_factor
        self.max_lag = max_lag
        self._clock = clock
        self._wall0: float | None = None
        self._sim0 = 0.0

    def restart(self, sim_time: float) -> None:
        """Forget the past (after a pause): pace from here on."""
        self._wall0 = self._clock()
        self._sim0 = sim_time

    def delay(self, sim_time: float) -> float:
        """Seconds of wall time to wait before simulating past ``sim_time``."""
        if self.rtf <= 0:
            return 0.0
        if self._wall0 is None:
            self.restart(sim_time)
        now = self._clock()
        target = self._wall0 + (sim_time - self._sim0) / self.rtf
        if self.max_lag is not None and now - target > self.max_lag:
            self.restart(sim_time)
            return 0.0
        return max(0.0, target - now)
