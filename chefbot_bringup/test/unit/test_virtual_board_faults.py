"""VirtualBoard build faults (issue 31): each wiring fault alone, the defaults, and the diagnosis.

The runs drive the emulated board through the firmware's own `s` command parser
(fw.feed) and read the counts the firmware's decoder produced; the diagnosis
(chefbot_bringup.bringup_check.diagnose_motors) must name the fault that was built in.
"""
from __future__ import annotations

import math

import pytest

from chefbot_bringup.bringup_check import HandTurn, MotorRun, diagnose_motors

vb = pytest.importorskip("chefbot_firmware.virtual_board")
try:
    from chefbot_firmware.host import LEFT, RIGHT, library_path
    library_path()
except Exception as e:  # noqa: BLE001 - library not built: skip the module
    pytest.skip(f"firmware host library: {e}", allow_module_level=True)

BuildFaults, VirtualBoard = vb.BuildFaults, vb.VirtualBoard
CMD = 300                 # `s` units of 1023: duty 0.29
SECONDS = 2.0
SIDE = {"left": LEFT, "right": RIGHT}


def counts(b: VirtualBoard) -> tuple[int, int]:
    return b.fw.encoder_count(LEFT), b.fw.encoder_count(RIGHT)


def drive(b: VirtualBoard, left: int, right: int, seconds: float = SECONDS, stop: float = 0.5) -> tuple[int, int]:
    """Command `s left right` (re-sent every 0.1 s) for ``seconds``, then stop until the wheels stand;
    returns the change of both counters."""
    start = counts(b)
    line = f"s {left} {right}\n".encode()
    n = round(seconds / 0.01)
    for k in range(n + round(stop / 0.01)):
        if k < n and k % 10 == 0:
            b.fw.feed(line)
        if k == n:
            b.fw.feed(b"s 0 0\n")
        b.step(0.01)
    end = counts(b)
    return end[0] - start[0], end[1] - start[1]


def hand_turn(b: VirtualBoard, side: int) -> tuple[int, int]:
    """One forward turn of wheel ``side`` by hand, in small steps, motors off."""
    start = counts(b)
    for _ in range(100):
        b.turn_wheel(side, 2 * math.pi / 100)
    b.step(0.01)
    end = counts(b)
    return end[0] - start[0], end[1] - start[1]


def records(faults: BuildFaults | None) -> tuple[list[MotorRun], list[HandTurn]]:
    """The bring-up check's records from the emulated robot: each motor alone forward and
    backward at low duty, then each wheel one turn forward by hand."""
    runs, turns = [], []
    with VirtualBoard(faults=faults) as b:
        for ch in ("left", "right"):
            for sign in (1, -1):
                cmd = sign * CMD
                dl, dr = drive(b, cmd if ch == "left" else 0, cmd if ch == "right" else 0)
                runs.append(MotorRun(ch, cmd / 1023, SECONDS, dl, dr))
        for w in ("left", "right"):
            dl, dr = hand_turn(b, SIDE[w])
            turns.append(HandTurn(w, dl, dr))
    return runs, turns


# ---- defaults: bit for bit the board of before ------------------------------------------------

SEQUENCE = [(300, 0), (0, -300), (500, 450), (-1023, 1023), (0, 0)]


def sequence_counts(**kw) -> list:
    out = []
    with VirtualBoard(**kw) as b:
        for left, right in SEQUENCE:
            out.append((drive(b, left, right, 0.7, 0.2), b.motors[0].angle, b.motors[1].angle, b.fw.now_us))
    return out


def test_defaults_reproduce_the_board_without_faults():
    plain = sequence_counts()
    assert plain == sequence_counts(faults=BuildFaults())
    assert plain == sequence_counts(faults=None)
    assert plain[0][0][0] > 0 and plain[1][0][1] < 0


def test_correct_robot_counts_forward_and_diagnoses_ok():
    with VirtualBoard() as b:
        dl, dr = drive(b, CMD, CMD)
        assert dl > 0 and dr > 0
        assert abs(b.motors[0].speed) < 0.01      # the wheel stands again (tau 0.08 s)
    runs, turns = records(None)
    v = diagnose_motors(runs, turns)
    assert [x.code for x in v] == ["ok"], [x.line() for x in v]


# ---- each fault alone ---------------------------------------------------------------------------

def test_left_leads_swapped_turns_the_left_wheel_backward():
    with VirtualBoard(faults=BuildFaults(left_leads_swapped=True)) as b:
        dl, dr = drive(b, CMD, CMD)
        assert dl < 0 and b.motors[LEFT].angle < 0        # the wheel itself turns backward
        assert dr > 0 and b.motors[RIGHT].angle > 0
        assert b.fw.wheel_duty(LEFT) == 0.0
        assert hand_turn(b, LEFT)[0] > 0                  # the encoder is fine


def test_right_leads_swapped_turns_the_right_wheel_backward():
    with VirtualBoard(faults=BuildFaults(right_leads_swapped=True)) as b:
        dl, dr = drive(b, CMD, CMD)
        assert dl > 0 and dr < 0 and b.motors[RIGHT].angle < 0


@pytest.mark.parametrize("side", [LEFT, RIGHT])
def test_encoder_reversed_wheel_forward_counts_negative(side):
    name = "left_encoder_reversed" if side == LEFT else "right_encoder_reversed"
    with VirtualBoard(faults=BuildFaults(**{name: True})) as b:
        d = drive(b, CMD, CMD)
        assert b.motors[side].angle > 0 and b.motors[1 - side].angle > 0    # both wheels turn forward
        assert d[side] < 0 and d[1 - side] > 0
        with VirtualBoard() as ref:
            assert d[side] == -drive(ref, CMD, CMD)[side]                    # same size, other sign


def test_encoders_swapped_moves_the_other_counter():
    with VirtualBoard(faults=BuildFaults(encoders_swapped=True)) as b:
        dl, dr = drive(b, CMD, 0)                     # the left wheel turns ...
        assert b.motors[LEFT].angle > 0 and b.motors[RIGHT].angle == 0
        assert dl == 0 and dr < -1000                 # ... the right counter moves (backward: the
        hl, hr = hand_turn(b, RIGHT)                  # right decoder inverts for its mirrored encoder)
        assert hl == -8400 and hr == 0


def test_motors_swapped_drives_the_other_wheel():
    with VirtualBoard(faults=BuildFaults(motors_swapped=True)) as b:
        dl, dr = drive(b, CMD, 0)                     # the left channel ...
        assert b.motors[LEFT].angle == 0 and b.motors[RIGHT].angle < 0    # ... turns the right wheel
        assert dl == 0 and dr < -1000                 # (backward: the right motor is mounted mirrored)
        assert hand_turn(b, LEFT)[0] > 0             # the encoders are in place


def test_wheel_scale_changes_travel_not_counts():
    with VirtualBoard() as ref, VirtualBoard(faults=BuildFaults(left_wheel_scale=1.03,
                                                                right_wheel_scale=0.99)) as b:
        assert drive(b, CMD, CMD) == drive(ref, CMD, CMD)
        for side, scale in ((LEFT, 1.03), (RIGHT, 0.99)):
            assert b.wheel_travel(side) == pytest.approx(scale * ref.wheel_travel(side))
        assert ref.wheel_travel(LEFT) == pytest.approx(ref.motors[LEFT].angle * vb.WHEEL_RADIUS)


@pytest.mark.parametrize("kw", [{"left_wheel_scale": 0.0}, {"right_wheel_scale": -1.0},
                                {"left_wheel_scale": float("nan")}, {"right_wheel_scale": float("inf")},
                                {"left_wheel_scale": "1.0"}, {"motors_swapped": 1}])
def test_bad_settings_raise(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        BuildFaults(**kw)


def test_faults_must_be_build_faults():
    with pytest.raises(ValueError, match="BuildFaults"):
        VirtualBoard(faults={"motors_swapped": True})


def test_mechanics_follow_the_firmware_config():
    """A robot whose config mounts the left side mirrored too: still correct without faults,
    and a swapped lead still reverses the wheel."""
    conf = {"invert_left": True, "invert_left_encoder": True}
    with VirtualBoard(config=conf) as b:
        assert all(d > 0 for d in drive(b, CMD, CMD))
    with VirtualBoard(config=conf, faults=BuildFaults(left_leads_swapped=True)) as b:
        dl, dr = drive(b, CMD, CMD)
        assert dl < 0 < dr and b.motors[LEFT].angle < 0


# ---- the emulator and the diagnosis, closed loop --------------------------------------------

CASES = [
    (BuildFaults(left_leads_swapped=True), {("motor_reversed", "left")}),
    (BuildFaults(right_leads_swapped=True), {("motor_reversed", "right")}),
    (BuildFaults(left_encoder_reversed=True), {("encoder_reversed", "left")}),
    (BuildFaults(right_encoder_reversed=True), {("encoder_reversed", "right")}),
    (BuildFaults(encoders_swapped=True), {("encoders_swapped", None)}),
    (BuildFaults(motors_swapped=True), {("motors_swapped", None)}),
    (BuildFaults(motors_swapped=True, encoders_swapped=True), {("motors_and_encoders_swapped", None)}),
    (BuildFaults(left_leads_swapped=True, right_encoder_reversed=True),
     {("motor_reversed", "left"), ("encoder_reversed", "right")}),
    (BuildFaults(left_wheel_scale=1.03, right_wheel_scale=0.99), {("ok", None)}),
]


@pytest.mark.parametrize("faults,expected", CASES, ids=lambda x: repr(x) if isinstance(x, set) else None)
def test_diagnosis_names_the_built_in_fault(faults, expected):
    runs, turns = records(faults)
    v = diagnose_motors(runs, turns)
    assert {(x.code, x.side) for x in v} == expected, [x.line() for x in v]


def test_without_hand_turns_reversed_leads_read_as_direction_reversed():
    runs, _ = records(BuildFaults(left_leads_swapped=True))
    v = diagnose_motors(runs)
    assert [(x.code, x.side) for x in v] == [("direction_reversed", "left")]
