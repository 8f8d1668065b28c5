"""Costmap layers: static conversion, inflation values, marking and clearing by ray tracing."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.costmap import INSCRIBED, LETHAL, NO_INFORMATION, CostmapParams, LayeredCostmap, inflate


def empty(n: int = 100, res: float = 0.05) -> OccupancyMap:
    return OccupancyMap(GridInfo(res, n, n, 0.0, 0.0, 0.0), np.zeros((n, n), dtype=np.int8))


def test_static_layer_values() -> None:
    occ = empty(10)
    occ.data[0, 0], occ.data[1, 1], occ.data[2, 2], occ.data[3, 3] = 100, 65, 64, -1
    lc = LayeredCostmap(occ, CostmapParams())
    assert lc.static[0, 0] == LETHAL and lc.static[1, 1] == LETHAL
    assert lc.static[2, 2] == 0 and lc.static[3, 3] == NO_INFORMATION
    lc2 = LayeredCostmap(occ, CostmapParams(track_unknown_space=False))
    assert lc2.static[3, 3] == 0


def test_inflation_values() -> None:
    p = CostmapParams(robot_radius=0.2, inflation_radius=0.5, cost_scaling_factor=5.0)
    base = np.zeros((101, 101), dtype=np.uint8)
    base[50, 50] = LETHAL
    out = inflate(base, 0.05, p)
    assert out[50, 50] == LETHAL
    assert out[50, 54] == INSCRIBED               # 0.20 m: inscribed
    d = 0.30
    assert out[50, 56] == int(252 * math.exp(-5.0 * (d - 0.2)))
    assert out[50, 60] == int(252 * math.exp(-5.0 * (0.5 - 0.2)))   # at the inflation radius
    assert out[50, 61] == 0                       # beyond it
    diag = np.hypot(3, 4) * 0.05                  # 0.25 m
    assert out[53, 54] == int(252 * math.exp(-5.0 * (diag - 0.2)))
    # monotone decay with distance
    row = out[50, 55:62].astype(int)
    assert np.all(np.diff(row) <= 0)


def test_unknown_only_inflated_within_inscribed_radius() -> None:
    base = np.full((21, 21), NO_INFORMATION, dtype=np.uint8)
    base[10, 10] = LETHAL
    out = inflate(base, 0.05, CostmapParams(robot_radius=0.1, inflation_radius=0.5))
    assert out[10, 12] == INSCRIBED and out[10, 16] == NO_INFORMATION


def test_marking_and_clearing_by_ray_tracing() -> None:
    lc = LayeredCostmap(empty(), CostmapParams(obstacle_range=2.5, raytrace_range=3.0))
    sensor = Pose2D(1.0, 2.5, 0.0)
    angles = np.array([-0.2, 0.0, 0.2])
    # three hits at 1.5 m
    lc.update_scan(sensor, np.full(3, 1.5), -0.2, 0.2, 0.1, 4.0)
    hx = 1.0 + 1.5 * np.cos(angles)
    hy = 2.5 + 1.5 * np.sin(angles)
    row, col = lc.info.world_to_cell(hx, hy)
    assert lc.obstacles[row, col].all()
    assert lc.master().cost[row, col].tolist() == [LETHAL] * 3
    # the obstacle moves away: a longer reading through the old cells clears them
    lc.update_scan(sensor, np.full(3, 2.2), -0.2, 0.2, 0.1, 4.0)
    assert not lc.obstacles[row, col].any()
    r2, c2 = lc.info.world_to_cell(1.0 + 2.2 * np.cos(angles), 2.5 + 2.2 * np.sin(angles))
    assert lc.obstacles[r2, c2].all()
    # +inf (nothing in range) clears without marking
    lc.update_scan(sensor, np.full(3, np.inf), -0.2, 0.2, 0.1, 4.0)
    assert lc.obstacles.sum() == 0


def test_ranges_beyond_obstacle_range_clear_but_do_not_mark() -> None:
    lc = LayeredCostmap(empty(), CostmapParams(obstacle_range=1.0, raytrace_range=3.0))
    lc.update_scan(Pose2D(0.5, 2.5, 0.0), np.array([2.0]), 0.0, 0.1, 0.1, 4.0)
    assert lc.obstacles.sum() == 0


def test_nan_and_short_ranges_ignored() -> None:
    lc = LayeredCostmap(empty(), CostmapParams())
    lc.mark_points(np.array([2.0]), np.array([2.5]))
    lc.update_scan(Pose2D(0.5, 2.5, 0.0), np.array([np.nan, 0.05]), 0.0, 0.0, 0.45, 4.0)
    assert lc.obstacles.sum() == 1


def test_static_obstacles_survive_clearing() -> None:
    occ = empty()
    occ.data[50, 80] = 100     # (4.0, 2.5)
    lc = LayeredCostmap(occ, CostmapParams())
    lc.update_scan(Pose2D(0.5, 2.5, 0.0), np.array([np.inf]), 0.0, 0.1, 0.1, 4.0)
    assert lc.master().cost[50, 80] == LETHAL
    lc.clear_obstacles()
    assert lc.master().cost[50, 80] == LETHAL


def test_unknown_static_cells_a_ray_passes_through_count_as_free() -> None:
    """A SLAM map's unseen hole in an aisle (two unknown cells) stops blocking once a scan has seen
    through it, in the global costmap and in the controller's window; a hit there is an obstacle;
    'clear costmaps' forgets what was seen (as costmap_2d's obstacle layer over its static layer)."""
    occ = empty()
    occ.data[50, 60:62] = -1                   # (3.0-3.1, 2.5): unknown
    occ.data[70, 60] = -1                      # (3.0, 3.5): unknown, off the ray
    lc = LayeredCostmap(occ, CostmapParams(robot_radius=0.1, inflation_radius=0.3))
    assert (lc.master().cost[50, 60:62] == NO_INFORMATION).all()
    lc.update_scan(Pose2D(0.5, 2.5, 0.0), np.array([np.inf]), 0.0, 0.1, 0.1, 4.0)
    assert (lc.master().cost[50, 60:62] == 0).all() and lc.master().cost[70, 60] == NO_INFORMATION
    win = lc.window(3.0, 2.5, 1.0, 1.0)
    r, c = win.info.world_to_cell(3.02, 2.52)
    assert win.cost[r, c] == 0
    assert lc.window(3.0, 2.5, 1.0, 1.0, static_only=True).cost[r, c] == NO_INFORMATION
    lc.update_scan(Pose2D(1.5, 2.5, 0.0), np.array([1.52]), 0.0, 0.1, 0.1, 4.0)   # something stands there
    assert lc.master().cost[50, 60] == LETHAL
    lc.clear_obstacles()
    assert (lc.master().cost[50, 60:62] == NO_INFORMATION).all()


def test_window_matches_global_costmap() -> None:
    occ = empty()
    occ.data[40:45, 40:45] = 100
    lc = LayeredCostmap(occ, CostmapParams())
    lc.mark_points(np.array([3.0]), np.array([3.0]))
    full = lc.master()
    win = lc.window(2.5, 2.5, 3.0, 3.0)
    assert win.cost.shape == (60, 60)
    xs, ys = np.meshgrid(np.linspace(1.1, 3.9, 20), np.linspace(1.1, 3.9, 20))
    np.testing.assert_array_equal(win.cost_at(xs, ys), full.cost_at(xs, ys))
    # off the map: unknown
    edge = lc.window(0.0, 0.0, 2.0, 2.0)
    assert edge.cost_at(-0.5, -0.5) == NO_INFORMATION


def test_occupancy_translation() -> None:
    lc = LayeredCostmap(empty(10), CostmapParams())
    cm = lc.master()
    cm.cost[0, :5] = [0, 1, 252, INSCRIBED, LETHAL]
    cm.cost[1, 0] = NO_INFORMATION
    occ = cm.to_occupancy()
    assert occ.data[0, :5].tolist() == [0, 1, 98, 99, 100] and occ.data[1, 0] == -1


@pytest.mark.parametrize("field,value", [("robot_radius", 0.0), ("inflation_radius", 0.1),
                                         ("cost_scaling_factor", -1.0), ("lethal_threshold", 0)])
def test_bad_params(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        CostmapParams(**{field: value})
