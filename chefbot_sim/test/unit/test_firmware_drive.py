"""Firmware-in-the-loop without ROS: the DC-motor model, and the sim core stepping
our firmware core on sim time, spoken to through the real pseudo-terminal."""
import math
import os
import select

import numpy as np
import pytest

from chefbot_sim import battery
from chefbot_sim.firmware_drive import (
    BOOK_FREE_SPEED,
    BOOK_STALL_TORQUE,
    DcMotor,
    FirmwareDriveError,
    motor_from_joint_limits,
)
from chefbot_sim.sim import SimConfigError, SimOptions, Simulator
from chefbot_sim.world import parse_yaml_world

EMPTY = parse_yaml_world("objects: []")
WALL = parse_yaml_world("objects: [{name: wall, shape: box, size: [0.2, 4.0, 1.0], pose: [2.0, 0.0, 0.0]}]")
SONAR_X = 0.1425      # m, ultrasonic_link ahead of base_footprint (chefbot.xacro)
EDGES_PER_REV = 8400  # firmware X4 decoding
STEPS_PER_S = 240


# ------------------------------------------------------------------ motor model
def test_motor_torque_speed_line():
    m = DcMotor(stall_torque=2.0, free_speed=10.0, friction_torque=0.0)
    assert m.torque(1.0, 0.0) == pytest.approx(2.0)          # stall
    assert m.torque(1.0, 10.0) == pytest.approx(0.0)         # free speed
    assert m.torque(0.5, 2.5) == pytest.approx(0.5)          # on the line
    assert m.torque(-1.0, 0.0) == pytest.approx(-2.0)
    assert m.torque(0.0, 5.0) == pytest.approx(-1.0)         # brake: opposes motion, proportional to speed
    assert m.torque(1.0, -10.0) == pytest.approx(2.0)        # clamped to the stall torque (current limit)
    assert m.torque(3.0, 0.0) == pytest.approx(2.0)          # duty clipped to 1
    assert m.velocity_command(0.5, 0.0) == pytest.approx((5.0, 1.0))
    assert m.velocity_command(0.5, 5.0) == pytest.approx((5.0, 0.0))    # at the target: no torque left
    assert m.velocity_command(0.0, -4.0) == pytest.approx((0.0, 0.8))   # braking a reversing wheel
    assert m.velocity_command(-2.0, 0.0) == pytest.approx((-10.0, 2.0))


def test_motor_friction():
    m = DcMotor(stall_torque=2.0, free_speed=9.0, friction_torque=0.2)   # friction 10 % of stall
    assert m.ideal_speed == pytest.approx(10.0)
    assert m.target_speed(1.0) == pytest.approx(9.0)         # the datasheet's no-load speed
    assert m.target_speed(-0.5) == pytest.approx(-4.0)
    assert m.target_speed(0.05) == 0.0                        # dead band: friction wins
    assert m.steady_speed(1.0) == pytest.approx(9.0)
    assert m.steady_speed(1.0, load_torque=0.8) == pytest.approx(5.0)
    assert m.steady_speed(0.3, load_torque=5.0) == 0.0
    assert m.velocity_command(0.0, 0.0) == (0.0, 0.2)        # at rest: holds up to the friction torque
    assert m.velocity_command(1.0, 0.0) == pytest.approx((9.0, 1.8))    # starts with stall - friction
    assert m.velocity_command(0.0, 5.0) == pytest.approx((0.0, 1.2))    # brake + friction
    assert m.velocity_command(1.0, 9.0) == pytest.approx((9.0, 0.0))    # balanced at the target
    assert m.velocity_command(0.5, -1.0) == pytest.approx((4.0, 1.4))   # friction helps against reverse


def test_motor_from_joint_limits_and_bad_values():
    assert motor_from_joint_limits(1.5, 7.0).stall_torque == 1.5
    assert motor_from_joint_limits(1.5, 7.0).free_speed == 7.0
    book = motor_from_joint_limits(None, None)
    assert book == DcMotor()
    assert (book.stall_torque, book.free_speed) == (BOOK_STALL_TORQUE, BOOK_FREE_SPEED)
    assert motor_from_joint_limits(1.5, 7.0).friction_torque / 1.5 == pytest.approx(
        book.friction_torque / book.stall_torque)
    assert BOOK_FREE_SPEED * 0.045 == pytest.approx(0.377, abs=1e-3)  # the book's 0.377 m/s top speed
    with pytest.raises(FirmwareDriveError, match="stall_torque"):
        DcMotor(stall_torque=0.0)
    with pytest.raises(FirmwareDriveError, match="free_speed"):
        DcMotor(free_speed=math.nan)
    with pytest.raises(FirmwareDriveError, match="friction_torque"):
        DcMotor(stall_torque=1.0, friction_torque=1.0)


# ------------------------------------------------------------------ sim core
class Link:
    """The PC end of the emulated LaunchPad: the pty's slave, opened like launchpad_node does."""

    def __init__(self, path: str) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.buf = b""

    def send(self, line: str) -> None:
        os.write(self.fd, line.encode() + b"\r")

    def lines(self) -> list[list[str]]:
        """Complete lines received since the last call, as fields without the checksum."""
        while select.select([self.fd], [], [], 0)[0]:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            if not chunk:
                break
            self.buf += chunk
        *complete, self.buf = self.buf.split(b"\n")
        out = []
        for raw in complete:
            fields = [f for f in raw.decode(errors="replace").split("\t") if f and not f.startswith("*")]
            if fields:
                out.append(fields)
        return out

    def close(self) -> None:
        os.close(self.fd)


@pytest.fixture()
def fw_sim(urdf, tmp_path):
    s = Simulator(urdf, EMPTY, options=SimOptions(seed=1, drive="firmware", pty_link=str(tmp_path / "lp")))
    link = Link(str(tmp_path / "lp"))
    yield s, link
    link.close()
    s.close()


def drive_with_commands(sim: Simulator, link: Link, left: int, right: int, seconds: float) -> list:
    """Send 's left right' at 30 Hz of sim time (the driver's rate) for ``seconds``."""
    lines = []
    for i in range(int(round(seconds * STEPS_PER_S))):
        if i % 8 == 0:
            link.send(f"s {left} {right}")
        sim.step()
        lines += link.lines()
    return lines


def test_pty_link_path_and_no_plugin_interfaces(fw_sim, tmp_path):
    sim, _ = fw_sim
    assert os.path.realpath(tmp_path / "lp") == sim.pty_path
    assert sim.pty_path.startswith("/dev/")
    with pytest.raises(RuntimeError, match="firmware"):
        sim.set_cmd_vel(0.1, 0.0)
    with pytest.raises(RuntimeError, match="firmware"):
        sim.snapshot()
    sim.set_enabled("odom", True)  # stays off: diff_tf owns odometry in firmware mode
    assert not any(e.kind == "odom" for e in sim.step(STEPS_PER_S))


def test_status_lines_on_sim_time_and_board_inputs(fw_sim):
    sim, link = fw_sim
    sim.step(STEPS_PER_S)  # 1 s of sim time: hello + status lines
    link.lines()
    sim.step(2 * STEPS_PER_S)
    lines = link.lines()
    enc = [f for f in lines if f[0] == "e"]
    assert len(enc) == pytest.approx(60, abs=2), "30 Hz of sim time"
    # the battery model's terminal voltage (chefbot_sim/battery.py; test_battery.py covers the discharge)
    volts = battery.terminal_voltage(sim.options.battery_config(), *sim.battery)
    assert any(f[0] == "b" and float(f[1]) == pytest.approx(volts, abs=0.05) for f in lines)
    quats = [f for f in lines if f[0] == "i"]
    assert quats and float(quats[-1][4]) == pytest.approx(1.0, abs=1e-3)  # facing +x: identity
    states = [f[3] for f in lines if f[0] == "s"]
    assert states[-1] == "idle"
    us = [f for f in lines if f[0] == "u"]
    assert us and us[-1][1] == "0", "empty world: no echo"


def test_drive_encoders_and_watchdog(fw_sim):
    sim, link = fw_sim
    sim.step(STEPS_PER_S // 2)
    x0 = sim.ground_truth()["x"]
    ang0 = sim.bullet.joint_states(sim._wheels)[0]
    fw = sim.firmware
    count0 = [fw.board.fw.encoder_count(side) for side in (0, 1)]
    lines = drive_with_commands(sim, link, 512, 512, 3.0)
    assert fw.drive_state == "run"
    duty = fw.duties()[0]
    assert duty == pytest.approx(512 / 1023, abs=0.01)
    # steady speed: the DC line at this duty, almost unloaded on a flat floor
    speeds = []
    for _ in range(STEPS_PER_S):
        if sim.s.steps % 8 == 0:
            link.send("s 512 512")
        sim.step()
        speeds.append(sim.ground_truth()["linear"][0])
    expected = sim.motor.steady_speed(duty) * 0.045
    assert np.mean(speeds) == pytest.approx(expected, rel=0.08)
    assert sim.ground_truth()["x"] - x0 > 3.0 * 0.5 * expected
    # encoder edges from the physics' wheel angles, in the firmware's own counter
    ang = sim.bullet.joint_states(sim._wheels)[0]
    for side in (0, 1):
        edges = (ang[side] - ang0[side]) / (2 * math.pi) * EDGES_PER_REV
        assert fw.board.fw.encoder_count(side) - count0[side] == pytest.approx(edges, abs=2)
    last_e = [f for f in lines + link.lines() if f[0] == "e"][-1]
    assert int(last_e[1]) > 0 and int(last_e[2]) > 0
    # silence: the firmware's 500 ms watchdog (sim time) brakes the motors
    t_last = sim.time
    stopped_at = None
    while sim.time < t_last + 2.0:
        sim.step()
        if fw.drive_state == "timeout" and stopped_at is None:
            stopped_at = sim.time
    assert stopped_at is not None and 0.45 < stopped_at - t_last < 0.55
    assert fw.duties() == (0.0, 0.0)
    assert abs(sim.ground_truth()["linear"][0]) < 0.005
    assert any(f[0] == "s" and f[3] == "timeout" for f in link.lines())


def test_turning_and_imu_line(fw_sim):
    sim, link = fw_sim
    drive_with_commands(sim, link, -400, 400, 2.0)
    yaw = sim.ground_truth()["yaw"]
    assert yaw > 0.5, "counter-clockwise for left back, right forward"
    sim.step(STEPS_PER_S)  # the watchdog stops the turn; the DMP line catches up
    q = [f for f in link.lines() if f[0] == "i"][-1]
    qz, qw = float(q[3]), float(q[4])
    assert 2 * math.atan2(qz, qw) == pytest.approx(sim.ground_truth()["yaw"], abs=0.01)


def test_sonar_reaches_the_firmware(urdf):
    sim = Simulator(urdf, WALL, options=SimOptions(seed=2, drive="firmware"))
    try:
        link = Link(sim.pty_path)
        sim.step(STEPS_PER_S)
        link.lines()
        sim.step(STEPS_PER_S // 2)
        us = [int(f[1]) for f in link.lines() if f[0] == "u"]
        expected_cm = (1.9 - SONAR_X) * 100  # wall face at x = 1.9 m
        assert us and abs(us[-1] - expected_cm) <= 2
        link.close()
    finally:
        sim.close()


def test_teleport_and_reset_send_no_encoder_edges(fw_sim):
    from chefbot_common.geometry import Pose2D
    sim, link = fw_sim
    drive_with_commands(sim, link, 400, 400, 1.0)
    sim.step(STEPS_PER_S)  # watchdog stop
    counts = [sim.firmware.board.fw.encoder_count(s) for s in (0, 1)]
    sim.reset()
    sim.step(10)
    sim.teleport(Pose2D(1.0, 1.0, 1.0))
    sim.step(10)
    after = [sim.firmware.board.fw.encoder_count(s) for s in (0, 1)]
    # the wheel angles jumped back by > 1 s of driving (thousands of edges); only the
    # physical settling on the wheels after each placement may count
    assert counts[0] > 5000
    assert max(abs(a - b) for a, b in zip(after, counts, strict=True)) < 100


def test_bad_firmware_options(urdf, tmp_path):
    with pytest.raises(SimConfigError, match="drive"):
        Simulator(urdf, EMPTY, options=SimOptions(drive="gazebo"))
    with pytest.raises(FirmwareDriveError, match="pty_link"):
        Simulator(urdf, EMPTY, options=SimOptions(drive="firmware", pty_link=str(tmp_path / "no" / "lp")))
    with pytest.raises(SimConfigError, match="battery_volts"):
        Simulator(urdf, EMPTY, options=SimOptions(drive="firmware", battery_volts=-1.0))


def test_build_faults_wire_the_simulated_robot_wrong(urdf, tmp_path):
    """build_faults: the left motor's leads swapped and the right encoder reversed -- commanded forward,
    the robot turns (left wheel backwards) and the right counter runs backwards; the board's own
    wish (wheel_duty) is unchanged."""
    opts = SimOptions(seed=1, drive="firmware", pty_link=str(tmp_path / "lp"),
                      build_faults="left_leads_swapped, right_encoder_reversed")
    sim = Simulator(urdf, EMPTY, options=opts)
    link = Link(str(tmp_path / "lp"))
    try:
        fw = sim.firmware
        yaw0 = sim.ground_truth()["yaw"]
        count0 = [fw.board.fw.encoder_count(side) for side in (0, 1)]
        drive_with_commands(sim, link, 400, 400, 1.5)
        left, right = fw.duties()
        assert left < 0 < right and fw.board.fw.wheel_duty(0) > 0
        assert wrap_yaw(sim.ground_truth()["yaw"] - yaw0) > 0.3       # spinning left on the spot
        assert fw.board.fw.encoder_count(0) - count0[0] < -500         # the left wheel really turned back
        assert fw.board.fw.encoder_count(1) - count0[1] < -500         # the right one forward, counted back
    finally:
        link.close()
        sim.close()
    with pytest.raises(SimConfigError, match="build_faults.*valid"):
        Simulator(urdf, EMPTY, options=SimOptions(drive="firmware", pty_link=str(tmp_path / "lp2"),
                                                  build_faults="left_leads_crossed"))
    with pytest.raises(SimConfigError, match="drive:=firmware"):
        Simulator(urdf, EMPTY, options=SimOptions(build_faults="motors_swapped"))


def wrap_yaw(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def test_close_unplugs(urdf, tmp_path):
    link = tmp_path / "lp"
    sim = Simulator(urdf, EMPTY, options=SimOptions(drive="firmware", pty_link=str(link)))
    assert link.is_symlink()
    sim.close()
    assert not link.exists() and not link.is_symlink()


def test_fault_injection_unplug_replug_and_garbage(fw_sim, tmp_path):
    """The sim node's ~unplug / ~replug / ~emit_garbage: the link disappears and comes back under the
    same name on a new pty, the board runs on (its watchdog brakes), and every line of the garbage
    burst is rejected and counted by the driver's own line handling."""
    from chefbot_bringup.launchpad import LaunchpadCore
    from chefbot_firmware.virtual_board import MALFORMED_BURST

    sim, link = fw_sim
    fw = sim.firmware
    drive_with_commands(sim, link, 512, 512, 1.0)
    assert fw.drive_state == "run" and fw.plugged
    fw.unplug()
    fw.unplug()                                   # idempotent
    assert not fw.plugged and not (tmp_path / "lp").exists()
    assert fw.emit_garbage() == 0                 # nobody to send to
    t0 = sim.time
    sim.step(STEPS_PER_S)                         # the board runs on: its watchdog stops the motors
    assert fw.drive_state == "timeout" and fw.duties() == (0.0, 0.0)
    assert sim.time > t0 + 0.9
    new_path = fw.replug()
    assert fw.replug() == new_path and fw.plugged  # idempotent
    assert os.path.realpath(tmp_path / "lp") == new_path == sim.pty_path
    link2 = Link(str(tmp_path / "lp"))
    try:
        core = LaunchpadCore(max_ticks_per_s=11200)
        core.on_open(0.0)
        sim.step(STEPS_PER_S // 4)
        core.on_bytes(os.read(link2.fd, 65536), 0.1)
        ok0, bad0 = core.stats.lines_ok, sum(core.stats.lines_bad.values())
        assert ok0 > 5, "status lines flow again after the replug"
        assert fw.emit_garbage() == len(MALFORMED_BURST)
        sim.step(2)
        core.on_bytes(os.read(link2.fd, 65536), 0.2)
        bad = sum(core.stats.lines_bad.values()) - bad0
        # the leading newline may cut a status line short: one extra bad line at most
        assert len(MALFORMED_BURST) <= bad <= len(MALFORMED_BURST) + 1, core.stats.lines_bad
    finally:
        link2.close()
