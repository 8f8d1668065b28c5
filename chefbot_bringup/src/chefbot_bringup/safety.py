"""Forward-speed limiter from the front ultrasonic range finder (pure logic).

The book's robot publishes the HC-SR04 distance but never uses it.  Here the
limiter sits inside ``twist_to_motors``, the last node before the wheels, so
every velocity source (teleop, ``move_base``, the GUI) is covered without
renaming ``cmd_vel``, and the limit is re-applied on every output tick with
the newest range (a 5 Hz command cannot outrun a 20 Hz sonar).

Only *forward* motion is limited: the sonar looks forward, so turning on the
spot and reversing stay allowed (that is how the robot gets away).

Range semantics (sensor_msgs/Range, REP 117):

* ``-inf`` = object closer than ``min_range`` -> stop;
* ``+inf`` or a value >= ``max_range`` = nothing in range -> clear;
* NaN, or a finite value < ``min_range`` (the HC-SR04 sketch reports 0 when
  no echo returns) = no information: the reading is ignored, it neither
  clears nor blocks, and if nothing else arrives the sonar becomes stale;
* stale (no informative reading for ``timeout`` s, including "never heard
  from"): forward speed is capped at ``stale_speed`` -- the robot can still
  creep (a dead sonar must not block it forever) but is not treated as clear.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class SonarLimitConfig:
    """Distances (m), timeout (s) and speed cap (m/s) of the ultrasonic forward-speed limiter."""
    stop_distance: float = 0.25   # at or below: no forward motion (m)
    slow_distance: float = 0.60   # from here down to stop_distance: linear slow-down (m)
    timeout: float = 0.5          # a reading older than this is stale (s)
    stale_speed: float = 0.10     # forward speed cap while stale (m/s)

    def __post_init__(self) -> None:
        if not (0.0 <= self.stop_distance < self.slow_distance and math.isfinite(self.slow_distance)):
            raise ValueError(
                f"need 0 <= stop_distance ({self.stop_distance}) < slow_distance ({self.slow_distance})")
        if not self.timeout > 0:
            raise ValueError(f"timeout must be > 0, got {self.timeout}")
        if not self.stale_speed >= 0:
            raise ValueError(f"stale_speed must be >= 0, got {self.stale_speed}")


class SonarLimiter:
    """Scale forward speed by the latest front range."""

    def __init__(self, cfg: SonarLimitConfig) -> None:
        self.cfg = cfg
        self._range: float | None = None   # latest informative distance (m), inf = clear
        self._t: float | None = None

    def add_range(self, rng: float, min_range: float, max_range: float, t: float) -> bool:
        """Record one reading (m) at time ``t`` (s); returns False if it carried no information."""
        if math.isnan(rng):
            return False
        if rng == -math.inf:
            value = 0.0
        elif rng == math.inf or rng >= max_range:
            value = math.inf
        elif rng < min_range:
            return False
        else:
            value = float(rng)
        self._range, self._t = value, t
        return True

    def stale(self, t: float) -> bool:
        """True if no ultrasonic reading arrived within the timeout at time ``t`` (s)."""
        return self._t is None or t - self._t > self.cfg.timeout

    def factor_cap(self, t: float) -> tuple[float, float]:
        """(scale factor in [0, 1], absolute forward cap in m/s) at time ``t``."""
        cfg = self.cfg
        if self.stale(t):
            return 1.0, cfg.stale_speed
        r = self._range
        if r <= cfg.stop_distance:
            return 0.0, 0.0
        if r >= cfg.slow_distance:
            return 1.0, math.inf
        return (r - cfg.stop_distance) / (cfg.slow_distance - cfg.stop_distance), math.inf

    def limit(self, v: float, t: float) -> float:
        """Forward speed ``v`` (m/s) limited for the obstacle ahead; v <= 0 passes unchanged."""
        if v <= 0.0:
            return v
        factor, cap = self.factor_cap(t)
        return min(v * factor, cap)
