"""DiffOdometry: exact arc, signs, wrap, resets, covariance, per-wheel ticks_meter."""
import hashlib
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from chefbot_bringup.encoder import INT16_RANGE, EncoderRange
from chefbot_bringup.odometry import DiffOdometry, OdometryConfig, integrate_arc

TPM = 14854.0
B = 0.30


def make(**kw) -> DiffOdometry:
    return DiffOdometry(OdometryConfig(ticks_meter=TPM, base_width=B, **kw))


def drive(odo: DiffOdometry, vl: float, vr: float, seconds: float, rate: float = 10.0,
          t0: float = 0.0, start=(0, 0)) -> tuple[float, int, int]:
    """Feed ticks of constant wheel speeds (m/s); returns end time and tick counts."""
    steps = round(seconds * rate)
    for k in range(1, steps + 1):
        t = t0 + k / rate
        left = start[0] + round(vl * (t - t0) * TPM)
        right = start[1] + round(vr * (t - t0) * TPM)
        odo.set_ticks(left, right)
        odo.update(t)
    return t0 + steps / rate, left, right


def started() -> DiffOdometry:
    odo = make()
    odo.set_ticks(0, 0)
    assert odo.update(0.0) is not None
    return odo


def test_none_until_both_wheels_reported():
    odo = make()
    odo.set_ticks(left=5)
    assert odo.update(0.0) is None


def test_straight_line():
    odo = started()
    drive(odo, 0.2, 0.2, 2.0)
    assert odo.x == pytest.approx(0.4, abs=1e-4)
    assert odo.y == pytest.approx(0.0, abs=1e-9)
    assert odo.theta == pytest.approx(0.0, abs=1e-9)
    assert odo.v == pytest.approx(0.2, abs=1e-3)


def test_rotation_in_place_is_ccw_when_right_wheel_forward():
    odo = started()
    drive(odo, -0.1, 0.1, 1.0)
    # dtheta = (dr - dl) / b = 0.2 / 0.3 rad
    assert odo.theta == pytest.approx(0.2 / B, abs=1e-3)
    assert odo.w > 0
    assert math.hypot(odo.x, odo.y) < 1e-4


def test_left_turn_arc_ends_on_the_circle():
    # vl = 0.1, vr = 0.2: turning left about an ICC at +y.
    odo = started()
    drive(odo, 0.1, 0.2, 3.0, rate=10.0)
    w = 0.1 / B
    radius = 0.15 / w
    th = w * 3.0
    assert odo.theta == pytest.approx(th, abs=1e-3)
    assert odo.x == pytest.approx(radius * math.sin(th), abs=1e-3)
    assert odo.y == pytest.approx(radius * (1 - math.cos(th)), abs=1e-3)
    assert odo.y > 0


def test_arc_is_exact_for_any_step_length():
    one = integrate_arc(0, 0, 0.3, 0.1, 0.3, B)
    x, y, th = 0.0, 0.0, 0.3
    for _ in range(1000):
        x, y, th = integrate_arc(x, y, th, 0.1e-3, 0.3e-3, B)
    assert one == pytest.approx((x, y, th), abs=1e-9)


def test_int16_wrap_is_continuous():
    odo = DiffOdometry(OdometryConfig(ticks_meter=TPM, base_width=B,
                                      encoder=EncoderRange(*INT16_RANGE)))
    start = 32000
    odo.set_ticks(start, start)
    odo.update(0.0)
    t = 0.0
    pos = start
    for _ in range(30):  # 0.2 m/s for 3 s = 8912 ticks: wraps once
        t += 0.1
        pos += int(0.02 * TPM)
        raw = (pos + 32768) % 65536 - 32768
        odo.set_ticks(raw, raw)
        odo.update(t)
    assert odo.x == pytest.approx(30 * int(0.02 * TPM) / TPM, abs=1e-6)
    assert odo.resets == 0


def test_lines_on_one_clock_reading_lose_no_travel():
    """A sim clock coarser than the encoder lines (uncapped sim): 30 Hz lines on a 10 Hz clock, so
    three lines share each time; every line's ticks must still count (they were dropped: 32 %)."""
    odo = started()
    for k in range(1, 61):   # 2 s of lines at 30 Hz
        ticks = round(0.2 * k / 30.0 * TPM)
        odo.set_ticks(ticks, ticks)
        odo.update(math.ceil(k / 3) / 10.0)
    assert odo.resets == 0
    assert odo.x == pytest.approx(0.4, abs=1e-4)
    assert odo.v == pytest.approx(0.2, abs=0.01)


def test_time_going_back_rebaselines():
    odo = started()
    t, left, right = drive(odo, 0.2, 0.2, 1.0, t0=5.0)
    x = odo.x
    odo.set_ticks(left + 1000, right + 1000)
    odo.update(0.5)            # sim time reset: the ticks since are not integrated over a negative dt
    assert odo.x == pytest.approx(x)
    drive(odo, 0.2, 0.2, 1.0, t0=0.5, start=(left + 1000, right + 1000))
    assert odo.x == pytest.approx(x + 0.2, abs=1e-3)


def test_counter_reset_does_not_teleport():
    odo = started()
    t, _left, _right = drive(odo, 0.3, 0.3, 5.0)
    x_before = odo.x
    odo.set_ticks(0, 0)   # board reset
    odo.update(t + 0.1)
    assert odo.resets == 1
    assert odo.x == pytest.approx(x_before)
    drive(odo, 0.3, 0.3, 1.0, t0=t + 0.1)
    assert odo.x == pytest.approx(x_before + 0.3, abs=1e-3)


def test_imu_yaw_replaces_encoder_heading():
    odo = started()
    odo.set_imu_yaw(1.0)
    odo.update(0.05)
    odo.set_ticks(0, 0)
    odo.set_imu_yaw(1.5)   # IMU says +0.5 rad, wheels say nothing
    odo.update(0.1)
    assert odo.theta == pytest.approx(0.5)


def test_a_silent_imu_hands_the_heading_back_to_the_wheels():
    odo = started()
    odo.set_imu_yaw(1.0, t=0.05)
    odo.update(0.05)
    odo.set_imu_yaw(1.2, t=0.1)
    odo.update(0.1)
    assert odo.imu_used and odo.theta == pytest.approx(0.2)
    # the IMU falls silent at 0.1 s while the wheels turn the robot in place at 0.5 rad/s for 1 s:
    # the wheels bridge the gap, first while waiting for the next sample, then (after imu_timeout)
    # as the heading source: no turning is lost
    w = odo.cfg.base_width / 2 * 0.5
    _, left, right = drive(odo, -w, w, 1.0, t0=0.1)
    assert not odo.imu_used
    assert odo.theta == pytest.approx(0.2 + 0.5, abs=0.01)
    # it comes back with a yaw that says nothing of the time it was away: no jump
    odo.set_imu_yaw(3.0, t=1.2)
    odo.set_ticks(left, right)
    odo.update(1.2)
    assert odo.theta == pytest.approx(0.7, abs=0.01)
    odo.set_imu_yaw(3.1, t=1.3)
    odo.update(1.3)
    assert odo.imu_used and odo.theta == pytest.approx(0.8, abs=0.01)


def test_a_late_imu_sample_corrects_the_wheels_that_bridged_it():
    odo = started()
    odo.set_imu_yaw(0.0, t=0.0)
    odo.update(0.0)
    # the wheels say 0.05 rad per 0.1 s, but slip: the IMU (truth) says 0.04
    w = odo.cfg.base_width / 2 * 0.5
    t, left, right = drive(odo, -w, w, 0.2)          # two steps, no IMU sample yet
    assert odo.theta == pytest.approx(0.1, abs=1e-3)
    odo.set_imu_yaw(0.08, t=t)                       # the late sample: 0.08 rad since the anchor
    odo.set_ticks(left, right)
    odo.update(t + 0.1)
    assert odo.imu_used and odo.theta == pytest.approx(0.08, abs=1e-6)


def test_covariance_grows_with_distance_not_time():
    odo = started()
    p0 = odo.state(0.0).pose_cov.copy()
    odo.set_ticks(0, 0)
    for k in range(1, 20):
        odo.update(k * 0.1)
    assert np.allclose(odo.state(2.0).pose_cov, p0)
    drive(odo, 0.2, 0.25, 5.0, t0=2.0)
    cov = odo.state(7.0).pose_cov
    assert cov[0, 0] > p0[0, 0] and cov[5, 5] > p0[5, 5]
    assert np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_bad_config_names_field():
    with pytest.raises(ValueError, match="base_width"):
        OdometryConfig(base_width=0.0)


def test_silent_encoders_names_the_stale_wheels() -> None:
    from chefbot_bringup.odometry import silent_encoders
    assert silent_encoders({"lwheel": None, "rwheel": 1.0}, 10.0, 1.0) == ""        # not both reported yet
    assert silent_encoders({"lwheel": 9.5, "rwheel": 9.2}, 10.0, 1.0) == ""         # fresh
    assert silent_encoders({"lwheel": 8.8, "rwheel": 9.5}, 10.0, 1.0) == "lwheel 1.2 s ago"
    assert silent_encoders({"lwheel": 8.0, "rwheel": 8.0}, 10.0, 1.0) == "lwheel 2.0 s ago, rwheel 2.0 s ago"
    assert silent_encoders({"lwheel": 0.0, "rwheel": 0.0}, 100.0, 0.0) == ""        # 0 = check off
    assert silent_encoders({"lwheel": 12.0, "rwheel": 12.0}, 10.0, 1.0) == ""       # time jumped back: fresh


# --- time: estimates describe the encoder data's time (diff_tf's stamps) ----------------------


def test_tick_pairer_pairs_one_line_and_takes_its_arrival_time() -> None:
    from chefbot_bringup.odometry import TickPairer
    p = TickPairer()
    assert p.add(1.000, left=10) is None
    assert p.add(1.001, right=20) == (10, 20, 1.000)          # the earlier arrival of the line
    assert p.add(1.034, right=21) is None                      # the other order works too
    assert p.add(1.035, left=11) == (11, 21, 1.034)
    # a lost right message: the left's newer reading is kept, the pair completes with it
    assert p.add(1.067, left=12) is None
    assert p.add(1.100, left=13) is None
    assert p.add(1.101, right=23) == (13, 23, 1.100)


def _turn_run(odo: DiffOdometry, w: float, rate: float, imu_delay: float, seconds: float,
              imu_after_line: float = 0.001):
    """Turn on the spot at ``w`` rad/s; encoder lines at ``rate`` Hz arrive on time, each followed
    ``imu_after_line`` s later by an IMU yaw that is ``imu_delay`` s old.  Yields (t, true heading)."""
    half = odo.cfg.base_width / 2
    odo.set_ticks(0, 0)
    odo.set_imu_yaw(0.0, 0.0)
    odo.update(0.0)
    for k in range(1, round(seconds * rate) + 1):
        t = k / rate
        ticks = round(w * t * half * TPM)
        odo.set_ticks(-ticks, ticks)
        odo.update(t)
        yield t, w * t
        odo.set_imu_yaw(w * (t + imu_after_line - imu_delay), t + imu_after_line)


def test_heading_describes_the_encoder_time_with_a_late_imu() -> None:
    """The estimate at time t is the heading at t: the IMU's yaw (imu_delay old when it arrives, the
    line after the encoder line) plus the wheels' turning since then -- not the IMU's yaw alone,
    which lagged one line period plus the IMU's own delay (~3 deg at 2 rad/s).  Fails when the
    wheels' turning after the sample is dropped or imu_delay is ignored."""
    delay = 0.02
    odo = make(imu_delay=delay)
    errs = [abs(odo.theta - math.remainder(truth, 2 * math.pi))
            for t, truth in _turn_run(odo, 2.0, 30.0, delay, 2.0) if t > 0.2]
    assert odo.imu_used
    assert max(errs) < math.radians(0.1)
    # the same run without placing the sample in time: the heading lags
    odo = make(imu_delay=0.0)
    errs = [abs(odo.theta - math.remainder(truth, 2 * math.pi))
            for t, truth in _turn_run(odo, 2.0, 30.0, delay, 2.0) if t > 0.2]
    assert max(errs) > math.radians(2.0)


def test_state_time_is_the_update_time_and_twist_is_smoothed() -> None:
    odo = started()
    w = odo.cfg.base_width / 2 * 1.0
    rng = np.random.default_rng(3)
    t = 0.0
    for _ in range(60):                       # 30 Hz lines with 5 ms arrival jitter
        t += 1 / 30 + rng.uniform(-0.005, 0.005)
        ticks = round(w * t * TPM)
        odo.set_ticks(-ticks, ticks)
        st = odo.update(t)
        assert st.t == t
    assert st.w == pytest.approx(1.0, abs=0.05)
    assert st.v == pytest.approx(0.0, abs=1e-3)


def test_imu_delay_is_checked() -> None:
    with pytest.raises(ValueError, match="imu_delay"):
        OdometryConfig(imu_delay=-0.01)
    with pytest.raises(ValueError, match="imu_delay"):
        OdometryConfig(imu_delay=0.3, imu_timeout=0.25)


def test_a_late_clock_loses_no_travel():
    """The ticks run ahead of this node's clock (a stalled host, a late /clock in an overloaded sim):
    30 Hz lines at 0.3 m/s; six lines arrive at once while the clock still reads the time before
    them, then it catches up.  The 6 cm step is held back and integrated whole once the clock has
    caught up, not dropped as a counter reset (39 such drops in an uncapped demo)."""
    odo = started()
    for k in range(1, 91):   # 3 s of lines
        if 30 <= k < 36:
            continue                  # queued behind the stall
        ticks = round(0.3 * k / 30.0 * TPM)
        odo.set_ticks(ticks, ticks)
        odo.update(29 / 30.0 if k in (36, 37) else k / 30.0)    # the clock stands, then jumps
    assert odo.resets == 0
    assert odo.held == 2
    assert odo.x == pytest.approx(0.9, abs=1e-4)


def test_a_jump_no_late_clock_explains_still_rebaselines():
    """Held back for at most CLOCK_LAG_S: counters that jump further than the wheels could go even
    over that lag re-baseline at once, and so does a held jump the clock never catches up with."""
    odo = started()
    t, left, right = drive(odo, 0.2, 0.2, 1.0)
    x = odo.x
    odo.set_ticks(left + round(0.8 * TPM), right + round(0.8 * TPM))   # 0.8 m in one line (a 1 s late clock: 0.59)
    odo.update(t + 0.01)
    assert odo.resets == 1 and odo.x == pytest.approx(x)


# ---------------------------------------------------------------- per-wheel ticks_meter (issue 31)
RECORDED = Path(__file__).resolve().parents[1] / "fixtures" / "odometry_ticks.json"


def replay(odo: DiffOdometry, events: list, use_imu: bool) -> tuple[str, list[str]]:
    """Feed a recording as diff_tf does (an ``e`` line: both counters then update at its arrival; an
    ``i`` sample: the IMU yaw, with ``use_imu``); sha256 of every estimate's floats (exact bits) and
    the last estimate as hex floats."""
    digest = hashlib.sha256()
    last: list[float] = []
    for ev in events:
        if ev[0] == "i":
            if use_imu:
                odo.set_imu_yaw(ev[2], ev[1])
            continue
        odo.set_ticks(ev[2], ev[3])
        st = odo.update(ev[1])
        if st is None:
            continue
        last = [st.t, st.x, st.y, st.theta, st.v, st.w, *st.pose_cov.ravel(), *st.twist_cov.ravel(),
                float(odo.resets), float(odo.held), float(odo.imu_used)]
        digest.update(struct.pack(f"<{len(last)}d", *last))
    return digest.hexdigest(), [v.hex() for v in last]


def recorded_config(rec: dict, **kw) -> OdometryConfig:
    c = rec["config"]
    return OdometryConfig(ticks_meter=c["ticks_meter"], base_width=c["base_width"],
                          encoder=EncoderRange(*c["encoder"]), wheel_slip_var=c["wheel_slip_var"],
                          twist_window=c["twist_window"], imu_delay=c["imu_delay"], **kw)


@pytest.mark.parametrize("use_imu", [False, True], ids=["wheels", "imu"])
@pytest.mark.parametrize("per_wheel", [{}, {"ticks_meter_left": None, "ticks_meter_right": None},
                                       {"ticks_meter_left": 29708.0, "ticks_meter_right": 29708.0}],
                         ids=["not_given", "unset", "equal_to_ticks_meter"])
def test_without_per_wheel_values_odometry_is_bit_identical_to_before(per_wheel, use_imu):
    """A recorded tick sequence (16 s: curves, a spin, reverse, Int16 wraps, a coarse clock, a stalled
    clock, a board reset, time going back) gives exactly (every bit of every estimate) what
    DiffOdometry gave before the per-wheel values existed (commit e245203), when they are unset
    or equal to ticks_meter."""
    rec = json.loads(RECORDED.read_text())
    odo = DiffOdometry(recorded_config(rec, **per_wheel))
    digest, last = replay(odo, rec["events"], use_imu)
    want = rec["expected"]["imu" if use_imu else "wheels"]
    assert last == want["last"]
    assert digest == want["sha256"]
    assert odo.resets == 1 and odo.held > 0   # the recording does reach the jump logic


def test_each_wheel_travels_its_own_ticks_over_its_own_ticks_meter():
    tl, tr = 30000.0, 29000.0
    odo = make(ticks_meter_left=tl, ticks_meter_right=tr)
    odo.set_ticks(0, 0)
    odo.update(0.0)
    odo.set_ticks(round(0.02 * tl), round(0.02 * tr))   # both wheels 2 cm in 0.1 s
    odo.update(0.1)
    assert odo.x == pytest.approx(0.02, abs=1e-9) and odo.theta == pytest.approx(0.0, abs=1e-9)
    assert odo.v == pytest.approx(0.2, abs=1e-9) and odo.w == pytest.approx(0.0, abs=1e-9)
    # with the shared value the same counts would read as a turn to the right
    shared = make()
    shared.set_ticks(0, 0)
    shared.update(0.0)
    shared.set_ticks(round(0.02 * tl), round(0.02 * tr))
    shared.update(0.1)
    assert shared.theta < -1e-3


def test_one_wheel_given_the_other_takes_ticks_meter():
    assert OdometryConfig(ticks_meter=TPM, ticks_meter_right=15000).wheel_ticks_meter == (TPM, 15000.0)
    assert OdometryConfig(ticks_meter=TPM, ticks_meter_left=15000).wheel_ticks_meter == (15000.0, TPM)
    assert OdometryConfig(ticks_meter=TPM).wheel_ticks_meter == (TPM, TPM)


def test_jump_limit_is_in_metres_of_each_wheel():
    """The counter-reset check judges each wheel's travel in metres: a right wheel with fewer ticks
    per metre covers more ground per tick, so the same counts can be a jump for it alone."""
    def jumps(tr: float) -> int:
        odo = make(ticks_meter_left=TPM, ticks_meter_right=tr, max_wheel_speed=0.377)
        odo.set_ticks(0, 0)
        odo.update(0.0)
        ticks = round(0.5 * TPM)   # 0.5 m in 1 s on the left: within 1.5 x 0.377 + 0.02 = 0.5855 m
        odo.set_ticks(ticks, ticks)
        odo.update(1.0)
        return odo.resets
    assert jumps(TPM) == 0
    assert jumps(TPM / 2.5) == 1   # the right wheel's 1.25 m: too far even for a late clock (1.151 m)


@pytest.mark.parametrize("bad", [0.0, -29708.0, math.inf, math.nan, "29708", True])
def test_bad_per_wheel_value_is_rejected_by_name(bad):
    for name in ("ticks_meter_left", "ticks_meter_right"):
        with pytest.raises(ValueError, match=name):
            OdometryConfig(**{name: bad})
