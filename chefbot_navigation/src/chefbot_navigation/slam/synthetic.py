"""Synthetic 2-D worlds, scans and noisy odometry for SLAM tests and the benchmark (pure numpy).

A world is a set of wall segments (M, 4) = (x0, y0, x1, y1) m.  ``cast``
returns the first hit along each ray (``inf`` when nothing is within range,
REP 117's "no return").  ``noisy_odometry`` turns a true trajectory into what
wheel odometry would report: every step's translation and rotation scaled by
a random factor and a slow heading bias added, so the error grows with the
distance driven as with real encoders.  For recorded bags, ``OdometryNoise``
adds such errors to a stream of odometry poses (``OdometryNoise.miscalibrated``:
a wrong wheel radius and base width and a heading drift, with or without random
noise) and ``Decimate`` thins the scans (``ros_slam_bag.run_bag``'s filters).
"""
from __future__ import annotations

import math

import numpy as np

from chefbot_common.geometry import Pose2D
from chefbot_navigation.slam.scan import scan_from_ranges


def box_segments(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Four segments of an axis-aligned rectangle (m)."""
    return np.array([[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]], dtype=float)


def cast(segments: np.ndarray, origin: tuple[float, float], angles: np.ndarray, max_range: float) -> np.ndarray:
    """Range (m) of the first segment hit along each ray; ``inf`` beyond ``max_range``."""
    seg = np.asarray(segments, dtype=float).reshape(-1, 4)
    ox, oy = origin
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    ax, ay = seg[None, :, 0], seg[None, :, 1]
    ex, ey = seg[None, :, 2] - ax, seg[None, :, 3] - ay
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((ax - ox) * ey - (ay - oy) * ex) / den
        u = ((ax - ox) * dy - (ay - oy) * dx) / den
    ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    r = np.where(ok, t, np.inf).min(axis=1)
    r[r > max_range] = np.inf
    return r


def noisy_odometry(truth: list[Pose2D], rng: np.random.Generator, scale_sigma: float = 0.03,
                   yaw_scale_sigma: float = 0.03, yaw_bias: float = 0.01) -> list[Pose2D]:
    """Odometry poses from true poses: per-step factors ~ N(1, sigma), a heading bias in rad/m."""
    out = [truth[0]]
    for a, b in zip(truth[:-1], truth[1:], strict=True):
        d = a.inverse().compose(b)
        dist = math.hypot(d.x, d.y)
        f = 1.0 + rng.normal(0.0, scale_sigma)
        g = 1.0 + rng.normal(0.0, yaw_scale_sigma)
        noisy = Pose2D(d.x * f, d.y * f, d.yaw * g + yaw_bias * dist)
        out.append(out[-1].compose(noisy))
    return out


def square_corridor(side: float = 8.0, width: float = 1.6) -> np.ndarray:
    """A closed square corridor (outer side ``side`` m, ``width`` m wide) with a few pillars as features."""
    h = side / 2.0
    segs = [box_segments(-h, -h, h, h), box_segments(-h + width, -h + width, h - width, h - width)]
    for cx, cy in ((-1.0, -h + 0.1), (h - 0.1, 1.5), (0.5, h - 0.1), (-h + 0.1, -0.5), (2.0, -h + width - 0.1)):
        segs.append(box_segments(cx - 0.1, cy - 0.1, cx + 0.1, cy + 0.1))
    return np.vstack(segs)


def square_route(side: float = 8.0, width: float = 1.6, laps: float = 2.0, step: float = 0.05) -> list[Pose2D]:
    """True poses along the centre line of :func:`square_corridor`, counter-clockwise, ``laps`` times."""
    c = side / 2.0 - width / 2.0
    corners = [(-c, -c), (c, -c), (c, c), (-c, c)]
    poses: list[Pose2D] = []
    total = int(round(4 * laps))
    for k in range(total):
        (x0, y0), (x1, y1) = corners[k % 4], corners[(k + 1) % 4]
        yaw = math.atan2(y1 - y0, x1 - x0)
        n = int(round(math.hypot(x1 - x0, y1 - y0) / step))
        poses += [Pose2D(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n)]
        for i in range(1, 10):       # turn in place at the corner
            poses.append(Pose2D(x1, y1, yaw + (math.pi / 2) * i / 10))
    return poses


def drive_square_corridor(slam, seed: int = 3, yaw_bias: float = 0.02) -> tuple[np.ndarray, list[Pose2D], list[Pose2D]]:
    """Feed ``slam`` (a ``Slam``: ``add_scan(t, scan, odom)``) two laps of :func:`square_corridor` seen by
    a 180 deg, 6 m lidar with :func:`noisy_odometry` (``seed``, ``yaw_bias``), one scan per 0.1 s;
    returns (segments, true poses, odometry poses)."""
    segs, truth = square_corridor(), square_route(laps=2.0)
    odom = noisy_odometry(truth, np.random.default_rng(seed), yaw_bias=yaw_bias)
    n, fov, rmax = 180, math.pi, 6.0
    angles = -fov / 2 + fov * np.arange(n) / n
    for k, (tp, op) in enumerate(zip(truth, odom, strict=True)):
        r = cast(segs, (tp.x, tp.y), angles + tp.yaw, rmax)
        slam.add_scan(0.1 * k, scan_from_ranges(r, -fov / 2, fov / n, 0.05, rmax, Pose2D(), 5.5), op)
    return segs, truth, odom


# the miscalibrated odometry of issue 30: 3 % too much distance, 2 % too much turn, 1.5 deg/m heading drift
MISCALIBRATION_SCALE = 0.03
MISCALIBRATION_TURN = 0.02
MISCALIBRATION_DRIFT = math.radians(1.5)     # rad/m


class OdometryNoise:
    """Stateful filter ``f(t, pose) -> pose`` adding wheel-odometry error to a stream of odometry poses.

    Each increment between consecutive calls is scaled by ``1 + N(0, scale_sigma)``
    (translation) and ``1 + N(0, yaw_scale_sigma)`` (rotation), with fixed
    systematic factors ``scale_bias`` / ``yaw_scale_bias`` (a wheel radius or
    base width mismatch) and a heading drift of ``yaw_bias`` rad per metre.
    With both sigmas 0 it is a pure, deterministic bias (the seed is unused).
    The random part is drawn per increment, so the same sigmas hurt more when
    the stream is thinned (one 0.7 m increment shares one draw).
    Used to test and benchmark SLAM with worse odometry than a recording has.
    """

    def __init__(self, seed: int = 0, scale_sigma: float = 0.02, yaw_scale_sigma: float = 0.05,
                 scale_bias: float = 0.02, yaw_scale_bias: float = 0.05, yaw_bias: float = 0.02) -> None:
        self.rng = np.random.default_rng(seed)
        self.s, self.ys, self.sb, self.yb, self.drift = scale_sigma, yaw_scale_sigma, scale_bias, yaw_scale_bias, \
            yaw_bias
        self.last_raw: Pose2D | None = None
        self.out = Pose2D()

    def __call__(self, t: float, pose: Pose2D) -> Pose2D:
        if self.last_raw is None:
            self.last_raw, self.out = pose, pose
            return pose
        d = self.last_raw.inverse().compose(pose)
        self.last_raw = pose
        dist = math.hypot(d.x, d.y)
        f = 1.0 + self.sb + self.rng.normal(0.0, self.s)
        g = 1.0 + self.yb + self.rng.normal(0.0, self.ys)
        self.out = self.out.compose(Pose2D(d.x * f, d.y * f, d.yaw * g + self.drift * dist))
        return self.out

    @classmethod
    def miscalibrated(cls, seed: int | None = None) -> OdometryNoise:
        """Issue 30's systematic error (``MISCALIBRATION_*``: 3 % scale, 2 % turn, 1.5 deg/m drift); with a
        ``seed``, also this class's default random per-increment noise drawn from it."""
        sigmas = {} if seed is not None else {"scale_sigma": 0.0, "yaw_scale_sigma": 0.0}
        return cls(seed=seed or 0, scale_bias=MISCALIBRATION_SCALE, yaw_scale_bias=MISCALIBRATION_TURN,
                   yaw_bias=MISCALIBRATION_DRIFT, **sigmas)


class Decimate:
    """Stateful scan filter ``f(t, odometry pose) -> keep?``: keeps the first scan and then each scan whose
    odometry moved at least ``min_dist`` m or turned at least ``min_yaw`` rad from the last kept one
    (a recording taken with sparser scans; ``ros_slam_bag.run_bag(scan_filter=...)``)."""

    def __init__(self, min_dist: float, min_yaw: float) -> None:
        if not (min_dist > 0 and min_yaw > 0):
            raise ValueError(f"min_dist and min_yaw must be > 0, got {min_dist}, {min_yaw}")
        self.min_dist, self.min_yaw = min_dist, min_yaw
        self.last: Pose2D | None = None
        self.kept = 0

    def __call__(self, t: float, pose: Pose2D) -> bool:
        if self.last is not None:
            d = self.last.inverse().compose(pose)
            if math.hypot(d.x, d.y) < self.min_dist and abs(d.yaw) < self.min_yaw:
                return False
        self.last = pose
        self.kept += 1
        return True
