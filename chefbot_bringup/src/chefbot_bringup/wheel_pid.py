"""Wheel velocity estimation and PID speed control (core of ``pid_velocity``).

Differences from the book's ``pid_velocity`` and why:

* Velocity comes from the *encoder message* times (a rolling window of the
  last ``rolling_pts`` intervals), not from the PID loop times: a PID tick
  that sees no new message carries no information and must not be read as
  "the wheel stopped".
* Stop detection is sign-correct: when messages stop arriving, the speed is
  bounded by one tick per elapsed time *in the direction the wheel was
  turning*; the book used a positive bound, so a wheel stopping in reverse
  was never detected as stopped.
* ``ticks_meter`` is one number given once (the book read it under two
  names).
* Anti-windup: the integral term is clamped to the output range and is not
  accumulated while the output saturates in the same direction
  (conditional integration).
* After idle (target timeout, zero target) the integral and derivative
  state are reset, and ``dt`` is capped, so the first step after idle does
  not integrate the whole idle time as the book's did.
* Optional feed-forward ``target / max_speed * out_max`` so the PID only
  corrects the error instead of carrying the whole command; with
  ``static_friction`` f (fraction of out_max the motor needs before the wheel
  turns: gearbox and brush friction) it is ``f + (1 - f) * target / max_speed``
  of out_max in the target's direction, the inverse of a DC motor's
  torque-speed line with Coulomb friction.  Without it a slow target (the last
  centimetres to a table, the last degrees of a turn) gets a command inside the
  dead band and the wheel creeps until the integrator has wound up.
* Stale feedback: with no encoder reading for ``feedback_timeout`` (a board
  that stopped talking, a dead driver) there is nothing to control against;
  the controller commands 0 and keeps its integrator reset instead of
  integrating the error of a wheel it cannot see (the book's wound up to
  full power).  It resumes from a fresh start when readings come back.
* Event-driven as well as periodic: :meth:`WheelController.react` runs one
  step at once when a new target arrives (the book waited for the next
  30 Hz tick, up to 33 ms).  The integral uses the real time elapsed since
  the previous step, so the integrated error over a period is the same as
  with the timer alone; the derivative's ``dt`` is floored at half a loop
  period so a step taken right after a tick gives no larger derivative kick
  than the timer loop would.  React steps do not count as loop ticks for
  ``timeout_ticks``.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from chefbot_bringup.encoder import EncoderRange, TickUnwrapper


@dataclass(frozen=True)
class PidConfig:
    """Parameters of one wheel's speed controller (book names in comments)."""

    kp: float = 400.0              # ~Kp, command units per (m/s)
    ki: float = 100.0              # ~Ki, command units per (m/s * s)
    kd: float = 0.0                # ~Kd, command units per (m/s^2)
    out_min: float = -1023.0       # ~out_min, command units
    out_max: float = 1023.0        # ~out_max, command units
    rate: float = 30.0             # ~rate, control loop frequency (Hz)
    timeout_ticks: int = 12        # ~timeout_ticks, loop ticks without a target before idling
    rolling_pts: int = 5           # ~rolling_pts, encoder intervals averaged for the speed
    ticks_meter: float = 14854.0   # ticks_meter, encoder ticks per metre (ticks/m)
    vel_threshold: float = 0.001   # ~vel_threshold, speeds below this read as 0 (m/s)
    max_speed: float = 0.377       # ~max_speed, wheel speed at out_max (m/s), for feed-forward
    feed_forward: bool = True      # ~feed_forward, add target/max_speed*out_max to the output
    static_friction: float = 0.0   # ~static_friction, fraction of out_max needed to turn the wheel (0..0.5)
    encoder_timeout: float = 0.2   # ~encoder_timeout, silence after which the stop bound applies (s)
    feedback_timeout: float = 0.5  # ~feedback_timeout, no encoder reading this long: command 0, no integration (s)
    event_driven: bool = True      # ~event_driven, step at once on a new target (False: only on the loop tick)
    encoder: EncoderRange = field(default_factory=EncoderRange)

    def __post_init__(self) -> None:
        def positive(name: str) -> None:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")

        for name in ("rate", "ticks_meter", "max_speed", "encoder_timeout", "feedback_timeout"):
            positive(name)
        for name in ("kp", "ki", "kd", "vel_threshold"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not (math.isfinite(self.static_friction) and 0.0 <= self.static_friction <= 0.5):
            raise ValueError(f"static_friction must be in [0, 0.5] (fraction of out_max), got {self.static_friction!r}")
        if not self.out_min < self.out_max:
            raise ValueError(f"out_min ({self.out_min}) must be less than out_max ({self.out_max})")
        if int(self.timeout_ticks) != self.timeout_ticks or self.timeout_ticks < 1:
            raise ValueError(f"timeout_ticks must be an integer >= 1, got {self.timeout_ticks!r}")
        if int(self.rolling_pts) != self.rolling_pts or self.rolling_pts < 1:
            raise ValueError(f"rolling_pts must be an integer >= 1, got {self.rolling_pts!r}")


class WheelVelocityEstimator:
    """Wheel speed (m/s) from cumulative encoder readings.

    :meth:`add_reading` gets each raw counter with its arrival time (s);
    :meth:`velocity` returns the speed over the last ``rolling_pts`` reading
    intervals, i.e. (newest - oldest position) / (newest - oldest time),
    which equals the time-weighted rolling average of the per-interval
    speeds.  When readings stop for longer than ``encoder_timeout`` the
    speed magnitude is bounded by one tick per elapsed time, keeping the sign
    of the last motion, so a silent encoder decays to zero in either
    direction.
    """

    def __init__(self, cfg: PidConfig) -> None:
        self.cfg = cfg
        self._unwrap = TickUnwrapper(cfg.encoder)
        self._hist: deque[tuple[float, int]] = deque(maxlen=int(cfg.rolling_pts) + 1)

    def reset(self) -> None:
        """Forget the tick history (the next reading starts a new estimate)."""
        self._unwrap.reset()
        self._hist.clear()

    def add_reading(self, raw_ticks: int, t: float) -> None:
        """Record one raw counter reading (ticks) received at time ``t`` (s)."""
        if self._hist and t <= self._hist[-1][0]:
            if t < self._hist[-1][0]:
                # Time jumped back (sim restart): start over.
                self.reset()
            else:
                # Same timestamp twice: keep the newer position only.
                self._hist.pop()
        self._hist.append((t, self._unwrap.update(raw_ticks)))

    def velocity(self, t_now: float) -> float:
        """Estimated wheel speed (m/s) at time ``t_now`` (s)."""
        if len(self._hist) < 2:
            return 0.0
        (t0, p0), (t1, p1) = self._hist[0], self._hist[-1]
        v = (p1 - p0) / self.cfg.ticks_meter / (t1 - t0)
        silent = t_now - t1
        if silent > self.cfg.encoder_timeout and v != 0.0:
            # No reading for a while: at most one tick can have gone unseen.
            bound = 1.0 / self.cfg.ticks_meter / silent
            v = math.copysign(min(abs(v), bound), v)
        return 0.0 if abs(v) < self.cfg.vel_threshold else v


class VelocityPid:
    """PID on wheel speed with feed-forward, output clamp and anti-windup.

    Pure math: the caller passes target and measured speed (m/s) and the
    step ``dt`` (s).  ``dt`` is capped at a few loop periods so a late call
    cannot inject a large integral step.
    """

    def __init__(self, cfg: PidConfig) -> None:
        self.cfg = cfg
        self.integral = 0.0          # integral term, already in output units
        self._prev_error: float | None = None
        self.output = 0.0

    def reset(self) -> None:
        """Forget integral and derivative history (call after idle)."""
        self.integral = 0.0
        self._prev_error = None
        self.output = 0.0

    def feed_forward(self, target: float) -> float:
        """Open-loop command for ``target`` m/s (output units)."""
        cfg = self.cfg
        if not cfg.feed_forward or abs(target) < cfg.vel_threshold:
            return 0.0
        f = cfg.static_friction
        span = cfg.out_max if target >= 0 else -cfg.out_min
        return math.copysign(f * span, target) + (1.0 - f) * target / cfg.max_speed * span

    def step(self, target: float, measured: float, dt: float) -> float:
        """One control step; returns the clamped motor command (output units)."""
        cfg = self.cfg
        dt = min(max(dt, 0.0), 3.0 / cfg.rate)
        error = target - measured
        deriv = 0.0
        if self._prev_error is not None and dt > 0.0:
            # floor: an event step right after a timer step must not amplify the kick by 1/dt
            deriv = (error - self._prev_error) / max(dt, 0.5 / cfg.rate)
        self._prev_error = error
        base = self.feed_forward(target) + cfg.kp * error + cfg.kd * deriv
        candidate = self.integral + cfg.ki * error * dt
        # Conditional integration: integrate only up to the point where the
        # output saturates, never further into saturation.
        hi, lo = cfg.out_max - base, cfg.out_min - base
        if error > 0 and candidate > hi:
            candidate = max(self.integral, hi)
        elif error < 0 and candidate < lo:
            candidate = min(self.integral, lo)
        self.integral = min(max(candidate, cfg.out_min), cfg.out_max)
        self.output = min(max(base + self.integral, cfg.out_min), cfg.out_max)
        return self.output


@dataclass
class WheelTick:
    """What one control-loop tick wants published."""

    wheel_vel: float             # measured wheel speed (m/s), always published
    motor_cmd: float | None      # motor command (output units) or None: publish nothing


class WheelController:
    """One wheel: target bookkeeping, timeout, idle handling around the PID.

    Call :meth:`set_target` on each ``wheel_vtarget`` message, :meth:`add_reading`
    on each ``wheel`` message and :meth:`tick` at ``rate``.  While targets keep
    arriving the controller runs the PID; a target of exactly 0 commands 0
    (stop, not "hold zero speed", so the motor does not hunt around 0); after
    ``timeout_ticks`` loop ticks without a target it sends 0 once and idles.
    Without an encoder reading for ``feedback_timeout`` s (none yet counts too)
    it commands 0 with the PID reset (:attr:`feedback_stale` tells the node).
    """

    def __init__(self, cfg: PidConfig) -> None:
        self.cfg = cfg
        self.estimator = WheelVelocityEstimator(cfg)
        self.pid = VelocityPid(cfg)
        self.target = 0.0
        self._ticks_since_target = int(cfg.timeout_ticks)   # idle until a target arrives
        self._t_last: float | None = None
        self._t_reading: float | None = None
        self.feedback_stale = False

    @property
    def active(self) -> bool:
        """True while a target is being held (fewer than timeout_ticks ticks since the last)."""
        return self._ticks_since_target < self.cfg.timeout_ticks

    def set_target(self, target: float) -> bool:
        """Accept a target speed (m/s); returns False (ignored) for NaN/Inf."""
        if not math.isfinite(target):
            return False
        self.target = float(target)
        self._ticks_since_target = 0
        return True

    def add_reading(self, raw_ticks: int, t: float) -> None:
        """A raw encoder count read at time ``t`` (s)."""
        self.estimator.add_reading(raw_ticks, t)
        self._t_reading = t

    def react(self, t: float) -> WheelTick:
        """Act on a target that just arrived, at time ``t`` (s), without waiting for the loop tick.

        Same output rules as :meth:`tick` (zero target, stale feedback, idle),
        but it does not count as a loop tick for ``timeout_ticks``.
        """
        return self._step(t, count_tick=False)

    def tick(self, t: float) -> WheelTick:
        """Run one loop iteration at time ``t`` (s)."""
        return self._step(t, count_tick=True)

    def _step(self, t: float, count_tick: bool) -> WheelTick:
        vel = self.estimator.velocity(t)
        # a reading "from the future" (time jumped back) counts as fresh; the estimator restarts
        self.feedback_stale = self._t_reading is None or t - self._t_reading > self.cfg.feedback_timeout
        if not self.active:
            self._t_last = None
            return WheelTick(vel, None)
        if count_tick:
            self._ticks_since_target += 1
        if not self.active:
            # Timed out on this tick: stop the motor once, then stay quiet.
            self.pid.reset()
            self._t_last = None
            return WheelTick(vel, 0.0)
        if self.target == 0.0 or self.feedback_stale:
            self.pid.reset()
            self._t_last = t
            return WheelTick(vel, 0.0)
        dt = 1.0 / self.cfg.rate if self._t_last is None else t - self._t_last
        self._t_last = t
        return WheelTick(vel, self.pid.step(self.target, vel, dt))
