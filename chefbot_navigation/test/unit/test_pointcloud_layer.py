"""The point-cloud obstacle layer on synthetic clouds (no master)."""
import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.costmap import LETHAL, CostmapParams, LayeredCostmap
from chefbot_navigation.pointcloud_layer import CloudLayerParams, PointCloudLayer

INFO = GridInfo(0.05, 100, 60, -1.0, -1.5, 0.0)     # 5 x 3 m, origin (-1, -1.5)
CAMERA = np.array([0.0, 0.0, 0.26])                   # sensor origin in the map frame


def table_top(x0=1.5, x1=2.0, y0=-0.3, y1=0.3, z=0.35, step=0.01) -> np.ndarray:
    """Points of the underside of a table top (a horizontal plate at height z)."""
    xs, ys = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step))
    return np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)])


def floor(x1=3.0, step=0.02) -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(0.5, x1, step), np.arange(-0.5, 0.5, step))
    return np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])


def cell(x, y):
    r, c = INFO.world_to_cell(x, y)
    return int(r), int(c)


def test_marks_points_in_the_height_band_only():
    layer = PointCloudLayer(INFO, CloudLayerParams())
    pts = np.vstack([table_top(z=0.35),                       # in the band: an overhang the scan misses
                     table_top(x0=0.8, x1=1.0, z=0.80),        # above the robot: a normal table top
                     floor(),                                  # floor: never an obstacle
                     [[np.nan, 0.0, 0.3]]])                    # NaN rows ignored
    rays, marked = layer.update(pts, CAMERA)
    assert rays > 0 and marked > 0
    assert layer.grid[cell(1.75, 0.0)] and layer.grid[cell(1.52, 0.28)]
    assert not layer.grid[cell(0.9, 0.0)]                     # 0.80 m passes over the robot
    assert not layer.grid[cell(2.5, 0.0)] and not layer.grid[cell(0.6, 0.0)]   # floor only
    assert layer.grid.sum() == pytest.approx(10 * 12, rel=0.25)   # 0.5 x 0.6 m = 10 x 12 cells


def test_band_limits_and_speckle():
    p = CloudLayerParams(min_obstacle_height=0.03, max_obstacle_height=0.43, min_voxel_points=2)
    layer = PointCloudLayer(INFO, p)
    low = table_top(x0=1.0, x1=1.2, z=0.02)                   # below floor + 0.03: floor noise
    high = table_top(x0=1.3, x1=1.5, z=0.44)                  # above robot top + 0.05
    lone = np.array([[0.5, 0.5, 0.2]])                        # one stray point: speckle
    layer.update(np.vstack([low, high, lone]), CAMERA)
    assert not layer.grid.any()
    layer.update(table_top(x0=1.0, x1=1.2, z=0.04), CAMERA)
    assert layer.grid[cell(1.1, 0.0)]


def test_rays_under_an_overhang_do_not_clear_it_but_rays_through_it_do():
    layer = PointCloudLayer(INFO, CloudLayerParams())
    layer.update(table_top(z=0.35), CAMERA)
    assert layer.grid[cell(1.75, 0.0)]
    # the far wall seen *under* the table top, at camera height: rays pass below the top's voxels
    wall = np.column_stack([np.full(60, 2.4), np.linspace(-0.3, 0.3, 60), np.full(60, 0.27)])
    layer.update(wall, CAMERA)
    assert layer.grid[cell(1.75, 0.0)], "a ray under the table top erased it"
    assert layer.grid[cell(2.4, 0.0)]
    # the table was taken away: now rays reach a wall behind it *at the top's height*, through its voxels
    wall_high = np.column_stack([np.full(400, 3.5), np.tile(np.linspace(-0.3, 0.3, 40), 10),
                                 np.repeat(np.linspace(0.42, 0.50, 10), 40)])
    layer.update(wall_high, CAMERA)
    assert not layer.grid[cell(1.75, 0.0)]


def test_ranges_and_clear():
    layer = PointCloudLayer(INFO, CloudLayerParams(obstacle_range=1.0))
    layer.update(table_top(z=0.3), CAMERA)                    # 1.5..2.0 m away: beyond obstacle_range
    assert not layer.grid.any()
    layer = PointCloudLayer(INFO, CloudLayerParams())
    layer.update(table_top(z=0.3), CAMERA)
    layer.clear()
    assert not layer.grid.any() and not layer.voxels.any()
    assert layer.update(np.zeros((0, 3)), CAMERA) == (0, 0)
    with pytest.raises(ValueError, match="origin"):
        layer.update(table_top(), np.array([np.nan, 0, 0]))


@pytest.mark.parametrize("kwargs, what", [
    ({"min_obstacle_height": 0.5}, "max_obstacle_height"), ({"voxel_size": 0.0}, "voxel_size"),
    ({"obstacle_range": -1.0}, "obstacle_range"), ({"decimation": 0}, "decimation"), ({"topic": ""}, "topic")])
def test_params_validated(kwargs, what):
    with pytest.raises(ValueError, match=what):
        CloudLayerParams(**kwargs)


def test_costmap_keeps_cloud_marks_apart_from_scan_clearing():
    occ = OccupancyMap(INFO, np.zeros((INFO.height, INFO.width), np.int8))
    layers = LayeredCostmap(occ, CostmapParams())
    layers.cloud_layer = PointCloudLayer(INFO, CloudLayerParams())
    layers.cloud_layer.update(table_top(z=0.35), CAMERA)
    layers.layers_changed()
    assert layers.master().cost[cell(1.75, 0.0)] == LETHAL
    # a scan at camera height sees the wall at 2.8 m *under* the table: it clears its own marks only
    n = 61
    layers.update_scan(Pose2D(0.0, 0.0, 0.0), np.full(n, 2.8), -0.1, 0.2 / (n - 1), 0.45, 8.0)
    assert layers.master().cost[cell(1.75, 0.0)] == LETHAL
    assert layers.window(1.5, 0.0, 2.0, 2.0).cost_at(1.75, 0.0) == LETHAL
    layers.clear_obstacles()                                  # recovery's clear costmaps clears both
    assert layers.master().cost[cell(1.75, 0.0)] != LETHAL and not layers.cloud_layer.voxels.any()
