"""A kinematic differential-drive robot built wrong, for testing and benchmarking the odometry calibration.

Not used by any node: the robot of ``test_calibration_procedure.py`` and ``bench/bench_bringup.py``.
It implements :class:`calibration_procedure.Robot`: ``cmd_vel`` becomes wheel speed targets with the
*configured* base width (as ``twist_to_motors`` does), each wheel's speed follows its target with a
first-order lag (the PIDs), and the wheels roll with their *true* radii on a *true* base, with optional
random slip (variance growing with the distance rolled, as chefbot_sim's wheel model). The encoders count
8400 per wheel turn. ``snapshot()`` returns the true pose, which :class:`TruthReference` compares (the
ideal of the scan reference, with optional noise of its size).
"""
from __future__ import annotations

import math

import numpy as np

from chefbot_bringup.calibration_procedure import Motion

NOMINAL_RADIUS = 0.045          # m: the 90 mm wheel of param/diff_drive.yaml
COUNTS_PER_TURN = 8400          # 64 CPR x 131.25 gear, 4X decoding
TICKS_METER = COUNTS_PER_TURN / (2 * math.pi * NOMINAL_RADIUS)   # 29708


class KinematicRobot:
    """Wheels ``scale_left``/``scale_right`` times the nominal radius, ``base_true`` m apart, driven with the
    configured ``base_configured``; ``slip`` m per sqrt(m) rolled; ``stuck``: the wheels never turn."""

    def __init__(self, scale_left: float = 1.03, scale_right: float = 0.99, base_true: float = 0.312,
                 base_configured: float = 0.30, lag: float = 0.1, slip: float = 0.0, seed: int = 0,
                 stuck: bool = False, dt: float = 0.005) -> None:
        self.radius = (NOMINAL_RADIUS * scale_left, NOMINAL_RADIUS * scale_right)
        self.base_true, self.base_configured = base_true, base_configured
        self.lag, self.slip, self.stuck, self.dt = lag, slip, stuck, dt
        self.rng = np.random.default_rng(seed)
        self.t = 0.0
        self.pose = np.zeros(3)          # true x, y, yaw
        self.angle = [0.0, 0.0]          # wheel angles, rad (what the encoders count)
        self.omega = [0.0, 0.0]          # wheel speeds, rad/s
        self.cmd = (0.0, 0.0)
        self.commands: list[tuple[float, float, float]] = []

    def now(self) -> float:
        """Simulated time (s)."""
        return self.t

    def drive(self, v: float, w: float) -> None:
        """cmd_vel: ``v`` m/s, ``w`` rad/s."""
        self.cmd = (v, w)
        self.commands.append((self.t, v, w))

    def counts(self) -> tuple[int, int]:
        """Encoder counts of both wheels."""
        return tuple(int(math.floor(a * COUNTS_PER_TURN / (2 * math.pi))) for a in self.angle)

    def snapshot(self) -> np.ndarray:
        """The true pose (x, y, yaw)."""
        return self.pose.copy()

    def roll(self, dl: float, dr: float) -> None:
        """The wheels' contact points travel ``dl``, ``dr`` m (plus slip): the true pose moves."""
        if self.slip:
            dl += self.slip * math.sqrt(abs(dl)) * float(self.rng.standard_normal())
            dr += self.slip * math.sqrt(abs(dr)) * float(self.rng.standard_normal())
        x, y, th = self.pose
        d, dth = (dl + dr) / 2, (dr - dl) / self.base_true
        self.pose = np.array([x + d * math.cos(th + dth / 2), y + d * math.sin(th + dth / 2), th + dth])

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass."""
        n = max(1, round(seconds / self.dt))
        h = seconds / n
        v, w = self.cmd
        half = w * self.base_configured / 2
        target = (0.0, 0.0) if self.stuck else ((v - half) / NOMINAL_RADIUS, (v + half) / NOMINAL_RADIUS)
        a = 1 - math.exp(-h / self.lag)
        for _ in range(n):
            for s in (0, 1):
                self.omega[s] += (target[s] - self.omega[s]) * a
                self.angle[s] += self.omega[s] * h
            self.roll(self.omega[0] * self.radius[0] * h, self.omega[1] * self.radius[1] * h)
            self.t += h


class TruthReference:
    """The true motion between two snapshots of a :class:`KinematicRobot`, with optional Gaussian noise."""

    name = "truth"

    def __init__(self, noise_m: float = 0.0, noise_rad: float = 0.0, seed: int = 0) -> None:
        self.noise_m, self.noise_rad = noise_m, noise_rad
        self.rng = np.random.default_rng(seed)

    def measure(self, kind: str, before: np.ndarray, after: np.ndarray, guess: Motion) -> Motion:
        """The robot's pose at ``after`` in its frame at ``before``, plus noise."""
        x0, y0, th0 = before
        dx, dy = after[0] - x0, after[1] - y0
        c, s = math.cos(th0), math.sin(th0)
        n = self.rng.normal(0, 1, 3) * (self.noise_m, self.noise_m, self.noise_rad)
        return Motion(c * dx + s * dy + n[0], -s * dx + c * dy + n[1], after[2] - th0 + n[2])
