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

Speed (``make bench``): everything that depends only on the camera or the
config (column tangents, the column -> bin segments, the squared-range
bounds) is computed once and cached; per frame the band's squared range
``s = x^2 + z^2`` is compared against bounds chosen so that
``lo2 <= s <= hi2`` holds exactly when ``range_min <= sqrt(s) <= range_max``
in floating point (sqrt is correctly rounded and monotonic, so the bounds are
found once with ``nextafter``); the square root then runs on one value per
column instead of per pixel, and bins are filled with one ``reduceat`` over
the (monotonic) column -> bin map.  The +/-inf rule only runs when some bin
got no in-range value.  Results are bit-identical to
:func:`depth_to_scan_reference` (unit tests and the bench check it).

Intrinsics come from ``P`` (rectified image, as upstream) or ``K`` when
``P`` is all zeros; lens distortion is not modelled (depth images from the
Astra/Kinect drivers and our simulator are published rectified).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

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


@lru_cache(maxsize=8)
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


@dataclass(frozen=True)
class _ColumnPlan:
    """Per-camera constants of the fast path."""

    tan: np.ndarray          # (u - cx) / fx per column, float64
    order: np.ndarray        # columns sorted by bin (bins fall with u: reversed columns)
    starts: np.ndarray       # first position in ``order`` of each occupied bin
    occupied: np.ndarray     # the occupied bins, in the same order


@lru_cache(maxsize=8)
def _column_plan(cam: Intrinsics) -> _ColumnPlan:
    bins = column_bins(cam)
    order = np.argsort(bins, kind="stable")
    sorted_bins = bins[order]
    starts = np.flatnonzero(np.r_[True, sorted_bins[1:] != sorted_bins[:-1]])
    tan = (np.arange(cam.width, dtype=np.float64) - cam.cx) / cam.fx
    for a in (tan, order, starts):
        a.setflags(write=False)
    occupied = sorted_bins[starts]
    occupied.setflags(write=False)
    return _ColumnPlan(tan, order, starts, occupied)


def _sqrt_bound(limit: float, lower: bool) -> float:
    """The squared-range bound equivalent to comparing ``sqrt(s)`` with ``limit`` (m).

    lower: smallest s with ``sqrt(s) >= limit``; else: largest s with ``sqrt(s) <= limit``.
    """
    s = limit * limit
    if lower:
        while s > 0.0 and math.sqrt(np.nextafter(s, 0.0)) >= limit:
            s = float(np.nextafter(s, 0.0))
        while math.sqrt(s) < limit:
            s = float(np.nextafter(s, math.inf))
    else:
        while math.sqrt(np.nextafter(s, math.inf)) <= limit:
            s = float(np.nextafter(s, math.inf))
        while math.sqrt(s) > limit:
            s = float(np.nextafter(s, 0.0))
    return s


@lru_cache(maxsize=8)
def _range_bounds(range_min: float, range_max: float) -> tuple[float, float]:
    return _sqrt_bound(range_min, lower=True), _sqrt_bound(range_max, lower=False)


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
    band = depth[r0:r1]
    plan = _column_plan(cam)
    lo2, hi2 = _range_bounds(cfg.range_min, cfg.range_max)

    # 1. smallest in-range finite value: squared ranges s, reduce rows, then columns into bins.
    #    Only s < lo2 needs masking: a value above hi2 can only win where nothing is in range,
    #    and `found` below tells those apart; NaN (no data, 0 * inf) is skipped by fmin.
    with np.errstate(invalid="ignore", over="ignore"):
        z = band * 0.001 if band.dtype == np.uint16 else band.astype(np.float64)   # uint16 0 -> range 0
        s = np.multiply(z, plan.tan)
        np.multiply(s, s, out=s)
        np.multiply(z, z, out=z)
        s += z                                    # x^2 + z^2, the reference's expression
    # the +/-inf rule below needs an infinite range somewhere: an inf depth, or (float64 only)
    # a finite depth so large that its range overflows
    may_have_inf = band.dtype != np.uint16 and (
        bool(np.isinf(band).any()) or (band.dtype == np.float64 and bool(np.isinf(s).any())))
    if lo2 > 0.0:
        np.copyto(s, np.inf, where=s < lo2)
    best2 = np.fmin.reduceat(np.fmin.reduce(s, axis=0)[plan.order], plan.starts)
    found = best2 <= hi2
    ranges[plan.occupied] = np.sqrt(np.where(found, best2, np.nan))
    if found.all() or not may_have_inf:   # bins without an in-range value stay NaN
        return Scan(angle_min, angle_max, inc, ranges)
    best = np.full(w, np.inf)
    best[plan.occupied[found]] = ranges[plan.occupied[found]]
    r = _ranges_of_band(band, cam)
    bins = column_bins(cam)

    # 2. bins without one keep the last +/-inf in row-major order.
    is_inf = np.isinf(r)
    rows_idx = np.arange(r1 - r0)[:, None]
    last_row = np.where(is_inf, rows_idx, -1).max(axis=0)            # per column
    key = np.where(last_row >= 0, last_row * w + np.arange(w), -1)   # processing order
    best_key = np.full(w, -1, dtype=np.int64)
    np.maximum.at(best_key, bins, key)
    has_inf = best_key >= 0
    inf_val = np.where(has_inf, r.reshape(-1)[np.maximum(best_key, 0)], np.nan)

    ranges[:] = np.where(np.isfinite(best), ranges, inf_val)
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
