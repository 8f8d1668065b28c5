"""The firmware's host library through ctypes, as the simulator uses it."""
from __future__ import annotations

import math

import pytest

from chefbot_firmware import FirmwareHost, MotorOutput, library_path
from chefbot_firmware.host import LEFT, RIGHT
from chefbot_firmware.protocol_vectors import load_vectors

CRC_POLY = 0x07


def crc8(data: bytes) -> int:
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ CRC_POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def lines(data: bytes) -> list[bytes]:
    return [ln for ln in data.split(b"\n") if ln]


def fields(line: bytes) -> list[str]:
    parts = line.decode("ascii").split("\t")
    if parts[-1].startswith("*"):
        assert int(parts[-1][1:], 16) == crc8(line[: line.rfind(b"\t")]), line
        parts = parts[:-1]
    return parts


def last(data: bytes, tag: str) -> list[str]:
    found = [fields(ln) for ln in lines(data) if ln.startswith(tag.encode() + b"\t")]
    assert found, f"no {tag!r} line in {data[-300:]!r}"
    return found[-1]


@pytest.fixture
def fw():
    with FirmwareHost() as board:
        yield board


def test_library_path_points_into_firmware_build():
    assert library_path().name == "libchefbot_fw.so"
    assert library_path().parent.name == "build"


def test_hello_line_after_power_on(fw):
    fw.advance(10_000)
    out = fw.read_tx()
    assert out.startswith(b"\nv\t")
    assert fields(lines(out)[0])[:2] == ["v", "1"]


def test_speed_command_motor_outputs_status_and_watchdog(fw):
    fw.advance(5_000)
    fw.read_tx()
    fw.feed(b"s 100 -100\r")
    fw.advance(1_000)
    # VNH2SP30: left clockwise; right motor is mounted mirrored, so its
    # negative command is clockwise at the pins too. 100/1023*255 -> 25.
    assert fw.motor(LEFT) == MotorOutput(ina=1, inb=0, pwm=25)
    assert fw.motor(RIGHT) == MotorOutput(ina=1, inb=0, pwm=25)
    assert fw.wheel_duty(LEFT) == pytest.approx(25 / 255)
    assert fw.wheel_duty(RIGHT) == pytest.approx(-25 / 255)
    assert fw.drive_state == "run"

    fw.advance(200_000)
    out = fw.read_tx()
    assert last(out, "s") == ["s", "100.00", "-100.00", "run"]
    assert last(out, "e") == ["e", "0", "0"]
    # The book's order (no IMU fitted: no `i` line). The first line read may be
    # a partial one: the UART ships bytes at 11 520 B/s.
    tags = b"".join(ln[:1] for ln in lines(out))
    assert b"teusbteusb" in tags

    # No further command: the watchdog (500 ms) brakes both motors.
    fw.advance(250_000)
    assert fw.drive_state == "run"
    fw.advance(100_000)
    assert fw.drive_state == "timeout"
    for side in (LEFT, RIGHT):
        assert fw.motor(side) == MotorOutput(ina=0, inb=0, pwm=255)
        assert fw.motor(side).braking
        assert fw.wheel_duty(side) == 0.0
    fw.read_tx()
    fw.advance(50_000)
    assert last(fw.read_tx(), "s") == ["s", "0.00", "0.00", "timeout"]
    assert fw.stat("watchdog_trips") == 1

    # A new command resumes.
    fw.feed(b"s -1023 0\r\n")
    fw.advance(1_000)
    assert fw.motor(LEFT) == MotorOutput(ina=0, inb=1, pwm=255)
    assert fw.drive_state == "run"


def test_status_rate_is_fixed(fw):
    fw.advance(3_000_000)
    out = fw.read_tx()
    ts = [ln for ln in lines(out) if ln.startswith(b"t\t")]
    assert 90 <= len(ts) <= 91
    periods = {fields(t)[2] for t in ts[1:]}
    assert periods == {"0.033"} or periods <= {"0.033", "0.034"}


def test_sensors_through_the_api(fw):
    fw.wheel_advance(LEFT, 840)
    fw.wheel_advance(RIGHT, -8400)
    fw.set_ultrasonic_cm(55)
    fw.set_imu_quaternion(0.0, 0.0, math.sin(0.25), math.cos(0.25))
    fw.set_battery_volts(11.8)
    fw.advance(300_000)
    out = fw.read_tx()
    assert last(out, "e") == ["e", "840", "-8400"]
    assert last(out, "u") == ["u", "55"]
    qz, qw = float(last(out, "i")[3]), float(last(out, "i")[4])
    assert qz == pytest.approx(math.sin(0.25), abs=1e-4)
    assert qw == pytest.approx(math.cos(0.25), abs=1e-4)
    assert float(last(out, "b")[1]) == pytest.approx(11.8, abs=0.05)
    assert fw.encoder_count(LEFT) == 840
    fw.set_ultrasonic_cm(None)
    fw.advance(200_000)
    assert last(fw.read_tx(), "u") == ["u", "0"]


def test_reset_command_restarts_the_board(fw):
    fw.wheel_advance(LEFT, 100)
    fw.advance(10_000)
    fw.feed(b"r\r")
    fw.advance(10_000)
    assert fw.stat("resets") == 1
    assert fw.encoder_count(LEFT) == 0
    assert b"\nv\t1\t" in fw.read_tx()


def test_configuration_and_counters():
    with FirmwareHost({"watchdog_ms": 100, "status_rate_hz": 10, "command_max": 255}) as fw:
        fw.feed(b"s 255 0\rs 256 0\rhello\r")
        fw.advance(50_000)
        assert fw.motor(LEFT).pwm == 255
        assert fw.stat("rx_ok") == 1
        assert fw.stat("rx_error.out_of_range") == 1
        assert fw.stat("rx_error.unknown_command") == 1
        fw.advance(100_000)
        assert fw.drive_state == "timeout"
        fw.advance(850_000)
        assert 9 <= sum(1 for ln in lines(fw.read_tx()) if ln.startswith(b"t\t")) <= 11
        with pytest.raises(KeyError):
            fw.stat("nope")
        with pytest.raises(KeyError):
            fw.configure("nope", 1)


def test_a_closed_board_raises_instead_of_crashing():
    b = FirmwareHost()
    b.close()
    b.close()                                   # idempotent
    for call in (lambda: b.command(LEFT), lambda: b.advance(1000), lambda: b.feed(b"s 0 0\n"), b.read_tx):
        with pytest.raises(ValueError, match="closed"):
            call()


def test_rx_vectors_through_the_library():
    """Every PC->board vector, fed to the emulated board: the accepted
    commands and the error counters match the golden events."""
    for vec in load_vectors().rx:
        with FirmwareHost({"instant_tx": 1}) as fw:
            fw.feed(vec.data)
            fw.advance(1_000)
            errors = [e[1] for e in vec.events if e[0] == "error"]
            speeds = [e for e in vec.events if e[0] == "s"]
            resets = [e for e in vec.events if e[0] == "r"]
            assert fw.stat("rx_errors") == len(errors), vec
            for cls in set(errors):
                assert fw.stat(f"rx_error.{cls}") == errors.count(cls), vec
            if resets:
                assert fw.stat("resets") >= 1, vec
            elif speeds:
                assert (fw.command(LEFT), fw.command(RIGHT)) == speeds[-1][1:], vec
                assert fw.stat("rx_ok") == len(speeds), vec
