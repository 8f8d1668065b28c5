"""The virtual LaunchPad: a real pty, our firmware core, the motor model, our driver core."""
from __future__ import annotations

import os

import pytest
import serial

from chefbot_bringup import launchpad_protocol as proto
from chefbot_bringup.launchpad import LaunchpadCore
from chefbot_firmware.virtual_board import (
    EDGES_PER_REV,
    FREE_SPEED_RAD_S,
    MotorModel,
    PtyPort,
    SteppedSerial,
    VirtualBoard,
)


def run(board: VirtualBoard, ser: serial.Serial, core: LaunchpadCore, seconds: float, cmd: bytes | None,
        t0: float = 0.0) -> list:
    """Step the board in 10 ms steps, sending cmd each step; returns the parsed messages."""
    msgs = []
    t = t0
    for _ in range(round(seconds / 0.01)):
        if cmd is not None:
            ser.write(cmd)
            ser.flush()
        board.step(0.01)
        t += 0.01
        msgs += [m for m, _ in core.on_bytes(ser.read(ser.in_waiting or 0), t)]
    # The kernel hands pty bytes to the other side asynchronously, and this loop runs
    # board time much faster than real time: drain until the port has been quiet a while.
    msgs += [m for m, _ in core.on_bytes(drain(ser), t)]
    return msgs


def drain(ser: serial.Serial, quiet_s: float = 0.1) -> bytes:
    """Read until nothing arrives for quiet_s seconds (waits on the port, no fixed sleep)."""
    out = b""
    ser.timeout = quiet_s
    while True:
        chunk = ser.read(65536)
        if not chunk:
            break
        out += chunk
    ser.timeout = 0
    return out


@pytest.fixture()
def link(tmp_path):
    return tmp_path / "launchpad"


def test_pty_symlink_points_at_the_slave_and_is_removed_on_close(link) -> None:
    with PtyPort(link) as port:
        assert link.is_symlink() and os.readlink(link) == port.path
    assert not link.exists()


def test_motor_model_reaches_free_speed() -> None:
    m = MotorModel()
    for _ in range(200):
        m.step(0.5, 0.01)
    assert m.speed == pytest.approx(0.5 * FREE_SPEED_RAD_S, rel=1e-3)


def test_driver_commands_turn_the_wheels_and_encoders_report_it(link) -> None:
    core = LaunchpadCore(max_ticks_per_s=2 * EDGES_PER_REV)
    with VirtualBoard(link) as board, serial.Serial(str(link), 115200, timeout=0) as ser:
        core.on_open(0.0)
        cmd = proto.format_command(512, 512)
        msgs = run(board, ser, core, 1.0, cmd)
        enc = [m for m in msgs if isinstance(m, proto.Encoders)]
        assert len(enc) >= 20                       # ~30 Hz status lines
        left, right = enc[-1].left, enc[-1].right
        # half duty, first-order lag: a bit under 0.5 x free speed x 1 s of travel
        expect = 0.5 * FREE_SPEED_RAD_S / (2 * 3.141592653589793) * EDGES_PER_REV
        assert 0.8 * expect < left < expect and abs(left - right) <= 2
        assert board.fw.command(0) == 512 and board.fw.drive_state == "run"
        assert core.stats.bad_total <= 1            # at most the first partial line


def test_watchdog_stops_the_wheels_when_the_driver_goes_silent(link) -> None:
    core = LaunchpadCore(max_ticks_per_s=2 * EDGES_PER_REV)
    with VirtualBoard(link) as board, serial.Serial(str(link), 115200, timeout=0) as ser:
        core.on_open(0.0)
        run(board, ser, core, 0.5, proto.format_command(400, -400))
        assert board.fw.drive_state == "run"
        msgs = run(board, ser, core, 1.0, None, t0=0.5)
        assert board.fw.drive_state == "timeout" and board.fw.wheel_duty(0) == 0.0
        states = [m.state for m in msgs if isinstance(m, proto.SpeedEcho)]
        assert "timeout" in states


def test_unplug_fails_the_open_port_and_replug_keeps_the_link(link) -> None:
    with VirtualBoard(link) as board:
        ser = serial.Serial(str(link), 115200, timeout=0)
        first = board.path
        board.port.close()
        board.step(0.1)                             # an unplugged board keeps running, sends into nothing
        with pytest.raises(serial.SerialException):
            for _ in range(3):
                ser.read(1)
        ser.close()
        board.reconnect(link)
        assert os.readlink(link) == board.path
        with serial.Serial(str(link), 115200, timeout=0) as ser2:
            board.step(0.1)
            assert drain(ser2)
        assert first  # the old path is gone; the link is what drivers use


def test_stepped_serial_moves_time_only_while_reading() -> None:
    with VirtualBoard() as board, SteppedSerial(board, dt=0.01) as port:
        assert port.now() == 0.0
        port.write(b"s 300 300\r")
        assert port.now() == 0.0                       # writing takes no time
        seen = b""
        while port.now() < 1.0:
            seen += port.read(0.1)
        assert 1.0 <= port.now() < 1.1
        lines = [ln for ln in seen.split(b"\n") if ln.startswith(b"e\t")]
        assert 25 <= len(lines) <= 35                   # 30 Hz status lines over one simulated second
        assert board.motors[0].angle > 0               # the command reached the board and turned the wheels
        assert port.read(0.0) is not None and port.now() >= 1.0
    with pytest.raises(ValueError, match="dt"):
        SteppedSerial(board, dt=0.0)
