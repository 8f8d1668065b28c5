"""Benchmark: depth_to_scan (vectorised) against a per-pixel Python loop, 640x480.

``run(quick)`` returns rows for tools/bench.py; ``python bench_depth_to_scan.py``
prints them.  Both implementations run on the same synthetic image in the
same process, and their scans are asserted identical before timing counts.

A second reference bounds how fast the conversion can be in numpy at all: a
plain vectorised band-minimum of the same frame (ray lengths of the band with
the same formula, masked to the valid range, minimum over rows -- no bins, no
+/-inf rule).  The goal is at most 1.5x that, measured in the same run.
"""
from __future__ import annotations

import time

import numpy as np

from chefbot_bringup.depth_scan import (
    Intrinsics,
    ScanConfig,
    depth_to_scan,
    depth_to_scan_reference,
    scan_rows,
)

W, H = 640, 480
CAM = Intrinsics(fx=570.3, cx=319.5, cy=239.5, width=W, height=H)   # Kinect-like intrinsics
# A camera at 30 Hz leaves 33 ms per frame; the scan should take a small part of it.
GOAL_MS = 2.0
GOAL_BAND_RATIO = 1.5   # ours / plain numpy band-minimum


def band_minimum(depth: np.ndarray, cam: Intrinsics, cfg: ScanConfig) -> np.ndarray:
    """The plain vectorised floor: per-column minimum valid ray length of the band (m)."""
    r0, r1 = scan_rows(cam, cfg.scan_height)
    z = depth[r0:r1].astype(np.float64)
    x = z * ((np.arange(cam.width) - cam.cx) / cam.fx)
    r = np.sqrt(x * x + z * z)
    return np.where((r >= cfg.range_min) & (r <= cfg.range_max), r, np.inf).min(axis=0)


def _scene(seed: int = 0) -> np.ndarray:
    """A room-like depth image: walls 1-6 m, noise, 5 % NaN holes, a few +inf."""
    rng = np.random.default_rng(seed)
    u = np.arange(W)
    base = 3.0 + 2.0 * np.sin(u / 90.0) + rng.normal(0.0, 0.01, (H, W))
    depth = np.broadcast_to(base, (H, W)).astype(np.float32).copy()
    depth[rng.random((H, W)) < 0.05] = np.nan
    depth[rng.random((H, W)) < 0.01] = np.inf
    return depth


def _time_ms(fn, repeats: int) -> float:
    """Best-of-repeats wall time per call (ms): the least disturbed run."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def run(quick: bool = False) -> list[dict]:
    depth = _scene()
    rows = []
    for scan_height in (1, 10, 100):
        cfg = ScanConfig(scan_height=scan_height, range_min=0.45, range_max=10.0)
        ours = depth_to_scan(depth, CAM, cfg).ranges
        ref = depth_to_scan_reference(depth, CAM, cfg).ranges
        if not np.array_equal(ours, ref, equal_nan=True):
            raise AssertionError(f"scan_height={scan_height}: vectorised and reference scans differ")
        ours_ms = _time_ms(lambda cfg=cfg: depth_to_scan(depth, CAM, cfg), 20 if quick else 200)
        ref_ms = _time_ms(lambda cfg=cfg: depth_to_scan_reference(depth, CAM, cfg),
                          1 if quick or scan_height >= 100 else 3)
        rows.append({
            "bench": "depth_to_scan",
            "case": f"{W}x{H} scan_height={scan_height}",
            "metric": "ms/frame",
            "ours": round(ours_ms, 4),
            "reference": round(ref_ms, 3),
            "reference_name": "per-column Python loop",
            "goal": f"< {GOAL_MS} ms/frame (30 Hz camera leaves 33 ms) and identical scans",
            "met": ours_ms < GOAL_MS,
        })
        if scan_height == 10:
            repeats = 200 if quick else 3000
            # interleaved best-of: both see the same machine load
            ours_us = band_us = float("inf")
            for _ in range(5):
                ours_us = min(ours_us, _time_ms(lambda cfg=cfg: depth_to_scan(depth, CAM, cfg), repeats // 5) * 1e3)
                band_us = min(band_us, _time_ms(lambda cfg=cfg: band_minimum(depth, CAM, cfg), repeats // 5) * 1e3)
            rows.append({
                "bench": "depth_to_scan",
                "case": f"{W}x{H} scan_height=10 vs the numpy floor",
                "metric": "us/frame",
                "ours": round(ours_us, 2),
                "reference": round(band_us, 2),
                "reference_name": "plain numpy band-minimum",
                "goal": f"<= {GOAL_BAND_RATIO} x reference, identical scans",
                "met": ours_us <= GOAL_BAND_RATIO * band_us,
            })
    return rows


if __name__ == "__main__":
    import sys

    for row in run(quick="--quick" in sys.argv):
        print(f"{row['case']:<42} ours {row['ours']:8.3f} {row['metric']}   {row['reference_name']} "
              f"{row['reference']:9.2f}   ours/ref {row['ours'] / row['reference']:7.3f}   "
              f"goal met: {row['met']}")
