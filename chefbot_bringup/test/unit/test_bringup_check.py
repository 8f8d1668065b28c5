"""bringup_check: the wiring fault table against a simulated robot, board answers, PID step verdicts."""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field, replace

import numpy as np
import pytest

from chefbot_bringup import bringup_check as bc
from chefbot_bringup.bringup_check import (
    BoardReport,
    Expectations,
    HandTurn,
    MotorRun,
    board_verdicts,
    diagnose_motors,
    step_response_verdict,
)

DUTY = 0.3
SECONDS = 2.0
E = Expectations()
EXPECTED = E.expected_counts(DUTY, SECONDS)   # 6720 counts of a correct run

# ---- a physical robot with wiring faults -------------------------------------------------
# Firmware defaults (core/config.h): the right motor and encoder are mounted mirrored and inverted.
INVERT = {"left": False, "right": True}
INVERT_ENC = {"left": False, "right": True}
MOUNT = {"left": 1, "right": -1}   # motor raw turn -> wheel forward, and wheel forward -> encoder raw


@dataclass
class Robot:
    channel_motors: dict = field(default_factory=lambda: {"left": ("left",), "right": ("right",)})
    lead_sign: dict = field(default_factory=lambda: {"left": 1, "right": 1})        # -1: motor leads swapped
    motor_gain: dict = field(default_factory=lambda: {"left": 1.0, "right": 1.0})   # 0: dead, 0.3: drags
    dead_input: dict = field(default_factory=lambda: {"left": None, "right": None})  # "INA"/"INB" never high
    encoder_decoder: dict = field(default_factory=lambda: {"left": "left", "right": "right"})  # cable -> pins
    ab_sign: dict = field(default_factory=lambda: {"left": 1, "right": 1})          # -1: A/B swapped
    encoder_alive: dict = field(default_factory=lambda: {"left": True, "right": True})
    decoding_factor: float = 1.0                                                    # 0.5: firmware 2X

    def _counts(self, wheel_revs: dict, rng: random.Random | None, spread: float) -> dict:
        counts = {"left": 0.0, "right": 0.0}
        for w, revs in wheel_revs.items():
            raw = revs * 8400 * self.decoding_factor * MOUNT[w] * self.ab_sign[w] * self.encoder_alive[w]
            d = self.encoder_decoder[w]
            counts[d] += -raw if INVERT_ENC[d] else raw
        out = {}
        for c, v in counts.items():
            if rng is not None:
                v = v * (1 + rng.uniform(-spread, spread)) + rng.randint(-3, 3)
            out[c] = round(v)
        return out

    def run(self, ch: str, duty: float, seconds: float = SECONDS, rng: random.Random | None = None) -> MotorRun:
        out = -duty if INVERT[ch] else duty
        dead = self.dead_input[ch]
        if (dead == "INA" and out > 0) or (dead == "INB" and out < 0):   # motor.cpp: INA high = clockwise
            out = 0.0
        revs = {m: out * self.lead_sign[m] * MOUNT[m] * self.motor_gain[m] * E.free_rev_per_s * seconds
                for m in self.channel_motors[ch]}
        c = self._counts(revs, rng, 0.02)
        return MotorRun(ch, duty, seconds, c["left"], c["right"])

    def hand(self, w: str, rng: random.Random | None = None) -> HandTurn:
        c = self._counts({w: 1.0}, rng, 0.05)   # a hand turn is good to +-5 %
        return HandTurn(w, c["left"], c["right"])


def check(robot: Robot, hand: bool, seed: int | None = 0):
    rng = random.Random(seed) if seed is not None else None
    runs = [robot.run(ch, d, rng=rng) for ch in ("left", "right") for d in (DUTY, -DUTY)]
    turns = [robot.hand(w, rng) for w in ("left", "right")] if hand else []
    return diagnose_motors(runs, turns)


def codes(verdicts) -> list[tuple[str, str | None]]:
    return sorted((v.code, v.side) for v in verdicts)


def swap(d: dict) -> dict:
    return {"left": d["right"], "right": d["left"]}


def fault(**kw) -> Robot:
    r = Robot()
    for k, v in kw.items():
        cur = getattr(r, k)
        setattr(r, k, {**cur, **v} if isinstance(cur, dict) else v)
    return r


# ---- expectations match the project -------------------------------------------------------

def test_expectations_from_the_params():
    assert E.counts_per_rev == pytest.approx(8400, abs=1)            # ticks_meter 29708 x pi x 0.09
    assert E.free_rev_per_s == pytest.approx(80 / 60, rel=1e-3)      # max_wheel_speed 0.377 = 80 RPM
    assert E.decoding == 4
    assert Expectations(ticks_meter=14854).decoding == 2
    assert Expectations(ticks_meter=7427).decoding == 1
    assert Expectations(ticks_meter=20000).decoding is None
    with pytest.raises(ValueError):
        Expectations(ticks_meter=0)


def test_expected_counts_match_the_emulator_motor():
    from chefbot_firmware.virtual_board import EDGES_PER_REV, MotorModel
    m = MotorModel()
    for _ in range(200):            # 2 s at duty 0.3, then stand still (counts until the wheel stops)
        m.step(DUTY, 0.01)
    for _ in range(100):
        m.step(0.0, 0.01)
    assert m.angle / (2 * math.pi) * EDGES_PER_REV == pytest.approx(EXPECTED, rel=0.005)


def _firmware_runs(config: dict | None) -> list[MotorRun]:
    """Each motor alone through our firmware core (host library) on the board emulator, whose motor
    model turns the wheels and feeds their encoder edges back (VirtualBoard.step)."""
    from chefbot_firmware.host import LEFT, RIGHT
    from chefbot_firmware.virtual_board import VirtualBoard
    runs = []
    with VirtualBoard(config=config) as b:
        for ch in ("left", "right"):
            for sign in (1, -1):
                start = (b.fw.encoder_count(LEFT), b.fw.encoder_count(RIGHT))
                cmd = sign * 300
                line = f"s {cmd if ch == 'left' else 0} {cmd if ch == 'right' else 0}\n".encode()
                for k in range(250):          # 10 ms steps: 2 s commanded (fed every 0.1 s), 0.5 s stop
                    if k < 200 and k % 10 == 0:
                        b.fw.feed(line)
                    if k == 200:
                        b.fw.feed(b"s 0 0\n")
                    b.step(0.01)
                runs.append(MotorRun(ch, cmd / 1023, SECONDS, b.fw.encoder_count(LEFT) - start[0],
                                     b.fw.encoder_count(RIGHT) - start[1]))
    return runs


def test_firmware_in_the_loop_correct_robot_is_ok():
    pytest.importorskip("chefbot_firmware.host")
    try:
        runs = _firmware_runs(None)
    except OSError as e:                      # libchefbot_fw.so not built
        pytest.skip(f"firmware host library: {e}")
    v = diagnose_motors(runs)
    assert codes(v) == [("ok", None)], [x.line() for x in v]


def test_firmware_in_the_loop_2x_decoding_is_named():
    pytest.importorskip("chefbot_firmware.host")
    try:
        runs = _firmware_runs({"encoder_mode": 2})
    except OSError as e:
        pytest.skip(f"firmware host library: {e}")
    v = diagnose_motors(runs)
    assert codes(v) == [("counts_per_rev", None)]
    assert "2X" in v[0].fix and "14854" in v[0].fix


# ---- the correct robot ------------------------------------------------------------------------

@pytest.mark.parametrize("hand", [False, True])
@pytest.mark.parametrize("seed", [None, *range(20)])
def test_correct_robot_is_ok_with_noise(hand, seed):
    v = check(Robot(), hand, seed)
    assert codes(v) == [("ok", None)], [x.line() for x in v]
    assert v[0].ok and v[0].fix == ""


def test_one_direction_only_runs_are_enough():
    r = Robot()
    v = diagnose_motors([r.run("left", DUTY), r.run("right", DUTY)])
    assert codes(v) == [("ok", None)]


# ---- each fault alone -> exactly its verdict ----------------------------------------------------

SINGLE = [
    # (name, robot, expected without hand turns, expected with hand turns)
    ("left encoder dead", fault(encoder_alive={"left": False}),
     [("no_counts", "left")], [("encoder_silent", "left")]),
    ("right encoder dead", fault(encoder_alive={"right": False}),
     [("no_counts", "right")], [("encoder_silent", "right")]),
    ("left motor dead", fault(motor_gain={"left": 0.0}),
     [("no_counts", "left")], [("motor_silent", "left")]),
    ("no motor power", fault(motor_gain={"left": 0.0, "right": 0.0}),
     [("no_motion", None)], [("no_motion", None)]),
    ("left motor leads swapped", fault(lead_sign={"left": -1}),
     [("direction_reversed", "left")], [("motor_reversed", "left")]),
    ("right motor leads swapped", fault(lead_sign={"right": -1}),
     [("direction_reversed", "right")], [("motor_reversed", "right")]),
    ("left encoder A/B reversed", fault(ab_sign={"left": -1}),
     [("direction_reversed", "left")], [("encoder_reversed", "left")]),
    ("right encoder A/B reversed", fault(ab_sign={"right": -1}),
     [("direction_reversed", "right")], [("encoder_reversed", "right")]),
    ("encoder cables swapped", fault(encoder_decoder={"left": "right", "right": "left"}),
     [("left_right_swapped", None)], [("encoders_swapped", None)]),
    ("motor channels swapped", fault(channel_motors={"left": ("right",), "right": ("left",)}),
     [("left_right_swapped", None)], [("motors_swapped", None)]),
    ("both motors on the left channel", fault(channel_motors={"left": ("left", "right"), "right": ()}),
     [("both_motors_one_channel", "left")], [("both_motors_one_channel", "left")]),
    ("both motors on the right channel", fault(channel_motors={"left": (), "right": ("left", "right")}),
     [("both_motors_one_channel", "right")], [("both_motors_one_channel", "right")]),
    ("firmware decodes 2X", fault(decoding_factor=0.5),
     [("counts_per_rev", None)], [("counts_per_rev", None)]),
    ("firmware decodes 1X", fault(decoding_factor=0.25),
     [("counts_per_rev", None)], [("counts_per_rev", None)]),
    ("left wheel drags", fault(motor_gain={"left": 0.3}),
     [("wheel_slow", "left")], [("wheel_slow", "left")]),
    ("right wheel drags", fault(motor_gain={"right": 0.35}),
     [("wheel_slow", "right")], [("wheel_slow", "right")]),
    ("left INB dead", fault(dead_input={"left": "INB"}),
     [("one_direction", "left")], [("one_direction", "left")]),
    ("right INA dead", fault(dead_input={"right": "INA"}),
     [("one_direction", "right")], [("one_direction", "right")]),
]


@pytest.mark.parametrize("name,robot,without,with_hand", SINGLE, ids=[s[0] for s in SINGLE])
@pytest.mark.parametrize("seed", [None, 1, 2])
def test_single_fault(name, robot, without, with_hand, seed):
    v = check(robot, False, seed)
    assert codes(v) == without, [x.line() for x in v]
    v = check(robot, True, seed)
    assert codes(v) == with_hand, [x.line() for x in v]
    assert all(not x.ok and x.message and x.fix for x in v)


def test_motors_and_encoders_swapped_needs_the_hand_turn():
    robot = fault(channel_motors={"left": ("right",), "right": ("left",)},
                  encoder_decoder={"left": "right", "right": "left"})
    assert codes(check(robot, False)) == [("ok", None)]          # the blind spot of powered runs alone
    v = check(robot, True)
    assert codes(v) == [("motors_and_encoders_swapped", None)]
    assert "backwards" in v[0].message


def test_both_encoders_dead():
    robot = fault(encoder_alive={"left": False, "right": False})
    v = check(robot, False)
    assert codes(v) == [("no_motion", None)]
    assert "both encoders unpowered" in v[0].fix
    assert codes(check(robot, True)) == [("encoder_silent", "left"), ("encoder_silent", "right")]


def test_no_motion_with_encoders_proven_by_hand():
    v = check(fault(motor_gain={"left": 0.0, "right": 0.0}), True)
    assert "both encoders count by hand" in v[0].fix
    assert "motor power/driver enable?" in v[0].fix


# ---- the messages name the project's parameters and pins -----------------------------------------

def test_messages_are_concrete():
    by = {name: (check(robot, False), check(robot, True)) for name, robot, _, _ in SINGLE}
    no_hand, hand = by["left motor leads swapped"]
    assert "invert_left_encoder" in no_hand[0].fix and "`invert_left`" in no_hand[0].fix
    assert "swap the left motor's leads" in hand[0].fix and "firmware/core/config.h" in hand[0].fix
    assert "(default true)" in by["right motor leads swapped"][1][0].fix
    assert "invert_right_encoder" in by["right encoder A/B reversed"][1][0].fix
    assert "encoder A/B of the right wheel reversed" in by["right encoder A/B reversed"][1][0].message
    silent = by["left encoder dead"][1][0]
    assert "5 V" in silent.fix and "PF_4" in silent.fix and "PD_7" in silent.fix and "firmware/README.md" in silent.fix
    assert "PA_3" in by["left motor dead"][1][0].fix
    assert "PD_6" in by["encoder cables swapped"][1][0].fix
    cpr = by["firmware decodes 2X"][1][0]
    assert "ticks_meter" in cpr.fix and "EncoderMode::X4" in cpr.fix and "14854" in cpr.fix
    assert "counts per turn by hand, configured 8400" in cpr.message
    assert "1X" in by["firmware decodes 1X"][1][0].fix
    assert "INB" in by["left INB dead"][0][0].fix and "PA_4" in by["left INB dead"][0][0].fix
    assert "forward only" in by["left INB dead"][0][0].message
    assert "PE_4" in by["right INA dead"][0][0].fix
    assert "right" in by["both motors on the left channel"][0][0].fix
    for name, (a, b) in by.items():
        for v in a + b:
            assert v.line().startswith(v.message) and ": " in v.line(), name


# ---- two faults at once -> both named ---------------------------------------------------------

PAIRS = [
    ("left leads swapped + right encoder dead", fault(lead_sign={"left": -1}, encoder_alive={"right": False}),
     [("direction_reversed", "left"), ("no_counts", "right")],
     [("encoder_silent", "right"), ("motor_reversed", "left")]),
    ("left encoder reversed + right wheel drags", fault(ab_sign={"left": -1}, motor_gain={"right": 0.3}),
     [("direction_reversed", "left"), ("wheel_slow", "right")],
     [("encoder_reversed", "left"), ("wheel_slow", "right")]),
    ("both motors' leads swapped", fault(lead_sign={"left": -1, "right": -1}),
     [("direction_reversed", "left"), ("direction_reversed", "right")],
     [("motor_reversed", "left"), ("motor_reversed", "right")]),
    ("left leads and left encoder both reversed", fault(lead_sign={"left": -1}, ab_sign={"left": -1}),
     [("ok", None)],                                   # cancel out on the powered run
     [("encoder_reversed", "left"), ("motor_reversed", "left")]),
    ("2X decoding + right leads swapped", fault(decoding_factor=0.5, lead_sign={"right": -1}),
     [("counts_per_rev", None), ("direction_reversed", "right")],
     [("counts_per_rev", None), ("motor_reversed", "right")]),
    ("motors swapped + left encoder dead", fault(channel_motors={"left": ("right",), "right": ("left",)},
                                                 encoder_alive={"left": False}),
     [("left_right_swapped", "left"), ("no_counts", "right")],
     [("encoder_silent", "left"), ("motors_swapped", "left")]),
    ("right motor dead + left INB dead", fault(motor_gain={"right": 0.0}, dead_input={"left": "INB"}),
     [("no_counts", "right"), ("one_direction", "left")],
     [("motor_silent", "right"), ("one_direction", "left")]),
    ("encoders swapped + right leads swapped", fault(encoder_decoder={"left": "right", "right": "left"},
                                                     lead_sign={"right": -1}),
     [("left_right_swapped", None)],                   # the sign is judged again after the swap is fixed
     [("encoders_swapped", None)]),
]


@pytest.mark.parametrize("name,robot,without,with_hand", PAIRS, ids=[p[0] for p in PAIRS])
def test_fault_pairs(name, robot, without, with_hand):
    for seed in (None, 3):
        assert codes(check(robot, False, seed)) == sorted(without)
        assert codes(check(robot, True, seed)) == sorted(with_hand)


# ---- thresholds at their edges ----------------------------------------------------------------

def _runs_scaled(left_ratio: float, right_other: float = 0.0) -> list[MotorRun]:
    n = EXPECTED * left_ratio
    o = EXPECTED * right_other
    full = round(EXPECTED)
    return [MotorRun("left", DUTY, SECONDS, round(n), round(o)), MotorRun("left", -DUTY, SECONDS, -round(n), -round(o)),
            MotorRun("right", DUTY, SECONDS, 0, full), MotorRun("right", -DUTY, SECONDS, 0, -full)]


@pytest.mark.parametrize("ratio,code", [(bc.SLOW_RATIO + 0.01, "ok"), (bc.SLOW_RATIO - 0.01, "wheel_slow"),
                                        (bc.FAST_RATIO - 0.01, "ok"), (bc.FAST_RATIO + 0.01, "wheel_fast"),
                                        (bc.MOVED_FRACTION + 0.01, "wheel_slow"),
                                        (bc.MOVED_FRACTION - 0.01, "no_counts")])
def test_speed_edges(ratio, code):
    v = diagnose_motors(_runs_scaled(ratio))
    assert [x.code for x in v] == [code]


def test_other_counter_edge():
    """The counter of the wheel not commanded may creep (a shared chassis) up to MOVED_FRACTION."""
    creep = _runs_scaled(1.0, bc.MOVED_FRACTION - 0.01)
    assert [x.code for x in diagnose_motors(creep)] == ["ok"]
    both = [r for r in _runs_scaled(1.0, bc.MOVED_FRACTION + 0.01) if r.side_commanded == "left"]
    both.append(MotorRun("right", DUTY, SECONDS, 0, 0))
    assert [(x.code, x.side) for x in diagnose_motors(both)] == [("both_motors_one_channel", "left")]


def test_moved_min_counts_for_tiny_runs():
    # 0.05 s at duty 0.05: 28 counts expected, 10 % would be 3: the 20-count floor ignores jitter
    tiny = [MotorRun("left", 0.05, 0.05, 25, 19), MotorRun("right", 0.05, 0.05, -19, 26)]
    assert [x.code for x in diagnose_motors(tiny)] == ["ok"]


@pytest.mark.parametrize("ratio,ok", [(1 + bc.CPR_TOLERANCE - 0.005, True), (1 + bc.CPR_TOLERANCE + 0.005, False),
                                      (1 - bc.CPR_TOLERANCE + 0.005, True), (1 - bc.CPR_TOLERANCE - 0.005, False)])
def test_hand_turn_tolerance_edges(ratio, ok):
    runs = _runs_scaled(1.0)
    turns = [HandTurn("left", round(8400 * ratio), 2), HandTurn("right", -1, 8400)]
    v = diagnose_motors(runs, turns)
    assert [(x.code, x.side) for x in v] == ([("ok", None)] if ok else [("counts_per_rev", "left")])
    if not ok:
        assert "set ticks_meter to" in v[0].fix      # not a decoding multiple: measure it


def test_speed_uses_the_hand_measured_counts_per_turn():
    runs = _runs_scaled(0.5)   # left at half the counts ...
    v = diagnose_motors(runs, [HandTurn("left", 4200, 0)])   # ... because its turn has 4200 counts
    assert [(x.code, x.side) for x in v] == [("counts_per_rev", "left")]


def test_half_speed_on_one_wheel_is_slow_not_decoding():
    v = diagnose_motors(_runs_scaled(0.45))
    assert [x.code for x in v] == ["wheel_slow"]


def test_configured_for_2x_but_firmware_4x():
    e2 = Expectations(ticks_meter=14854)
    r = Robot()
    runs = [r.run(ch, d) for ch in ("left", "right") for d in (DUTY, -DUTY)]
    v = diagnose_motors(runs, expect=e2)
    assert [x.code for x in v] == ["counts_per_rev"]
    assert "4X" in v[0].fix and "29708" in v[0].fix


def test_inputs_are_validated():
    with pytest.raises(ValueError):
        MotorRun("middle", DUTY, 1.0, 0, 0)
    with pytest.raises(ValueError):
        MotorRun("left", 0.0, 1.0, 0, 0)
    with pytest.raises(ValueError):
        MotorRun("left", 1.5, 1.0, 0, 0)
    with pytest.raises(ValueError):
        MotorRun("left", DUTY, 0.0, 0, 0)
    with pytest.raises(ValueError):
        HandTurn("up", 0, 0)
    with pytest.raises(ValueError):
        diagnose_motors([])


# ---- the board answers ------------------------------------------------------------------------

GOOD = BoardReport(hello=("1", "chefbot_fw-1.0.0", "30", "500", "4", "1023"), status_rate_hz=30.0,
                   battery_volts=12.4, imu_rate_hz=30.0, sonar_rate_hz=30.0, sonar_no_echo_fraction=0.0)


def test_board_all_ok():
    v = board_verdicts(GOOD)
    assert [x.code for x in v] == ["hello", "status_rate", "battery", "imu", "sonar"]
    assert all(x.ok for x in v)


@pytest.mark.parametrize("change,code", [
    ({"hello": None}, "no_hello"),
    ({"hello": ("2", "chefbot_fw-2.0.0", "30", "500", "4", "1023")}, "protocol_mismatch"),
    ({"hello": ("1", "other-1.0", "30", "500", "4", "1023")}, "protocol_mismatch"),
    ({"hello": ("1", "chefbot_fw-1.0.0", "30", "500", "2", "1023")}, "decoding_mismatch"),
    ({"status_rate_hz": 0.0}, "no_status"),
    ({"status_rate_hz": 20.0}, "status_rate"),
    ({"status_rate_hz": 40.0}, "status_rate"),
    ({"battery_volts": None}, "no_battery"),
    ({"battery_volts": 0.3}, "battery_absent"),
    ({"battery_volts": 10.8}, "battery_low"),
    ({"battery_volts": 16.0}, "battery_high"),
    ({"imu_rate_hz": 0.0}, "no_imu"),
    ({"imu_rate_hz": 12.0}, "imu_rate"),
    ({"sonar_rate_hz": 0.0}, "no_sonar"),
    ({"sonar_no_echo_fraction": 0.9}, "sonar_no_echo"),
])
def test_board_each_fault(change, code):
    v = board_verdicts(replace(GOOD, **change))
    bad = [x for x in v if not x.ok]
    assert [x.code for x in bad] == [code]
    assert bad[0].fix
    assert len(v) == 5


def test_board_messages():
    v = {x.code: x for x in board_verdicts(replace(GOOD, hello=("1", "chefbot_fw-1.0.0", "30", "500", "2", "1023"),
                                                   battery_volts=None, imu_rate_hz=0.0))}
    assert "14854" in v["decoding_mismatch"].fix and "encoder_mode" in v["decoding_mismatch"].fix
    assert "PE_3" in v["no_battery"].fix
    assert "PD_0" in v["no_imu"].fix


@pytest.mark.parametrize("field_,value,ok", [
    ("status_rate_hz", 27.0, True), ("status_rate_hz", 26.9, False),
    ("status_rate_hz", 33.0, True), ("status_rate_hz", 33.1, False),
    ("battery_volts", 11.35, True), ("battery_volts", 11.33, False),
    ("battery_volts", 14.8, True), ("battery_volts", 14.81, False),
    ("battery_volts", 6.0, False), ("imu_rate_hz", 27.0, True), ("imu_rate_hz", 26.9, False),
    ("sonar_no_echo_fraction", 0.5, True), ("sonar_no_echo_fraction", 0.51, False),
])
def test_board_edges(field_, value, ok):
    v = board_verdicts(replace(GOOD, **{field_: value}))
    assert all(x.ok for x in v) is ok


# ---- PID step response ---------------------------------------------------------------------

T = np.arange(0, 2.0, 1 / 30)        # pid_velocity's 30 Hz


def first_order(tau: float, final: float = 1.0, target: float = 1.0):
    return target * final * (1 - np.exp(-T / tau))


def second_order(zeta: float, wn: float):
    wd = wn * math.sqrt(1 - zeta ** 2)
    return 1 - np.exp(-zeta * wn * T) * (np.cos(wd * T) + zeta / math.sqrt(1 - zeta ** 2) * np.sin(wd * T))


def test_step_first_order_is_ok():
    tau = 0.1
    r = step_response_verdict(T, 1.0, first_order(tau))
    assert r.rise_time == pytest.approx(tau * math.log(9), abs=0.01)   # 10-90 % of a first-order lag
    assert r.overshoot_pct == pytest.approx(0.0, abs=1e-9)
    assert r.steady_state_error == pytest.approx(0.0, abs=1e-3)
    assert r.oscillations == 0
    assert [v.code for v in r.verdicts] == ["pid_ok"] and r.verdicts[0].ok


def test_step_negative_and_offset_steps():
    r = step_response_verdict(T, -0.2, first_order(0.1, target=-0.2))
    assert r.rise_time == pytest.approx(0.1 * math.log(9), abs=0.01)
    assert [v.code for v in r.verdicts] == ["pid_ok"]
    r = step_response_verdict(T, 0.3, 0.1 + first_order(0.1, target=0.2), start=0.1)
    assert r.rise_time == pytest.approx(0.1 * math.log(9), abs=0.01)
    assert r.steady_state_error == pytest.approx(0.0, abs=1e-3)


def test_step_noise_is_not_oscillation():
    rng = np.random.default_rng(4)
    y = first_order(0.1) + rng.uniform(-0.01, 0.01, T.size)
    r = step_response_verdict(T, 1.0, y)
    assert r.oscillations == 0
    assert [v.code for v in r.verdicts] == ["pid_ok"]


def test_step_underdamped_overshoots_and_oscillates():
    zeta = 0.2
    r = step_response_verdict(T, 1.0, second_order(zeta, 20.0))
    expected_os = 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2))   # 52.7 %
    assert r.overshoot_pct == pytest.approx(expected_os, abs=3.0)              # sampled at 30 Hz
    assert r.oscillations > bc.OSCILLATION_MAX
    got = {v.code for v in r.verdicts}
    assert got == {"pid_oscillates", "pid_overshoot"}
    assert all("lower Kp" in v.fix for v in r.verdicts)


def test_step_slow_and_no_rise_and_steady_error():
    r = step_response_verdict(T, 1.0, first_order(0.5))          # rise 1.1 s
    assert [v.code for v in r.verdicts] == ["pid_slow"] and "raise Kp" in r.verdicts[0].fix
    r = step_response_verdict(T, 1.0, first_order(0.1, final=0.8))
    assert r.rise_time is None
    assert {v.code for v in r.verdicts} == {"pid_no_rise", "pid_steady_error"}
    r = step_response_verdict(T, 1.0, first_order(0.1, final=0.93))
    assert [v.code for v in r.verdicts] == ["pid_steady_error"] and "raise Ki" in r.verdicts[0].fix
    assert r.steady_state_error == pytest.approx(0.07, abs=2e-3)


def _shaped(overshoot: float, swings: int):
    """Reach the target at sample 10, peak at 1+overshoot, then swing +-0.1 `swings` times, then settle."""
    y = np.ones(T.size)
    y[:10] = np.linspace(0, 0.99, 10)
    y[12] = 1 + overshoot
    for k in range(swings):
        y[14 + 2 * k] = 0.9 if k % 2 == 0 else 1.1
    return y


@pytest.mark.parametrize("overshoot,flag", [(bc.OVERSHOOT_MAX / 100 - 0.005, False),
                                            (bc.OVERSHOOT_MAX / 100 + 0.005, True)])
def test_overshoot_edge(overshoot, flag):
    r = step_response_verdict(T, 1.0, _shaped(overshoot, 0))
    assert r.overshoot_pct == pytest.approx(overshoot * 100, abs=1e-6)
    assert ("pid_overshoot" in {v.code for v in r.verdicts}) is flag


@pytest.mark.parametrize("swings", [bc.OSCILLATION_MAX - 1, bc.OSCILLATION_MAX])
def test_oscillation_edge(swings):
    # peak above, then `swings` alternating excursions: the error changes sign `swings` times, +1 when
    # the first excursion goes below after the peak above
    r = step_response_verdict(T, 1.0, _shaped(0.05, swings))
    assert r.oscillations == swings
    assert "pid_oscillates" not in {v.code for v in r.verdicts}
    r = step_response_verdict(T, 1.0, _shaped(0.05, swings + 2))
    assert r.oscillations == swings + 2
    assert "pid_oscillates" in {v.code for v in r.verdicts}


def test_step_rise_edge():
    tau = bc.RISE_TIME_MAX / math.log(9)
    fine = np.arange(0, 5.0, 1 / 1000)
    slower = 1 - np.exp(-fine / (tau * 1.02))
    faster = 1 - np.exp(-fine / (tau * 0.98))
    assert "pid_slow" in {v.code for v in step_response_verdict(fine, 1.0, slower).verdicts}
    assert [v.code for v in step_response_verdict(fine, 1.0, faster).verdicts] == ["pid_ok"]


def test_step_input_checks():
    with pytest.raises(ValueError):
        step_response_verdict([0, 1, 2], 1.0, [0, 1, 1])
    with pytest.raises(ValueError):
        step_response_verdict(T, 0.0, first_order(0.1))
    with pytest.raises(ValueError):
        step_response_verdict(T[::-1], 1.0, first_order(0.1))
