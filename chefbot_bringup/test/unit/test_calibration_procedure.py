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

from chefbot_bringup import kinematic_robot as kr
from chefbot_bringup.calibration_procedure import (
    CalibrationError,
    CalibrationOptions,
    Motion,
    OdometryCalibration,
    TapeReference,
    WheelOdometry,
    merge_calibration,
)
from chefbot_bringup.kinematic_robot import NOMINAL_RADIUS, TICKS_METER, TruthReference
from chefbot_bringup.odometry_calibration import calibrate

BASE = 0.30                    # configured base width
TICKS_PER_RAD = TICKS_METER * NOMINAL_RADIUS


def KinematicRobot(scale_left=1.03, scale_right=0.99, base_true=BASE * 1.04, **kw):
    return kr.KinematicRobot(scale_left, scale_right, base_true, BASE, **kw)


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
    assert c.ticks_meter_left == pytest.approx(TICKS_PER_RAD / robot.radius[0], rel=0.005)
    assert c.ticks_meter_right == pytest.approx(TICKS_PER_RAD / robot.radius[1], rel=0.005)
    assert c.base_width == pytest.approx(robot.base_true, rel=0.005)
    # the verify squares close: UMBmark's E_max at least 10x smaller
    assert rep.e_max_before > 0.05
    assert rep.e_max_after < rep.e_max_before / 10, (rep.e_max_before, rep.e_max_after)
    assert robot.cmd == (0.0, 0.0)                     # stopped at the end
    d = rep.to_dict()
    assert d["result"]["base_width"] == pytest.approx(robot.base_true, rel=0.005)
    assert set(d["steps"]) == {"straight", "turns", "umbmark", "verify"}


def test_the_report_is_plain_yaml_with_numpy_references():
    """The scan reference answers in numpy floats; the report must still dump."""
    class NumpyRef(TruthReference):
        def measure(self, kind, before, after, guess):
            m = super().measure(kind, before, after, guess)
            return Motion(np.float64(m.x), np.float64(m.y), np.float64(m.yaw))
    rep, _robot, _ui = run(reference=NumpyRef(), options=CalibrationOptions(verify=False))
    text = yaml.safe_dump(rep.to_dict())
    assert yaml.safe_load(text)["steps"]["umbmark"]["runs"][0]["clockwise"] is True


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
    for got, want in ((c.ticks_meter_left, TICKS_PER_RAD / robot.radius[0]),
                      (c.ticks_meter_right, TICKS_PER_RAD / robot.radius[1]), (c.base_width, robot.base_true)):
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
    class NoTicks(kr.KinematicRobot):
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
