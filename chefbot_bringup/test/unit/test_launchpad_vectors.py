"""The PC-side protocol against the firmware: shared golden vectors and the real core.

``firmware/protocol_vectors.txt`` is read by the firmware's C++ tests too, so a
change on either side that breaks the other fails here.  Commands formatted by
the driver are fed into the firmware core (host library, ctypes) to check that
the board accepts exactly what we send.
"""
from __future__ import annotations

import pytest

from chefbot_bringup import launchpad_protocol as proto
from chefbot_firmware.host import FirmwareHost
from chefbot_firmware.protocol_vectors import load_vectors

VECTORS = load_vectors()


def fields(msg: proto.Message) -> tuple:
    """The message's values in the order the line carries them."""
    if isinstance(msg, proto.Battery):
        return (msg.volts,)
    if isinstance(msg, proto.TimeStamp):
        return (msg.micros, msg.loop_s)
    if isinstance(msg, proto.Encoders):
        return (msg.left, msg.right)
    if isinstance(msg, proto.Ultrasonic):
        return (msg.cm,)
    if isinstance(msg, proto.SpeedEcho):
        return (msg.left, msg.right) + ((msg.state,) if msg.state else ())
    if isinstance(msg, proto.Quaternion):
        return (msg.x, msg.y, msg.z, msg.w)
    if isinstance(msg, proto.Hello):
        return msg.fields
    if isinstance(msg, proto.Diagnostics):
        return msg.counters
    raise AssertionError(f"unexpected message {msg!r}")


def as_value(text: str):
    try:
        return float(text)
    except ValueError:
        return text


def test_vectors_file_is_not_empty() -> None:
    assert len(VECTORS.crc) >= 3 and len(VECTORS.tx) >= 20 and len(VECTORS.rx) >= 10


@pytest.mark.parametrize("vec", VECTORS.crc, ids=lambda v: f"line{v.line_no}")
def test_crc_vectors(vec) -> None:
    assert proto.crc8(vec.data) == vec.crc


@pytest.mark.parametrize("vec", VECTORS.tx, ids=lambda v: f"{v.kind}-line{v.line_no}")
def test_board_lines_parse_to_the_vector_values(vec) -> None:
    msg, had_crc = proto.parse_line(vec.line)
    assert had_crc == (vec.kind == "tx")
    got = tuple(as_value(str(v)) if isinstance(v, str) else float(v) for v in fields(msg))
    want = tuple(as_value(v) for v in vec.values)
    assert got == pytest.approx(want) if all(isinstance(x, float) for x in want) else got == want


@pytest.mark.parametrize("vec", [v for v in VECTORS.tx if v.kind == "tx"], ids=lambda v: f"line{v.line_no}")
def test_any_flipped_bit_of_a_checksummed_line_is_caught(vec) -> None:
    """Every single-bit error in a checksummed line is refused by the driver core.

    (Once the board has sent one checksummed line the core requires the token, so
    a flip that turns '*' into another character cannot make the line pass as an
    unchecked book-firmware line.)
    """
    from chefbot_bringup.launchpad import LaunchpadCore
    body = vec.line[:-1]
    for i in range(len(body)):
        for bit in range(8):
            bad = bytearray(body)
            bad[i] ^= 1 << bit
            core = LaunchpadCore(max_ticks_per_s=11200)
            core.on_open(0.0)
            core.on_bytes(b"\n" + vec.line, 0.0)  # establishes the checksummed link
            assert core.stats.lines_ok == 1 and core.crc_required
            got = core.on_bytes(bytes(bad) + b"\n", 0.1)
            if bad[i] in (10, 13):
                continue  # the flip made a terminator: the line is split, each part judged on its own
            assert core.stats.lines_ok == 1, f"flip byte {i} bit {bit}: {bytes(bad)!r} accepted as {got!r}"


@pytest.mark.parametrize("left,right", [(100, -100), (0, 0), (1023, -1023), (-1023, 1023), (1, -1),
                                        (5000, -5000), (512.4, -512.6)])
@pytest.mark.parametrize("checksum", [True, False])
def test_firmware_accepts_our_commands(left: float, right: float, checksum: bool) -> None:
    line = proto.format_command(left, right, checksum)
    expect = [max(-1023, min(1023, round(v))) for v in (left, right)]
    with FirmwareHost() as board:
        board.power_on()
        board.feed(line)
        board.advance(2000)
        assert [board.command(0), board.command(1)] == expect
        assert board.stat("rx_ok") == 1 and board.stat("rx_errors") == 0


def test_firmware_output_parses_without_errors() -> None:
    """Two seconds of real firmware output (all line kinds, with CRC) parse cleanly."""
    from chefbot_bringup.launchpad import LaunchpadCore
    core = LaunchpadCore(max_ticks_per_s=11200)
    with FirmwareHost() as board:
        board.power_on()
        core.on_open(0.0)
        core.on_bytes(b"\n", 0.0)  # start at a line boundary: no partial first line
        board.set_ultrasonic_cm(42.0)
        board.set_battery_volts(12.3)
        board.set_imu_quaternion(0.0, 0.0, 0.0, 1.0)
        for k in range(200):
            board.feed(proto.format_command(300, 300))
            board.advance(10_000)
            board.wheel_advance(0, 30)
            board.wheel_advance(1, 30)
            core.on_bytes(board.read_tx(), k * 0.01)
    s = core.stats
    assert s.bad_total == 0, s.lines_bad
    assert s.lines_ok > 300 and s.crc_lines == s.lines_ok
    assert s.hello is not None and s.board_state == "run"
