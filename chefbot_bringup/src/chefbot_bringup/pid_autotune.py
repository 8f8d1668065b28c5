"""Wheel speed PID autotune of the bring-up check (issue 31): fit a model, propose gains, compare.

Pure Python (numpy, scipy), no rospy. A future guided node drives one wheel (robot on
blocks) with an open-loop command step, records the speed, and calls:

* :func:`fit_fopdt` -- a first-order-plus-dead-time (FOPDT) model
  ``speed = y0 + gain * (command - start_command) * (1 - exp(-(t - dead_time) / tau))``
  fitted to the record (:class:`Fopdt`). Feed it the speed from the encoder counts
  through the loop's own estimator (``wheel_pid.WheelVelocityEstimator``), so the
  estimator's rolling-window lag shows up as dead time and the gains account for it.
* :func:`simc_pi` -- PI gains for ``pid_velocity`` by Skogestad's SIMC rule
  (:class:`Gains`, ``to_params()`` gives the ``Kp``/``Ki``/``Kd`` keys of
  ``param/diff_drive.yaml``).
* :func:`propose_gains` -- SIMC with ``tau_c`` relaxed until :func:`predict_step` (the
  fitted model in closed loop with ``VelocityPid``, feed-forward included) overshoots
  at most 10 %: plain SIMC ignores our feed-forward and overshoots ~50 % with it.
* :func:`compare_steps` -- scores the closed-loop steps with the current and the
  proposed gains (:class:`StepScore`: IAE / step and overshoot) and says whether the
  proposal is better.

Names adapted from the issue: ``fit_fopdt``'s ``command`` is the command *level* sent
from ``t[0]`` on (what the board was told) and ``start_command`` the level before it; the
step is their difference (with the default ``start_command`` 0 both readings agree).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from chefbot_bringup.bringup_check import OVERSHOOT_MAX
from chefbot_bringup.wheel_pid import PidConfig, VelocityPid

MIN_SAMPLES = 10             # fewer points cannot pin three parameters
TAIL_FRACTION = 0.2          # the last 20 % of the record is its "steady state" (as bringup_check)
NO_RESPONSE_SPEED = 0.002    # m/s, 2 x pid_velocity's vel_threshold: a smaller change is "did not move"
NO_RESPONSE_NOISE = 3.0      # ... and the change must exceed this many standard deviations of the tail
SETTLE_TAUS = 3.0            # the record must last dead_time + 3 tau (95 % of the step) to show the gain
DISCRETE_TAU_C = 1.5         # loop periods: floor of the closed-loop time constant (see simc_pi)
BETTER_IAE = 0.95            # the proposal must cut the IAE by at least 5 % to count as better
PREDICTED_OVERSHOOT = 10.0   # %, propose_gains' aim on the model: half bringup_check's 20 %, a margin for the
                             # model's pure delay standing in for the estimator's rolling window (on the simulated
                             # 37D the prediction was within 1 point near 10 %, 7 points low at SIMC's tightest)
TAU_C_STEPS = (1, 1.5, 2, 3, 4, 6, 8, 12, 16, 24, 32)   # multiples of SIMC's tight tau_c tried, tightest first
SUBSTEPS = 10                # model integration steps per loop period (dead time resolution: 3.3 ms at 30 Hz)


@dataclass(frozen=True)
class Fopdt:
    """First-order-plus-dead-time model of command -> wheel speed."""

    gain: float        # (m/s) per command unit (the 37D at 12 V: 0.377 / 1023 = 3.7e-4)
    tau: float         # s, time constant
    dead_time: float   # s, delay before the speed starts to move (estimator lag included)
    rmse: float        # m/s, root-mean-square residual of the fit

    def response(self, t: Sequence[float] | np.ndarray, step: float) -> np.ndarray:
        """Speed change (m/s) at times ``t`` (s) after a command step of ``step`` units at t = 0."""
        return _fopdt(np.asarray(t, dtype=float), self.gain * step, self.tau, self.dead_time)


@dataclass(frozen=True)
class Gains:
    """PID gains in ``pid_velocity``'s units."""

    kp: float          # command units per (m/s)
    ki: float          # command units per m (per (m/s) x s)
    kd: float = 0.0    # command units per (m/s^2)

    def to_params(self) -> dict[str, float]:
        """The keys of ``lwheel_pid``/``rwheel_pid`` in param/diff_drive.yaml."""
        return {"Kp": float(self.kp), "Ki": float(self.ki), "Kd": float(self.kd)}


@dataclass(frozen=True)
class StepScore:
    """How good one closed-loop step is: smaller is better for both."""

    iae: float           # s: integral of |target - measured| dt divided by |step|
    overshoot_pct: float  # % of the step beyond the target (0 if none)


@dataclass(frozen=True)
class Comparison:
    """Current vs proposed gains on the same step."""

    current: StepScore
    proposed: StepScore
    better: bool         # proposed cuts the IAE by >= 5 % without overshooting past bringup_check's limit


def _fopdt(t: np.ndarray, amplitude: float, tau: float, dead_time: float) -> np.ndarray:
    return amplitude * -np.expm1(-np.clip(t - dead_time, 0.0, None) / tau)


def _first_crossing(t: np.ndarray, y: np.ndarray, level: float) -> float:
    i = int(np.argmax(y >= level))      # the caller makes sure y reaches the level
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (level - y[i - 1]) / (y[i] - y[i - 1]) * (t[i] - t[i - 1]))


def fit_fopdt(t: Sequence[float] | np.ndarray, speed: Sequence[float] | np.ndarray, command: float,
              start_command: float = 0.0) -> Fopdt:
    """Fit an FOPDT model to an open-loop step record.

    ``t`` (s, strictly increasing; ``t[0]`` is when ``command`` was applied), ``speed``
    (m/s, ``speed[0]`` the speed before the step), ``command`` and ``start_command``
    (command units, the levels after and before the step). The response is measured
    from ``speed[0]`` (with the loop's estimator a wheel at rest reads exactly 0).

    Raises ValueError for: fewer than MIN_SAMPLES samples, non-finite values,
    non-increasing ``t``, no step, a wheel that did not move, a wheel that moved
    against the command (wiring), and a record shorter than ``dead_time + 3 tau``.
    """
    ta = np.asarray(t, dtype=float)
    ya = np.asarray(speed, dtype=float)
    if ta.ndim != 1 or ta.shape != ya.shape:
        raise ValueError(f"t and speed must be 1-D and of equal length, got shapes {ta.shape} and {ya.shape}")
    if ta.size < MIN_SAMPLES:
        raise ValueError(f"too few samples: {ta.size}, need at least {MIN_SAMPLES} (record at 30 Hz for >= 1 s)")
    if not (np.all(np.isfinite(ta)) and np.all(np.isfinite(ya))):
        raise ValueError("t and speed must be finite (no NaN or inf)")
    if not np.all(np.diff(ta) > 0):
        raise ValueError("t must be strictly increasing")
    step = float(command) - float(start_command)
    if not math.isfinite(step) or step == 0.0:
        raise ValueError(f"command ({command!r}) must be finite and differ from start_command ({start_command!r})")

    t0 = ta - ta[0]
    y0 = float(ya[0])
    tail = ya[-max(2, int(round(TAIL_FRACTION * ya.size))):]
    change = float(tail.mean()) - y0
    if abs(change) <= max(NO_RESPONSE_SPEED, NO_RESPONSE_NOISE * float(tail.std())):
        raise ValueError(f"no response: the speed changed by {change:+.4f} m/s after a command step of "
                         f"{step:+.0f}; is the motor powered and the encoder counting? run the wiring check "
                         "(bringup_check.diagnose_motors) first")
    if change * step < 0:
        raise ValueError(f"response of the wrong sign: a command step of {step:+.0f} moved the wheel at "
                         f"{change:+.3f} m/s; motor leads or encoder reversed (wiring is wrong): run the wiring "
                         "check (bringup_check.diagnose_motors) first")

    # Initial guess from Smith's two points (28.3 % and 63.2 % of the change): tau = 1.5 (t63 - t28).
    yn = (ya - y0) / change                      # 0 -> 1 whatever the sign
    t28, t63 = _first_crossing(t0, yn, 0.283), _first_crossing(t0, yn, 0.632)
    dt_min = float(np.min(np.diff(t0)))
    tau_guess = max(1.5 * (t63 - t28), dt_min)
    x0 = [abs(change), tau_guess, min(max(t63 - tau_guess, 0.0), t0[-1])]
    lower, upper = [0.0, 0.1 * dt_min, 0.0], [np.inf, 100.0 * t0[-1], t0[-1]]
    sign = math.copysign(1.0, change)

    def residuals(p: np.ndarray) -> np.ndarray:
        return y0 + sign * _fopdt(t0, p[0], p[1], p[2]) - ya

    sol = least_squares(residuals, x0, bounds=(lower, upper), x_scale=[abs(change), tau_guess, tau_guess])
    amplitude, tau, dead_time = sign * float(sol.x[0]), float(sol.x[1]), float(sol.x[2])
    needed = dead_time + SETTLE_TAUS * tau
    if t0[-1] < needed:
        raise ValueError(f"record too short to reach steady state: {t0[-1]:.2f} s, the fit needs at least "
                         f"dead_time + {SETTLE_TAUS:.0f} tau = {needed:.2f} s; record for longer")
    rmse = float(np.sqrt(np.mean(sol.fun ** 2)))
    return Fopdt(gain=amplitude / step, tau=tau, dead_time=dead_time, rmse=rmse)


def simc_pi(model: Fopdt, rate: float, tau_c: float | None = None) -> Gains:
    """PI gains by Skogestad's SIMC rule for the loop running at ``rate`` Hz.

    Skogestad (2003), "Simple analytic rules for model reduction and PID controller
    tuning", J. Process Control 13: ``Kc = tau / (K (tau_c + theta))``,
    ``Ti = min(tau, 4 (tau_c + theta))``; here ``kp = Kc`` and ``ki = Kc / Ti`` (our
    integral gain multiplies the error integral directly). ``theta`` is the model's dead
    time plus half a loop period: the command is held for a whole period, on average
    half a period late. ``tau_c`` (s) is the desired closed-loop time constant; the
    default ``max(theta, 1.5 / rate)`` is SIMC's "tight control" choice ``tau_c = theta``,
    floored because a sampled loop cannot follow a time constant of about one period:
    below ~1.5 periods the delay of the sampling itself (beyond the half period the model
    holds) makes the loop ring, so the rule would promise what 30 Hz cannot give.
    """
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive number (Hz), got {rate!r}")
    if not (math.isfinite(model.gain) and model.gain != 0 and model.tau > 0 and model.dead_time >= 0):
        raise ValueError(f"model must have a non-zero gain, tau > 0 and dead_time >= 0, got {model!r}")
    theta = model.dead_time + 0.5 / rate
    if tau_c is None:
        tau_c = max(theta, DISCRETE_TAU_C / rate)
    elif not (math.isfinite(tau_c) and tau_c > 0):
        raise ValueError(f"tau_c must be a positive number (s), got {tau_c!r}")
    kc = model.tau / (abs(model.gain) * (tau_c + theta))   # |gain|: a negative plant is a wiring fault, not a tune
    ti = min(model.tau, 4.0 * (tau_c + theta))
    return Gains(kp=kc, ki=kc / ti)


def predict_step(model: Fopdt, gains: Gains, cfg: PidConfig, target: float,
                 seconds: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed-loop step of ``VelocityPid`` (``cfg`` with ``gains``: feed-forward, clamp, anti-windup) on the model.

    The wheel starts at rest, ``target`` (m/s) is set at t = 0; returns the loop times (s)
    and the speed the loop sees there (m/s). The model's output stands for the estimated
    speed (its dead time includes the estimator's lag); the command is held for a period.
    """
    pid = VelocityPid(replace(cfg, kp=gains.kp, ki=gains.ki, kd=gains.kd))
    h = 1.0 / (cfg.rate * SUBSTEPS)
    decay = math.exp(-h / model.tau)
    queue = [0.0] * int(round(model.dead_time / h))   # commands in flight through the dead time
    n = int(round(seconds * cfg.rate)) + 1
    speed = np.zeros(n)
    y = 0.0
    for k in range(n):
        speed[k] = y
        u = pid.step(target, y, 1.0 / cfg.rate)
        for _ in range(SUBSTEPS):
            queue.append(u)
            y = model.gain * queue.pop(0) * (1.0 - decay) + y * decay   # exact first order over h
    return np.arange(n) / cfg.rate, speed


def propose_gains(model: Fopdt, cfg: PidConfig, target: float = 0.2) -> Gains:
    """SIMC PI gains for our loop: the tightest ``tau_c`` whose predicted step overshoots <= PREDICTED_OVERSHOOT.

    Plain SIMC (:func:`simc_pi` with its default ``tau_c``) assumes the PI makes the whole
    command. ``pid_velocity`` adds a feed-forward that already drives the wheel towards the
    target; with a right feed-forward the integral ends where it started, so all the error
    integrated while the wheel rises is paid back as overshoot (50 % on the simulated 37D).
    ``tau_c`` is SIMC's one tuning knob, so it is relaxed (TAU_C_STEPS) until
    :func:`predict_step` at ``target`` (m/s) stays within PREDICTED_OVERSHOOT; a motor
    weaker than the feed-forward assumes needs the integral and gets a tighter ``tau_c``.
    If none does (the feed-forward alone overshoots: check max_wheel_speed and
    static_friction) the slowest candidate is returned.
    """
    base = max(model.dead_time + 0.5 / cfg.rate, DISCRETE_TAU_C / cfg.rate)
    for m in TAU_C_STEPS:
        gains = simc_pi(model, cfg.rate, base * m)
        t, y = predict_step(model, gains, cfg, target)
        if step_score(t, target, y).overshoot_pct <= PREDICTED_OVERSHOOT:
            break
    return gains


def step_score(t: Sequence[float] | np.ndarray, target: float, measured: Sequence[float] | np.ndarray,
               start: float = 0.0) -> StepScore:
    """IAE (trapezoidal, divided by the step) and overshoot of a step from ``start`` to ``target`` at ``t[0]``."""
    ta = np.asarray(t, dtype=float)
    ya = np.asarray(measured, dtype=float)
    span = target - start
    if ta.ndim != 1 or ta.shape != ya.shape or ta.size < 2 or not math.isfinite(span) or span == 0:
        raise ValueError("t and measured must be 1-D of equal length (>= 2) and target must differ from start")
    e = np.abs(target - ya) / abs(span)
    iae = float(np.sum(0.5 * (e[1:] + e[:-1]) * np.diff(ta)))
    overshoot = max(0.0, float(((ya - start) / span).max()) - 1.0) * 100.0
    return StepScore(iae=iae, overshoot_pct=overshoot)


def compare_steps(t: Sequence[float] | np.ndarray, target: float, current: Sequence[float] | np.ndarray,
                  proposed: Sequence[float] | np.ndarray, start: float = 0.0) -> Comparison:
    """Score the same step with the current and the proposed gains (same ``t``, m/s).

    The proposal is better when its IAE is at least 5 % lower and its overshoot stays
    within bringup_check's OVERSHOOT_MAX (or no worse than the current one's).
    """
    cur = step_score(t, target, current, start)
    new = step_score(t, target, proposed, start)
    better = new.iae <= BETTER_IAE * cur.iae and new.overshoot_pct <= max(OVERSHOOT_MAX, cur.overshoot_pct)
    return Comparison(current=cur, proposed=new, better=better)
