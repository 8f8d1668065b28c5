"""Time-optimal limit of a leg: closed forms for straight lines, turns and arcs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_navigation.time_limit import MotionLimits, path_length, profile_limit, rotation_time, simple_limit

LIM = MotionLimits(v_max=0.35, w_max=2.5, acc=0.8, dec=0.8, alpha=3.0)


def line(length: float, n: int = 200) -> np.ndarray:
    return np.column_stack((np.linspace(0.0, length, n), np.zeros(n)))


def test_straight_line_trapezoid() -> None:
    L = 4.0
    expected = L / 0.35 + 0.35 / 0.8          # accelerate + cruise + brake (symmetric a = d)
    assert profile_limit(line(L, 4001), LIM) == pytest.approx(expected, rel=2e-3)
    assert simple_limit(line(L), LIM) == pytest.approx(L / 0.35)


def test_short_line_triangle() -> None:
    L = 0.05                                   # never reaches v_max: t = 2 sqrt(L / a)
    assert profile_limit(line(L, 2001), LIM) == pytest.approx(2.0 * math.sqrt(L / 0.8), rel=5e-3)


def test_rotation_time_trapezoid_and_triangle() -> None:
    assert rotation_time(math.pi, 2.5, 3.0) == pytest.approx(math.pi / 2.5 + 2.5 / 3.0)
    assert rotation_time(0.5, 2.5, 3.0) == pytest.approx(2.0 * math.sqrt(0.5 / 3.0))
    assert rotation_time(-0.5, 2.5, 3.0) == rotation_time(0.5, 2.5, 3.0)


def test_end_turns_are_added() -> None:
    pts = line(1.0, 1001)
    base = profile_limit(pts, LIM)
    with_turns = profile_limit(pts, LIM, start_yaw=math.pi / 2, goal_yaw=-math.pi / 2)
    assert with_turns - base == pytest.approx(2 * rotation_time(math.pi / 2, 2.5, 3.0))
    assert simple_limit(pts, LIM, math.pi / 2, -math.pi / 2) == pytest.approx(1.0 / 0.35 + math.pi / 2.5)


def test_tight_arc_is_limited_by_w_max() -> None:
    r = 0.1                                    # w_max / kappa = 0.25 m/s < v_max
    th = np.linspace(0.0, math.pi, 2001)
    arc = np.column_stack((r * np.cos(th), r * np.sin(th)))
    t = profile_limit(arc, LIM)
    assert t >= math.pi * r / 0.25
    assert t == pytest.approx(math.pi * r / 0.25 + 0.25 / 0.8, rel=0.02)
    assert path_length(arc) == pytest.approx(math.pi * r, rel=1e-4)


def test_profile_is_never_faster_than_length_over_vmax() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        pts = np.cumsum(rng.uniform(-0.5, 0.5, (30, 2)), axis=0)
        assert profile_limit(pts, LIM) >= path_length(pts) / LIM.v_max - 1e-9


@pytest.mark.parametrize("bad", [dict(v_max=0.0), dict(w_max=-1.0), dict(acc=float("nan"))])
def test_bad_limits_are_refused(bad) -> None:
    with pytest.raises(ValueError):
        MotionLimits(**bad)


def test_bad_paths_are_refused() -> None:
    with pytest.raises(ValueError, match="empty"):
        profile_limit(np.zeros((0, 2)), LIM)
    with pytest.raises(ValueError, match="non-finite"):
        simple_limit(np.array([[0.0, 0.0], [np.nan, 1.0]]), LIM)
