"""The guided odometry calibration (calibration_procedure) on a kinematic robot built wrong.

The robot: wheels whose true radii differ from the nominal 45 mm (+3 % / -1 %), a true wheel base
4 % wider than configured, wheel speeds following the commands with a 0.1 s lag, ticks counted
from the wheels' turning (8400 per turn). The reference is the true motion (what a good scan match
or a careful tape gives), optionally with noise. The calibration must recover ticks_meter per wheel
and base_width within 0.5 %, and the verify squares must close far better than before.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from chefbot_bringup.calibration_procedure import (
    CalibrationError,
    CalibrationOptions,
    Motion,
    OdometryCalibration,
    TapeReference,
    WheelOdometry,
    merge_calibration,
)
from chefbot_bringup.odometry_calibration import calibrate

TICKS_METER = 29708.0          # nominal: 8400 / (pi 0.09)
BASE = 0.30                    # configured base width
R_NOM = 0.045
TICKS_PER_RAD = TICKS_METER * R_NOM


class KinematicRobot:
    def __init__(self, scale_left=1.03, scale_right=0.99, base_true=BASE * 1.04, lag=0.1, stuck=False):
        self.r = (R_NOM * scale_left, R_NOM * scale_right)
        self.base_true, self.lag, self.stuck = base_true, lag, stuck
        self.t = 0.0
        self.pose = np.zeros(3)
        self.angle = [0.0, 0.0]          # wheel angles, rad
        self.omega = [0.0, 0.0]          # wheel speeds, rad/s
        self.cmd = (0.0, 0.0)
        self.commands = []

    def now(self):
        return self.t

    def drive(self, v, w):
        self.cmd = (v, w)
        self.commands.append((self.t, v, w))

    def counts(self):
        return tuple(int(math.floor(a * TICKS_PER_RAD)) for a in self.angle)

    def snapshot(self):
        return self.pose.copy()

    def wait(self, seconds):
        n = max(1, round(seconds / 0.005))
        dt = seconds / n
        v, w = self.cmd
        # twist_to_motors with the configured base; the PIDs hold each wheel's angular speed
        target = [(v - w * BASE / 2) / R_NOM, (v + w * BASE / 2) / R_NOM]
        if self.stuck:
            target = [0.0, 0.0]
        for _ in range(n):
            a = 1 - math.exp(-dt / self.lag)
            for s in (0, 1):
                self.omega[s] += (target[s] - self.omega[s]) * a
                self.angle[s] += self.omega[s] * dt
            dl, dr = self.omega[0] * self.r[0] * dt, self.omega[1] * self.r[1] * dt
            x, y, th = self.pose
            d, dth = (dl + dr) / 2, (dr - dl) / self.base_true
            self.pose = np.array([x + d * math.cos(th + dth / 2), y + d * math.sin(th + dth / 2), th + dth])
            self.t += dt


class TruthReference:
    name = "truth"

    def __init__(self, noise_m=0.0, noise_rad=0.0, seed=0):
        self.noise_m, self.noise_rad = noise_m, noise_rad
        self.rng = np.random.default_rng(seed)

    def measure(self, kind, before, after, guess):
        x0, y0, th0 = before
        dx, dy = after[0] - x0, after[1] - y0
        c, s = math.cos(th0), math.sin(th0)
        yaw = after[2] - th0
        n = self.rng.normal(0, 1, 3) * (self.noise_m, self.noise_m, self.noise_rad)
        return Motion(c * dx + s * dy + n[0], -s * dx + c * dy + n[1], yaw + n[2])


class Ui:
    def __init__(self, answers=()):
        self.lines, self.answers, self.questions = [], list(answers), []

    def say(self, text):
        self.lines.append(text)

    def ask(self, text):
        self.questions.append(text)
        return self.answers.pop(0) if self.answers else None


FAST = CalibrationOptions(distance=1.0, turns=2, side=1.0, runs=1)


def run(robot=None, reference=None, options=FAST, ui=None):
    robot = robot or KinematicRobot()
    ui = ui or Ui()
    cal = OdometryCalibration(robot, reference or TruthReference(), ui, TICKS_METER, BASE, options)
    return cal.run(), robot, ui


def test_recovers_wheel_radii_and_base_within_half_a_percent():
    rep, robot, ui = run()
    assert not rep.aborted, ui.lines
    c = rep.calibration
    # true ticks per metre of each wheel: ticks per rad / true radius
    assert c.ticks_meter_left == pytest.approx(TICKS_PER_RAD / robot.r[0], rel=0.005)
    assert c.ticks_meter_right == pytest.approx(TICKS_PER_RAD / robot.r[1], rel=0.005)
    assert c.base_width == pytest.approx(robot.base_true, rel=0.005)
    # the verify squares close: UMBmark's E_max at least 10x smaller
    assert rep.e_max_before > 0.05
    assert rep.e_max_after < rep.e_max_before / 10, (rep.e_max_before, rep.e_max_after)
    assert robot.cmd == (0.0, 0.0)                     # stopped at the end
    d = rep.to_dict()
    assert d["result"]["base_width"] == pytest.approx(robot.base_true, rel=0.005)
    assert set(d["steps"]) == {"straight", "turns", "umbmark", "verify"}


def test_a_correct_robot_keeps_its_parameters():
    rep, _robot, _ui = run(KinematicRobot(1.0, 1.0, BASE))
    c = rep.calibration
    assert c.ticks_meter_left == pytest.approx(TICKS_METER, rel=0.002)
    assert c.ticks_meter_right == pytest.approx(TICKS_METER, rel=0.002)
    assert c.base_width == pytest.approx(BASE, rel=0.002)


def test_reference_noise_of_a_few_millimetres_still_gives_half_a_percent():
    rep, robot, ui = run(reference=TruthReference(noise_m=0.002, noise_rad=math.radians(0.2), seed=4),
                         options=CalibrationOptions(runs=2, verify=False))
    c = rep.calibration
    assert not rep.aborted, ui.lines
    for got, want in ((c.ticks_meter_left, TICKS_PER_RAD / robot.r[0]),
                      (c.ticks_meter_right, TICKS_PER_RAD / robot.r[1]), (c.base_width, robot.base_true)):
        assert got == pytest.approx(want, rel=0.005)


def test_stalled_wheels_abort_with_the_reason_and_stop():
    rep, robot, ui = run(KinematicRobot(stuck=True))
    assert "no wheel tick" in rep.aborted
    assert rep.calibration is None
    assert robot.cmd == (0.0, 0.0)
    assert any("ABORTED" in line for line in ui.lines)


def test_a_failing_reference_aborts():
    class Blind:
        name = "scan"

        def measure(self, kind, before, after, guess):
            raise ValueError("only one flat wall in view")
    rep, robot, _ui = run(reference=Blind())
    assert rep.aborted == "straight: no reference (scan): only one flat wall in view"
    assert robot.cmd == (0.0, 0.0)


def test_interrupt_stops_the_robot_and_passes_on():
    robot = KinematicRobot()
    calls = []

    def wait(seconds, orig=robot.wait):
        calls.append(seconds)
        if len(calls) == 60:
            raise KeyboardInterrupt
        orig(seconds)
    robot.wait = wait
    with pytest.raises(KeyboardInterrupt):
        OdometryCalibration(robot, TruthReference(), Ui(), TICKS_METER, BASE, FAST).run()
    assert robot.cmd == (0.0, 0.0) and robot.commands[-1][1:] == (0.0, 0.0)


def test_tape_reference_asks_and_parses():
    ui = Ui(["0,97", "3", "0.05", "-0.02", "x"])
    tape = TapeReference(ui)
    assert tape.measure("straight", None, None, Motion(1.0, 0.0, 0.0)).distance == pytest.approx(0.97)
    turned = tape.measure("turn", None, None, Motion(0, 0, 4 * math.pi - 0.1))
    assert turned.yaw == pytest.approx(4 * math.pi + math.radians(3))
    end = tape.measure("square", None, None, Motion(0, 0, 0))
    assert (end.x, end.y) == pytest.approx((0.05, -0.02))
    with pytest.raises(ValueError, match="not a number"):
        tape.measure("straight", None, None, Motion(1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="non-interactive"):
        tape.measure("straight", None, None, Motion(1.0, 0.0, 0.0))


def test_wheel_odometry_wraps_int32():
    odo = WheelOdometry(TICKS_METER, TICKS_METER, BASE)
    odo.reset((2**31 - 100, -(2**31) + 50))
    m = odo.update((-(2**31) + 200, -(2**31) + 350))          # +300 ticks each, across the wrap on the left
    assert m.x == pytest.approx(300 / TICKS_METER) and abs(m.yaw) < 1e-12


@pytest.mark.parametrize("kw,match", [({"distance": 0}, "distance"), ({"turns": 0}, "turns"),
                                      ({"speed": 0.5}, "slip"), ({"side": float("nan")}, "side")])
def test_bad_options(kw, match):
    with pytest.raises(ValueError, match=match):
        CalibrationOptions(**kw)


def test_unplugged_ticks_abort_before_moving():
    class NoTicks(KinematicRobot):
        def counts(self):
            return None
    rep, robot, _ui = run(NoTicks())
    assert "no wheel ticks" in rep.aborted and all(c[1:] == (0.0, 0.0) for c in robot.commands)


def test_calibration_error_is_a_runtime_error():
    assert issubclass(CalibrationError, RuntimeError)


def test_merge_calibration_keeps_the_gains_and_replaces_the_odometry_keys():
    cal = calibrate(TICKS_METER, BASE, 1.01, 1.03)
    old = "ticks_meter: 1\nbase_width: 2\nlwheel_pid: {Kp: 520.3, Ki: 5104.2, Kd: 0.0}\n"
    data = yaml.safe_load(merge_calibration(old, cal))
    assert data["ticks_meter"] == pytest.approx(TICKS_METER * 1.01, abs=0.1)
    assert data["base_width"] == pytest.approx(BASE * 1.03, abs=1e-5)
    assert data["lwheel_pid"] == {"Kp": 520.3, "Ki": 5104.2, "Kd": 0.0}
    assert yaml.safe_load(merge_calibration(None, cal))["base_width"] == pytest.approx(BASE * 1.03, abs=1e-5)
    for bad in ("[1, 2]", "a: [1,"):
        with pytest.raises(ValueError, match="fix or remove it"):
            merge_calibration(bad, cal)
