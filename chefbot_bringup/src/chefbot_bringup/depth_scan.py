"""Depth image -> planar laser scan (core of ``depth_to_scan``).

Same semantics as ROS's ``depthimage_to_laserscan`` (which Debian does not
package), re-implemented vectorised from its documented behaviour:

* rows ``offset .. offset + scan_height - 1`` with
  ``offset = int(cy - scan_height // 2)`` (integer halving as there); ours
  clips those rows to the image instead of refusing to run when the band
  does not fit;
* for pixel (u, v) with depth z (m) the range is measured along the ray in
  the x-z plane: ``r = hypot((u - cx) / fx * z, z) = z * sqrt(1 + ((u-cx)/fx)^2)``;
* the pixel's bearing is ``th = -atan((u - cx) / fx)`` so the leftmost
  column gets the most positive angle (REP 103: +angle = left);
  ``angle_max`` = angle of column 0, ``angle_min`` = angle of column
  ``W - 1``, ``angle_increment = (angle_max - angle_min) / (W - 1)``, one bin
  per column; a pixel goes to bin ``int((th - angle_min) / angle_increment)``
  (bins are equal in angle, columns are not, so a few bins stay empty and
  some get two columns -- exactly as upstream);
* per bin the result is the smallest *finite* range inside
  ``[range_min, range_max]``; if there is none, the last ``+inf``/``-inf``
  seen (in row-major order) is kept; otherwise NaN;
* invalid pixels: float NaN -> NaN (no return), float +/-inf pass through as
  +/-inf (REP 117: +inf = nothing within range), float 0 and any finite value
  outside ``[range_min, range_max]`` never wins, so the bin stays NaN;
  16UC1 value 0 means "no data" and becomes range 0 (NaN in practice,
  because 0 < range_min).

Intrinsics come from ``P`` (rectified image, as upstream) or ``K`` when
``P`` is all zeros; lens distortion is not modelled (depth images from the
Astra/Kinect drivers and our simulator are published rectified).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ScanConfig:
    """depth_to_scan settings: rows merged, valid range (m), scan period (s), output frame."""

    scan_height: int = 10        # image rows merged into the scan (pixels)
    range_min: float = 0.45      # shortest valid range (m)
    range_max: float = 10.0      # longest valid range (m)
    scan_time: float = 1.0 / 30  # time between scans reported in the message (s)
    output_frame_id: str = "camera_depth_frame"

    def __post_init__(self) -> None:
        if int(self.scan_height) != self.scan_height or self.scan_height < 1:
            raise ValueError(f"scan_height must be an integer >= 1, got {self.scan_height!r}")
        if not (0.0 <= self.range_min < self.range_max):
            raise ValueError(f"need 0 <= range_min ({self.range_min}) < range_max ({self.range_max})")
        if not self.scan_time >= 0:
            raise ValueError(f"scan_time must be >= 0, got {self.scan_time!r}")
        if not self.output_frame_id:
            raise ValueError("output_frame_id must not be empty")


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of the depth camera that the scan needs (px)."""

    fx: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def from_matrices(cls, k: list[float], p: list[float], width: int, height: int) -> Intrinsics:
        """From camera_info's ``K`` (3x3) and ``P`` (3x4), row-major lists."""
        if p is not None and len(p) == 12 and p[0] != 0.0:
            fx, cx, cy = p[0], p[2], p[6]
        else:
            fx, cx, cy = k[0], k[2], k[5]
        if not (fx > 0 and math.isfinite(fx)):
            raise ValueError(f"camera_info has no usable focal length (fx={fx})")
        if width < 2 or height < 1:
            raise ValueError(f"image too small: {width}x{height}")
        return cls(float(fx), float(cx), float(cy), int(width), int(height))


@dataclass
class Scan:
    """One laser scan: angles (rad) and a range (m) per image column."""

    angle_min: float        # rad (float32-rounded, as the message carries it)
    angle_max: float
    angle_increment: float
    ranges: np.ndarray      # float32, one per image column (m)


def scan_angles(cam: Intrinsics) -> tuple[float, float, float]:
    """(angle_min, angle_max, angle_increment) in rad, rounded to float32 like the message."""
    angle_max = math.atan2(cam.cx, cam.fx)                       # column 0
    angle_min = -math.atan2(cam.width - 1 - cam.cx, cam.fx)      # column W - 1
    inc = (angle_max - angle_min) / (cam.width - 1)
    return float(np.float32(angle_min)), float(np.float32(angle_max)), float(np.float32(inc))


def scan_rows(cam: Intrinsics, scan_height: int) -> tuple[int, int]:
    """First and one-past-last image row of the band, clipped to the image."""
    offset = int(cam.cy - scan_height // 2)
    return max(offset, 0), min(offset + scan_height, cam.height)


def column_bins(cam: Intrinsics) -> np.ndarray:
    """Scan bin of every image column (int array of length W)."""
    angle_min, _, inc = scan_angles(cam)
    u = np.arange(cam.width, dtype=np.float64)
    th = -np.arctan2((u - cam.cx) / cam.fx, 1.0)
    # int() in C truncates toward zero; the value is >= 0 up to rounding.
    return np.clip(np.trunc((th - angle_min) / inc).astype(np.int64), 0, cam.width - 1)


def _ranges_of_band(band: np.ndarray, cam: Intrinsics) -> np.ndarray:
    """Range along the ray (m, float64) for every pixel of the band; invalid pixels passed through."""
    u = np.arange(cam.width, dtype=np.float64)
    tan = (u - cam.cx) / cam.fx
    if band.dtype == np.uint16:
        z = band.astype(np.float64) * 0.001
        x = tan * z
        return np.where(band != 0, np.sqrt(x * x + z * z), 0.0)
    z = band.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        x = tan * z
        r = np.sqrt(x * x + z * z)
    return np.where(np.isfinite(z), r, z)


def depth_to_scan(depth: np.ndarray, cam: Intrinsics, cfg: ScanConfig) -> Scan:
    """Convert one depth image (H x W, float32 metres or uint16 millimetres)."""
    if depth.shape != (cam.height, cam.width):
        raise ValueError(f"depth image is {depth.shape[1]}x{depth.shape[0]}, camera_info says "
                         f"{cam.width}x{cam.height}")
    if depth.dtype not in (np.float32, np.float64, np.uint16):
        raise ValueError(f"unsupported depth dtype {depth.dtype}")
    angle_min, angle_max, inc = scan_angles(cam)
    w = cam.width
    r0, r1 = scan_rows(cam, cfg.scan_height)
    ranges = np.full(w, np.nan, dtype=np.float32)
    if r1 <= r0:
        return Scan(angle_min, angle_max, inc, ranges)
    r = _ranges_of_band(depth[r0:r1], cam)
    bins = column_bins(cam)

    # 1. smallest in-range finite value: reduce rows first, then columns into bins.
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r >= cfg.range_min) & (r <= cfg.range_max)
    col_min = np.where(ok, r, np.inf).min(axis=0)
    best = np.full(w, np.inf)
    np.minimum.at(best, bins, col_min)

    # 2. bins without one keep the last +/-inf in row-major order.
    is_inf = np.isinf(r)
    rows_idx = np.arange(r1 - r0)[:, None]
    last_row = np.where(is_inf, rows_idx, -1).max(axis=0)            # per column
    key = np.where(last_row >= 0, last_row * w + np.arange(w), -1)   # processing order
    best_key = np.full(w, -1, dtype=np.int64)
    np.maximum.at(best_key, bins, key)
    has_inf = best_key >= 0
    inf_val = np.where(has_inf, r.reshape(-1)[np.maximum(best_key, 0)], np.nan)

    ranges[:] = np.where(np.isfinite(best), best, inf_val)
    return Scan(angle_min, angle_max, inc, ranges)


def depth_to_scan_reference(depth: np.ndarray, cam: Intrinsics, cfg: ScanConfig) -> Scan:
    """Plain per-pixel loop with the upstream update rule; the yardstick for tests and the bench."""
    angle_min, angle_max, inc = scan_angles(cam)
    ranges = [math.nan] * cam.width
    r0, r1 = scan_rows(cam, cfg.scan_height)
    is_u16 = depth.dtype == np.uint16
    for v in range(r0, r1):
        row = depth[v].tolist()
        for u in range(cam.width):
            d = row[u]
            th = -math.atan2((u - cam.cx) / cam.fx, 1.0)
            index = min(max(int((th - angle_min) / inc), 0), cam.width - 1)
            z = d * 0.001 if is_u16 else d
            x = (u - cam.cx) / cam.fx * z
            valid = d != 0 if is_u16 else math.isfinite(d)
            if valid:
                r = math.sqrt(x * x + z * z)
            else:
                r = 0.0 if is_u16 else d
            if _use_point(r, ranges[index], cfg.range_min, cfg.range_max):
                ranges[index] = r
    return Scan(angle_min, angle_max, inc, np.array(ranges, dtype=np.float32))


def _use_point(new: float, old: float, range_min: float, range_max: float) -> bool:
    """Upstream's per-pixel rule: finite in-range beats inf beats NaN; shorter beats longer."""
    new_finite, old_finite = math.isfinite(new), math.isfinite(old)
    if not new_finite and not old_finite:
        return not math.isnan(new)
    if not (range_min <= new <= range_max):
        return False
    if not old_finite:
        return True
    return new < old
