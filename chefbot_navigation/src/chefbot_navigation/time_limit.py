"""Time-optimal limit of a delivery leg (pure): how fast could a differential-drive robot with these
limits follow this path at best?  Legs are judged against it (a leg may take at most ``k`` times it).

Two measures:

* :func:`simple_limit` -- the interim definition of the end-to-end issue: path length / v_max plus
  every heading change (start turn, turns along the path, final turn) at the maximum angular rate.
* :func:`profile_limit` -- a forward-backward velocity profile along the path: speed capped by v_max
  and by w_max / curvature, accelerating at ``acc`` and braking at ``dec`` (m/s^2), from and to rest;
  plus turning on the spot at the start and the end (trapezoidal, ``alpha`` rad/s^2).  It is the
  larger (stricter to reach, fairer to judge) of the two.

Units: m, s, rad.  The path is a polyline (N, 2) in m (e.g. the global plan, or the straight-line /
grid-shortest route of a test world).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chefbot_common.geometry import wrap_angle


@dataclass(frozen=True)
class MotionLimits:
    """Robot limits: speeds (m/s, rad/s) and accelerations (m/s^2, rad/s^2)."""

    v_max: float = 0.35
    w_max: float = 2.5
    acc: float = 0.8
    dec: float = 0.8
    alpha: float = 3.0

    def __post_init__(self) -> None:
        for name in ("v_max", "w_max", "acc", "dec", "alpha"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")


def _clean(points: np.ndarray) -> np.ndarray:
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise ValueError("path has non-finite points")
    if len(pts) == 0:
        raise ValueError("path is empty")
    keep = np.concatenate(([True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9))
    return pts[keep]


def path_length(points: np.ndarray) -> float:
    """Length (m) of a polyline (N, 2)."""
    pts = _clean(points)
    return float(np.sum(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0


def rotation_time(angle: float, w_max: float, alpha: float) -> float:
    """Shortest time (s) to turn on the spot by ``angle`` rad from rest to rest (trapezoid / triangle)."""
    a = abs(angle)
    if a < 1e-12:
        return 0.0
    if a >= w_max * w_max / alpha:          # reaches w_max
        return a / w_max + w_max / alpha
    return 2.0 * math.sqrt(a / alpha)


def _headings(pts: np.ndarray) -> np.ndarray:
    d = np.diff(pts, axis=0)
    return np.arctan2(d[:, 1], d[:, 0])


def _end_turns(pts: np.ndarray, start_yaw: float | None, goal_yaw: float | None) -> tuple[float, float]:
    if len(pts) < 2:
        turn = 0.0 if start_yaw is None or goal_yaw is None else abs(wrap_angle(goal_yaw - start_yaw))
        return turn, 0.0
    h = _headings(pts)
    first = 0.0 if start_yaw is None else abs(wrap_angle(h[0] - start_yaw))
    last = 0.0 if goal_yaw is None else abs(wrap_angle(goal_yaw - h[-1]))
    return first, last


def simple_limit(points: np.ndarray, limits: MotionLimits, start_yaw: float | None = None,
                 goal_yaw: float | None = None) -> float:
    """Path length / v_max + total heading change / w_max (s)."""
    pts = _clean(points)
    first, last = _end_turns(pts, start_yaw, goal_yaw)
    along = float(np.sum(np.abs(wrap_angle(np.diff(_headings(pts)))))) if len(pts) > 2 else 0.0
    return path_length(pts) / limits.v_max + (first + along + last) / limits.w_max


def profile_limit(points: np.ndarray, limits: MotionLimits, start_yaw: float | None = None,
                  goal_yaw: float | None = None) -> float:
    """Time (s) of the forward-backward velocity profile along the path, plus the turns on the spot
    at both ends; never less than :func:`simple_limit`'s translation part."""
    pts = _clean(points)
    first, last = _end_turns(pts, start_yaw, goal_yaw)
    turns = rotation_time(first, limits.w_max, limits.alpha) + rotation_time(last, limits.w_max, limits.alpha)
    if len(pts) < 2:
        return turns
    ds = np.hypot(*np.diff(pts, axis=0).T)
    # curvature at inner vertices: heading change over the mean of the two adjacent segments
    vcap = np.full(len(pts), limits.v_max)
    if len(pts) > 2:
        dth = np.abs(wrap_angle(np.diff(_headings(pts))))
        kappa = dth / (0.5 * (ds[:-1] + ds[1:]))
        with np.errstate(divide="ignore"):
            vcap[1:-1] = np.minimum(limits.v_max, np.where(kappa > 0, limits.w_max / kappa, np.inf))
    vcap[0] = vcap[-1] = 0.0
    v = vcap.copy()
    for i in range(1, len(v)):                      # forward: accelerate
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2.0 * limits.acc * ds[i - 1]))
    for i in range(len(v) - 2, -1, -1):             # backward: brake
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * limits.dec * ds[i]))
    vm = 0.5 * (v[:-1] + v[1:])
    # constant acceleration within a segment: t = 2 ds / (v0 + v1); a vertex where v is 0 mid-path
    # (a corner taken on the spot) costs a turn on the spot instead
    seg_t = np.where(vm > 1e-9, ds / np.maximum(vm, 1e-9), np.inf)
    t = float(np.sum(seg_t))
    if not math.isfinite(t):
        raise ValueError("velocity profile stalls on a zero-length-free path")
    return t + turns
