"""Bring-up (wiring) check of a freshly built ChefBot: the diagnosis core (issue 31).

Pure Python (numpy), no rospy: a future guided ``bringup_check`` node records what
each step saw and calls these functions; each returns :class:`Verdict` objects, one
line each with the fix.

* :func:`diagnose_motors` -- robot on blocks, each motor alone forward then backward at
  low duty (:class:`MotorRun`), optionally each wheel turned one turn forward by hand
  (:class:`HandTurn`). From the encoder counts' sign and size it names dead encoders,
  motors that do not turn, reversed motor leads vs reversed encoders, left/right swaps
  (motors, encoders or both), both motors on one driver channel, a motor that turns one
  way only, counts per turn that differ from ``ticks_meter``, and slow wheels.
* :func:`board_verdicts` -- "the board answers": hello line, status line rate, battery,
  IMU and sonar (:class:`BoardReport`).
* :func:`step_response_verdict` -- a wheel PID's step response: rise time, overshoot,
  steady-state error, oscillation, and which gain to turn.

Conventions: counts are the PC's view (the ``e`` line, ``lwheel``/``rwheel``), after the
firmware's ``invert_*`` flags; a correctly wired robot counts positive on both wheels
when driven forward. ``duty`` is the signed fraction of full command (``s`` value /
``command_max`` 1023). A run's counts are the change from the command's start until the
wheel stood still again; the board's first-order motor (``virtual_board.MotorModel``)
then turns exactly ``duty x free speed x seconds`` (counting only while commanded
loses ``tau`` = 0.08 s of travel, 4 % of a 2 s run: well inside the tolerances).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

SIDES = ("left", "right")

# ---- what the project configures (sources in the comments) -----------------------------
# param/diff_drive.yaml: ticks_meter 29708 = 8400 counts/rev (64 CPR x 131.25 gear, 4X
# decoding, firmware/README.md "Encoder counts") / (pi x 0.09 m wheel);
# max_wheel_speed 0.377 m/s = 80 RPM x pi x 0.09 m (Pololu 37D at 12 V, the free speed of
# chefbot_firmware.virtual_board.MotorModel).
TICKS_METER = 29708.0
WHEEL_DIAMETER = 0.09          # m
MAX_WHEEL_SPEED = 0.377        # m/s at full duty
COUNTS_PER_REV_1X = 2100       # 16 lines x 131.25 gear: rising edges of A per wheel turn; x4 = 8400 (X4 decoding,
                               # firmware/core/config.h encoder_mode), x2 = 4200 (the book's sketch)

# firmware/core/config.h defaults (the right motor and encoder are mounted mirrored).
INVERT_DEFAULTS = {"invert_left": False, "invert_right": True,
                   "invert_left_encoder": False, "invert_right_encoder": True}

# firmware/chefbot/board_config.h (the book's pin map, firmware/README.md "Pins and wiring").
PINS = {
    "left": {"INA": "PA_3 (Energia 12)", "INB": "PA_4 (Energia 13)", "PWM": "PC_6 (Energia 35)",
             "A": "PF_4 (Energia 31)", "B": "PD_7 (Energia 32)"},
    "right": {"INA": "PE_4 (Energia 5)", "INB": "PE_5 (Energia 6)", "PWM": "PC_5 (Energia 36)",
              "A": "PD_6 (Energia 33)", "B": "PC_7 (Energia 34)"},
}
CONFIG_H = "firmware/core/config.h"
PIN_TABLE = "firmware/README.md, \"Pins and wiring\""

# ---- thresholds of the motor step ---------------------------------------------------------
MOVED_FRACTION = 0.10     # a counter "moved" if it changed by more than this part of the expected counts
MOVED_MIN_COUNTS = 20     # ... and by more than this many counts (jitter, a touched wheel)
SLOW_RATIO = 0.6          # powered run: below this part of the expected counts the wheel is "slow"
                          # (a real 37D at duty 0.3 with its 3.6 % dead band reaches ~0.9; 2X decoding reads 0.5)
FAST_RATIO = 1.5          # above this many times the expected counts it is "fast"
CPR_TOLERANCE = 0.10      # hand turn: counts per turn within +-10 % of the configured are fine
DECODING_MATCH = 0.15     # a count ratio within +-15 % of 1/2, 1/4, 2 ... is read as another decoding


@dataclass(frozen=True)
class Verdict:
    """One finding: ``ok``, a stable ``code``, what was seen and what to do."""

    ok: bool
    code: str
    message: str
    fix: str = ""
    side: str | None = None     # "left" / "right" when the finding is about one wheel

    def line(self) -> str:
        """The one line shown to the builder."""
        return f"{self.message}: {self.fix}" if self.fix else self.message


@dataclass(frozen=True)
class MotorRun:
    """One motor commanded alone: the change of both counters during the run."""

    side_commanded: str   # "left" | "right"
    duty: float           # signed fraction of full command, -1..1, not 0
    seconds: float        # how long the command was applied
    left_counts: int
    right_counts: int

    def __post_init__(self) -> None:
        _check_side(self.side_commanded)
        if not (math.isfinite(self.duty) and 0 < abs(self.duty) <= 1):
            raise ValueError(f"duty must be in [-1, 1] and not 0, got {self.duty!r}")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds must be > 0, got {self.seconds!r}")


@dataclass(frozen=True)
class HandTurn:
    """The builder turned wheel ``side`` one turn FORWARD by hand (motors off)."""

    side: str
    left_counts: int
    right_counts: int

    def __post_init__(self) -> None:
        _check_side(self.side)


@dataclass(frozen=True)
class Expectations:
    """What the configuration promises (defaults: param/diff_drive.yaml, 4X firmware)."""

    ticks_meter: float = TICKS_METER          # ticks/m: encoder ticks per metre of wheel travel (counts per wheel turn)
    wheel_diameter: float = WHEEL_DIAMETER    # m: nominal wheel
    max_wheel_speed: float = MAX_WHEEL_SPEED  # m/s: wheel speed at full duty

    def __post_init__(self) -> None:
        for name in ("ticks_meter", "wheel_diameter", "max_wheel_speed"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")

    @property
    def decoding(self) -> int | None:
        """The firmware decoding (4, 2, 1) ticks_meter was set for, None if it fits none of them."""
        for mode in (4, 2, 1):
            if abs(self.counts_per_rev / (mode * COUNTS_PER_REV_1X) - 1) <= DECODING_MATCH:
                return mode
        return None

    @property
    def counts_per_rev(self) -> float:
        """Counts per wheel turn: ticks_meter x pi x wheel diameter (8400 by default)."""
        return self.ticks_meter * math.pi * self.wheel_diameter

    @property
    def free_rev_per_s(self) -> float:
        """Wheel turns per second at full duty (80 RPM = 1.333 by default)."""
        return self.max_wheel_speed / (math.pi * self.wheel_diameter)

    def expected_counts(self, duty: float, seconds: float, counts_per_rev: float | None = None) -> float:
        """Counts of a run (magnitude) for the emulator's linear motor: |duty| x free speed x time."""
        cpr = self.counts_per_rev if counts_per_rev is None else counts_per_rev
        return abs(duty) * self.free_rev_per_s * seconds * cpr


def _check_side(side: str) -> None:
    if side not in SIDES:
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")


def _other(side: str) -> str:
    return "right" if side == "left" else "left"


def _moved(counts: float, expected: float) -> bool:
    return abs(counts) > max(MOVED_MIN_COUNTS, MOVED_FRACTION * expected)


@dataclass
class _Response:
    """What one motor channel (or one hand-turned wheel) did to the two counters."""

    counter: str | None        # "left" | "right" | "both" | None (nothing moved)
    sign: int                  # +1 forward, -1 backward relative to the command, 0 mixed
    ratio: float               # |counts| / expected of the moved counter (0 if none)
    only: str | None = None    # "forward" / "backward": the only direction that moved


def _summarize_runs(ch: str, runs: Sequence[MotorRun], expect: Expectations) -> _Response:
    per_dir: dict[str, dict[str, float]] = {}
    for r in runs:
        d = "forward" if r.duty > 0 else "backward"
        acc = per_dir.setdefault(d, {"left": 0.0, "right": 0.0, "expected": 0.0})
        s = 1.0 if r.duty > 0 else -1.0
        acc["left"] += s * r.left_counts
        acc["right"] += s * r.right_counts
        acc["expected"] += expect.expected_counts(r.duty, r.seconds)
    moved = {d: {c for c in SIDES if _moved(a[c], a["expected"])} for d, a in per_dir.items()}
    counters = set().union(*moved.values())
    if not counters:
        return _Response(None, 0, 0.0)
    moving_dirs = [d for d in per_dir if moved[d]]
    only = moving_dirs[0] if len(moving_dirs) < len(per_dir) else None
    if len(counters) == 2:
        return _Response("both", 0, 0.0, only)
    c = counters.pop()
    signs = {int(np.sign(per_dir[d][c])) for d in moving_dirs}
    total = sum(per_dir[d][c] for d in moving_dirs)
    expected = sum(per_dir[d]["expected"] for d in moving_dirs)
    sign = signs.pop() if len(signs) == 1 else 0
    return _Response(c, sign, abs(total) / expected, only)


def _summarize_hand(turns: Sequence[HandTurn], cpr: float) -> _Response:
    left = sum(t.left_counts for t in turns)
    right = sum(t.right_counts for t in turns)
    expected = cpr * len(turns)
    counters = [c for c, v in (("left", left), ("right", right)) if _moved(v, expected)]
    if not counters:
        return _Response(None, 0, 0.0)
    if len(counters) == 2:
        return _Response("both", 0, 0.0)
    v = left if counters[0] == "left" else right
    return _Response(counters[0], int(np.sign(v)), abs(v) / expected)


# ---- messages ------------------------------------------------------------------------------

def _motor_pins(s: str) -> str:
    p = PINS[s]
    return f"INA/INB/PWM on {p['INA']} / {p['INB']} / {p['PWM']}"


def _encoder_pins(s: str) -> str:
    p = PINS[s]
    extra = "; PD_7 is the NMI pin: our firmware's board HAL unlocks it, the book's sketch does not" \
        if s == "left" else ""
    return f"A on {p['A']}, B on {p['B']}{extra}"


def _flag(name: str) -> str:
    return f"`{name}` (default {str(INVERT_DEFAULTS[name]).lower()}) in {CONFIG_H} and flash again"


def _decoding_hint(ratio: float, expect: Expectations) -> str | None:
    """Name the firmware decoding a count ratio points to, or None."""
    if expect.decoding is None:
        return None
    implied = expect.decoding * ratio
    for mode in (4, 2, 1):
        if mode != expect.decoding and abs(implied / mode - 1) <= DECODING_MATCH:
            tm_for_mode = expect.ticks_meter * mode / expect.decoding
            return (f"the firmware decodes {mode}X but ticks_meter {expect.ticks_meter:.0f} assumes "
                    f"{expect.decoding}X: set `encoder_mode = EncoderMode::X{expect.decoding}` in {CONFIG_H} and "
                    f"flash again, or set ticks_meter to {tm_for_mode:.0f} in chefbot_bringup/param/diff_drive.yaml")
    return None


def _cpr_verdict(sides: list[str], ratio: float, expect: Expectations, by_hand: bool) -> Verdict:
    cpr = expect.counts_per_rev
    who = " and ".join(sides) + (" wheels" if len(sides) > 1 else " wheel")
    if by_hand:
        msg = (f"{who}: {ratio * cpr:.0f} counts per turn by hand, configured {cpr:.0f} "
               f"(ticks_meter {expect.ticks_meter:.0f} x pi x {expect.wheel_diameter} m)")
    else:
        msg = (f"{who}: {ratio:.0%} of the counts expected at this duty, alike on both: probably counts per turn "
               f"not as configured ({cpr:.0f} from ticks_meter {expect.ticks_meter:.0f})")
    hint = _decoding_hint(ratio, expect)
    if hint is None:
        tm = ratio * expect.ticks_meter
        hint = (f"another encoder or gear ratio? set ticks_meter to {tm:.0f} in chefbot_bringup/param/diff_drive.yaml "
                "(odometry_calibration.straight_line refines it)")
    if not by_hand:
        hint += "; confirm by turning a wheel one turn by hand"
    return Verdict(False, "counts_per_rev", msg, hint, sides[0] if len(sides) == 1 else None)


def _no_counts(s: str) -> Verdict:
    return Verdict(False, "no_counts", f"no counts from the {s} encoder while the {s} motor was commanded",
                   f"if the {s} wheel turned, check the {s} encoder's 5 V/GND and {_encoder_pins(s)} "
                   f"({PIN_TABLE}); if it did not turn, check the {s} motor's leads on the VNH2SP30 and "
                   f"{_motor_pins(s)}; turning the wheel by hand tells which", s)


def _encoder_silent(s: str) -> Verdict:
    return Verdict(False, "encoder_silent",
                   f"no counts from the {s} encoder, not even when its wheel is turned by hand",
                   f"check the {s} encoder's 5 V/GND, the level shifter and {_encoder_pins(s)} ({PIN_TABLE})", s)


def _motor_silent(s: str) -> Verdict:
    return Verdict(False, "motor_silent",
                   f"the {s} motor did not turn (its encoder counts when the wheel is turned by hand)",
                   f"check the {s} motor's leads on the VNH2SP30 and {_motor_pins(s)} through the level shifter", s)


def _no_motion(encoders_known_ok: bool) -> Verdict:
    why = "both encoders count by hand" if encoders_known_ok else \
        "or both encoders unpowered: turn a wheel by hand to tell"
    return Verdict(False, "no_motion", "no motor moved: no encoder counted while either motor was commanded",
                   f"motor power/driver enable? check the 12 V supply of the VNH2SP30, its DIAG/EN pull-ups and the "
                   f"level shifter's 5 V side, and that the board's `s` line said `run` during the step ({why})")


def _direction_reversed(s: str) -> Verdict:
    return Verdict(False, "direction_reversed",
                   f"the {s} wheel counts backwards when driven forward: the {s} motor's leads or its encoder A/B are "
                   "reversed",
                   f"turn the {s} wheel one turn forward by hand: negative counts -> encoder reversed, flip "
                   f"{_flag(f'invert_{s}_encoder')}; positive -> swap the {s} motor's leads, or flip "
                   f"{_flag(f'invert_{s}')}", s)


def _motor_reversed(s: str) -> Verdict:
    return Verdict(False, "motor_reversed",
                   f"the {s} motor turns backwards when commanded forward (its encoder counts forward by hand)",
                   f"swap the {s} motor's leads, or flip {_flag(f'invert_{s}')}", s)


def _encoder_reversed(s: str) -> Verdict:
    return Verdict(False, "encoder_reversed",
                   f"encoder A/B of the {s} wheel reversed: one forward turn by hand counts negative",
                   f"flip {_flag(f'invert_{s}_encoder')}, or swap the {s} encoder's A and B wires "
                   f"({_encoder_pins(s)})", s)


def _crossed_text(channels: list[str]) -> str:
    return " and ".join(f"commanding the {c} motor moved the {_other(c)} counter" for c in channels)


def _left_right_swapped(channels: list[str]) -> Verdict:
    return Verdict(False, "left_right_swapped",
                   f"{_crossed_text(channels)}: left and right are swapped, in the motor connections or in the "
                   "encoder connectors",
                   "turn the left wheel one turn by hand: the right counter moves -> swap the encoder connectors "
                   f"(left A/B on {PINS['left']['A']}/{PINS['left']['B']}); the left counter moves -> swap the motor "
                   f"connections (the left motor on the channel of {_motor_pins('left')})",
                   channels[0] if len(channels) == 1 else None)


def _motors_swapped(channels: list[str]) -> Verdict:
    return Verdict(False, "motors_swapped",
                   f"{_crossed_text(channels)}, while the hand turns show the encoders in place: the motors are "
                   "swapped left/right",
                   f"swap the motor connections at the VNH2SP30: the left motor on the channel of "
                   f"{_motor_pins('left')}, the right one on {_motor_pins('right')}",
                   channels[0] if len(channels) == 1 else None)


def _encoders_swapped(wheels: list[str]) -> Verdict:
    what = " and ".join(f"turning the {w} wheel by hand moved the {_other(w)} counter" for w in wheels)
    return Verdict(False, "encoders_swapped", f"{what}: the encoder connectors are swapped left/right",
                   f"swap them: left A/B on {PINS['left']['A']} / {PINS['left']['B']}, right on "
                   f"{PINS['right']['A']} / {PINS['right']['B']}", wheels[0] if len(wheels) == 1 else None)


def _all_swapped() -> Verdict:
    return Verdict(False, "motors_and_encoders_swapped",
                   "motors AND encoder connectors are both swapped left/right: the driving runs look right, but the "
                   "hand turns show the board's left is the robot's right wheel (driven forward, the robot rolls "
                   "backwards while odometry says forward)",
                   f"swap both back: motors ({_motor_pins('left')} drive the left motor) and encoders (left A/B on "
                   f"{PINS['left']['A']} / {PINS['left']['B']}), see {PIN_TABLE}")


def _both_on_one(ch: str) -> Verdict:
    o = _other(ch)
    return Verdict(False, "both_motors_one_channel",
                   f"commanding the {ch} motor turned both wheels and the {o} motor none: both motors are wired to "
                   f"the {ch} channel of the VNH2SP30",
                   f"connect the {o} motor to the channel driven by {_motor_pins(o)}", ch)


def _one_direction(s: str, moved: str) -> Verdict:
    # motor.cpp: forward = INA high unless invert_<side>; the direction that does not move needs the other input.
    fwd_pin = "INB" if INVERT_DEFAULTS[f"invert_{s}"] else "INA"
    dead = fwd_pin if moved == "backward" else ("INA" if fwd_pin == "INB" else "INB")
    missing = "backward" if moved == "forward" else "forward"
    return Verdict(False, "one_direction", f"the {s} motor turns {moved} only, not {missing}",
                   f"its {dead} input ({PINS[s][dead]}, default invert flags) never goes high: check that wire "
                   "and its level shifter channel", s)


def _encoder_erratic(s: str) -> Verdict:
    return Verdict(False, "encoder_erratic",
                   f"the {s} counter moved the same way for forward and backward commands",
                   f"one encoder channel is missing or noisy: check the {s} encoder's {_encoder_pins(s)} and 5 V, "
                   f"and encoder_illegal_{s} in the board's `d` line", s)


def _speed_verdict(s: str, ratio: float) -> Verdict:
    if ratio < SLOW_RATIO:
        return Verdict(False, "wheel_slow",
                       f"the {s} wheel turned at {ratio:.0%} of the expected speed for the duty",
                       f"it drags or is braked: free the wheel (rubbing, tight mount or gearbox), check the {s} "
                       f"motor's leads and PWM on {PINS[s]['PWM']}, and the battery (`b` line)", s)
    return Verdict(False, "wheel_fast", f"the {s} wheel counted {ratio:.1f}x the counts expected for the duty",
                   "more counts per turn than configured (ticks_meter set for a lower decoding than the firmware's, "
                   "or another gear ratio): turn the wheel one turn by hand to measure", s)


def _inconsistent(s: str) -> Verdict:
    return Verdict(False, "inconsistent",
                   f"the {s} motor's run moved a counter that no hand turn explains",
                   f"repeat the hand turn of the {s} wheel (one full turn forward, motors off) and the run", s)


# ---- the motor step --------------------------------------------------------------------

def diagnose_motors(runs: Iterable[MotorRun], hand_turns: Iterable[HandTurn] = (),
                    expect: Expectations | None = None) -> list[Verdict]:
    """Diagnose the motor/encoder wiring from single-motor runs and optional hand turns.

    Returns the faults found (each named once, several at once if present) or a single
    ``ok`` verdict. Without hand turns a reversed encoder and reversed motor leads look
    the same (both count against the command), as do swapped motors and swapped encoders:
    the verdict then names both possibilities and how to tell them apart; motors and
    encoders swapped together are only visible with a hand turn.
    """
    expect = expect or Expectations()
    runs = list(runs)
    turns = list(hand_turns)
    if not runs:
        raise ValueError("no motor runs: command each motor alone, forward and backward")
    resp = {ch: _summarize_runs(ch, [r for r in runs if r.side_commanded == ch], expect)
            for ch in SIDES if any(r.side_commanded == ch for r in runs)}
    hand = {w: _summarize_hand([t for t in turns if t.side == w], expect.counts_per_rev)
            for w in SIDES if any(t.side == w for t in turns)}
    faults: list[Verdict] = []

    # 1. The encoders, from the hand turns (wheel -> counter, sign, whether measured).
    enc: dict[str, tuple[str | None, int, bool]] = {}
    crossed_wheels: list[str] = []
    cpr_off: dict[str, float] = {}
    for w, h in hand.items():
        enc[w] = (h.counter, h.sign, True)
        if h.counter is None:
            faults.append(_encoder_silent(w))
        elif h.counter == "both":
            faults.append(Verdict(False, "encoder_crosstalk",
                                  f"turning the {w} wheel by hand moved both counters",
                                  f"the encoder signals are shorted or shared: check the A/B wires of both encoders "
                                  f"({PIN_TABLE})", w))
        else:
            if h.counter != w:
                crossed_wheels.append(w)
            elif h.sign < 0:
                faults.append(_encoder_reversed(w))
            if abs(h.ratio - 1) > CPR_TOLERANCE:
                cpr_off[w] = h.ratio
    taken = {c for c, _, _ in enc.values()}
    for w in SIDES:
        if w not in enc:   # not turned by hand: assume its own counter unless another wheel took it
            c = w if w not in taken else (_other(w) if _other(w) not in taken else None)
            enc[w] = (c, 1 if c == w else 0, False)
    if len(cpr_off) == 2 and abs(cpr_off["left"] / cpr_off["right"] - 1) <= DECODING_MATCH:
        faults.append(_cpr_verdict(["left", "right"], (cpr_off["left"] + cpr_off["right"]) / 2, expect, True))
    else:
        faults += [_cpr_verdict([w], r, expect, True) for w, r in cpr_off.items()]

    # 2. The motors, from the powered runs.
    one_channel = [ch for ch, r in resp.items() if r.counter == "both"]
    faults += [_both_on_one(ch) for ch in one_channel]
    if len(resp) == 2 and all(r.counter is None for r in resp.values()):
        if not (hand and all(enc[w][0] is None for w in SIDES)):
            ok_by_hand = all(w in hand and enc[w][0] in SIDES for w in SIDES)
            faults.append(_no_motion(ok_by_hand))
        return _finish(faults, resp)
    motor_crossed: list[str] = []
    motor_crossed_known = False
    speed: dict[str, float] = {}
    drives = {ch: w for ch, r in resp.items() for w in SIDES if r.counter in SIDES and enc[w][0] == r.counter}
    for ch, r in resp.items():
        if r.counter == "both" or (r.counter is None and one_channel):
            continue
        if r.only is not None:
            faults.append(_one_direction(ch, r.only))
        if r.counter is None:
            # the other channel drives this channel's wheel: this one presumably drives the other wheel
            wheel = _other(ch) if drives.get(_other(ch)) == ch else ch
            counter, _, known = enc[wheel]
            if known and counter is None:
                continue                        # encoder_silent already says it
            faults.append(_motor_silent(ch) if known else _no_counts(ch))
            continue
        if ch not in drives:
            faults.append(_inconsistent(ch))
            continue
        w = drives[ch]
        if w != ch:
            motor_crossed.append(ch)
            motor_crossed_known |= enc[w][2] or enc[ch][2]
            continue
        if enc[w][1] == 0 or enc[w][0] != w:
            continue                            # encoder crossed: the sign says nothing until it is fixed
        if r.sign == 0:
            faults.append(_encoder_erratic(ch))
            continue
        if r.sign * enc[w][1] < 0:
            faults.append(_motor_reversed(ch) if enc[w][2] else _direction_reversed(ch))
        cpr = expect.counts_per_rev * (hand[w].ratio if w in hand and enc[w][2] else 1.0)
        speed[ch] = r.ratio * expect.counts_per_rev / cpr
    if crossed_wheels and motor_crossed:
        faults.append(_all_swapped())
    else:
        if crossed_wheels:
            faults.append(_encoders_swapped(crossed_wheels))
        if motor_crossed:
            faults.append(_motors_swapped(motor_crossed) if motor_crossed_known else _left_right_swapped(motor_crossed))
    off = {s: v for s, v in speed.items() if not SLOW_RATIO <= v <= FAST_RATIO}
    if (len(off) == 2 and not hand and abs(off["left"] / off["right"] - 1) <= DECODING_MATCH
            and _decoding_hint((off["left"] + off["right"]) / 2, expect)):
        faults.append(_cpr_verdict(["left", "right"], (off["left"] + off["right"]) / 2, expect, False))
    else:
        faults += [_speed_verdict(s, v) for s, v in off.items()]
    return _finish(faults, resp, speed)


def _finish(faults: list[Verdict], resp: dict[str, _Response],
            speed: dict[str, float] | None = None) -> list[Verdict]:
    if faults:
        return faults
    tested = " and ".join(f"{s} ({speed[s]:.2f} of the expected counts)" if speed and s in speed else s
                          for s in resp)
    return [Verdict(True, "ok",
                    f"motors and encoders: {tested} turn forward when commanded forward, each on its own counter")]


# ---- the board answers ---------------------------------------------------------------------

# firmware/core/config.h kProtocolVersion and kFirmwareVersion (the `v` hello line, PROTOCOL.md).
PROTOCOL_VERSION = 1
FIRMWARE_PREFIX = "chefbot_fw-"
# config.h status_rate_hz: `t e u s i b` lines at 30 Hz; +-10 % for the PC's clock and the window.
STATUS_RATE_HZ = 30.0
RATE_TOLERANCE = 0.10
# param/launchpad.yaml: battery_empty_voltage 11.0 V (12 V SLA), battery_full_voltage 12.7 V, battery_low
# 0.2 of the span (11.34 V). Above 14.8 V not even a charging SLA (14.4-14.7 V): the divider (47k/10k,
# config.h battery_r_top_ohm/battery_r_bottom_ohm) or another pack. Below 6 V: the divider reads no battery.
BATTERY_EMPTY_V = 11.0
BATTERY_FULL_V = 12.7
BATTERY_LOW_FRACTION = 0.2
BATTERY_MAX_V = 14.8
BATTERY_ABSENT_V = 6.0
# The HC-SR04 answers every ultrasonic_period_ms = 60 ms; the `u` line repeats the last reading each cycle.
# With a hand 10-100 cm in front, more than half of the readings being 0 ("no echo") is a fault.
SONAR_MAX_NO_ECHO = 0.5


@dataclass(frozen=True)
class BoardReport:
    """What the "board answers" step saw over a few seconds."""

    hello: tuple[str, ...] | None   # fields of the `v` line, None if none was seen
    status_rate_hz: float           # `e` lines per second
    battery_volts: float | None     # latest `b` value, None if no `b` line
    imu_rate_hz: float              # `i` lines per second
    sonar_rate_hz: float            # `u` lines per second
    sonar_no_echo_fraction: float | None = None   # share of `u` readings that were 0 (hand held in front)


def board_verdicts(rep: BoardReport, expect: Expectations | None = None) -> list[Verdict]:
    """One verdict per item: hello/version, line rate, battery, IMU, sonar."""
    expect = expect or Expectations()
    out: list[Verdict] = []
    lo, hi = STATUS_RATE_HZ * (1 - RATE_TOLERANCE), STATUS_RATE_HZ * (1 + RATE_TOLERANCE)

    if rep.hello is None:
        out.append(Verdict(False, "no_hello", "no `v` hello line from the board",
                           "our firmware sends it after every reset: press RESET (or send `r`) during the check; the "
                           "book's sketch sends none, flash firmware/ (firmware/README.md, Flashing)"))
    else:
        f = rep.hello
        proto = f[0] if f else ""
        fw = f[1] if len(f) > 1 else "?"
        if proto != str(PROTOCOL_VERSION) or not fw.startswith(FIRMWARE_PREFIX):
            out.append(Verdict(False, "protocol_mismatch",
                               f"board announces protocol {proto or '?'} and firmware {fw}, this PC expects protocol "
                               f"{PROTOCOL_VERSION} ({FIRMWARE_PREFIX}*)",
                               "flash the firmware of this checkout (make -C firmware sketch, firmware/README.md)"))
        elif len(f) > 4 and expect.decoding is not None and f[4] != str(expect.decoding):
            out.append(Verdict(False, "decoding_mismatch",
                               f"board decodes the encoders {f[4]}X, ticks_meter {expect.ticks_meter:.0f} assumes "
                               f"{expect.decoding}X",
                               f"set `encoder_mode` in {CONFIG_H} to X{expect.decoding} and flash again, or set "
                               f"ticks_meter in chefbot_bringup/param/diff_drive.yaml for {f[4]}X "
                               f"({expect.ticks_meter * int(f[4]) / expect.decoding:.0f})"
                               if f[4] in ("1", "2", "4") else "flash the firmware of this checkout"))
        else:
            out.append(Verdict(True, "hello", f"board: protocol {proto}, {fw}"))

    r = rep.status_rate_hz
    if r <= 0:
        out.append(Verdict(False, "no_status", "no `e` status lines",
                           "is launchpad_node connected (diagnostics `chefbot: launchpad`)? baud 115200 on both sides"))
    elif not lo <= r <= hi:
        out.append(Verdict(False, "status_rate", f"status lines at {r:.1f} Hz, expected {STATUS_RATE_HZ:.0f} Hz",
                           "lines are being lost: look at tx_dropped_lines and schedule_overruns in the `d` line and "
                           "at the USB cable; no other program may hold the port" if r < lo else
                           f"status_rate_hz in {CONFIG_H} differs from {STATUS_RATE_HZ:.0f}: flash this checkout"))
    else:
        out.append(Verdict(True, "status_rate", f"status lines at {r:.1f} Hz"))

    v = rep.battery_volts
    low_v = BATTERY_EMPTY_V + BATTERY_LOW_FRACTION * (BATTERY_FULL_V - BATTERY_EMPTY_V)
    if v is None:
        out.append(Verdict(False, "no_battery", "no `b` battery line",
                           "the firmware sends it only with the divider connected: Vbat - 47 kOhm - PE_3 (A0) - "
                           "10 kOhm - GND, 100 nF at PE_3"))
    elif v < BATTERY_ABSENT_V:
        out.append(Verdict(False, "battery_absent", f"battery reads {v:.2f} V",
                           "the divider sees no battery: check its top end at Vbat (after the fuse/switch) and PE_3"))
    elif v < low_v:
        out.append(Verdict(False, "battery_low", f"battery {v:.2f} V, below the low mark {low_v:.2f} V",
                           f"charge it before driving (battery_empty_voltage {BATTERY_EMPTY_V} V, "
                           "chefbot_bringup/param/launchpad.yaml)"))
    elif v > BATTERY_MAX_V:
        out.append(Verdict(False, "battery_high", f"battery reads {v:.2f} V, more than a 12 V SLA gives",
                           "check the divider (47k/10k: battery_r_top_ohm/battery_r_bottom_ohm in "
                           f"{CONFIG_H}); for another pack set battery_empty_voltage/battery_full_voltage "
                           "in chefbot_bringup/param/launchpad.yaml"))
    else:
        out.append(Verdict(True, "battery", f"battery {v:.2f} V"))

    if rep.imu_rate_hz <= 0:
        out.append(Verdict(False, "no_imu", "no `i` IMU lines",
                           "MPU6050 on I2C 3: SCL PD_0 (23), SDA PD_1 (24), 3.3 V; leave PB_6/PB_7 unused (R9/R10); "
                           "imu_ok in the `d` line"))
    elif rep.imu_rate_hz < lo:
        out.append(Verdict(False, "imu_rate", f"IMU lines at {rep.imu_rate_hz:.1f} Hz, expected "
                           f"{STATUS_RATE_HZ:.0f} Hz", "the MPU6050 drops out: check its I2C wires and supply"))
    else:
        out.append(Verdict(True, "imu", f"IMU lines at {rep.imu_rate_hz:.1f} Hz"))

    if rep.sonar_rate_hz <= 0:
        out.append(Verdict(False, "no_sonar", "no `u` sonar lines",
                           "the firmware was built without the HC-SR04: check its echo PA_6 (9) and trigger PA_7 (10)"))
    elif rep.sonar_no_echo_fraction is not None and rep.sonar_no_echo_fraction > SONAR_MAX_NO_ECHO:
        out.append(Verdict(False, "sonar_no_echo",
                           f"sonar: no echo in {rep.sonar_no_echo_fraction:.0%} of the readings with a hand in front",
                           "HC-SR04: 5 V, trigger PA_7 (Energia 10), echo PA_6 (Energia 9) through a divider or "
                           "level shifter (the echo is 5 V)"))
    else:
        out.append(Verdict(True, "sonar", f"sonar lines at {rep.sonar_rate_hz:.1f} Hz"))
    return out


# ---- the PID step response -------------------------------------------------------------------

RISE_TIME_MAX = 0.5        # s, 10-90 %; the motor alone (tau 0.08 s) rises in ~0.18 s
OVERSHOOT_MAX = 20.0       # % of the step
STEADY_STATE_MAX = 0.05    # mean |error| over the last part, as a fraction of the step
STEADY_WINDOW = 0.2        # the last 20 % of the record is "steady state"
OSCILLATION_BAND = 0.02    # error sign changes count only beyond +-2 % of the step (noise)
OSCILLATION_MAX = 3        # more sign changes after the first crossing than this: oscillating
PID_PARAMS = "lwheel_pid/rwheel_pid in chefbot_bringup/param/diff_drive.yaml (one anchor: both wheels)"


@dataclass(frozen=True)
class StepResult:
    """Metrics of a step response and the verdicts drawn from them."""

    rise_time: float | None        # s from 10 % to 90 % of the step; None if 90 % was never reached
    overshoot_pct: float           # % of the step beyond the target (0 if none)
    steady_state_error: float      # target - mean(measured) over the last STEADY_WINDOW, in the signal's units
    oscillations: int              # error sign changes (beyond the band) after the first crossing
    verdicts: tuple[Verdict, ...]


def _crossing_time(t: np.ndarray, y: np.ndarray, level: float) -> float | None:
    idx = np.nonzero(y >= level)[0]
    if idx.size == 0:
        return None
    i = int(idx[0])
    if i == 0:
        return float(t[0])
    y0, y1 = y[i - 1], y[i]
    return float(t[i - 1] + (level - y0) / (y1 - y0) * (t[i] - t[i - 1]))


def step_response_verdict(t: Sequence[float], target: float, measured: Sequence[float],
                          start: float = 0.0) -> StepResult:
    """Judge a step from ``start`` to ``target`` applied at ``t[0]`` (e.g. wheel speed in m/s)."""
    ta = np.asarray(t, dtype=float)
    ya = np.asarray(measured, dtype=float)
    if ta.ndim != 1 or ta.shape != ya.shape or ta.size < 5:
        raise ValueError("t and measured must be 1-D, of equal length, at least 5 samples")
    if not (np.all(np.isfinite(ta)) and np.all(np.isfinite(ya)) and np.all(np.diff(ta) > 0)):
        raise ValueError("t must increase and all values be finite")
    span = target - start
    if not math.isfinite(span) or span == 0:
        raise ValueError("target must differ from start")
    y = (ya - start) / span                   # 0 -> 1 whatever the step's sign
    t10, t90 = _crossing_time(ta, y, 0.1), _crossing_time(ta, y, 0.9)
    rise = None if t10 is None or t90 is None else t90 - t10
    overshoot = max(0.0, float(y.max()) - 1.0) * 100.0
    n_tail = max(1, int(round(STEADY_WINDOW * ta.size)))
    sse = float(target - ya[-n_tail:].mean())
    # oscillation: sign changes of the error after the first crossing of the target, with a dead band
    osc = 0
    first = np.nonzero(y >= 1.0)[0]
    if first.size:
        last = 0
        for e in 1.0 - y[int(first[0]):]:
            s = 1 if e > OSCILLATION_BAND else (-1 if e < -OSCILLATION_BAND else 0)
            if s and last and s != last:
                osc += 1
            if s:
                last = s
    v: list[Verdict] = []
    if osc > OSCILLATION_MAX:
        v.append(Verdict(False, "pid_oscillates", f"the wheel speed oscillates ({osc} swings around the target)",
                         f"lower Kp (and Kd if set) in {PID_PARAMS}"))
    if overshoot > OVERSHOOT_MAX:
        v.append(Verdict(False, "pid_overshoot", f"overshoot {overshoot:.0f} % (limit {OVERSHOOT_MAX:.0f} %)",
                         f"lower Kp, then Ki, in {PID_PARAMS}"))
    if rise is None:
        v.append(Verdict(False, "pid_no_rise", "the wheel never reached 90 % of the target",
                         "the motor cannot deliver it (target above max_wheel_speed, low battery, stall) or the "
                         f"loop is too weak: raise Kp/Ki in {PID_PARAMS}, keep feed_forward true"))
    elif rise > RISE_TIME_MAX:
        v.append(Verdict(False, "pid_slow", f"rise time {rise:.2f} s (limit {RISE_TIME_MAX} s)",
                         f"raise Kp in {PID_PARAMS}; check feed_forward true and max_wheel_speed"))
    if abs(sse) > STEADY_STATE_MAX * abs(span) and osc <= OSCILLATION_MAX:
        v.append(Verdict(False, "pid_steady_error",
                         f"steady-state error {sse:+.3f} ({abs(sse / span):.0%} of the step)",
                         f"raise Ki in {PID_PARAMS}; if feed_forward overshoots the target, check max_wheel_speed "
                         "and static_friction"))
    if not v:
        v.append(Verdict(True, "pid_ok", f"step response: rise {rise:.2f} s, overshoot {overshoot:.0f} %, "
                         f"steady-state error {sse:+.3f}"))
    return StepResult(rise, overshoot, sse, osc, tuple(v))
