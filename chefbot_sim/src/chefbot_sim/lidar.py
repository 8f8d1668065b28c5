"""A planar 2-D lidar (pure): beam geometry and REP 117 ranges.

The simulator casts one ray per beam in the laser frame's x-y plane (``directions``) and turns the
distances of the first hits into a LaserScan's ``ranges`` here (``ranges``).  Beam ``i`` points at
``angle_min + i * angle_increment`` (rad, counter-clockwise about the frame's +z, 0 = +x), exactly
the angles a LaserScan consumer computes from the message.

A full circle (fov 360) has ``beams`` beams ``2 pi / beams`` apart, the last one short of
``angle_min + 2 pi`` (no beam twice); a sector (fov < 360) has both edges as beams,
``fov / (beams - 1)`` apart, as a Hokuyo's scan does.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LidarConfig:
    """A scanner: field of view (deg), beams, rate (Hz), limits (m), noise (m) and its frame."""

    fov: float = 360.0          # [deg] (0, 360]
    beams: int = 360            # >= 2
    rate: float = 10.0          # [Hz] scans per second of sim time (> 0)
    range_min: float = 0.12     # [m] closer returns read -inf (REP 117)
    range_max: float = 12.0     # [m] nothing within it reads +inf (REP 117)
    noise: float = 0.0          # [m] standard deviation of the range noise (>= 0)
    frame: str = "laser"        # tf frame of the scan plane

    def validate(self) -> None:
        """ValueError naming the first bad setting as its ``lidar_*`` parameter."""
        if not (math.isfinite(self.fov) and 0.0 < self.fov <= 360.0):
            raise ValueError(f"lidar_fov must be in (0, 360] deg (0 = no lidar), got {self.fov!r}")
        if self.beams < 2:
            raise ValueError(f"lidar_beams must be >= 2, got {self.beams!r}")
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise ValueError(f"lidar_rate must be a number > 0 (Hz), got {self.rate!r}")
        if not (math.isfinite(self.range_min) and self.range_min >= 0):
            raise ValueError(f"lidar_range_min must be a number >= 0 (m), got {self.range_min!r}")
        if not (math.isfinite(self.range_max) and self.range_max > self.range_min):
            raise ValueError(f"lidar_range_max must be finite and > lidar_range_min ({self.range_min} m), "
                             f"got {self.range_max!r}")
        if not (math.isfinite(self.noise) and self.noise >= 0):
            raise ValueError(f"lidar_noise must be a number >= 0 (m), got {self.noise!r}")
        if not self.frame:
            raise ValueError("lidar_frame must be a non-empty frame name")

    @property
    def full_circle(self) -> bool:
        """The scanner turns all the way round (fov 360)."""
        return self.fov >= 360.0

    @property
    def angle_increment(self) -> float:
        """rad between neighbouring beams."""
        fov = math.radians(self.fov)
        return fov / self.beams if self.full_circle else fov / (self.beams - 1)

    @property
    def angle_min(self) -> float:
        """rad of beam 0 (the sector is centred on +x)."""
        return -math.radians(self.fov) / 2.0

    @property
    def angle_max(self) -> float:
        """rad of the last beam: ``angle_min + (beams - 1) * angle_increment``."""
        return self.angle_min + (self.beams - 1) * self.angle_increment

    def angles(self) -> np.ndarray:
        """(beams,) beam angles, rad."""
        return self.angle_min + np.arange(self.beams) * self.angle_increment

    def directions(self) -> np.ndarray:
        """(beams, 3) unit beam directions in the laser frame (z = 0)."""
        a = self.angles()
        return np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)

    def ranges(self, distances: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """LaserScan ranges (float32, m) of the first-hit ``distances`` (m; +inf = no hit within range_max).

        Gaussian noise of ``noise`` m on every return, then REP 117: beyond range_max +inf (no return),
        below range_min -inf (too close to measure)."""
        r = np.array(distances, dtype=float)
        hit = np.isfinite(r)
        if self.noise > 0 and rng is not None and hit.any():
            r[hit] += rng.normal(0.0, self.noise, int(hit.sum()))
        out = np.where(hit & (r > self.range_max), np.inf, r)
        out = np.where(np.isfinite(out) & (out < self.range_min), -np.inf, out)
        return out.astype(np.float32)
