"""A LaunchPad on a pseudo-terminal, running our own firmware core (host library).

``launchpad_node`` cannot tell it from the real board: it opens the pty's slave
path (or a fixed symlink to it), and the bytes go through the firmware's own
parser, watchdog, encoder decoder, scheduler and line formatter.  The wheels are
a first-order DC-motor model (80 RPM free speed at full duty), or are driven by
the caller (the simulator feeds its physics' wheel angles instead).

The firmware package's emulated board.  Used by the bringup rostests, by
``rosrun chefbot_bringup virtual_launchpad``
(try ``robot_standalone.launch`` without hardware) and by the simulator's
firmware-in-the-loop mode.  No rospy here.
"""
from __future__ import annotations

import errno
import math
import os
import pty
import tty
from collections.abc import Iterable
from dataclasses import dataclass, fields
from pathlib import Path

from chefbot_firmware.host import LEFT, RIGHT, FirmwareHost

# Malformed board lines for fault injection (VirtualBoard.emit_garbage): each one must be
# rejected (and counted) by a correct driver, none may move odometry or the robot.  The burst
# starts with a newline so a status line cut off by it is also just one bad line.
MALFORMED_BURST: tuple[bytes, ...] = (
    b"\xff\xfe\x00\x01\x80\x9b\xc3",          # binary noise
    b"e\t1234b\t12.3",                             # a truncated line run into the next one
    b"e",                                           # wrong field count (no fields)
    b"e\t5",                                        # wrong field count (one of two)
    b"u",                                           # wrong field count
    b"e\t99999999999999999999\t0",                  # huge number (beyond Int32)
    b"b\t1e309",                                    # huge number (float overflow)
    b"e\tnan\t5",                                   # NaN
    b"b\tnan",                                      # NaN
    b"u\tinf",                                      # inf
    b"i\t0.1\t0.2\tNaN\t0.9",                       # NaN in a quaternion
    b"e\t1\t2\t*00",                                # bad checksum
    b"x" * 500,                                     # overlong
)
EDGES_PER_REV = 8400            # quadrature edges per wheel revolution (64 CPR x 131.25 gear, 4X)
FREE_SPEED_RAD_S = 80 * 2 * math.pi / 60  # Pololu 37D 80 RPM at 12 V, full duty
WHEEL_RADIUS = 0.045            # m, nominal: the 90 mm wheel of ticks_meter (chefbot_bringup/param/diff_drive.yaml)
# firmware/core/config.h defaults: the right motor and encoder are mounted mirrored.
MOUNT_DEFAULTS = {"invert_left": False, "invert_right": True,
                  "invert_left_encoder": False, "invert_right_encoder": True}


@dataclass(frozen=True)
class BuildFaults:
    """How the emulated robot was built wrong (issue 31); all off = a correctly built robot.

    The faults sit where the builder makes them, not in the firmware: between the
    VNH2SP30 outputs and the motors (leads, channels) and between the encoders and the
    board's decoder inputs (A/B, connectors).  The firmware's ``invert_*`` flags
    (core/config.h) are left alone and still describe the robot as it should be.

    * ``left_leads_swapped`` / ``right_leads_swapped``: that motor's two leads are
      swapped at the driver: it turns opposite to the firmware's output.
    * ``left_encoder_reversed`` / ``right_encoder_reversed``: that encoder's A and B
      wires are swapped: its wheel turns as commanded, the decoder counts the other way.
    * ``encoders_swapped``: the left encoder's connector is on the right decoder's pins
      and vice versa.  The right encoder is mounted mirrored, so the crossed counts also
      change sign (the decoder's ``invert_*_encoder`` flag is meant for the other encoder).
    * ``motors_swapped``: the left channel's outputs drive the right motor and vice versa
      (with a change of sign for the same reason: the right motor is mounted mirrored).
    * ``left_wheel_scale`` / ``right_wheel_scale``: true wheel radius over nominal
      (e.g. 1.03 / 0.99).  Counts per wheel turn do not change (robot on blocks); it
      only scales :meth:`VirtualBoard.wheel_travel`, the distance the wheel would roll.
    """

    left_leads_swapped: bool = False
    right_leads_swapped: bool = False
    left_encoder_reversed: bool = False
    right_encoder_reversed: bool = False
    encoders_swapped: bool = False
    motors_swapped: bool = False
    left_wheel_scale: float = 1.0
    right_wheel_scale: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type in (bool, "bool"):
                if not isinstance(v, bool):
                    raise ValueError(f"BuildFaults.{f.name} must be True or False, got {v!r}")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"BuildFaults.{f.name} must be a finite number > 0 "
                                 f"(true wheel radius / nominal, e.g. 1.03), got {v!r}")

    @classmethod
    def from_names(cls, names: Iterable[str] = (),
                   wheel_scale: tuple[float, float] | None = None) -> BuildFaults:
        """The faults named in ``names`` (any of :data:`FAULT_NAMES`; repeats are harmless) and
        ``wheel_scale`` = (left, right) true radius / nominal (None: 1.0 both), as the
        ``virtual_launchpad --fault NAME --wheel-scale LEFT RIGHT`` options give them.

        Raises ValueError naming the valid faults for an unknown name, or for a scale that is
        not a finite number > 0."""
        names = list(names)
        unknown = [n for n in names if n not in FAULT_NAMES]
        if unknown:
            raise ValueError(f"unknown build fault {unknown[0]!r}; valid: {', '.join(FAULT_NAMES)}")
        kw: dict[str, bool | float] = {n: True for n in names}
        if wheel_scale is not None:
            if len(wheel_scale) != 2:
                raise ValueError(f"wheel scale must be two numbers (left right), got {wheel_scale!r}")
            kw["left_wheel_scale"], kw["right_wheel_scale"] = wheel_scale
        return cls(**kw)

    def describe(self) -> str:
        """One line for a log: the faults that are on (in :data:`FAULT_NAMES` order) and the wheel
        scales when not 1, or ``none (a correctly built robot)``."""
        parts = [n for n in FAULT_NAMES if getattr(self, n)]
        if (self.left_wheel_scale, self.right_wheel_scale) != (1.0, 1.0):
            parts.append(f"wheel scale left {self.left_wheel_scale:g} right {self.right_wheel_scale:g}")
        return ", ".join(parts) if parts else "none (a correctly built robot)"

    def leads_swapped(self, side: int) -> bool:
        """The motor of wheel ``side`` (LEFT/RIGHT) has its leads swapped."""
        return self.right_leads_swapped if side == RIGHT else self.left_leads_swapped

    def encoder_reversed(self, side: int) -> bool:
        """The encoder of wheel ``side`` has A and B swapped."""
        return self.right_encoder_reversed if side == RIGHT else self.left_encoder_reversed

    def wheel_scale(self, side: int) -> float:
        """True radius / nominal of wheel ``side``."""
        return self.right_wheel_scale if side == RIGHT else self.left_wheel_scale


# The on/off faults, by name (the ``--fault`` choices of ``virtual_launchpad``), in field order.
FAULT_NAMES: tuple[str, ...] = tuple(f.name for f in fields(BuildFaults) if f.type in (bool, "bool"))


class PtyPort:
    """The board's end (master) of a pseudo-terminal; the driver opens ``path`` or ``link``.

    The slave side stays open here too, so the pty lives until ``close()`` even
    while no driver has it open (reads would otherwise fail with EIO).
    """

    def __init__(self, link: str | os.PathLike | None = None) -> None:
        self.master, self._slave = pty.openpty()
        tty.setraw(self._slave)          # no echo, no line discipline: bytes as on a UART
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self.link = Path(link) if link else None
        self.dropped = 0                 # bytes lost because nobody drained the pty
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + f".tmp{os.getpid()}")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.path)
            os.replace(tmp, self.link)   # atomic: a reconnecting driver never sees a half state

    def read(self) -> bytes:
        """Whatever the driver wrote since the last call (never blocks; nothing once unplugged)."""
        if self.master < 0:
            return b""
        chunks = []
        while True:
            try:
                data = os.read(self.master, 4096)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno == errno.EIO:   # no reader/writer on the slave side right now
                    break
                raise
            if not data:
                break
            chunks.append(data)
        return b"".join(chunks)

    def write(self, data: bytes) -> None:
        """Send bytes to the driver; what does not fit in the pty buffer, or is sent while
        unplugged, is dropped (as a UART would)."""
        if self.master < 0:
            self.dropped += len(data)
            return
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.master, view)
            except (BlockingIOError, OSError):
                self.dropped += len(view)
                return
            view = view[n:]

    def close(self) -> None:
        """Unplug: the driver sees its port fail; the symlink goes away."""
        if self.link is not None and self.link.is_symlink() and os.readlink(self.link) == self.path:
            self.link.unlink()
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self.master = self._slave = -1

    def __enter__(self) -> PtyPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class MotorModel:
    """First-order DC gear motor: wheel speed follows duty x free speed with time constant tau."""

    free_speed: float = FREE_SPEED_RAD_S   # rad/s at full duty
    tau: float = 0.08                      # s, mechanical time constant
    speed: float = 0.0                     # rad/s, robot-forward positive
    angle: float = 0.0                     # rad, accumulated

    def step(self, duty: float, dt: float) -> float:
        """Advance dt seconds at the given signed duty (-1..1); returns the angle change (rad)."""
        target = max(-1.0, min(1.0, duty)) * self.free_speed
        a = 1.0 - math.exp(-dt / self.tau) if self.tau > 0 else 1.0
        old = self.speed
        self.speed += (target - self.speed) * a
        dangle = 0.5 * (old + self.speed) * dt
        self.angle += dangle
        return dangle


class VirtualBoard:
    """Firmware core + pty + (optionally) modelled wheels, stepped by the caller.

    ``step(dt)`` moves the board's clock by dt seconds: bytes from the driver go
    into the firmware, the motor model turns the wheels (unless ``model_wheels``
    is False and the caller feeds ``turn_wheel``), encoder edges go back into the
    firmware's decoder, and the firmware's output goes to the driver -- unless
    ``silent`` is set: then the port stays open and commands still arrive, but
    every line the board writes is dropped (a board that stopped talking).

    ``faults`` (:class:`BuildFaults`, default none) emulates a wrongly built robot:
    swapped motor leads or channels between the driver and the motors, reversed or
    swapped encoders between the wheels and the decoder.  The robot's mechanics (which
    motor and encoder are mounted mirrored) follow the firmware ``config``'s
    ``invert_*`` flags (core/config.h defaults: the right side), so without faults the
    firmware's flags are right, as today.
    """

    def __init__(self, link: str | os.PathLike | None = None, model_wheels: bool = True,
                 config: dict[str, int] | None = None, faults: BuildFaults | None = None) -> None:
        if faults is not None and not isinstance(faults, BuildFaults):
            raise ValueError(f"faults must be a BuildFaults, got {type(faults).__name__}")
        self.faults = faults if faults is not None else BuildFaults()
        conf = dict(config or {})
        # +1/-1 per side: how the motor / encoder is mounted (-1: mirrored, as the flags say)
        self._motor_mount = tuple(-1.0 if conf.get(k, MOUNT_DEFAULTS[k]) else 1.0
                                  for k in ("invert_left", "invert_right"))
        self._encoder_mount = tuple(-1 if conf.get(k, MOUNT_DEFAULTS[k]) else 1
                                    for k in ("invert_left_encoder", "invert_right_encoder"))
        self.fw = FirmwareHost(config)
        self.fw.power_on()
        self.port = PtyPort(link)
        self.model_wheels = model_wheels
        self.motors = (MotorModel(), MotorModel())
        self._edge_rest = [0.0, 0.0]     # fractional edges carried between steps
        self.silent = False              # True: the board runs and listens but sends nothing (a hung TX)
        self.fw.set_ultrasonic_cm(None)
        self.fw.set_battery_volts(12.4)
        self.fw.set_imu_quaternion(0.0, 0.0, 0.0, 1.0)

    @property
    def path(self) -> str:
        """Device path the driver opens (the pty slave)."""
        return self.port.path

    def turn_wheel(self, side: int, dangle: float) -> None:
        """Turn one wheel by dangle rad (robot-forward positive): encoder edges into the firmware
        (through the encoder wiring faults, if any)."""
        edges = dangle / (2 * math.pi) * EDGES_PER_REV + self._edge_rest[side]
        whole = math.trunc(edges)
        self._edge_rest[side] = edges - whole
        if whole:
            self.fw.wheel_advance(*self._encoder_wiring(side, whole))

    def _encoder_wiring(self, wheel: int, edges: int) -> tuple[int, int]:
        """(decoder side, edges in that decoder's robot-forward convention) for ``edges``
        forward edges of ``wheel``'s encoder, through the build faults."""
        pins = edges * self._encoder_mount[wheel]          # Gray-code steps at the encoder's A/B
        if self.faults.encoder_reversed(wheel):
            pins = -pins                                   # A and B swapped
        decoder = (RIGHT if wheel == LEFT else LEFT) if self.faults.encoders_swapped else wheel
        return decoder, pins * self._encoder_mount[decoder]   # wheel_advance re-applies the decoder's flag

    def motor_duty(self, wheel: int) -> float:
        """Signed duty (-1..1, robot-forward) that reaches the motor of ``wheel`` from the
        driver, through the build faults (the firmware's own wish: ``fw.wheel_duty``)."""
        channel = (RIGHT if wheel == LEFT else LEFT) if self.faults.motors_swapped else wheel
        bridge = self.fw.wheel_duty(channel) * self._motor_mount[channel]   # polarity at the outputs
        if self.faults.leads_swapped(wheel):
            bridge = -bridge
        return bridge * self._motor_mount[wheel]

    def wheel_travel(self, side: int) -> float:
        """Distance (m) the modelled wheel ``side`` would have rolled on the floor: its angle
        x nominal radius x ``wheel_scale`` (the counts only see the angle)."""
        return self.motors[side].angle * WHEEL_RADIUS * self.faults.wheel_scale(side)

    def step(self, dt: float) -> None:
        """Advance the board by ``dt`` s: serial in, firmware, motors, encoders, serial out."""
        if dt <= 0:
            return
        data = self.port.read()
        if data:
            self.fw.feed(data)
        if self.model_wheels:
            for side in (LEFT, RIGHT):
                self.turn_wheel(side, self.motors[side].step(self.motor_duty(side), dt))
        self.fw.advance(max(1, round(dt * 1e6)))
        out = self.fw.read_tx()
        if out and not self.silent:
            self.port.write(out)

    def emit_garbage(self, lines: tuple[bytes, ...] = MALFORMED_BURST) -> int:
        """Send ``lines`` (default :data:`MALFORMED_BURST`) to the driver between the board's own
        lines (a noisy cable, a brown-out mid-line); returns how many were sent (0 when unplugged)."""
        if self.port.master < 0:
            return 0
        self.port.write(b"\n" + b"\n".join(lines) + b"\n")
        return len(lines)

    def unplug(self) -> None:
        """Pull the USB cable: the pty and the symlink go away; the firmware keeps running
        (its watchdog stops the motors once commands stop) until :meth:`reconnect`."""
        self.port.close()

    def reconnect(self, link: str | os.PathLike | None = None) -> None:
        """Unplug and plug back in: a new pty (new path), the same symlink."""
        link = link or self.port.link
        self.port.close()
        self.port = PtyPort(link)

    def close(self) -> None:
        """Close the pty and destroy the firmware instance."""
        self.port.close()
        self.fw.close()

    def __enter__(self) -> VirtualBoard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SteppedSerial:
    """A :class:`VirtualBoard`'s pty opened as a driver opens its serial port, in simulated time.

    For running PC-side code against the board faster than real time and deterministically:
    ``write`` sends bytes to the board; ``read(timeout)`` steps the board by ``dt`` at a time until
    it has written something or ``timeout`` of simulated time passed; ``now()`` is that time (s).
    Time moves only inside ``read``.
    """

    def __init__(self, board: VirtualBoard, dt: float = 0.005) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        self.board, self.dt, self.t = board, dt, 0.0
        self.fd = os.open(board.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)

    def now(self) -> float:
        return self.t

    def write(self, data: bytes) -> None:
        os.write(self.fd, data)

    def read(self, timeout: float) -> bytes:
        end = self.t + max(timeout, self.dt)
        out = b""
        while not out and self.t < end - 1e-9:
            self.board.step(self.dt)
            self.t += self.dt
            try:
                out = os.read(self.fd, 4096)
            except BlockingIOError:
                pass
        return out

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> SteppedSerial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class BuilderHands:
    """The builder at an emulated robot, for a guided check's questions (the ``Ui`` of
    ``chefbot_bringup.bringup_procedure``): lines said are kept in ``lines``; every question is
    answered at once (Enter); one that asks to turn the LEFT or RIGHT wheel first turns that wheel
    of ``board`` one full turn forward, by hand (motors off, through the encoder wiring faults)."""

    def __init__(self, board: VirtualBoard) -> None:
        self.board = board
        self.lines: list[str] = []
        self.questions: list[str] = []
        self._pending: str | None = None

    def say(self, text: str) -> None:
        """Keep a line."""
        self.lines.append(text)

    def ask(self, text: str) -> None:
        """Do what the question asks and press Enter."""
        self.questions.append(text)
        for side, name in ((LEFT, "LEFT"), (RIGHT, "RIGHT")):
            if f"the {name} wheel" in text:
                for _ in range(100):
                    self.board.turn_wheel(side, 2 * math.pi / 100)
        self._pending = ""

    def answer(self) -> str | None:
        """The Enter of the last question, once."""
        a, self._pending = self._pending, None
        return a
