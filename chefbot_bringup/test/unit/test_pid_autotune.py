"""Wheel PID autotune: FOPDT fit, SIMC gains, the proposal in closed loop with the real controller."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_bringup.bringup_check import OVERSHOOT_MAX, RISE_TIME_MAX, step_response_verdict
from chefbot_bringup.pid_autotune import (
    Fopdt,
    Gains,
    compare_steps,
    fit_fopdt,
    predict_step,
    propose_gains,
    simc_pi,
    step_score,
)
from chefbot_bringup.wheel_pid import PidConfig, WheelController, WheelVelocityEstimator

RATE = 30.0                  # Hz: the board's encoder lines and the PID loop
TPM = 29708.0                # ticks_meter (param/diff_drive.yaml, 4X decoding)
OUT_MAX = 1023.0
FREE_SPEED = 0.377           # m/s at full duty (virtual_board.MotorModel: 80 RPM x 0.045 m)
MOTOR_TAU = 0.08             # s (virtual_board.MotorModel)
K_NOMINAL = FREE_SPEED / OUT_MAX
TODAY = Gains(kp=400.0, ki=100.0)
CFG = PidConfig(ticks_meter=TPM, static_friction=0.036)   # diff_drive.yaml's lwheel_pid without the gains


# ---- a motor like virtual_board.MotorModel, read through the loop's estimator ----------------------

class Motor:
    """First-order wheel: speed follows duty x free speed x ``strength`` with MOTOR_TAU (exact steps)."""

    def __init__(self, strength: float = 1.0) -> None:
        self.strength = strength
        self.v = 0.0       # m/s
        self.x = 0.0       # m

    def run(self, cmd: float, seconds: float, substeps: int = 10) -> None:
        dt = seconds / substeps
        a = -math.expm1(-dt / MOTOR_TAU)
        for _ in range(substeps):
            old = self.v
            self.v += (max(-1.0, min(1.0, cmd / OUT_MAX)) * FREE_SPEED * self.strength - self.v) * a
            self.x += 0.5 * (old + self.v) * dt

    @property
    def counts(self) -> int:
        return round(self.x * TPM)


PRE_ROLL = 15   # encoder lines at rest before the step: the estimator's window is full, as on the robot


def open_loop_record(command: float, seconds: float = 1.5, strength: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop step from rest at t = 0: the speed the loop's estimator reports on each encoder line."""
    motor, est = Motor(strength), WheelVelocityEstimator(CFG)
    for k in range(-PRE_ROLL, 0):
        est.add_reading(0, k / RATE)
    t = np.arange(round(seconds * RATE) + 1) / RATE
    v = np.zeros_like(t)
    for k, tk in enumerate(t):
        est.add_reading(motor.counts, tk)
        v[k] = est.velocity(tk)
        motor.run(command, 1.0 / RATE)
    return t, v


def closed_loop(gains: Gains, target: float = 0.2, seconds: float = 2.0,
                strength: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Our WheelController (feed-forward with static friction) driving the motor from rest to ``target``."""
    motor = Motor(strength)
    ctl = WheelController(PidConfig(ticks_meter=TPM, static_friction=0.036, kp=gains.kp, ki=gains.ki, kd=gains.kd))
    for k in range(-PRE_ROLL, 0):
        ctl.add_reading(0, k / RATE)
    t = np.arange(round(seconds * RATE) + 1) / RATE
    v = np.zeros_like(t)
    for k, tk in enumerate(t):
        ctl.add_reading(motor.counts, tk)
        ctl.set_target(target)
        out = ctl.tick(tk)
        v[k] = out.wheel_vel
        motor.run(out.motor_cmd or 0.0, 1.0 / RATE)
    return t, v


# ---- fit_fopdt ------------------------------------------------------------------------------------

def fopdt_counts_record(gain: float, tau: float, dead: float, command: float, seconds: float,
                        count_noise: float, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """An exact FOPDT wheel read as integer counts at 30 Hz (+ Gaussian count jitter), speed per interval."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds * RATE) + 1) / RATE
    s = np.clip(t - dead, 0.0, None)
    x = gain * command * (s - tau * -np.expm1(-s / tau))            # position (m): integral of the speed
    counts = np.round(x * TPM + rng.normal(0.0, count_noise, t.size))
    counts[0] = 0.0
    v = np.concatenate([[0.0], np.diff(counts) / TPM * RATE])       # each interval's mean speed, at its end
    return t, v


def test_fit_recovers_a_quantised_noisy_fopdt():
    tau, dead = 0.08, 0.05
    t, v = fopdt_counts_record(K_NOMINAL, tau, dead, 500.0, 2.0, count_noise=3.0)
    m = fit_fopdt(t, v, 500.0)
    assert m.gain == pytest.approx(K_NOMINAL, rel=0.02)           # the feed-forward slope: 2 %
    assert m.tau == pytest.approx(tau, rel=0.15)
    # the per-interval speed is the mean over the last 1/30 s: on average half an interval (17 ms) late
    assert m.dead_time == pytest.approx(dead + 0.5 / RATE, abs=0.01)
    step = K_NOMINAL * 500.0
    assert m.rmse < 0.05 * step                                    # the noise (~0.004 m/s), not a misfit
    assert np.max(np.abs(m.response(t, 500.0) - v)) < 0.1 * step


def test_fit_of_a_reverse_step_from_a_running_wheel():
    t, v = fopdt_counts_record(K_NOMINAL, 0.08, 0.05, -300.0, 2.0, count_noise=0.0)
    m = fit_fopdt(t, v + 0.1, command=100.0, start_command=400.0)   # 400 -> 100: the same -300 step
    assert m.gain == pytest.approx(K_NOMINAL, rel=0.02)
    assert m.tau == pytest.approx(0.08, rel=0.15)


def test_fit_through_the_loop_estimator_puts_its_lag_into_the_dead_time():
    t, v = open_loop_record(512.0)
    m = fit_fopdt(t, v, 512.0)
    assert m.gain == pytest.approx(K_NOMINAL, rel=0.02)
    # the 5-interval window (0.167 s) lags about half its length: dead time plus extra time constant
    assert 0.05 < m.dead_time < 0.11
    assert MOTOR_TAU < m.tau < MOTOR_TAU + 0.05


T_OK, V_OK = fopdt_counts_record(K_NOMINAL, 0.08, 0.05, 500.0, 1.0, count_noise=0.0)


@pytest.mark.parametrize("t, v, command, start, match", [
    (T_OK[:9], V_OK[:9], 500.0, 0.0, "too few samples"),
    (T_OK, np.where(np.arange(T_OK.size) == 7, np.nan, V_OK), 500.0, 0.0, "finite"),
    (np.where(np.arange(T_OK.size) == 7, T_OK[6], T_OK), V_OK, 500.0, 0.0, "strictly increasing"),
    (T_OK, V_OK[:-1], 500.0, 0.0, "equal length"),
    (T_OK, V_OK, 300.0, 300.0, "differ from start_command"),
    (T_OK, np.zeros_like(V_OK), 500.0, 0.0, "no response"),
    (T_OK, -V_OK, 500.0, 0.0, "wrong sign.*wiring"),
    (*fopdt_counts_record(K_NOMINAL, 0.25, 0.05, 500.0, 0.6, 0.0), 500.0, 0.0, "too short"),  # needs 0.82 s
])
def test_fit_rejects_bad_records(t, v, command, start, match):
    with pytest.raises(ValueError, match=match):
        fit_fopdt(t, v, command, start)


def test_fit_rejects_noise_without_a_step():
    rng = np.random.default_rng(3)
    with pytest.raises(ValueError, match="no response"):
        fit_fopdt(T_OK, rng.normal(0.0, 0.01, T_OK.size), 500.0)


def test_fit_rejects_a_ramp_that_never_settles():
    with pytest.raises(ValueError, match="too short"):
        fit_fopdt(T_OK, 0.1 * T_OK, 500.0)


# ---- simc_pi ---------------------------------------------------------------------------------------

def test_simc_textbook_numbers():
    # K 2, tau 10, theta 0.9 + half of a 0.2 s period = 1; tau_c = theta = 1 (floor 1.5 x 0.2 = 0.3 below):
    # Kc = 10 / (2 (1 + 1)) = 2.5, Ti = min(10, 4 x 2) = 8, ki = Kc / Ti = 0.3125.
    g = simc_pi(Fopdt(gain=2.0, tau=10.0, dead_time=0.9, rmse=0.0), rate=5.0)
    assert g.kp == pytest.approx(2.5, rel=1e-9)
    assert g.ki == pytest.approx(0.3125, rel=1e-9)
    assert g.kd == 0.0
    # a fast process: Ti = tau = 2 (< 8): Kc = 2 / 4 = 0.5, ki = 0.25; tau_c given: 3 -> Kc = 2 / (2 x 4)
    assert simc_pi(Fopdt(2.0, 2.0, 0.9, 0.0), 5.0).ki == pytest.approx(0.25, rel=1e-9)
    assert simc_pi(Fopdt(2.0, 2.0, 0.9, 0.0), 5.0, tau_c=3.0).kp == pytest.approx(0.25, rel=1e-9)


def test_simc_discrete_floor_and_params():
    # no dead time at 30 Hz: theta = 1/60 s, tau_c floored at 1.5/30 = 0.05 s (not 1/60)
    g = simc_pi(Fopdt(gain=K_NOMINAL, tau=0.08, dead_time=0.0, rmse=0.0), rate=RATE)
    kc = 0.08 / (K_NOMINAL * (0.05 + 1 / 60))
    assert g.kp == pytest.approx(kc, rel=1e-9)
    assert g.ki == pytest.approx(kc / 0.08, rel=1e-9)
    assert g.to_params() == {"Kp": g.kp, "Ki": g.ki, "Kd": 0.0}


@pytest.mark.parametrize("model, rate, tau_c", [
    (Fopdt(0.0, 0.1, 0.05, 0.0), 30.0, None),
    (Fopdt(1e-3, 0.0, 0.05, 0.0), 30.0, None),
    (Fopdt(1e-3, 0.1, -0.01, 0.0), 30.0, None),
    (Fopdt(1e-3, 0.1, 0.05, 0.0), 0.0, None),
    (Fopdt(1e-3, 0.1, 0.05, 0.0), 30.0, -1.0),
])
def test_simc_rejects_bad_input(model, rate, tau_c):
    with pytest.raises(ValueError):
        simc_pi(model, rate, tau_c)


# ---- the proposal in closed loop with the real controller ------------------------------------------

def verdict_codes(t: np.ndarray, v: np.ndarray) -> set[str]:
    return {x.code for x in step_response_verdict(t, 0.2, v).verdicts}


def test_plain_simc_overshoots_with_our_feed_forward_and_the_prediction_sees_it():
    m = fit_fopdt(*open_loop_record(512.0), 512.0)
    plain = simc_pi(m, RATE)
    t, v = closed_loop(plain)
    real = step_response_verdict(t, 0.2, v)
    t, y = predict_step(m, plain, CFG, 0.2)
    predicted = step_score(t, 0.2, y)
    assert real.overshoot_pct > 2 * OVERSHOOT_MAX          # ~50 %: the feed-forward and the integral add up
    assert predicted.overshoot_pct > 2 * OVERSHOOT_MAX


@pytest.mark.parametrize("strength", [1.0, 0.8])   # 0.8: heavier robot / weak battery, the feed-forward falls short
def test_proposed_gains_pass_the_bringup_step(strength):
    m = fit_fopdt(*open_loop_record(512.0, strength=strength), 512.0)
    assert m.gain == pytest.approx(K_NOMINAL * strength, rel=0.02)
    g = propose_gains(m, CFG)
    t, v = closed_loop(g, strength=strength)
    r = step_response_verdict(t, 0.2, v)
    assert r.rise_time is not None and r.rise_time < RISE_TIME_MAX
    assert r.overshoot_pct < OVERSHOOT_MAX
    assert not verdict_codes(t, v) & {"pid_slow", "pid_no_rise", "pid_overshoot", "pid_oscillates"}


def test_weak_motor_today_fails_and_the_proposal_is_better():
    m = fit_fopdt(*open_loop_record(512.0, strength=0.8), 512.0)
    g = propose_gains(m, CFG)
    t, today = closed_loop(TODAY, strength=0.8)
    _, proposed = closed_loop(g, strength=0.8)
    assert {"pid_no_rise", "pid_steady_error"} <= verdict_codes(t, today)   # Ki 100: 15 % short after 2 s
    assert verdict_codes(t, proposed) == {"pid_ok"}
    assert compare_steps(t, 0.2, today, proposed).better


# ---- step_score / compare_steps ------------------------------------------------------------------

def test_step_score_of_a_first_order_step_is_its_time_constant():
    t = np.arange(0.0, 3.0, 1e-3)
    s = step_score(t, -0.2, -0.2 * -np.expm1(-t / 0.1))          # any sign: normalised by the step
    assert s.iae == pytest.approx(0.1, rel=0.01)                  # integral of exp(-t/tau) = tau
    assert s.overshoot_pct == pytest.approx(0.0, abs=1e-9)


def test_compare_steps():
    t = np.arange(0.0, 2.0, 1 / RATE)
    slow, fast = 1 - np.exp(-t / 0.3), 1 - np.exp(-t / 0.1)
    ringing = 1 - np.exp(-5 * t) * np.cos(20 * t)                 # faster but ~50 % overshoot
    assert compare_steps(t, 1.0, slow, fast).better
    assert not compare_steps(t, 1.0, fast, slow).better
    c = compare_steps(t, 1.0, slow, ringing)
    assert c.proposed.overshoot_pct > OVERSHOOT_MAX and not c.better
    with pytest.raises(ValueError):
        step_score(t, 0.0, slow)
