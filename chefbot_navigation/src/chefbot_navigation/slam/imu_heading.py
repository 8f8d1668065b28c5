"""The IMU's heading over time (pure), for checking the wheels' turns (:class:`~.mapper.Slam`).

Wheels report turns the body did not make (one wheel slipping) and miss turns it did make (a
collision swinging the robot round while both wheels push on).  A gyro measures the body.  This
keeps the recent IMU headings - from the orientation (the MPU6050's DMP yaw, any fixed offset)
or, for an IMU without orientation, integrated from the z rate - and gives the heading at any
stamp between two samples, unwrapped, so that differences over several turns come out right.
"""
from __future__ import annotations

import bisect
import math
from collections import deque


class HeadingTrack:
    """Unwrapped IMU heading (rad) against time (s); samples must come in time order.

    ``max_gap``: a stamp further than this from the nearest samples on both sides has no heading
    (an IMU that stopped publishing); ``keep``: seconds of history kept (None: all, offline).
    """

    def __init__(self, max_gap: float = 0.25, keep: float | None = 30.0) -> None:
        self.max_gap, self.keep = max_gap, keep
        self._t: deque[float] = deque()
        self._yaw: deque[float] = deque()
        self._last_rate: tuple[float, float] | None = None
        self.rejected = 0            # samples out of time order or not finite

    def add_yaw(self, t: float, yaw: float) -> bool:
        """An orientation sample: heading ``yaw`` (rad, any fixed offset) at ``t`` s; False: rejected."""
        if not (math.isfinite(t) and math.isfinite(yaw)) or (self._t and t <= self._t[-1]):
            self.rejected += 1
            return False
        if self._yaw:
            prev = self._yaw[-1]
            yaw = prev + math.remainder(yaw - prev, 2.0 * math.pi)
        self._append(t, yaw)
        return True

    def add_rate(self, t: float, rate: float) -> bool:
        """A z-rate sample (rad/s) of an IMU without orientation: the heading is its integral
        (trapezoids; starts at 0); False: rejected."""
        if not (math.isfinite(t) and math.isfinite(rate)) or (self._t and t <= self._t[-1]):
            self.rejected += 1
            return False
        if self._last_rate is None or t - self._last_rate[0] > self.max_gap:
            yaw = self._yaw[-1] if self._yaw else 0.0      # a gap: the turn in it is unknown, restart there
        else:
            t0, r0 = self._last_rate
            yaw = self._yaw[-1] + 0.5 * (r0 + rate) * (t - t0)
        self._last_rate = (t, rate)
        self._append(t, yaw)
        return True

    def _append(self, t: float, yaw: float) -> None:
        self._t.append(t)
        self._yaw.append(yaw)
        if self.keep is not None:
            while self._t and self._t[0] < t - self.keep:
                self._t.popleft()
                self._yaw.popleft()

    def at(self, t: float) -> float | None:
        """Heading (rad, unwrapped) at ``t`` s, interpolated; None without samples within ``max_gap``."""
        ts = self._t
        if not ts:
            return None
        i = bisect.bisect_left(ts, t)
        if i < len(ts) and ts[i] == t:
            return self._yaw[i]
        if 0 < i < len(ts):
            t0, t1 = ts[i - 1], ts[i]
            if t1 - t0 > 2.0 * self.max_gap:
                return None
            f = (t - t0) / (t1 - t0)
            return self._yaw[i - 1] + f * (self._yaw[i] - self._yaw[i - 1])
        j = 0 if i == 0 else len(ts) - 1       # before the first or after the last sample
        return self._yaw[j] if abs(t - ts[j]) <= self.max_gap else None
