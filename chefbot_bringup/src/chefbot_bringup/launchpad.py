"""The LaunchPad driver's logic without serial ports or ROS (the node adds both).

* ``LineAssembler`` cuts the byte stream into lines with a length cap.
* ``EncoderContinuity`` turns the board's tick counters into counters that
  never jump: an MCU reboot (counters back to ~0, or a hello line) or an
  impossible jump (faster than 1.5× the wheels' top speed) is flagged and
  absorbed, so odometry downstream never teleports.
* ``LaunchpadCore`` ties them together: it parses lines, keeps counts for
  diagnostics, tracks link health (silence timeout), and produces the single
  coherent ``s <l> <r>`` command per control cycle from the latest left/right
  requests -- zero while the board is not heard from (no valid line since the
  port was opened, or none for ``silence_timeout``): a board that stopped
  talking gives no encoder feedback, so it must not be driven.
* ``link_status`` turns the core's state into the diagnostic level and text.

Time is passed in as float seconds (host monotonic or ROS time).
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from chefbot_bringup import launchpad_protocol as proto

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
OK, WARN, ERROR = 0, 1, 2   # diagnostic_msgs/DiagnosticStatus levels


def wrap_int32(v: int) -> int:
    """Wrap an integer into the int32 range, as the board's counters do."""
    return (v - INT32_MIN) % 2**32 + INT32_MIN


@dataclass(frozen=True)
class LaunchpadConfig:
    """Settings of launchpad_node (param/launchpad.yaml); units in the names' comments."""

    port: str = "/dev/ttyACM0"
    baud: int = 115200
    silence_timeout: float = 1.0        # s without a valid line before the link counts as dead
    control_rate: float = 30.0          # Hz, motor commands sent to the board
    command_timeout: float = 0.5        # s, a wheel command older than this is sent as 0
    backoff_max: float = 2.0            # s, longest wait between reconnect attempts
    ticks_meter: float = 29708.0        # ticks per metre (8400 counts/rev, 4X, / (pi * 0.09 m))
    max_wheel_speed: float = 0.377      # m/s, physical top speed (encoder jump detection)
    checksum_commands: bool = True
    battery_empty_voltage: float = 11.0  # V, 0 %
    battery_full_voltage: float = 12.7   # V, 100 %
    battery_low: float = 0.2            # fraction: WARN diagnostic at or below
    battery_critical: float = 0.05      # fraction: ERROR diagnostic at or below
    ultrasonic_frame_id: str = "ultrasonic_link"  # frame_id of ultrasonic (sensor_msgs/Range); a namespaced
                                                  # robot (robot_standalone.launch) prefixes it and imu_frame_id
    imu_frame_id: str = "gyro_link"     # frame_id of imu/data, the board's MPU6050 orientation
    event_driven: bool = True           # write a wheel command when it arrives (False: only on the control timer)

    def __post_init__(self) -> None:
        if not self.port:
            raise ValueError("port must not be empty: name the LaunchPad's serial device (e.g. "
                             "/dev/chefbot_launchpad with the udev rule, /dev/ttyACM0, or the simulator's pty)")
        for name in ("baud", "silence_timeout", "control_rate", "command_timeout", "backoff_max",
                     "ticks_meter", "max_wheel_speed"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")
        if not 0.0 <= self.battery_critical <= self.battery_low <= 1.0:
            raise ValueError(f"need 0 <= battery_critical ({self.battery_critical}) <= battery_low "
                             f"({self.battery_low}) <= 1")
        if not self.battery_full_voltage > self.battery_empty_voltage:
            raise ValueError(f"battery_full_voltage ({self.battery_full_voltage}) must exceed "
                             f"battery_empty_voltage ({self.battery_empty_voltage})")

    @property
    def max_ticks_per_s(self) -> float:
        """Fastest wheel speed in encoder ticks/s (max_wheel_speed x ticks_meter)."""
        return self.max_wheel_speed * self.ticks_meter

    def battery_fraction(self, volts: float) -> float:
        """State of charge 0..1 from the voltage (linear between empty and full)."""
        span = self.battery_full_voltage - self.battery_empty_voltage
        return min(1.0, max(0.0, (volts - self.battery_empty_voltage) / span))


LAUNCHPAD_PARAMS = {
    "port": "~port", "baud": "~baudRate", "silence_timeout": "~silence_timeout",
    "control_rate": "~control_rate", "command_timeout": "~command_timeout",
    "backoff_max": "~reconnect_backoff_max", "ticks_meter": ("ticks_meter", "~ticks_meter"),
    "max_wheel_speed": "~max_wheel_speed", "checksum_commands": "~checksum_commands",
    "battery_empty_voltage": "~battery_empty_voltage", "battery_full_voltage": "~battery_full_voltage",
    "ultrasonic_frame_id": "~ultrasonic_frame_id", "imu_frame_id": "~imu_frame_id",
    "event_driven": "~event_driven", "battery_low": "~battery_low", "battery_critical": "~battery_critical",
}


class LineAssembler:
    """Bytes → complete lines (``\\n``, ``\\r\\n`` or ``\\r`` terminated), capped in length.

    The first line after ``reset()`` (a port (re)open) is reported as partial:
    the port may have been opened in the middle of a line.
    """

    def __init__(self, max_len: int = proto.MAX_LINE_BYTES) -> None:
        self.max_len = max_len
        self._buf = bytearray()
        self._overlong = False
        self._first = True

    def reset(self) -> None:
        """Forget any partial line (the port was reopened)."""
        self._buf.clear()
        self._overlong = False
        self._first = True

    def feed(self, data: bytes) -> list[bytes | proto.LineError]:
        """Split received bytes into complete lines (without CR/LF) or LineErrors for overlong ones."""
        out: list[bytes | proto.LineError] = []
        for byte in data:
            if byte in (10, 13):  # '\n' or '\r': end of line; an empty one ('\r\n') is skipped
                if self._overlong:
                    out.append(proto.LineError("overlong", f"line longer than {self.max_len} bytes dropped"))
                elif self._first and self._buf:
                    out.append(proto.LineError("partial", f"first line after open dropped: {bytes(self._buf[:40])!r}"))
                elif self._buf:
                    out.append(bytes(self._buf))
                # Whatever came before the first terminator was a fragment; after it we
                # are at a line boundary.
                self._first = False
                self._buf.clear()
                self._overlong = False
            elif self._overlong:
                continue
            elif len(self._buf) >= self.max_len:
                self._overlong = True
                self._buf.clear()
            else:
                self._buf.append(byte)
        return out


@dataclass
class EncoderEvent:
    """An encoder counter reset or impossible jump that was absorbed, and why (for the log)."""
    kind: str     # "reset" | "jump"
    detail: str


class EncoderContinuity:
    """Keep published tick counters continuous across board reboots and glitches.

    ``max_ticks_per_s`` is the physical limit (top wheel speed × ticks per metre);
    a change larger than ``jump_factor`` × that × elapsed time (+ ``slack`` ticks)
    is impossible. Such a reading is held back: if the next reading continues
    from the old counters, it was a one-line glitch and is simply skipped (no
    travel is lost); if the next reading continues from the jumped value, the
    counters really moved (e.g. a reboot without hello) and tracking goes on
    from there, without passing the jump itself on. Counters back near zero
    after a hello line, or any jump that lands near zero, count as a reboot.
    """

    def __init__(self, max_ticks_per_s: float, jump_factor: float = 1.5, slack: int = 50,
                 reset_window: int = 100) -> None:
        if max_ticks_per_s <= 0:
            raise ValueError(f"max_ticks_per_s must be > 0, got {max_ticks_per_s}")
        self.max_ticks_per_s = max_ticks_per_s
        self.jump_factor = jump_factor
        self.slack = slack
        self.reset_window = reset_window
        self._raw: tuple[int, int] | None = None      # last accepted raw counters
        self._t: float | None = None                  # and when (s); None = unknown (retimed)
        self._out: tuple[int, int] = (0, 0)
        self._pending: tuple[tuple[int, int], float] | None = None   # held-back jumped reading
        self._expect_reset = False
        self._unknown_gap: float | None = None

    def board_restarted(self) -> None:
        """The board said hello: its counters start again from zero."""
        self._expect_reset = True

    def retime(self, max_gap: float = 1.0) -> None:
        """The time base changed (port reopened, board clock restarted): the next interval is
        unknown; judge it as if up to ``max_gap`` s (the link's silence limit) had passed."""
        self._t = None
        self._unknown_gap = max_gap
        self._pending = None

    def _limit(self, dt: float) -> float:
        return self.jump_factor * self.max_ticks_per_s * dt + self.slack

    def _accept(self, left: int, right: int, t: float, base: tuple[int, int]) -> tuple[int, int]:
        dl, dr = wrap_int32(left - base[0]), wrap_int32(right - base[1])
        self._raw, self._t, self._pending = (left, right), t, None
        self._out = (wrap_int32(self._out[0] + dl), wrap_int32(self._out[1] + dr))
        return self._out

    def update(self, left: int, right: int, t: float) -> tuple[tuple[int, int], EncoderEvent | None]:
        """Feed raw counters at time t (s); returns (published counters, event or None)."""
        if self._raw is None:
            self._raw, self._t = (left, right), t
            self._out = (left, right)
            return self._out, None
        if self._t is None:
            dt = self._unknown_gap or 0.0
            self._unknown_gap = None
        else:
            dt = max(t - self._t, 0.0)
        dl, dr = wrap_int32(left - self._raw[0]), wrap_int32(right - self._raw[1])
        near_zero = abs(left) <= self.reset_window and abs(right) <= self.reset_window
        expect_reset, self._expect_reset = self._expect_reset, False
        if expect_reset and near_zero:
            event = EncoderEvent("reset", f"board restarted; counters {self._raw} -> ({left}, {right})")
            return self._accept(left, right, t, base=(left, right)), event
        limit = self._limit(dt)
        if abs(dl) <= limit and abs(dr) <= limit:
            return self._accept(left, right, t, base=self._raw), None
        if near_zero:   # a reboot without hello: counters start again from zero
            event = EncoderEvent("reset", f"counters fell to ({left}, {right}) from {self._raw}")
            return self._accept(left, right, t, base=(left, right)), event
        if self._pending is not None:
            (pl, pr), pt = self._pending
            plimit = self._limit(max(t - pt, 0.0))
            if abs(wrap_int32(left - pl)) <= plimit and abs(wrap_int32(right - pr)) <= plimit:
                # the jump persisted: continue from the jumped value (the jump itself is not passed on)
                return self._accept(left, right, t, base=(pl, pr)), None
        self._pending = ((left, right), t)
        event = EncoderEvent("jump", f"counters moved ({dl}, {dr}) ticks in {dt:.3f} s; limit {limit:.0f}; held back")
        return self._out, event


class BoardClock:
    """The board's 32-bit microsecond clock (``t`` lines), unwrapped into seconds.

    Encoder speeds are judged on this clock, not on when lines reach the PC:
    USB and a loaded PC deliver lines in bunches, and a simulated board may
    run faster than real time, so host receive times would make legitimate
    motion look like an impossible jump.
    """

    def __init__(self) -> None:
        self._last: int | None = None
        self._wraps = 0

    def reset(self) -> None:
        """Forget the board's clock (a new connection)."""
        self._last = None
        self._wraps = 0

    def update(self, micros: int) -> float:
        """The board's micros() stamp as seconds since it booted, counting 32-bit wraps."""
        if self._last is not None and micros < self._last and self._last - micros > 2**31:
            self._wraps += 1       # the counter wrapped (every 71.6 min)
        self._last = micros
        return (self._wraps * 2**32 + micros) * 1e-6

    @property
    def seconds(self) -> float | None:
        """The last board time (s), or None before the first stamp."""
        return None if self._last is None else (self._wraps * 2**32 + self._last) * 1e-6


@dataclass
class LinkStats:
    """Counters of the serial link for the diagnostics (lines good/bad, reconnects, commands)."""
    lines_ok: int = 0
    lines_bad: Counter = field(default_factory=Counter)
    crc_lines: int = 0
    reconnects: int = 0
    encoder_resets: int = 0
    encoder_jumps: int = 0
    commands_sent: int = 0
    commands_zeroed: int = 0         # drive requests sent as 0 because the board was not heard from
    board_state: str | None = None   # last drive state in the `s` echo
    hello: tuple[str, ...] | None = None

    @property
    def bad_total(self) -> int:
        """Number of bad lines of every kind."""
        return sum(self.lines_bad.values())


class LaunchpadCore:
    """Parse board output, keep counters and link health, build motor commands."""

    def __init__(self, max_ticks_per_s: float, silence_timeout: float = 1.0,
                 command_timeout: float = 0.5, checksum_commands: bool = True) -> None:
        if silence_timeout <= 0:
            raise ValueError(f"silence_timeout must be > 0 s, got {silence_timeout}")
        if command_timeout <= 0:
            raise ValueError(f"command_timeout must be > 0 s, got {command_timeout}")
        self.silence_timeout = silence_timeout
        self.command_timeout = command_timeout
        self.checksum_commands = checksum_commands
        self.assembler = LineAssembler()
        self.encoders = EncoderContinuity(max_ticks_per_s)
        self.stats = LinkStats()
        self.connected = False
        # Set by the first checksummed line of a connection: from then on a line
        # without the CRC token is refused. Otherwise a bit flip that hits the
        # '*' would turn the token into a data field and the line would pass as
        # an old (book) firmware line with no integrity check at all.
        self.crc_required = False
        self.board_clock = BoardClock()
        self._last_rx: float | None = None
        self.heard = False               # a valid line arrived since the port was opened
        self.clean_encoder_readings = 0  # encoder readings in a row without a jump/reset event
        self._cmd = [0.0, 0.0]
        self._cmd_t = [float("-inf"), float("-inf")]

    # ---- link
    def on_open(self, t: float) -> None:
        """The port was (re)opened at time ``t`` (s): start with a clean parser, board clock and encoders."""
        self.assembler.reset()
        self.board_clock.reset()
        self.encoders.retime(self.silence_timeout)
        self.crc_required = False  # the board on the other end may be a different firmware
        self.connected = True
        self.heard = False
        self._last_rx = t

    def on_close(self) -> None:
        """The port was closed or lost: count a reconnect, not connected nor heard any more."""
        if self.connected:
            self.stats.reconnects += 1
        self.connected = False
        self.heard = False
        self.assembler.reset()

    def silent(self, t: float) -> bool:
        """True when the open link has delivered no valid line for silence_timeout."""
        return self.connected and self._last_rx is not None and t - self._last_rx > self.silence_timeout

    def alive(self, t: float) -> bool:
        """True when the board is heard from: port open, a valid line since the open, and the
        last one at most silence_timeout ago.  Only then may a non-zero command go out."""
        return self.connected and self.heard and not self.silent(t)

    # ---- receive
    def on_bytes(self, data: bytes, t: float) -> list[tuple[object, object]]:
        """Feed received bytes; returns [(message, extra)] for each valid line.

        ``extra`` is, for Encoders, a tuple (published_left, published_right, EncoderEvent|None);
        for other messages None.  Invalid lines are counted in ``stats.lines_bad`` by kind and
        returned as (LineError, None) so the caller can log them.
        """
        out: list[tuple[object, object]] = []
        for item in self.assembler.feed(data):
            if isinstance(item, proto.LineError):
                self.stats.lines_bad[item.kind] += 1
                out.append((item, None))
                continue
            try:
                msg, had_crc = proto.parse_line(item)
                if self.crc_required and not had_crc:
                    raise proto.LineError("checksum", f"line without checksum from a board that sends them: "
                                                      f"{item[:40]!r}")
            except proto.LineError as err:
                self.stats.lines_bad[err.kind] += 1
                out.append((err, None))
                continue
            self.crc_required |= had_crc
            self.stats.lines_ok += 1
            self.stats.crc_lines += had_crc
            self._last_rx = t
            self.heard = True
            extra = None
            if isinstance(msg, proto.Hello):
                self.stats.hello = msg.fields
                self.encoders.board_restarted()
                self.board_clock.reset()   # its clock restarts too
            elif isinstance(msg, proto.TimeStamp):
                if self.board_clock.seconds is None:   # switching from host to board time
                    self.encoders.retime(self.silence_timeout)
                self.board_clock.update(msg.micros)
            elif isinstance(msg, proto.SpeedEcho):
                self.stats.board_state = msg.state
            elif isinstance(msg, proto.Encoders):
                # board time when the board sends `t` lines (ours and the book's do), else host time
                board_t = self.board_clock.seconds
                (pl, pr), ev = self.encoders.update(msg.left, msg.right, t if board_t is None else board_t)
                if ev is not None:
                    self.clean_encoder_readings = 0
                    if ev.kind == "reset":
                        self.stats.encoder_resets += 1
                    else:
                        self.stats.encoder_jumps += 1
                else:
                    self.clean_encoder_readings += 1
                extra = (pl, pr, ev)
            out.append((msg, extra))
        return out

    # ---- transmit
    def set_left(self, value: float, t: float) -> None:
        """New left wheel command (motor units) received at time ``t`` (s)."""
        self._cmd[0], self._cmd_t[0] = value, t

    def set_right(self, value: float, t: float) -> None:
        """New right wheel command (motor units) received at time ``t`` (s)."""
        self._cmd[1], self._cmd_t[1] = value, t

    def command(self, t: float) -> bytes:
        """The one ``s`` line for this control cycle; a side not refreshed within
        command_timeout is sent as 0 (its PID stopped publishing), and both are 0
        while the board is not heard from (see :meth:`alive`)."""
        left = self._cmd[0] if t - self._cmd_t[0] <= self.command_timeout else 0.0
        right = self._cmd[1] if t - self._cmd_t[1] <= self.command_timeout else 0.0
        if not self.alive(t):
            if left or right:
                self.stats.commands_zeroed += 1
            left = right = 0.0
        self.stats.commands_sent += 1
        return proto.format_command(left, right, self.checksum_commands)

    def stop_command(self) -> bytes:
        """The ``s 0 0`` line (and forget the held commands)."""
        self._cmd = [0.0, 0.0]
        return proto.format_command(0.0, 0.0, self.checksum_commands)


def link_status(core: LaunchpadCore, t: float, port: str, last_error: str,
                settle_readings: int = 10) -> tuple[int, str]:
    """Diagnostic (level, message) of the link at time ``t`` (s).

    * ERROR while the port is closed, and while it is open but the board is not heard
      from after an error (a silent board stays ERROR across reopen attempts);
    * WARN while the port is open before the board's first line ever, and for the
      ``settle_readings`` encoder readings after an absorbed jump or reset;
    * OK ("connected to <port>") otherwise.
    """
    if not core.connected:
        return ERROR, last_error or f"{port} not open"
    if not core.alive(t):
        if not core.heard and last_error:
            return ERROR, f"{last_error}; port reopened, no valid line yet (motors held at 0)"
        if not core.heard:
            return WARN, f"{port} open, waiting for the board's first valid line (motors held at 0)"
        return ERROR, f"no valid line from {port} for {core.silence_timeout:.1f} s (motors held at 0)"
    text = f"connected to {port}"
    if (core.stats.encoder_jumps or core.stats.encoder_resets) and core.clean_encoder_readings < settle_readings:
        return WARN, text + "; encoder counters jumped or reset (absorbed)"
    return OK, text


def battery_status(cfg: LaunchpadConfig, volts: float | None) -> tuple[int, str]:
    """Diagnostic (level, message) of the battery from the board's last voltage (V), None = none yet."""
    if volts is None:
        return WARN, "no battery reading from the board yet"
    if volts <= 0.5:
        return WARN, f"battery not measured (board reports {volts:.2f} V)"
    frac = cfg.battery_fraction(volts)
    text = f"{volts:.2f} V, {frac * 100:.0f} %"
    if frac <= cfg.battery_critical:
        return ERROR, f"battery critical: {text}; return to the charger now"
    if frac <= cfg.battery_low:
        return WARN, f"battery low: {text}"
    return OK, text
