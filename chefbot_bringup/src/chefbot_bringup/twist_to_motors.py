"""Body twist -> wheel speed targets (core of ``twist_to_motors``).

Timing (defaults, see the package README for the budget): commands arrive
at ~5 Hz from ``move_base`` (200 ms apart); targets are published at
``rate`` = 50 Hz for up to ``timeout_ticks`` = 18 ticks (0.36 s) after the
last command, so one late or lost command does not stop the wheels (the
book's 2 ticks = 40 ms did, 5 times a second).  On the tick the timeout
expires a zero target is published once, so the PID stops the motor at
once instead of waiting for its own timeout.  A new command is also
published at once (:meth:`TwistToMotors.current`), so it does not wait up
to one tick (20 ms) for the timer.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from chefbot_bringup.safety import SonarLimiter


@dataclass(frozen=True)
class TwistToMotorsConfig:
    """Parameters of twist_to_motors (param/twist_to_motors.yaml); units in the comments."""
    base_width: float = 0.30        # wheel separation (m)
    rate: float = 50.0              # output rate (Hz)
    timeout_ticks: int = 18         # output ticks to keep going after the last command
    max_wheel_speed: float = 0.377  # fastest wheel speed (m/s); 80 RPM x pi x 0.09 m
    event_driven: bool = True       # publish a changed command at once (False: only on the tick)

    def __post_init__(self) -> None:
        for name in ("base_width", "rate", "max_wheel_speed"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        if int(self.timeout_ticks) != self.timeout_ticks or self.timeout_ticks < 1:
            raise ValueError(f"timeout_ticks must be an integer >= 1, got {self.timeout_ticks!r}")

    @property
    def stop_delay(self) -> float:
        """Worst-case time from the last command to the zero target (s)."""
        return self.timeout_ticks / self.rate


def wheel_speeds(v: float, w: float, base_width: float, max_speed: float) -> tuple[float, float]:
    """Left/right wheel speeds (m/s) for body speed ``v`` (m/s) and yaw rate ``w`` (rad/s).

    If a wheel would exceed ``max_speed`` both are scaled by the same factor,
    which keeps the ratio and so the radius of the turn.  The arithmetic runs
    on inputs scaled down to at most 1, so any finite command (up to
    ±1.7e308) saturates instead of overflowing to inf and then NaN.
    """
    scale = max(abs(v), abs(w), 1.0)
    vn, half = v / scale, 0.5 * (w / scale) * base_width
    left, right = vn - half, vn + half            # wheel speeds / scale, finite
    peak = max(abs(left), abs(right))
    if peak > max_speed / scale:
        k = max_speed / peak
        return left * k, right * k
    return left * scale, right * scale


class TwistToMotors:
    """Hold the latest command, apply the sonar limiter, time out."""

    def __init__(self, cfg: TwistToMotorsConfig, limiter: SonarLimiter | None = None) -> None:
        self.cfg = cfg
        self.limiter = limiter
        self.v = 0.0
        self.w = 0.0
        self._ticks_since_cmd = int(cfg.timeout_ticks)   # silent until the first command

    def set_twist(self, v: float, w: float) -> bool:
        """Accept a command (m/s, rad/s); returns False (ignored) if it is NaN/Inf."""
        if not (math.isfinite(v) and math.isfinite(w)):
            return False
        self.v, self.w = float(v), float(w)
        self._ticks_since_cmd = 0
        return True

    @property
    def active(self) -> bool:
        """True while a command is being held (fewer than timeout_ticks ticks since the last)."""
        return self._ticks_since_cmd < self.cfg.timeout_ticks

    def current(self, t: float) -> tuple[float, float] | None:
        """Wheel targets (m/s) for the command held now, at time ``t`` (s), without counting a tick.

        Called when a command arrives so it goes out at once instead of on the
        next tick; None while inactive.
        """
        if not self.active:
            return None
        v = self.v if self.limiter is None else self.limiter.limit(self.v, t)
        return wheel_speeds(v, self.w, self.cfg.base_width, self.cfg.max_wheel_speed)

    def tick(self, t: float) -> tuple[float, float] | None:
        """One output tick at time ``t`` (s): wheel targets (m/s) to publish, or None."""
        if not self.active:
            return None
        self._ticks_since_cmd += 1
        if not self.active:
            self.v = self.w = 0.0
            return 0.0, 0.0
        return self.current(t)
