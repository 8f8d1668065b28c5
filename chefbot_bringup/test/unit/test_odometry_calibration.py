"""odometry_calibration: the estimators against a simulated robot that drives by its own odometry.

The simulator below is independent of the module's model: integer encoder ticks, true ticks per
metre per wheel (from the wheel radii), a true base, and a controller that closes the loop on the
robot's *belief* (odometry.integrate_arc with the configured ticks_meter and base_width, checked
against DiffOdometry itself), so the robot believes it drove the square.
"""
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from chefbot_bringup.odometry import DiffOdometry, OdometryConfig, integrate_arc
from chefbot_bringup.odometry_calibration import (
    MAX_END_ERROR_PER_SIDE,
    Calibration,
    calibrate,
    in_place_turns,
    square_end_error,
    straight_line,
    umbmark,
    umbmark_closed_form,
    wheel_factors,
)

PKG = Path(__file__).resolve().parents[2]   # chefbot_bringup
TPM = 29708.0       # param/diff_drive.yaml
B = 0.30


class Robot:
    """True robot + its odometry belief; the controller drives by the belief in integer ticks."""

    def __init__(self, r_left=1.0, r_right=1.0, base=1.0, tpm_left=TPM, tpm_right=TPM, base_width=B):
        # wheel radii relative to nominal: a wheel 3 % larger travels 3 % more per tick
        self.true_tpm = (TPM / r_left, TPM / r_right)
        self.true_base = B * base
        self.tpm = (tpm_left, tpm_right)
        self.base_width = base_width
        self.belief = (0.0, 0.0, 0.0)
        self.truth = (0.0, 0.0, 0.0)
        self.ticks = [0, 0]
        self.history = []      # cumulative ticks after every step

    def _step(self, dl: float, dr: float) -> bool:
        nl, nr = round(dl * self.tpm[0]), round(dr * self.tpm[1])
        if nl == 0 and nr == 0:
            return False
        self.ticks[0] += nl
        self.ticks[1] += nr
        self.history.append(tuple(self.ticks))
        self.belief = integrate_arc(*self.belief, nl / self.tpm[0], nr / self.tpm[1], self.base_width)
        self.truth = integrate_arc(*self.truth, nl / self.true_tpm[0], nr / self.true_tpm[1], self.true_base)
        return True

    def straight(self, goal: tuple[float, float], heading: float, step: float = 0.01) -> None:
        """Drive by the belief to ``goal`` (m, m) along ``heading`` (rad), holding that heading."""
        c, s = math.cos(heading), math.sin(heading)
        while True:
            x, y, th = self.belief
            remaining = (goal[0] - x) * c + (goal[1] - y) * s
            ds = min(step, remaining)
            dth = heading - th           # back to the heading within the step (tick-rounded turns)
            if remaining < 0.5 / max(self.tpm) or not self._step(ds - 0.5 * dth * self.base_width,
                                                                  ds + 0.5 * dth * self.base_width):
                return

    def turn(self, goal: float, step: float = 0.01) -> None:
        """Turn on the spot by the belief to the heading ``goal`` (rad, unwrapped)."""
        while True:
            remaining = goal - self.belief[2]
            wheel = max(-step, min(step, 0.5 * remaining * self.base_width))
            if not self._step(-wheel, wheel):
                return

    def square(self, side: float, clockwise: bool) -> tuple[float, float]:
        """UMBmark run from the current pose; the true end position in the true start frame (m, m)."""
        x0, y0, h0 = self.truth
        bx, by, heading = self.belief
        turn = -math.pi / 2 if clockwise else math.pi / 2
        for _ in range(4):
            bx, by = bx + side * math.cos(heading), by + side * math.sin(heading)
            self.straight((bx, by), heading)
            heading += turn
            self.turn(heading)
        dx, dy = self.truth[0] - x0, self.truth[1] - y0
        return dx * math.cos(h0) + dy * math.sin(h0), -dx * math.sin(h0) + dy * math.cos(h0)


def mean_travel_tpm(r_left: float, r_right: float) -> float:
    """The single ticks_meter a perfect straight-line calibration gives (harmonic mean of the wheels')."""
    return 2.0 / (r_left / TPM + r_right / TPM)


def runs(robot_kw: dict, side: float, n: int = 1, noise: float = 0.0, seed: int = 0):
    rng = np.random.default_rng(seed)
    out = {}
    for cw in (True, False):
        out[cw] = [np.add(Robot(**robot_kw).square(side, cw), rng.normal(0.0, noise, 2) if noise else 0.0)
                   for _ in range(n)]
    return out[True], out[False]


# ---------------------------------------------------------------------------- the simulator itself

def test_simulated_belief_is_diff_odometry():
    # the test robot's belief is what diff_tf would compute from the same ticks (signs, left/right)
    robot = Robot(r_left=0.99, r_right=1.03)
    odo = DiffOdometry(OdometryConfig(ticks_meter=TPM, base_width=B))
    robot.straight((0.5, 0.0), 0.0)
    robot.turn(math.pi / 2)
    robot.straight((0.5, 0.3), math.pi / 2)
    robot.turn(math.pi / 2 - 2.0)
    odo.set_ticks(0, 0)
    odo.update(0.0)
    for k, (left, right) in enumerate(robot.history, start=1):
        odo.set_ticks(left, right)
        odo.update(0.1 * k)
    assert odo.resets == 0
    assert (odo.x, odo.y) == pytest.approx(robot.belief[:2], abs=1e-9)
    assert odo.theta == pytest.approx(robot.belief[2], abs=1e-9)
    assert odo.theta == pytest.approx(math.pi / 2 - 2.0, abs=2e-4)     # one tick: 1.1e-4 rad


def test_simulated_square_is_closed_in_the_belief():
    robot = Robot(r_left=0.99, r_right=1.03, base=1.04)
    robot.square(1.0, clockwise=True)
    # the belief is back at the start to a few ticks (34 um each): only the truth is off
    assert robot.belief[:2] == pytest.approx((0.0, 0.0), abs=2e-4)
    assert robot.belief[2] == pytest.approx(-2 * math.pi, abs=1e-3)
    assert math.hypot(*robot.truth[:2]) > 0.1


# ---------------------------------------------------------------------------- straight line

def test_straight_line_factor_from_the_tape():
    # counted 1.00 m on 0.97 m of tape: more ticks per metre (wheels smaller than configured)
    assert straight_line(1.00, 0.97) == pytest.approx(1.00 / 0.97, rel=1e-12)


@pytest.mark.parametrize("r", [0.97, 1.03])
def test_straight_line_recovers_the_wheel_scale(r):
    robot = Robot(r_left=r, r_right=r)
    robot.straight((3.0, 0.0), 0.0)
    measured = math.hypot(*robot.truth[:2])
    factor = straight_line(3.0, measured)
    # 1 tick of 3 m (1e-5) is the resolution; the true ticks per metre are TPM / r
    assert TPM * factor == pytest.approx(TPM / r, rel=2e-5)


@pytest.mark.parametrize("args, name", [((0.0, 1.0), "odom_distance_m"), ((1.0, -1.0), "measured_distance_m"),
                                        ((math.nan, 1.0), "odom_distance_m"), ((1.0, math.inf), "measured_distance_m"),
                                        (("a", 1.0), "odom_distance_m")])
def test_straight_line_rejects_bad_input_naming_it(args, name):
    with pytest.raises(ValueError, match=name):
        straight_line(*args)


def test_straight_line_rejects_a_factor_2_with_a_hint():
    with pytest.raises(ValueError, match="decoding"):
        straight_line(2.0, 1.0)


# ---------------------------------------------------------------------------- in-place turns

def test_in_place_turns_direction():
    # odometry counted 2 turns, the robot turned 2.06: the true base is narrower
    assert in_place_turns(2 * 2 * math.pi, 2.06 * 2 * math.pi) == pytest.approx(2 / 2.06, rel=1e-12)


@pytest.mark.parametrize("base, turns", [(1.04, 3), (0.97, -2)])
def test_in_place_turns_recover_the_base_by_simulation(base, turns):
    # unequal wheels must not matter on the spot (only their mean enters)
    kw = {"r_left": 0.99, "r_right": 1.01, "base": base, "tpm_left": mean_travel_tpm(0.99, 1.01),
          "tpm_right": mean_travel_tpm(0.99, 1.01)}
    robot = Robot(**kw)
    robot.turn(turns * 2 * math.pi)
    factor = in_place_turns(robot.belief[2], robot.truth[2])
    # a tick is 1.1e-4 of a 0.3 m base's quarter circle, ~1e-5 of 2 turns
    assert B * factor == pytest.approx(B * base, rel=1e-4)
    corrected = Robot(**{**kw, "base_width": B * factor})
    corrected.turn(turns * 2 * math.pi)
    assert corrected.truth[2] == pytest.approx(turns * 2 * math.pi, abs=2e-3)   # 0.1 degree after N turns
    assert abs(robot.truth[2] - turns * 2 * math.pi) > 0.3                      # it was 17+ degrees off


@pytest.mark.parametrize("args, match", [((0.0, 1.0), "odom_yaw_rad"), ((1.0, 0.0), "measured_yaw_rad"),
                                         ((math.nan, 1.0), "odom_yaw_rad"), ((12.5, -12.6), "opposite signs"),
                                         ((4 * math.pi, 0.3), "wrapped")])
def test_in_place_turns_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        in_place_turns(*args)


# ---------------------------------------------------------------------------- UMBmark

def test_wheel_factors():
    c_l, c_r = wheel_factors(1.04)
    assert c_r / c_l == pytest.approx(1.04, rel=1e-12)
    assert (c_l + c_r) / 2 == pytest.approx(1.0, rel=1e-12)


# (left radius, right radius, base) relative to nominal: the brief's +3 % / -1 % wheels and +4 % base
CASES = {"base +4 %": (1.0, 1.0, 1.04), "right +3 %, left -1 %": (0.99, 1.03, 1.0),
         "left +3 %, right -1 %": (1.03, 0.99, 1.0), "wheels and base": (0.99, 1.03, 1.04),
         "base -4 %": (1.0, 1.0, 0.96), "left +3 %, right -1 %, base -4 %": (1.03, 0.99, 0.96)}
MILD = {"right +0.3 %": (1.0, 1.003, 1.0), "base +1 %": (1.0, 1.0, 1.01), "both": (0.999, 1.002, 0.99)}


def robot_kw(r_left: float, r_right: float, base: float) -> dict:
    # ticks_meter from a perfect straight-line calibration: the mean wheel travel is right
    tpm = mean_travel_tpm(r_left, r_right)
    return {"r_left": r_left, "r_right": r_right, "base": base, "tpm_left": tpm, "tpm_right": tpm}


@pytest.mark.parametrize("clockwise", [True, False])
@pytest.mark.parametrize("side", [0.3, 0.75])
@pytest.mark.parametrize("case", CASES)
def test_model_matches_the_simulator_each_direction(case, side, clockwise):
    r_left, r_right, base = CASES[case]
    simulated = Robot(**robot_kw(r_left, r_right, base)).square(side, clockwise)
    model = square_end_error(side, B, r_right / r_left, base, clockwise)
    # the simulator stops each segment on a whole tick (34 um): well under a mm at the end
    assert model == pytest.approx(simulated, abs=3e-4)


def check_recovery(case: tuple, side: float, tol: float):
    r_left, r_right, base = case
    cw, ccw = runs(robot_kw(r_left, r_right, base), side)
    res = umbmark(cw, ccw, side, B)
    assert res.e_d == pytest.approx(r_right / r_left, abs=tol)
    assert res.e_b == pytest.approx(base, abs=tol)
    assert res.base_width == pytest.approx(B * base, abs=tol * B)
    return res


@pytest.mark.parametrize("side", [0.3, 0.5, 0.75])
@pytest.mark.parametrize("case", CASES)
def test_umbmark_recovers_large_errors(case, side):
    # 5e-5: 1/800 of the errors simulated (0.04); the simulator's whole ticks leave up to 1e-5
    res = check_recovery(CASES[case], side, 5e-5)
    assert res.e_max < MAX_END_ERROR_PER_SIDE * side


@pytest.mark.parametrize("side", [1.0, 2.0, 4.0])
@pytest.mark.parametrize("case", MILD)
def test_umbmark_recovers_typical_errors_on_long_sides(case, side):
    # Borenstein's 4 m square with errors of his robots' size (E_d ~ 1.003, E_b ~ 1.01)
    # 3e-5: 1/30 of the smallest error simulated (1e-3); whole ticks leave up to 1.3e-5
    res = check_recovery(MILD[case], side, 3e-5)
    # the closed form alone is close here (its error is second order in the heading errors)
    assert res.closed_form == pytest.approx((res.e_d, res.e_b), abs=1e-3)


def test_closed_form_alone_is_fragile_for_large_errors():
    # why the fit: for E_d 1.04 on a 0.75 m square the first-order closed form is 1e-3 off
    e_d, e_b = 1.03 / 0.99, 1.04
    cw = square_end_error(0.75, B, e_d, e_b, True)
    ccw = square_end_error(0.75, B, e_d, e_b, False)
    closed = umbmark_closed_form(cw, ccw, 0.75, B)
    assert abs(closed[0] - e_d) + abs(closed[1] - e_b) > 1e-3
    res = umbmark([cw], [ccw], 0.75, B)
    assert (res.e_d, res.e_b) == pytest.approx((e_d, e_b), abs=1e-9)    # model data: exact


def test_umbmark_with_noisy_runs():
    # 5 runs each way with 5 mm of tape/placement noise per coordinate
    r_left, r_right, base = 0.998, 1.004, 1.02
    cw, ccw = runs(robot_kw(r_left, r_right, base), 2.0, n=5, noise=0.005, seed=3)
    res = umbmark(cw, ccw, 2.0, B)
    # noise on a centroid ~2.2 mm -> ~1e-4 on E_d and E_b on a 2 m square; 5e-4 is 3+ sigma
    assert res.e_d == pytest.approx(r_right / r_left, abs=5e-4)
    assert res.e_b == pytest.approx(base, abs=5e-4)
    assert res.runs == 5


def corrected_robot(case: tuple, r_left_tpm: float, r_right_tpm: float, base_width: float) -> Robot:
    r_left, r_right, base = case
    return Robot(r_left=r_left, r_right=r_right, base=base, tpm_left=r_left_tpm, tpm_right=r_right_tpm,
                 base_width=base_width)


def worst_end_error(robot_factory, side: float) -> float:
    return max(math.hypot(*robot_factory().square(side, cw)) for cw in (True, False))


@pytest.mark.parametrize("case", ["wheels and base", "left +3 %, right -1 %, base -4 %", "right +3 %, left -1 %"])
def test_correction_closes_the_square_and_a_flipped_one_would_not(case):
    r_left, r_right, base = CASES[case]
    side = 0.75
    tpm = mean_travel_tpm(r_left, r_right)
    before = worst_end_error(lambda: Robot(**robot_kw(r_left, r_right, base)), side)
    res = umbmark(*runs(robot_kw(r_left, r_right, base), side), side, B)
    after = worst_end_error(lambda: corrected_robot(CASES[case], tpm / res.c_left, tpm / res.c_right,
                                                    res.base_width), side)
    assert after < before / 10
    # the same correction with the sign convention flipped (E_d -> 1/E_d, E_b -> 1/E_b) makes it worse:
    # a sign slip in the estimator fails the assertion above
    c_l, c_r = wheel_factors(1.0 / res.e_d)
    flipped = worst_end_error(lambda: corrected_robot(CASES[case], tpm / c_l, tpm / c_r, B / res.e_b), side)
    assert flipped > before


def test_whole_workflow_straight_line_then_umbmark():
    # nominal ticks_meter and base on a robot with +3 % / -1 % wheels and a 4 % wider base
    r_left, r_right, base = 0.99, 1.03, 1.04
    robot = Robot(r_left=r_left, r_right=r_right, base=base)
    robot.straight((2.0, 0.0), 0.0)
    straight = straight_line(2.0, math.hypot(*robot.truth[:2]))    # the tape measures the chord
    tpm = TPM * straight
    kw = {"r_left": r_left, "r_right": r_right, "base": base, "tpm_left": tpm, "tpm_right": tpm}
    side = 0.5
    res = umbmark(*runs(kw, side, n=5), side, B)
    cal = calibrate(TPM, B, straight_factor=straight, umbmark=res)
    assert cal.ticks_meter == pytest.approx(tpm, rel=1e-12)       # E_d keeps the mean travel
    before = worst_end_error(lambda: Robot(r_left=r_left, r_right=r_right, base=base), side)
    after = worst_end_error(lambda: corrected_robot((r_left, r_right, base), cal.ticks_meter_left,
                                                    cal.ticks_meter_right, cal.base_width), side)
    assert after < before / 10
    # the chord (2 m arc curving 0.27 rad) is 0.3 % short, which stays in the mean scale: 1 % not 0.3 % off
    assert cal.ticks_meter_left == pytest.approx(TPM / r_left, rel=5e-3)
    assert cal.ticks_meter_right == pytest.approx(TPM / r_right, rel=5e-3)


# ---------------------------------------------------------------------------- UMBmark: bad input

GOOD = square_end_error(1.0, B, 1.004, 1.01, True), square_end_error(1.0, B, 1.004, 1.01, False)


@pytest.mark.parametrize("cw, ccw, side, base, match", [
    ([], [GOOD[1]], 1.0, B, "cw_end_errors is empty"),
    ([GOOD[0]], [], 1.0, B, "ccw_end_errors is empty"),
    ([GOOD[0], GOOD[0]], [GOOD[1]], 1.0, B, "same number of times"),
    ([(math.nan, 0.0)], [GOOD[1]], 1.0, B, "NaN"),
    ([(0.1, 0.0, 0.0)], [GOOD[1]], 1.0, B, r"\(x, y\)"),
    ([GOOD[0]], [GOOD[1]], 0.0, B, "side_m"),
    ([GOOD[0]], [GOOD[1]], -1.0, B, "side_m"),
    ([GOOD[0]], [GOOD[1]], 1.0, math.nan, "base_width_m"),
    ([(3.5, 0.1)], [(1.5, -0.3)], 4.0, B, "not closed: end errors of 3.5 m on a 4 m square"),
    ([(-45.0, -50.0)], [(45.0, -40.0)], 1.0, B, "not closed"),       # millimetres
    ([GOOD[1]], [GOOD[0]], 1.0, B, "CW and CCW"),                     # swapped
    ([(GOOD[0][0], -GOOD[0][1])], [(GOOD[1][0], -GOOD[1][1])], 1.0, B, "start frame"),  # y to the right
])
def test_umbmark_rejects_bad_input(cw, ccw, side, base, match):
    with pytest.raises(ValueError, match=match):
        umbmark(cw, ccw, side, base)


def test_umbmark_rejects_an_implausible_wheel_ratio():
    # E_d 1.3 on a small square still closes within half the side: the ratio itself is implausible
    cw = square_end_error(0.15, B, 1.3, 1.0, True)
    ccw = square_end_error(0.15, B, 1.3, 1.0, False)
    with pytest.raises(ValueError, match="E_d"):
        umbmark([cw], [ccw], 0.15, B)


# ---------------------------------------------------------------------------- Calibration and YAML

def test_calibrate_multiplies_the_steps():
    b_used = B * 0.98     # the squares were driven with the in-place turns' base width
    res = umbmark([square_end_error(1.0, b_used, 1.01, 1.02, True)],
                  [square_end_error(1.0, b_used, 1.01, 1.02, False)], 1.0, b_used)
    cal = calibrate(TPM, B, straight_factor=1.03, turn_factor=0.98, umbmark=res)
    assert cal.ticks_meter == pytest.approx(TPM * 1.03, rel=1e-12)
    assert cal.ticks_meter_right / cal.ticks_meter_left == pytest.approx(1 / 1.01, rel=1e-6)
    assert cal.base_width == pytest.approx(B * 0.98 * 1.02, rel=1e-6)
    assert (cal.ticks_meter_before, cal.base_width_before) == (TPM, B)


def test_calibrate_wants_umbmark_driven_with_the_calibrated_base():
    res = umbmark([GOOD[0]], [GOOD[1]], 1.0, B)
    with pytest.raises(ValueError, match="calibrated base width"):
        calibrate(TPM, B, turn_factor=0.97, umbmark=res)


def test_yaml_has_the_diff_drive_keys_and_says_how(tmp_path):
    res = umbmark([GOOD[0]], [GOOD[1]], 1.0, B)
    cal = calibrate(TPM, B, straight_factor=1.02, umbmark=res)
    path = cal.save(tmp_path / "new" / "dir" / "calibration.yaml")
    assert path.parent.is_dir()
    text = path.read_text()
    data = yaml.safe_load(text)
    shipped = yaml.safe_load((PKG / "param" / "diff_drive.yaml").read_text())
    assert {"ticks_meter", "base_width"} <= set(shipped) & set(data)
    # printed to 0.1 tick/m and 0.01 mm
    assert data["ticks_meter"] == pytest.approx(cal.ticks_meter, abs=0.05)
    assert data["base_width"] == pytest.approx(cal.base_width, abs=5e-6)
    assert data["ticks_meter_left"] == pytest.approx(cal.ticks_meter_left, abs=0.05)
    assert data["ticks_meter_right"] == pytest.approx(cal.ticks_meter_right, abs=0.05)
    assert "UMBmark" in text and "straight line" in text and "before: ticks_meter 29708.0" in text
    assert "not read" not in text and "diff_tf" in text and "lwheel_pid / rwheel_pid" in text


def test_calibration_without_steps_keeps_the_values():
    cal = Calibration(ticks_meter_left=TPM, ticks_meter_right=TPM, base_width=B, ticks_meter_before=TPM,
                      base_width_before=B)
    assert cal.ticks_meter == pytest.approx(TPM, rel=1e-12)
    assert "UMBmark" not in cal.to_yaml()


def test_update_calibration_file_merges_and_leaves_a_corrupt_file_alone(tmp_path):
    from chefbot_bringup.odometry_calibration import load_calibration_yaml, update_calibration_file

    path = tmp_path / "new" / "calibration.yaml"

    def add(key, value):
        def merge(old):
            data = load_calibration_yaml(old)
            data[key] = value
            return yaml.safe_dump(data)
        return merge
    assert update_calibration_file(path, add("base_width", 0.31)) == path
    update_calibration_file(path, add("ticks_meter", 29950.0))
    assert yaml.safe_load(path.read_text()) == {"base_width": 0.31, "ticks_meter": 29950.0}
    path.write_text("[1, 2")
    with pytest.raises(ValueError, match="fix or remove it"):
        update_calibration_file(path, add("base_width", 0.3))
    assert path.read_text() == "[1, 2" and not path.with_name(path.name + ".tmp").exists()
