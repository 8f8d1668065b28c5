"""Firmware-in-the-loop drive: the LaunchPad emulated by our firmware core, on sim time.

The simulator owns a :class:`chefbot_firmware.virtual_board.VirtualBoard`
(``model_wheels=False``): a pseudo-terminal (plus a symlink such as
``/tmp/chefbot_launchpad``) whose bytes go through the firmware's own parser,
watchdog, encoder decoder, scheduler and line formatter
(``chefbot_firmware.host.FirmwareHost``).  Each physics step:

1. the firmware's motor outputs (INA/INB/PWM, read as a signed duty) drive the
   wheels through :class:`DcMotor` (torque–speed line + gearbox friction, see there);
2. physics steps;
3. the wheel joints' angle changes go into the firmware's quadrature decoder
   (8400 edges per revolution) and the board's clock advances by the same
   step, so its 30 Hz status lines and its 500 ms watchdog run on SIM time.

The sonar range, the IMU orientation and the battery voltage come from the
simulator.  No pybullet and no rospy here: the simulator core passes wheel
states in and applies the motor commands it gets back.
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

BOOK_STALL_TORQUE = 18.0 * 9.80665 / 100.0   # N·m: Pololu 37D 12 V, ~18 kg·cm at the gearbox output
BOOK_FREE_SPEED = 80.0 * 2.0 * math.pi / 60.0  # rad/s: 80 RPM at 12 V, no load
# Gearbox + brush friction: the 37D's no-load current (~0.2 A) over its stall
# current (~5.5 A) is ~3.6 % of the stall torque.
BOOK_FRICTION = 0.036 * BOOK_STALL_TORQUE  # N·m at the wheel
DEFAULT_BATTERY_VOLTS = 12.4                 # V: a charged 12 V SLA at rest


class FirmwareDriveError(RuntimeError):
    """The firmware-in-the-loop drive cannot start or was misused (names the culprit)."""


@dataclass(frozen=True)
class DcMotor:
    """A gear motor behind an H-bridge: the DC torque–speed line plus gearbox friction.

    At duty ``d`` (−1..1, the VNH2SP30's signed PWM fraction) and wheel speed
    ``w`` (rad/s, robot-forward positive) the motor's torque at the wheel is

        tau_m = stall_torque · (d − w / w0),  clamped to ±stall_torque

    (the permanent-magnet DC motor line; the clamp stands for the driver's
    current limit), and the gearbox loses a Coulomb friction torque
    ``friction_torque`` against the motion (at rest it holds up to that much).
    ``w0`` is the line's ideal no-load speed, chosen so that the unloaded
    wheel at full duty turns at ``free_speed`` (the datasheet's 80 RPM, which
    already includes the friction): ``w0 = free_speed / (1 − friction/stall)``.
    Duty 0 is the driver's brake (INA = INB): the shorted motor brakes with a
    torque proportional to speed, and friction stops the last bit.  Small
    duties (|d| <= friction/stall) do not turn the wheel, as on the robot.

    How it is applied: a pybullet velocity motor whose target is the speed
    where motor torque and friction balance and whose force limit is the net
    torque at the current speed, re-evaluated every physics step.  The motor
    constraint is implicit, so it pushes toward the balance speed with the
    model's torque but never overshoots it, even for a lifted wheel whose
    small inertia would make an explicit torque step unstable at 240 Hz.
    """

    stall_torque: float = BOOK_STALL_TORQUE   # N·m at the wheel
    free_speed: float = BOOK_FREE_SPEED       # rad/s at the wheel, full duty, no load
    friction_torque: float = BOOK_FRICTION    # N·m at the wheel, gearbox + brushes

    def __post_init__(self) -> None:
        for name in ("stall_torque", "free_speed", "friction_torque"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise FirmwareDriveError(f"DcMotor.{name} must be a finite number >= 0, got {value!r}")
        if self.stall_torque <= 0 or self.free_speed <= 0:
            raise FirmwareDriveError("DcMotor.stall_torque and DcMotor.free_speed must be > 0")
        if self.friction_torque >= self.stall_torque:
            raise FirmwareDriveError(f"DcMotor.friction_torque ({self.friction_torque}) must be below "
                                     f"stall_torque ({self.stall_torque})")

    @property
    def _f(self) -> float:
        return self.friction_torque / self.stall_torque

    @property
    def ideal_speed(self) -> float:
        """w0 (rad/s): where the line alone reaches zero torque at full duty."""
        return self.free_speed / (1.0 - self._f)

    def torque(self, duty: float, speed: float) -> float:
        """Motor torque (N·m) at ``duty`` (−1..1, clipped) and wheel ``speed`` (rad/s), before friction."""
        d = max(-1.0, min(1.0, duty))
        tau = self.stall_torque * (d - speed / self.ideal_speed)
        return max(-self.stall_torque, min(self.stall_torque, tau))

    def target_speed(self, duty: float) -> float:
        """Speed (rad/s) where motor torque and friction balance (no other load)."""
        d = max(-1.0, min(1.0, duty))
        return math.copysign(self.ideal_speed * max(abs(d) - self._f, 0.0), d)

    def velocity_command(self, duty: float, speed: float) -> tuple[float, float]:
        """(target speed rad/s, force limit N·m) for a velocity motor standing in for the model."""
        target = self.target_speed(duty)
        if speed == 0.0 and target == 0.0:
            return 0.0, self.friction_torque          # at rest: friction holds
        direction = math.copysign(1.0, speed) if speed != 0.0 else math.copysign(1.0, target)
        net = self.torque(duty, speed) - self.friction_torque * direction
        return target, abs(net)

    def steady_speed(self, duty: float, load_torque: float = 0.0) -> float:
        """Forward speed (rad/s) where motor torque balances friction plus ``load_torque``
        (N·m, resisting forward motion); 0 if the motor cannot overcome them."""
        d = max(-1.0, min(1.0, duty))
        return self.ideal_speed * max(d - (self.friction_torque + load_torque) / self.stall_torque, 0.0)


def motor_from_joint_limits(effort: float | None, velocity: float | None) -> DcMotor:
    """A :class:`DcMotor` from a URDF wheel joint ``<limit effort velocity>`` (N·m, rad/s);
    missing values fall back to the book's motor (18 kg·cm, 80 RPM).  Friction is
    the same fraction of the stall torque as the book motor's (3.6 %)."""
    stall = float(effort) if effort else BOOK_STALL_TORQUE
    return DcMotor(stall_torque=stall, free_speed=float(velocity) if velocity else BOOK_FREE_SPEED,
                   friction_torque=BOOK_FRICTION / BOOK_STALL_TORQUE * stall)


class FirmwareDrive:
    """The emulated LaunchPad on a pty, stepped by the simulator on sim time.

    ``link``: symlink to the pty's slave end ('' = none; the path is then only
    in :attr:`pty_path`).  ``wheel_angles``: the wheel joint angles (rad,
    robot-forward positive, left then right) at the start.  ``faults``: a
    ``chefbot_firmware.virtual_board.BuildFaults``, the robot wired wrong (None: right).
    """

    def __init__(self, link: str, motor: DcMotor, wheel_angles: Sequence[float],
                 battery_volts: float = DEFAULT_BATTERY_VOLTS, faults=None) -> None:
        try:
            from chefbot_firmware.virtual_board import VirtualBoard
        except ImportError as e:  # pragma: no cover - chefbot_bringup is a dependency
            raise FirmwareDriveError(f"chefbot_firmware.virtual_board is not importable: {e}") from e
        if not (math.isfinite(battery_volts) and battery_volts >= 0):
            raise FirmwareDriveError(f"battery_volts must be a finite number >= 0, got {battery_volts!r}")
        if link:
            parent = os.path.dirname(os.path.abspath(link))
            if not os.path.isdir(parent):
                raise FirmwareDriveError(f"pty_link '{link}': directory {parent} does not exist")
        try:
            self.board = VirtualBoard(link or None, model_wheels=False, faults=faults)
        except OSError as e:
            raise FirmwareDriveError(f"cannot open a pseudo-terminal (pty_link '{link}'): {e}") from e
        except Exception as e:  # FirmwareLibraryMissing and friends: say what to build
            raise FirmwareDriveError(f"cannot start the firmware core: {e}") from e
        self.motor = motor
        self.link = link
        self._angles = [float(a) for a in wheel_angles]
        self._board_us = 0            # µs of sim time the board has run
        self.board.fw.set_battery_volts(battery_volts)

    # ------------------------------------------------------------ properties
    @property
    def pty_path(self) -> str:
        """The pty's slave device (e.g. /dev/pts/7): what launchpad_node opens."""
        return self.board.path

    @property
    def drive_state(self) -> str:
        """The firmware's drive state: idle (no command since reset), run, timeout (watchdog stop)."""
        return self.board.fw.drive_state

    def duties(self) -> tuple[float, float]:
        """Signed duties (−1..1, robot-forward) that reach the left and right motors now: the driver's
        outputs through the robot's wiring (``faults``: swapped leads or channels; none: the firmware's wish)."""
        return self.board.motor_duty(0), self.board.motor_duty(1)

    # ------------------------------------------------------------ stepping
    def motor_commands(self, speeds: Sequence[float]) -> list[tuple[float, float]]:
        """Velocity-motor (target rad/s, force limit N·m) per wheel for the coming
        physics step, from the firmware's duties and the wheel ``speeds`` (rad/s)."""
        return [self.motor.velocity_command(d, w) for d, w in zip(self.duties(), speeds, strict=True)]

    def after_physics(self, wheel_angles: Sequence[float], sim_time: float) -> None:
        """The wheels now stand at ``wheel_angles`` (rad) at ``sim_time`` (s): encoder
        edges into the firmware, bytes from the pty in, the board's clock up to
        ``sim_time``, its output to the pty."""
        board = self.board
        for side in (0, 1):
            angle = float(wheel_angles[side])
            d = angle - self._angles[side]
            self._angles[side] = angle
            if d:
                board.turn_wheel(side, d)
        due = int(round(sim_time * 1e6)) - self._board_us
        if due > 0:
            board.step(due * 1e-6)   # VirtualBoard rounds to whole µs: exact, no drift
            self._board_us += due

    def resync(self, wheel_angles: Sequence[float]) -> None:
        """Forget angle changes made outside physics (teleport, reset): no encoder edges."""
        self._angles = [float(a) for a in wheel_angles]

    # ------------------------------------------------------------ sensor inputs
    def set_ultrasonic(self, range_m: float) -> None:
        """Distance (m) the HC-SR04 echoes from now on; inf/NaN = no echo."""
        self.board.fw.set_ultrasonic_cm(range_m * 100.0 if math.isfinite(range_m) else None)

    def set_imu(self, quat_xyzw: Sequence[float]) -> None:
        """Orientation (x, y, z, w) the MPU6050's DMP streams from now on."""
        x, y, z, w = (float(v) for v in quat_xyzw)
        self.board.fw.set_imu_quaternion(x, y, z, w)

    def set_battery(self, volts: float) -> None:
        """Battery voltage (V) the board measures."""
        self.board.fw.set_battery_volts(float(volts))

    # ------------------------------------------------------------ fault injection
    @property
    def plugged(self) -> bool:
        """False between :meth:`unplug` and :meth:`replug`."""
        return self.board.port.master >= 0

    def unplug(self) -> None:
        """Pull the LaunchPad's USB cable: the pty and ``link`` disappear, the driver's port fails;
        the board keeps running on sim time (its 500 ms watchdog stops the motors).  Idempotent."""
        if self.plugged:
            self.board.unplug()

    def replug(self) -> str:
        """Plug it back in: a new pty (new :attr:`pty_path`) under the same ``link``; the board's
        state (encoder counts, watchdog) carries on.  Returns the new pty path.  Idempotent."""
        if not self.plugged:
            self.board.reconnect(self.link or None)
        return self.pty_path

    def emit_garbage(self) -> int:
        """A burst of malformed lines to the driver (``virtual_board.MALFORMED_BURST``: binary
        noise, truncated lines, wrong field counts, huge numbers, NaN/inf, bad CRC, overlong);
        returns how many lines (0 while unplugged)."""
        return self.board.emit_garbage()

    def close(self) -> None:
        """Unplug: the pty and the symlink go away."""
        self.board.close()
