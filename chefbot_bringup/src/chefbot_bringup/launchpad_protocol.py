"""The LaunchPad serial protocol, PC side (see firmware/PROTOCOL.md).

Board → PC: ASCII lines ``<tag>\\t<field>\\t...[\\t*HH]\\n`` with the book's tags
and field order (``b t e u s i``) plus our ``v`` (hello/version, sent on reset)
and ``d`` (diagnostic counters).  ``*HH`` is an optional CRC-8/SMBUS of every
byte before the tab that precedes it; lines of the book's firmware have none
and are accepted.  Trailing fields we do not know are ignored (that is how the
protocol is extended without breaking old parsers).

PC → board: ``s <left> <right>\\r`` (integers, ±1023) and ``r\\r``, optionally
with `` *HH`` before the terminator.

Numbers are parsed strictly: plain ASCII decimals only.  Python's ``float()``
would accept ``nan``, ``inf``, ``1e309``, ``1_000`` and non-ASCII digits; none
of them is a valid reading from the board, so each is rejected.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

MAX_LINE_BYTES = 160  # longest board line is the `d` line, < 112 bytes
COMMAND_MAX = 1023

_INT = re.compile(r"[+-]?[0-9]{1,10}\Z")
_DEC = re.compile(r"[+-]?[0-9]{1,10}(\.[0-9]{1,9})?\Z")
_CRC = re.compile(r"\*[0-9A-F]{2}\Z")  # uppercase, as the firmware writes it


class LineError(ValueError):
    """A board line that is not valid; ``kind`` is a short machine-readable class."""

    KINDS = ("empty", "overlong", "binary", "checksum", "unknown_tag", "missing_field",
             "bad_number", "out_of_range", "partial")

    def __init__(self, kind: str, detail: str) -> None:
        assert kind in self.KINDS, kind
        super().__init__(f"{kind}: {detail}")
        self.kind = kind


def crc8(data: bytes) -> int:
    """CRC-8/SMBUS: polynomial 0x07, init 0, no reflection (check('123456789') = 0xF4)."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


# ----------------------------------------------------------------- messages
@dataclass(frozen=True)
class Battery:
    """`b` line: battery voltage (V)."""

    volts: float


@dataclass(frozen=True)
class TimeStamp:
    """`t` line: board clock and measured status period."""

    micros: int          # board clock, µs (wraps at 2^32)
    loop_s: float        # status period measured on the board, s


@dataclass(frozen=True)
class Encoders:
    """`e` line: cumulative encoder ticks of both wheels."""

    left: int            # cumulative ticks, int32
    right: int


@dataclass(frozen=True)
class Ultrasonic:
    """`u` line: sonar distance (cm)."""

    cm: float            # 0 = no echo in the book's firmware and ours


@dataclass(frozen=True)
class SpeedEcho:
    """`s` line: the motor commands the board applies, and its drive state."""

    left: float          # the motor command the board applies (book: PWM units)
    right: float
    state: str | None    # our firmware: "idle" | "run" | "timeout"; None from the book's


@dataclass(frozen=True)
class Quaternion:
    """`i` line: the IMU orientation quaternion."""

    x: float
    y: float
    z: float
    w: float


@dataclass(frozen=True)
class Hello:
    """`v` line: protocol and firmware versions, settings."""

    fields: tuple[str, ...]  # protocol version, firmware version, settings (PROTOCOL.md)


@dataclass(frozen=True)
class Diagnostics:
    """`d` line: the board's error and event counters."""

    counters: tuple[int, ...]


Message = Battery | TimeStamp | Encoders | Ultrasonic | SpeedEcho | Quaternion | Hello | Diagnostics


# ----------------------------------------------------------------- parsing
def _number(field: str, name: str, lo: float, hi: float, integer: bool) -> float:
    """``field`` as an int (``integer``) or float within [lo, hi]; LineError naming ``name`` if not."""
    if not (_INT if integer else _DEC).match(field):
        raise LineError("bad_number", f"{name}={field!r} is not {'an integer' if integer else 'a decimal number'}")
    v = int(field) if integer else float(field)
    if not lo <= v <= hi:
        raise LineError("out_of_range", f"{name}={v} outside [{lo}, {hi}]")
    return v


def _int(field: str, name: str, lo: int, hi: int) -> int:
    return _number(field, name, lo, hi, integer=True)


def _dec(field: str, name: str, lo: float, hi: float) -> float:
    return _number(field, name, lo, hi, integer=False)


_INT32 = (-(2**31), 2**31 - 1)
# tag: (number of required fields, parser of the fields)
_PARSERS = {
    "b": (1, lambda f: Battery(_dec(f[0], "battery", 0.0, 100.0))),
    "t": (2, lambda f: TimeStamp(_int(f[0], "micros", 0, 2**32 - 1), _dec(f[1], "loop_s", 0.0, 1000.0))),
    "e": (2, lambda f: Encoders(_int(f[0], "left_ticks", *_INT32), _int(f[1], "right_ticks", *_INT32))),
    "u": (1, lambda f: Ultrasonic(_dec(f[0], "ultrasonic_cm", 0.0, 10000.0))),
    "s": (2, lambda f: SpeedEcho(_dec(f[0], "left_cmd", -65535.0, 65535.0),
                                 _dec(f[1], "right_cmd", -65535.0, 65535.0),
                                 f[2] if len(f) > 2 and f[2] in ("idle", "run", "timeout") else None)),
    "i": (4, lambda f: Quaternion(*(_dec(v, n, -1.01, 1.01)
                                    for v, n in zip(f[:4], ("qx", "qy", "qz", "qw"), strict=True)))),
    "v": (1, lambda f: Hello(tuple(f))),
    "d": (1, lambda f: Diagnostics(tuple(_int(v, f"diag[{k}]", 0, 2**32 - 1) for k, v in enumerate(f)))),
}


def parse_line(raw: bytes) -> tuple[Message, bool]:
    """Parse one board line (without or with its terminator).

    Returns (message, had_checksum).  Raises LineError for anything invalid.
    """
    if len(raw) > MAX_LINE_BYTES:
        raise LineError("overlong", f"{len(raw)} bytes > {MAX_LINE_BYTES}")
    raw = raw.rstrip(b"\r\n")
    if not raw.strip():
        raise LineError("empty", "blank line")
    if any(b != 9 and not 32 <= b < 127 for b in raw):
        raise LineError("binary", f"non-printable bytes in {raw[:40]!r}")
    text = raw.decode("ascii")
    fields = text.split("\t")
    had_crc = False
    if len(fields) > 1 and _CRC.match(fields[-1]):
        body = raw[: raw.rfind(b"\t")]
        want = int(fields[-1][1:], 16)
        got = crc8(body)
        if got != want:
            raise LineError("checksum", f"CRC {want:02X} in line, {got:02X} computed for {body[:40]!r}")
        fields = fields[:-1]
        had_crc = True
    elif fields[-1].startswith("*"):
        raise LineError("checksum", f"malformed checksum token {fields[-1]!r}")
    tag = fields[0].strip()
    if tag not in _PARSERS:
        raise LineError("unknown_tag", f"tag {tag!r} in {text[:40]!r}")
    need, parse = _PARSERS[tag]
    args = [f.strip() for f in fields[1:]]
    if len(args) < need:
        raise LineError("missing_field", f"{tag!r} line needs {need} fields, got {len(args)}: {text[:60]!r}")
    # Extra trailing fields are extensions of newer firmware: ignored, except where
    # the message keeps them (`s` state, `v`, `d`).
    return parse(args), had_crc


def format_command(left: float, right: float, checksum: bool = True) -> bytes:
    """The ``s <left> <right>\\r`` motor command, integers clamped to ±1023; NaN/Inf → 0."""
    def clean(v: float) -> int:
        if not math.isfinite(v):
            return 0
        return int(max(-COMMAND_MAX, min(COMMAND_MAX, round(v))))

    body = f"s {clean(left)} {clean(right)}".encode("ascii")
    if checksum:
        body += b" *%02X" % crc8(body)
    return body + b"\r"


def format_reset() -> bytes:
    """The ``r\\r`` reset request (the book sends it twice on shutdown)."""
    return b"r\r"
