"""Cliff guard: no forward motion while a cliff sensor sees no floor (pure logic).

The book's base carries three downward IR cliff sensors on the edge of the
base plate (left, front, right).  Each publishes ``sensor_msgs/Range``: the
distance down to the floor.  The guard sits between ``cmd_vel`` and
``twist_to_motors`` (node ``cliff_guard``, see the package README), so every
velocity source (teleop, ``move_base``, the GUI) is covered.

While any sensor is *unsafe*, the forward component of a command is cut to
zero; reversing and turning pass, so the robot can back or turn away from
the edge.  A sensor is unsafe when its newest reading says

* no floor: a range above ``drop_threshold``, ``+inf`` (REP 117: nothing
  within ``max_range``) or above ``max_range``;
* nothing trustworthy: NaN, or a finite value under ``min_range`` (an IR
  ranger does not report those for a floor that is there);

or when it is *stale*: no reading for ``timeout`` s (including never heard
from).  ``-inf`` (REP 117: something closer than ``min_range``) is a floor
right under the sensor: safe.

Staleness is judged on two clocks: the ROS clock (sim time in a simulation)
and the wall clock; a sensor is stale only when both have advanced by
``timeout`` since its last reading.  On a robot they are the same clock; a
simulation running faster than real time would otherwise see message-delivery
jitter as missing readings, and a paused one would see none at all.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class CliffGuardConfig:
    """Thresholds of the cliff guard (m, s)."""

    drop_threshold: float = 0.07   # a range above this (m) is a drop (the sensors sit ~0.03 m above the floor)
    timeout: float = 0.25          # a sensor without a reading for this long (s) is stale, hence unsafe

    def __post_init__(self) -> None:
        if not (math.isfinite(self.drop_threshold) and self.drop_threshold > 0):
            raise ValueError(f"drop_threshold must be a finite number > 0 (m), got {self.drop_threshold!r}")
        if not (math.isfinite(self.timeout) and self.timeout > 0):
            raise ValueError(f"timeout must be a finite number > 0 (s), got {self.timeout!r}")


@dataclass(frozen=True)
class CliffStatus:
    """Verdict at one instant: ``safe`` and, when not, one reason per unsafe sensor."""

    safe: bool
    reasons: tuple[str, ...] = ()

    @property
    def message(self) -> str:
        """One line for a diagnostic or a log."""
        return "all cliff sensors see the floor" if self.safe else "; ".join(self.reasons)


def reading_problem(rng: float, min_range: float, max_range: float, drop_threshold: float) -> str | None:
    """Why one reading (m) is unsafe, or None when it shows a floor close enough."""
    if math.isnan(rng):
        return "invalid reading (NaN)"
    if rng == -math.inf:
        return None                      # REP 117: closer than min_range -- the floor is right there
    if rng == math.inf or rng > max_range:
        return f"no floor within {max_range:.3f} m (drop)"
    if rng < min_range:
        return f"invalid reading {rng:.3f} m (below min_range {min_range:.3f} m)"
    if rng > drop_threshold:
        return f"floor {rng:.3f} m away, more than {drop_threshold:.3f} m (drop)"
    return None


class CliffGuard:
    """The guard's state: the newest reading of each named sensor.

    Times: ``t`` is the ROS clock (s), ``wall`` a monotonic wall clock (s).
    """

    def __init__(self, cfg: CliffGuardConfig, sensors: Sequence[str]) -> None:
        if not sensors:
            raise ValueError("the cliff guard needs at least one sensor")
        if len(set(sensors)) != len(sensors):
            raise ValueError(f"sensor names must differ, got {list(sensors)}")
        self.cfg = cfg
        self.sensors = tuple(sensors)
        # sensor -> (problem or None, ROS time, wall time) of its newest reading
        self._last: dict[str, tuple[str | None, float, float]] = {}

    def add_range(self, sensor: str, rng: float, min_range: float, max_range: float, t: float,
                  wall: float) -> None:
        """Record a reading (m) of ``sensor`` received at ``t`` / ``wall`` (s)."""
        if sensor not in self.sensors:
            raise KeyError(f"unknown cliff sensor {sensor!r} (known: {', '.join(self.sensors)})")
        self._last[sensor] = (reading_problem(rng, min_range, max_range, self.cfg.drop_threshold), t, wall)

    def reset(self) -> None:
        """Forget every reading (after the ROS clock jumped back): all sensors stale until they speak."""
        self._last.clear()

    def status(self, t: float, wall: float) -> CliffStatus:
        """Safe, or the reason each unsafe sensor gives, at ``t`` / ``wall`` (s)."""
        reasons = []
        for name in self.sensors:
            last = self._last.get(name)
            if last is None:
                reasons.append(f"{name}: no reading yet")
                continue
            problem, t0, wall0 = last
            age, wall_age = t - t0, wall - wall0
            if age > self.cfg.timeout and wall_age > self.cfg.timeout:
                reasons.append(f"{name}: no reading for {age:.2f} s (stale, timeout {self.cfg.timeout:.2f} s)")
            elif problem is not None:
                reasons.append(f"{name}: {problem}")
        return CliffStatus(not reasons, tuple(reasons))

    def limit(self, v: float, t: float, wall: float) -> tuple[float, CliffStatus]:
        """Forward speed (m/s) allowed for a commanded ``v``: unchanged when safe, else at most 0
        (reversing passes).  A non-finite ``v`` becomes 0."""
        st = self.status(t, wall)
        if not math.isfinite(v):
            return 0.0, st
        return (v if st.safe else min(v, 0.0)), st
