"""LaunchPad protocol (PC side) and the driver core: parsing, malformed input, continuity."""
from __future__ import annotations

import pytest

from chefbot_bringup import launchpad_protocol as proto
from chefbot_bringup.launchpad import (
    ERROR,
    OK,
    WARN,
    EncoderContinuity,
    LaunchpadConfig,
    LaunchpadCore,
    LineAssembler,
    battery_status,
    link_status,
    wrap_int32,
)


def with_crc(body: str) -> bytes:
    b = body.encode()
    return b + b"\t*%02X\n" % proto.crc8(b)


# ------------------------------------------------------------------ protocol
def test_crc8_check_value() -> None:
    assert proto.crc8(b"123456789") == 0xF4  # CRC-8/SMBUS catalogue check value


@pytest.mark.parametrize("line,expected", [
    (b"b\t0.00\n", proto.Battery(0.0)),
    (b"t\t66458239\t0.05\n", proto.TimeStamp(66458239, 0.05)),
    (b"e\t0\t0\n", proto.Encoders(0, 0)),
    (b"u\t10\n", proto.Ultrasonic(10.0)),
    (b"s\t0.00\t0.00\n", proto.SpeedEcho(0.0, 0.0, None)),
    (b"i\t-0.68\t-0.47\t-0.40\t0.40\n", proto.Quaternion(-0.68, -0.47, -0.40, 0.40)),
])
def test_book_lines_parse(line: bytes, expected) -> None:
    """The lines printed in the book (ch. 8), without checksum, as the book's firmware sends them."""
    msg, had_crc = proto.parse_line(line)
    assert msg == expected and not had_crc


def test_checksummed_lines_and_extensions() -> None:
    msg, had_crc = proto.parse_line(with_crc("e\t-2147483648\t2147483647"))
    assert msg == proto.Encoders(-2**31, 2**31 - 1) and had_crc
    msg, _ = proto.parse_line(with_crc("s\t-1023.00\t512.00\ttimeout"))
    assert msg == proto.SpeedEcho(-1023.0, 512.0, "timeout")
    # unknown trailing fields of a newer firmware are ignored
    msg, _ = proto.parse_line(b"u\t120\tfuture\t42\n")
    assert msg == proto.Ultrasonic(120.0)


def test_bad_checksum_rejected() -> None:
    good = with_crc("e\t100\t200")
    bad = good.replace(b"100", b"101")
    with pytest.raises(proto.LineError) as e:
        proto.parse_line(bad)
    assert e.value.kind == "checksum"
    with pytest.raises(proto.LineError) as e:
        proto.parse_line(b"e\t1\t2\t*Z9\n")
    assert e.value.kind == "checksum"


@pytest.mark.parametrize("line,kind", [
    (b"\n", "empty"),
    (b"   \t \n", "empty"),
    (b"e\tnan\t0\n", "bad_number"),
    (b"e\tinf\t0\n", "bad_number"),
    (b"b\t1e309\n", "bad_number"),
    (b"e\t1_000\t0\n", "bad_number"),
    ("e\t\u0661\u0662\t0\n".encode(), "binary"),          # Arabic-Indic digits: not ASCII
    (b"e\t\xd9\xa1\t0\n", "binary"),
    (b"e\t0x10\t0\n", "bad_number"),
    (b"e\t99999999999\t0\n", "bad_number"),
    (b"e\t2147483648\t0\n", "out_of_range"),
    (b"i\t1.5\t0\t0\t0\n", "out_of_range"),
    (b"e\t5\n", "missing_field"),
    (b"i\t0\t0\t0\n", "missing_field"),
    (b"x\t1\n", "unknown_tag"),
    (b"ChefBot LaunchPad booting...\n", "unknown_tag"),   # boot banner
    (b"e\t1\x00\t2\n", "binary"),
    (b"\xff\xfe\x00garbage\n", "binary"),
    (b"e\t" + b"1" * 200 + b"\n", "overlong"),
])
def test_malformed_lines(line: bytes, kind: str) -> None:
    with pytest.raises(proto.LineError) as e:
        proto.parse_line(line)
    assert e.value.kind == kind


def test_format_command_clamps_and_rounds() -> None:
    assert proto.format_command(100, -100, checksum=False) == b"s 100 -100\r"
    assert proto.format_command(5000.4, -99999, checksum=False) == b"s 1023 -1023\r"
    assert proto.format_command(float("nan"), float("inf"), checksum=False) == b"s 0 0\r"
    assert proto.format_command(10.6, -10.6, checksum=False) == b"s 11 -11\r"
    line = proto.format_command(100, -100)
    body, token = line[:-1].rsplit(b" ", 1)
    assert token == b"*%02X" % proto.crc8(body)
    assert proto.format_reset() == b"r\r"


# ------------------------------------------------------------------ assembler
def test_assembler_splits_terminators_and_drops_partial_first_line() -> None:
    a = LineAssembler()
    out = a.feed(b"3\t44\ne\t1\t2\r\nu\t5\rb\t1.0")
    assert isinstance(out[0], proto.LineError) and out[0].kind == "partial"
    assert out[1:] == [b"e\t1\t2", b"u\t5"]
    assert a.feed(b"2\n") == [b"b\t1.02"]       # a line split across reads


def test_assembler_caps_line_length() -> None:
    a = LineAssembler(max_len=16)
    a.feed(b"\n")  # start at a line boundary
    out = a.feed(b"x" * 1000 + b"\ne\t1\t2\n")
    assert isinstance(out[0], proto.LineError) and out[0].kind == "overlong"
    assert out[1] == b"e\t1\t2"


# ------------------------------------------------------------------ continuity
def test_continuity_passes_normal_motion_and_int32_wrap() -> None:
    c = EncoderContinuity(max_ticks_per_s=11200)
    c.update(2**31 - 100, 0, 0.0)
    (left, right), ev = c.update(wrap_int32(2**31 - 100 + 300), 300, 0.1)
    assert ev is None and left == wrap_int32(2**31 + 200) and right == 300


def test_continuity_absorbs_reboot_and_jump() -> None:
    c = EncoderContinuity(max_ticks_per_s=11200)
    c.update(50000, -40000, 0.0)
    (left, right), ev = c.update(50100, -40100, 0.1)
    assert ev is None and (left, right) == (50100, -40100)
    # MCU reboot: counters back to zero → flagged, published counters stay put
    (left, right), ev = c.update(0, 0, 0.2)
    assert ev is not None and ev.kind == "reset" and (left, right) == (50100, -40100)
    (left, right), ev = c.update(30, -30, 0.25)
    assert ev is None and (left, right) == (50130, -40130)
    # impossible jump: 1e6 ticks in 0.05 s (> 1.5 x 11200 ticks/s): held back
    (left, right), ev = c.update(1_000_030, -30, 0.3)
    assert ev is not None and ev.kind == "jump" and (left, right) == (50130, -40130)
    # it persists (the counters really moved): tracking goes on from the new value
    (left, right), ev = c.update(1_000_130, 70, 0.35)
    assert ev is None and (left, right) == (50230, -40030)


def test_continuity_hello_marks_reset_even_when_small() -> None:
    c = EncoderContinuity(max_ticks_per_s=11200)
    c.update(40, 40, 0.0)
    c.board_restarted()
    (left, right), ev = c.update(0, 0, 0.01)
    assert ev is not None and ev.kind == "reset" and (left, right) == (40, 40)


def test_continuity_rejects_bad_limit() -> None:
    with pytest.raises(ValueError, match="max_ticks_per_s"):
        EncoderContinuity(0)


# ------------------------------------------------------------------ core
def test_core_counts_good_and_bad_lines_and_keeps_odometry() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200)
    core.on_open(0.0)
    stream = (b"tial line\n" + with_crc("e\t10\t20") + b"e\tnan\t0\n" + b"\xff\xfe\n"
              + with_crc("e\t30\t40") + with_crc("s\t1.0\t2.0\trun"))
    results = core.on_bytes(stream, 0.1)
    enc = [extra for msg, extra in results if isinstance(msg, proto.Encoders)]
    assert [e[:2] for e in enc] == [(10, 20), (30, 40)]
    assert core.stats.lines_ok == 3 and core.stats.crc_lines == 3
    assert core.stats.lines_bad == {"partial": 1, "bad_number": 1, "binary": 1}
    assert core.stats.board_state == "run"


def test_core_requires_checksums_once_the_board_sends_them() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200)
    core.on_open(0.0)
    core.on_bytes(b"\n" + with_crc("e\t1\t2"), 0.0)
    core.on_bytes(b"e\t3\t4\n", 0.1)               # unchecked line on a checksummed link
    assert core.stats.lines_ok == 1 and core.stats.lines_bad == {"checksum": 1}
    core.on_close()
    core.on_open(1.0)                                # maybe the book's firmware now
    results = core.on_bytes(b"\ne\t3\t4\nu\t10\n", 1.1)
    assert [type(m) for m, _ in results] == [proto.Encoders, proto.Ultrasonic]


def test_lowercase_checksum_token_is_malformed() -> None:
    line = with_crc("e\t1\t2")
    with pytest.raises(proto.LineError) as e:
        proto.parse_line(line[:-3] + line[-3:-1].lower() + b"\n" if line[-3:-1].lower() != line[-3:-1]
                         else b"e\t1\t2\t*ab\n")
    assert e.value.kind == "checksum"


def test_core_silence_and_reconnect_counting() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200, silence_timeout=1.0)
    assert not core.silent(10.0)              # not connected: nothing to time out
    core.on_open(0.0)
    core.on_bytes(b"\ne\t0\t0\n", 0.5)
    assert not core.silent(1.4)
    assert core.silent(1.6)
    core.on_close()
    assert core.stats.reconnects == 1 and not core.connected


def test_core_single_coherent_command_with_stale_side_zeroed() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200, command_timeout=0.5, silence_timeout=10.0,
                         checksum_commands=False)
    core.on_open(0.0)
    core.on_bytes(b"\ne\t0\t0\n", 0.0)
    core.set_left(300.0, 1.0)
    core.set_right(-200.0, 1.0)
    assert core.command(1.2) == b"s 300 -200\r"
    core.set_left(310.0, 1.6)                 # right PID went silent
    assert core.command(1.7) == b"s 310 0\r"
    assert core.command(5.0) == b"s 0 0\r"    # both stale
    assert core.stop_command() == b"s 0 0\r"


def talking_core(t: float = 0.0) -> LaunchpadCore:
    core = LaunchpadCore(max_ticks_per_s=11200, silence_timeout=1.0, command_timeout=0.5,
                         checksum_commands=False)
    core.on_open(t)
    core.on_bytes(b"\ne\t0\t0\n", t)
    return core


def test_no_drive_command_to_a_board_that_stopped_talking() -> None:
    core = talking_core()
    t = 0.0
    core.set_left(500.0, t)
    core.set_right(500.0, t)
    assert core.command(t) == b"s 500 500\r"
    # the board goes silent at t = 0; the PIDs keep asking for 500 at 30 Hz
    sent = []
    while t < 5.0:
        t += 1 / 30
        core.set_left(500.0, t)
        core.set_right(500.0, t)
        sent.append((t, core.command(t)))
        if core.silent(t):                    # the node closes and reopens the port
            core.on_close()
            core.on_open(t + 0.06)
    assert all(cmd == b"s 0 0\r" for ts, cmd in sent if ts > 1.0)
    assert all(cmd == b"s 500 500\r" for ts, cmd in sent if ts <= 1.0)
    assert core.stats.commands_zeroed == sum(ts > 1.0 for ts, _ in sent)
    # a valid line again: drive requests go through
    core.on_bytes(b"\ne\t0\t0\n", t)
    assert core.command(t) == b"s 500 500\r"


def test_no_drive_command_after_open_before_the_first_valid_line() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200, checksum_commands=False)
    core.set_left(200.0, 0.0)
    assert core.command(0.0) == b"s 0 0\r"          # port not open
    core.on_open(0.0)
    assert core.command(0.1) == b"s 0 0\r"          # open, nothing heard
    core.on_bytes(b"tial line\ngarbage\n", 0.1)     # a partial line and garbage are not "heard"
    assert core.command(0.2) == b"s 0 0\r"
    core.on_bytes(b"e\t0\t0\n", 0.2)
    core.set_left(200.0, 0.2)
    assert core.command(0.25) == b"s 200 0\r"


def test_link_status_stays_error_while_the_board_is_silent() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200, silence_timeout=1.0)
    assert link_status(core, 0.0, "/dev/x", "")[0] == ERROR
    core.on_open(0.0)
    assert link_status(core, 0.0, "/dev/x", "") == (WARN, "/dev/x open, waiting for the board's first valid "
                                                         "line (motors held at 0)")
    core.on_bytes(b"\ne\t0\t0\n", 0.1)
    assert link_status(core, 0.2, "/dev/x", "") == (OK, "connected to /dev/x")
    level, text = link_status(core, 1.2, "/dev/x", "")     # silent, not yet closed
    assert level == ERROR and "no valid line" in text
    core.on_close()
    err = "no valid line from /dev/x for 1.0 s; reconnecting"
    assert link_status(core, 1.2, "/dev/x", err) == (ERROR, err)
    core.on_open(1.3)                                        # reopened, still silent: not OK
    level, text = link_status(core, 1.3, "/dev/x", err)
    assert level == ERROR and text.startswith(err)
    core.on_bytes(b"\ne\t0\t0\n", 1.5)                     # it speaks again
    assert link_status(core, 1.5, "/dev/x", err) == (OK, "connected to /dev/x")


def test_encoder_warning_clears_once_readings_are_consistent_again() -> None:
    core = talking_core()
    core.on_bytes(b"e\t100\t100\n", 0.05)
    core.on_bytes(b"v\t1\n" + b"e\t0\t0\n", 0.1)             # hello + counters from 0: a reboot
    assert core.stats.encoder_resets == 1
    level, text = link_status(core, 0.1, "/dev/x", "")
    assert level == WARN and text.startswith("connected to /dev/x") and "absorbed" in text
    for i in range(1, 11):
        core.on_bytes(b"e\t%d\t%d\n" % (i, i), 0.1 + i * 0.03)
    assert link_status(core, 0.5, "/dev/x", "") == (OK, "connected to /dev/x")


def test_core_rejects_bad_timeouts() -> None:
    with pytest.raises(ValueError, match="silence_timeout"):
        LaunchpadCore(1.0, silence_timeout=0)
    with pytest.raises(ValueError, match="command_timeout"):
        LaunchpadCore(1.0, command_timeout=-1)


# ------------------------------------------------------------------ board clock
def test_board_clock_unwraps_the_32_bit_microsecond_counter() -> None:
    from chefbot_bringup.launchpad import BoardClock
    c = BoardClock()
    assert c.seconds is None
    assert c.update(2**32 - 1_000_000) == pytest.approx(4294.967296 - 1.0)
    assert c.update(500_000) == pytest.approx(4294.967296 + 0.5)   # wrapped
    c.reset()
    assert c.update(10) == pytest.approx(10e-6)


def test_encoder_speed_is_judged_on_the_board_clock_not_on_arrival_times() -> None:
    """A board (or simulation) running 4x faster than the host clock at top wheel speed,
    and lines arriving in bunches: nothing may be taken for an impossible jump."""
    core = LaunchpadCore(max_ticks_per_s=11200)
    core.on_open(0.0)
    core.on_bytes(b"\n", 0.0)
    ticks_per_cycle = int(11000 / 30)           # just under top speed, 30 status cycles per board second
    micros, left = 1_000_000, 0
    host_t = 0.0
    for cycle in range(120):
        micros += 33_333
        left += ticks_per_cycle
        host_t += 0.25 / 30 if cycle % 10 else 0.0   # 4x faster than real time, and bunched
        core.on_bytes(with_crc(f"t\t{micros}\t0.033") + with_crc(f"e\t{left}\t{left}"), host_t)
    assert core.stats.encoder_jumps == 0 and core.stats.encoder_resets == 0
    assert core.stats.bad_total == 0


def test_a_real_jump_is_still_caught_on_board_time_and_after_a_reopen() -> None:
    core = LaunchpadCore(max_ticks_per_s=11200)
    core.on_open(0.0)
    core.on_bytes(b"\n" + with_crc("t\t1000000\t0.033") + with_crc("e\t5000\t5000"), 0.0)
    core.on_bytes(with_crc("t\t1033333\t0.033") + with_crc("e\t5300\t5300"), 0.03)
    core.on_bytes(with_crc("t\t1066666\t0.033") + with_crc("e\t905300\t5600"), 0.06)
    assert core.stats.encoder_jumps == 1
    # a one-line glitch: the next line continues from before it, nothing is lost or counted again
    results = core.on_bytes(with_crc("t\t1100000\t0.033") + with_crc("e\t5900\t5900"), 0.09)
    assert core.stats.encoder_jumps == 1
    assert [extra[:2] for msg, extra in results if isinstance(msg, proto.Encoders)] == [(5900, 5900)]
    # reopen: the first e line (host time) and the next (board time) must not fake a jump
    core.on_close()
    core.on_open(5.0)
    results = core.on_bytes(b"\n" + with_crc("e\t5900\t5900") + with_crc("t\t9000000\t0.033")
                            + with_crc("e\t6200\t6200"), 5.5)
    assert core.stats.encoder_jumps == 1
    published = [extra[:2] for msg, extra in results if isinstance(msg, proto.Encoders)]
    assert published[-1][0] - published[0][0] == 300


def test_battery_diagnostic_levels():
    cfg = LaunchpadConfig(battery_empty_voltage=11.0, battery_full_voltage=13.0, battery_low=0.2,
                          battery_critical=0.05)
    assert battery_status(cfg, None)[0] == WARN
    assert battery_status(cfg, 0.0)[0] == WARN                 # board without a divider
    assert battery_status(cfg, 12.5) == (OK, "12.50 V, 75 %")
    level, text = battery_status(cfg, 11.3)
    assert level == WARN and "battery low" in text and "15 %" in text
    level, text = battery_status(cfg, 11.05)
    assert level == ERROR and "critical" in text


def test_battery_thresholds_validated():
    with pytest.raises(ValueError, match="battery_critical"):
        LaunchpadConfig(battery_low=0.1, battery_critical=0.3)
