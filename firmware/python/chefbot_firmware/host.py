"""ctypes wrapper of ``firmware/build/libchefbot_fw.so``: the firmware core on
an in-memory board (see firmware/PROTOCOL.md, "Host library").

Time only advances in :meth:`FirmwareHost.advance`; inside it the board runs
its main loop every ``loop_us`` of simulated time, the UART drains at the real
line rate (115200 baud = 11 520 B/s) and the HC-SR04 answers triggers with
echo edges. Typical use by a simulator::

    fw = FirmwareHost()
    fw.feed(bytes_from_pty)
    fw.wheel_advance(LEFT, edges)      # from the simulated wheel rotation
    fw.advance(dt_us)
    pty.write(fw.read_tx())
    duty = fw.wheel_duty(LEFT)         # -1..1, robot-forward convention
"""
from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from pathlib import Path

LEFT = 0
RIGHT = 1
DRIVE_STATES = ("idle", "run", "timeout")
API_VERSION = 1
LIBRARY_ENV = "CHEFBOT_FW_LIB"


class FirmwareLibraryMissing(RuntimeError):
    """The host shared library has not been built."""


def firmware_dir() -> Path:
    """The ``firmware/`` source directory (this file is ``firmware/python/chefbot_firmware/host.py``)."""
    return Path(os.path.realpath(__file__)).parents[2]


def library_path() -> Path:
    """Path of the host library; ``$CHEFBOT_FW_LIB`` overrides the default
    ``firmware/build/libchefbot_fw.so``. Raises :class:`FirmwareLibraryMissing`
    when the file does not exist."""
    override = os.environ.get(LIBRARY_ENV)
    path = Path(override) if override else firmware_dir() / "build" / "libchefbot_fw.so"
    if not path.is_file():
        raise FirmwareLibraryMissing(
            f"ChefBot firmware host library not found at {path}: build it with "
            f"'make -C {firmware_dir()} lib' (tools/setup.sh does this)")
    return path


@dataclass(frozen=True)
class MotorOutput:
    """VNH2SP30 inputs of one motor: INA, INB (0/1) and PWM (0..255)."""

    ina: int
    inb: int
    pwm: int

    @property
    def braking(self) -> bool:
        """True when both bridge inputs are equal (motor shorted: brake)."""
        return self.ina == self.inb


_U8P = ctypes.POINTER(ctypes.c_uint8)
_SIGNATURES = {
    "cfw_api_version": (ctypes.c_int, []),
    "cfw_create": (ctypes.c_void_p, []),
    "cfw_destroy": (None, [ctypes.c_void_p]),
    "cfw_configure": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int64]),
    "cfw_power_on": (None, [ctypes.c_void_p]),
    "cfw_feed": (ctypes.c_size_t, [ctypes.c_void_p, _U8P, ctypes.c_size_t]),
    "cfw_advance": (None, [ctypes.c_void_p, ctypes.c_uint64]),
    "cfw_poll": (None, [ctypes.c_void_p]),
    "cfw_now_us": (ctypes.c_uint32, [ctypes.c_void_p]),
    "cfw_set_clock_us": (None, [ctypes.c_void_p, ctypes.c_uint32]),
    "cfw_tx_available": (ctypes.c_size_t, [ctypes.c_void_p]),
    "cfw_read_tx": (ctypes.c_size_t, [ctypes.c_void_p, _U8P, ctypes.c_size_t]),
    "cfw_get_motor": (None, [ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int),
                             ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)]),
    "cfw_wheel_duty": (ctypes.c_double, [ctypes.c_void_p, ctypes.c_int]),
    "cfw_command": (ctypes.c_int32, [ctypes.c_void_p, ctypes.c_int]),
    "cfw_drive_state": (ctypes.c_int, [ctypes.c_void_p]),
    "cfw_encoder_edge": (None, [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int]),
    "cfw_encoder_step": (None, [ctypes.c_void_p, ctypes.c_int, ctypes.c_int32]),
    "cfw_wheel_advance": (None, [ctypes.c_void_p, ctypes.c_int, ctypes.c_int32]),
    "cfw_set_encoder_count": (None, [ctypes.c_void_p, ctypes.c_int, ctypes.c_int32]),
    "cfw_encoder_count": (ctypes.c_int32, [ctypes.c_void_p, ctypes.c_int]),
    "cfw_set_ultrasonic_echo_us": (None, [ctypes.c_void_p, ctypes.c_int32]),
    "cfw_set_imu_quaternion": (None, [ctypes.c_void_p] + [ctypes.c_double] * 4),
    "cfw_clear_imu": (None, [ctypes.c_void_p]),
    "cfw_set_battery_raw": (None, [ctypes.c_void_p, ctypes.c_uint16]),
    "cfw_set_battery_volts": (None, [ctypes.c_void_p, ctypes.c_double]),
    "cfw_stat": (ctypes.c_uint64, [ctypes.c_void_p, ctypes.c_char_p, ctypes.POINTER(ctypes.c_int)]),
}
_lib: ctypes.CDLL | None = None


def _load() -> ctypes.CDLL:
    global _lib
    if _lib is None:
        lib = ctypes.CDLL(str(library_path()))
        for name, (restype, argtypes) in _SIGNATURES.items():
            fn = getattr(lib, name)
            fn.restype = restype
            fn.argtypes = argtypes
        version = lib.cfw_api_version()
        if version != API_VERSION:
            raise FirmwareLibraryMissing(f"{library_path()} has C API version {version}, expected {API_VERSION}: "
                                         f"rebuild it with 'make -C {firmware_dir()} lib'")
        _lib = lib
    return _lib


def _side(side: int) -> int:
    if side not in (LEFT, RIGHT):
        raise ValueError(f"side must be LEFT (0) or RIGHT (1), not {side!r}")
    return side


class FirmwareHost:
    """One emulated LaunchPad running the firmware core.

    ``config`` sets fields of the firmware's ``Config`` (core/config.h) by name,
    e.g. ``{"watchdog_ms": 300, "status_rate_hz": 20}``, plus the host-only
    ``loop_us`` (main-loop period, default 200 µs) and ``instant_tx`` (skip the
    line-rate model). The board powers on at construction (sending its ``v``
    hello line).
    """

    def __init__(self, config: dict[str, int] | None = None) -> None:
        self._lib = _load()
        self._handle = self._lib.cfw_create()
        if not self._handle:
            raise MemoryError("cfw_create failed")
        if config:
            for key, value in config.items():
                self.configure(key, value)
            self.power_on()

    # ------------------------------------------------------------ lifecycle
    @property
    def _h(self):
        """The C handle; using a closed board raises instead of passing NULL to C (a segfault)."""
        if not getattr(self, "_handle", None):
            raise ValueError("the firmware board is closed")
        return self._handle

    def close(self) -> None:
        """Destroy the firmware instance (idempotent)."""
        if getattr(self, "_handle", None):
            self._lib.cfw_destroy(self._handle)
            self._handle = None

    def __enter__(self) -> FirmwareHost:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown may have unloaded ctypes
            pass

    def configure(self, key: str, value: int | bool) -> None:
        """Set a config field; takes effect at the next :meth:`power_on` (host keys at once)."""
        if self._lib.cfw_configure(self._h, key.encode(), int(value)) != 0:
            raise KeyError(f"unknown firmware config key or bad value: {key}={value!r}")

    def power_on(self) -> None:
        """Hardware reset: a fresh core with the current config."""
        self._lib.cfw_power_on(self._h)

    # ------------------------------------------------------------ serial + time
    def feed(self, data: bytes) -> int:
        """Bytes from the PC; returns how many fit into the board's RX buffer."""
        if not data:
            return 0
        buf = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
        return int(self._lib.cfw_feed(self._h, buf, len(data)))

    def advance(self, us: int) -> None:
        """Run the board for ``us`` microseconds of simulated time."""
        if us < 0:
            raise ValueError("time only moves forward")
        self._lib.cfw_advance(self._h, int(us))

    def poll(self) -> None:
        """One main-loop pass without moving the clock."""
        self._lib.cfw_poll(self._h)

    @property
    def now_us(self) -> int:
        """The board's micros() (wraps at 2^32)."""
        return int(self._lib.cfw_now_us(self._h))

    def set_clock_us(self, us: int) -> None:
        """Set the board clock (µs, wraps at 2^32)."""
        self._lib.cfw_set_clock_us(self._h, us & 0xFFFFFFFF)

    def read_tx(self, max_bytes: int = 1 << 20) -> bytes:
        """Bytes the board has put on the wire (drained)."""
        n = int(self._lib.cfw_tx_available(self._h))
        n = min(n, max_bytes)
        if n == 0:
            return b""
        buf = (ctypes.c_uint8 * n)()
        got = self._lib.cfw_read_tx(self._h, buf, n)
        return bytes(buf[:got])

    # ------------------------------------------------------------ outputs
    def motor(self, side: int) -> MotorOutput:
        """Current H-bridge outputs of one side."""
        ina, inb, pwm = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
        self._lib.cfw_get_motor(self._h, _side(side), ctypes.byref(ina), ctypes.byref(inb), ctypes.byref(pwm))
        return MotorOutput(ina.value, inb.value, pwm.value)

    def wheel_duty(self, side: int) -> float:
        """Signed duty −1..1 the motor driver applies, in the robot-forward
        convention (motor inversion undone); 0 when braking."""
        return float(self._lib.cfw_wheel_duty(self._h, _side(side)))

    def command(self, side: int) -> int:
        """The applied command in PC units (0 while stopped)."""
        return int(self._lib.cfw_command(self._h, _side(side)))

    @property
    def drive_state(self) -> str:
        """The firmware's drive state (idle, run, timeout ...)."""
        return DRIVE_STATES[self._lib.cfw_drive_state(self._h)]

    # ------------------------------------------------------------ inputs
    def encoder_edge(self, side: int, a: bool, b: bool) -> None:
        """Pin levels after one edge, as the interrupt would see them."""
        self._lib.cfw_encoder_edge(self._h, _side(side), int(bool(a)), int(bool(b)))

    def encoder_step(self, side: int, steps: int) -> None:
        """``steps`` Gray-code transitions at the pins (negative = B lags A)."""
        self._lib.cfw_encoder_step(self._h, _side(side), int(steps))

    def wheel_advance(self, side: int, edges: int) -> None:
        """Turn a wheel by ``edges`` quadrature edges, positive = robot forward
        (encoder inversion applied). 8400 edges per wheel revolution; in X2/X1
        mode the count moves by edges/2 or edges/4."""
        self._lib.cfw_wheel_advance(self._h, _side(side), int(edges))

    def set_encoder_count(self, side: int, count: int) -> None:
        """Overwrite one side's encoder counter (ticks)."""
        self._lib.cfw_set_encoder_count(self._h, _side(side), int(count))

    def encoder_count(self, side: int) -> int:
        """One side's encoder counter (ticks)."""
        return int(self._lib.cfw_encoder_count(self._h, _side(side)))

    def set_ultrasonic_echo_us(self, us: int) -> None:
        """Echo pulse width the HC-SR04 answers each trigger with; <= 0: no echo."""
        self._lib.cfw_set_ultrasonic_echo_us(self._h, int(us))

    def set_ultrasonic_cm(self, cm: float | None) -> None:
        """Obstacle distance in cm (None or <= 0: nothing in range)."""
        self.set_ultrasonic_echo_us(0 if cm is None or cm <= 0 else round(cm * 58.0))

    def set_imu_quaternion(self, x: float, y: float, z: float, w: float) -> None:
        """Orientation the DMP streams (100 Hz) from now on."""
        self._lib.cfw_set_imu_quaternion(self._h, x, y, z, w)

    def clear_imu(self) -> None:
        """IMU stops delivering (the `i` line stops after 1 s)."""
        self._lib.cfw_clear_imu(self._h)

    def set_battery_raw(self, raw: int) -> None:
        """Battery ADC reading (raw counts) the firmware sees."""
        self._lib.cfw_set_battery_raw(self._h, int(raw))

    def set_battery_volts(self, volts: float) -> None:
        """Battery voltage (V) the firmware sees."""
        self._lib.cfw_set_battery_volts(self._h, float(volts))

    # ------------------------------------------------------------ counters
    def stat(self, name: str) -> int:
        """A counter by name: rx_ok, rx_empty, rx_errors, rx_error.<class>,
        rx_overflow, watchdog_trips, encoder_illegal_left/right,
        tx_dropped_lines, tx_bytes, wire_overflow, schedule_overruns,
        status_cycles, resets, ultrasonic_triggers, ultrasonic_cm, battery_mv,
        imu_ok, elapsed_us."""
        found = ctypes.c_int()
        value = self._lib.cfw_stat(self._h, name.encode(), ctypes.byref(found))
        if not found.value:
            raise KeyError(f"unknown firmware counter {name!r}")
        return int(value)
