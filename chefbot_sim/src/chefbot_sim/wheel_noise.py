"""Imperfect wheel odometry: what the encoders report versus how the wheels really turned.

The physics (and so the ground truth) is untouched; only the wheel *measurement*
is corrupted, so both plugin-mode ``odom`` and the firmware's encoder ticks
drift as on a real robot.  Per wheel and per measurement step, for a true
wheel turn ``da`` (rad) of a wheel of nominal radius ``r`` (m):

    measured = da / (1 + radius_error)  +  slip_stddev · sqrt(|da| · r) · N(0, 1) / r

* ``radius_error`` (fraction): the wheel's real rolling radius is ``r (1 + e)``
  (tyre tolerance, load, wear); odometry assuming ``r`` sees ``1/(1+e)`` of the
  turn, so a left/right difference makes a heading drift on straight runs.
* ``slip_stddev`` (m/√m): random slip, whose variance grows with the distance
  the wheel rolled (a random walk), independent of the step size.
* ``encoder_counts`` (counts/rev, plugin mode): the reported angle is quantised
  to whole counts, as the LaunchPad's quadrature decoder does in firmware mode
  (there the decoder itself quantises, so this setting is not applied twice).

No wheel turn, no error: standing still never drifts.  Defaults in
``param/sim.yaml`` (see the package README for where the figures come from).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class WheelNoise:
    """Wheel radius errors, slip and encoder quantisation of the simulated wheels (odometry error model)."""
    radius_error_left: float = 0.0    # fraction (0.003 = real rolling radius 0.3 % above nominal)
    radius_error_right: float = 0.0   # fraction
    slip_stddev: float = 0.0          # m per sqrt(m) of wheel travel
    encoder_counts: int = 0           # counts per wheel revolution to quantise to (0 = no quantisation)

    def validate(self) -> None:
        """Check the values; ValueError naming the first bad one."""
        for name in ("radius_error_left", "radius_error_right"):
            v = getattr(self, name)
            if not (math.isfinite(v) and -0.2 < v < 0.2):
                raise ValueError(f"wheel {name} must be a fraction in (-0.2, 0.2), got {v}")
        if not (math.isfinite(self.slip_stddev) and self.slip_stddev >= 0):
            raise ValueError(f"wheel slip_stddev must be >= 0 m/sqrt(m), got {self.slip_stddev}")
        if self.encoder_counts < 0:
            raise ValueError(f"wheel encoder_counts must be >= 0, got {self.encoder_counts}")

    @property
    def active(self) -> bool:
        """True if any radius error or slip is set."""
        return bool(self.radius_error_left or self.radius_error_right or self.slip_stddev)


def measure_wheels(noise: WheelNoise, rng: np.random.Generator, true_prev: tuple[float, float],
                   true_now: tuple[float, float], measured_prev: tuple[float, float],
                   radius: float) -> tuple[float, float]:
    """Measured wheel angles (rad, left/right, unquantised) after the wheels turned from
    ``true_prev`` to ``true_now``, starting from ``measured_prev``."""
    out = []
    for side, err in ((0, noise.radius_error_left), (1, noise.radius_error_right)):
        da = float(true_now[side]) - float(true_prev[side])
        m = da / (1.0 + err)
        if noise.slip_stddev > 0.0 and da != 0.0:
            m += noise.slip_stddev * math.sqrt(abs(da) * radius) * float(rng.standard_normal()) / radius
        out.append(measured_prev[side] + m)
    return out[0], out[1]


def quantise(angle: float, counts: int) -> float:
    """``angle`` (rad) rounded down to whole encoder counts (``counts`` per revolution; 0 = as is)."""
    if counts <= 0:
        return angle
    step = 2.0 * math.pi / counts
    return math.floor(angle / step) * step
