"""Unit tests of chefbot_gui.geometry (no ROS, no Qt)."""
from __future__ import annotations

import math

import pytest

from chefbot_common.grid import GridInfo
from chefbot_gui import geometry as g


def test_remaining_without_plan_is_straight_line() -> None:
    assert g.remaining_distance((0, 0), (3, 4)) == pytest.approx(5.0)
    assert g.remaining_distance((0, 0), (3, 4), [(1, 1)]) == pytest.approx(5.0)


def test_remaining_follows_plan_from_the_closest_point() -> None:
    plan = [(0, 0), (4, 0), (4, 3)]
    # robot 0.5 m beside the first leg, at x = 1: 0.5 + 3 + 3
    assert g.remaining_distance((1, 0.5), (4, 3), plan) == pytest.approx(6.5)
    # on the second leg
    assert g.remaining_distance((4, 1), (4, 3), plan) == pytest.approx(2.0)
    # a plan that stops short of the goal adds the last gap
    assert g.remaining_distance((0, 0), (4, 3.5), plan) == pytest.approx(7.5)


def test_path_length_and_eta() -> None:
    assert g.path_length([(0, 0), (3, 4), (3, 5)]) == pytest.approx(6.0)
    assert g.path_length([]) == 0.0
    assert g.eta_seconds(3.0, 0.25) == pytest.approx(12.0)
    assert g.eta_seconds(3.0, 0.0) == math.inf


def test_nearest_index() -> None:
    assert g.nearest_index((0, 0), []) == -1
    assert g.nearest_index((5, 0), [(0, 0), (4, 1), (6, 0)]) == 2
    assert g.nearest_index((0, 0), [(1, 0), (0, 1)]) == 0  # first on ties


def test_grid_world_image_round_trip() -> None:
    info = GridInfo(resolution=0.05, width=328, height=268, origin_x=-3.7, origin_y=-6.7)
    col, row = info.world_to_grid(-3.7, -6.7)
    assert (col, row) == pytest.approx((0.0, 0.0))
    u, v = info.world_to_image(0.0, 0.0)
    assert u == pytest.approx(74.0)
    assert v == pytest.approx(268 - 134.0)
    assert info.image_to_world(u, v) == pytest.approx((0.0, 0.0))
    rotated = GridInfo(0.1, 10, 10, 1.0, 2.0, math.pi / 2)
    assert rotated.grid_to_world(*rotated.world_to_grid(1.3, 2.7)) == pytest.approx((1.3, 2.7))
    assert rotated.world_to_grid(1.0, 3.0) == pytest.approx((10.0, 0.0))


def test_grid_to_grey_colours_and_flips() -> None:
    # 2 × 2 grid, row 0 (bottom): free, occupied; row 1 (top): unknown, 50 %
    grey = g.grid_to_grey([0, 100, -1, 50], 2, 2)
    assert grey == bytes([160, 127, 255, 0])
    with pytest.raises(ValueError):
        g.grid_to_grey([0, 0, 0], 2, 2)
