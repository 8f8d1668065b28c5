"""The other robots' layer: footprints where they are, paths ahead as costs, stale robots dropped."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.costmap import INSCRIBED, LETHAL, ROBOT_COST, CostmapParams, LayeredCostmap
from chefbot_navigation.footprint import Footprint
from chefbot_navigation.planners import PlannerParams, make_planner
from chefbot_navigation.robots_layer import OtherRobot, RobotsLayer, RobotsLayerParams

RES = 0.05
INFO = GridInfo(RES, 120, 80, -1.0, -1.0)          # 6 m x 4 m, x in -1..5, y in -1..3
RECT = np.array([[-0.2, -0.15], [0.2, -0.15], [0.2, 0.15], [-0.2, 0.15]])   # 0.4 m x 0.3 m


def cells_world(mask: np.ndarray) -> np.ndarray:
    """Centres (K, 2) m of the marked cells."""
    row, col = np.nonzero(mask)
    x, y = INFO.cell_to_world(row, col)
    return np.column_stack((x, y))


def to_body(pts: np.ndarray, x: float, y: float, yaw: float) -> np.ndarray:
    """World points in the frame of a robot at (x, y, yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    d = pts - np.array([x, y])
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))


def layer(**kw) -> RobotsLayer:
    return RobotsLayer(INFO, RobotsLayerParams(**{"footprint_padding": 0.0, **kw}), own_name="chefbot1")


@pytest.mark.parametrize("yaw", [0.0, math.pi / 2, 0.6])
def test_footprint_rasterised_where_the_robot_is(yaw: float) -> None:
    lay = layer()
    assert lay.update(OtherRobot("chefbot2", 10.0, 2.0, 1.0, yaw, footprint=RECT))
    lay.refresh(10.0)
    body = to_body(cells_world(lay.grid), 2.0, 1.0, yaw)
    # every marked cell centre lies within half a cell diagonal of the rectangle
    tol = RES * math.sqrt(2) / 2 + 1e-9
    assert np.all(np.abs(body[:, 0]) <= 0.2 + tol) and np.all(np.abs(body[:, 1]) <= 0.15 + tol)
    # and every cell centre well inside it is marked
    row, col = np.mgrid[0:INFO.height, 0:INFO.width]
    x, y = INFO.cell_to_world(row.ravel(), col.ravel())
    b = to_body(np.column_stack((x, y)), 2.0, 1.0, yaw)
    inner = (np.abs(b[:, 0]) < 0.2 - tol) & (np.abs(b[:, 1]) < 0.15 - tol)
    assert inner.sum() > 20
    assert lay.grid.ravel()[inner].all()
    # area within 20 % of 0.12 m^2
    assert lay.grid.sum() * RES ** 2 == pytest.approx(0.4 * 0.3, rel=0.1)


def test_padding_and_round_robots() -> None:
    lay = layer(footprint_padding=0.1)
    lay.update(OtherRobot("chefbot2", 0.0, 1.0, 1.0, 0.0, radius=0.2))      # no polygon: a circle
    lay.refresh(0.0)
    d = np.hypot(*(cells_world(lay.grid) - [1.0, 1.0]).T)
    assert d.max() <= 0.3 + RES                       # radius + padding (+ the polygon's cell rounding)
    assert lay.grid.sum() * RES ** 2 == pytest.approx(math.pi * 0.3 ** 2, rel=0.15)


def test_own_state_and_older_states_are_ignored() -> None:
    lay = layer()
    assert not lay.update(OtherRobot("chefbot1", 0.0, 1.0, 1.0, 0.0, footprint=RECT))
    assert lay.update(OtherRobot("chefbot2", 5.0, 1.0, 1.0, 0.0, footprint=RECT))
    assert not lay.update(OtherRobot("chefbot2", 4.0, 3.0, 1.0, 0.0, footprint=RECT))   # out of order
    lay.refresh(5.0)
    assert np.hypot(*(cells_world(lay.grid).mean(axis=0) - [1.0, 1.0])) < RES


def test_stale_robots_are_dropped_after_the_timeout() -> None:
    lay = layer(timeout=2.0)
    lay.update(OtherRobot("chefbot2", 10.0, 1.0, 1.0, 0.0, footprint=RECT))
    lay.update(OtherRobot("chefbot3", 11.5, 3.0, 1.0, 0.0, footprint=RECT))
    assert lay.refresh(11.9) == [] and lay.grid.any()
    assert lay.refresh(12.1) == ["chefbot2"]
    assert set(lay.robots) == {"chefbot3"}
    assert cells_world(lay.grid)[:, 0].min() > 2.5        # only chefbot3's cells remain
    assert lay.refresh(13.6) == ["chefbot3"]
    assert not lay.grid.any() and not lay.cost.any()


def test_pose_is_extrapolated_along_the_velocity_for_at_most_max_extrapolation() -> None:
    lay = layer(max_extrapolation=0.5)
    lay.update(OtherRobot("chefbot2", 10.0, 1.0, 1.0, 0.0, v=0.4, footprint=RECT))
    lay.refresh(10.25)                                         # 0.1 m further
    assert cells_world(lay.grid).mean(axis=0)[0] == pytest.approx(1.1, abs=RES / 2)
    lay.refresh(11.5)                                          # capped at 0.5 s: 0.2 m
    assert cells_world(lay.grid).mean(axis=0)[0] == pytest.approx(1.2, abs=RES / 2)
    r = OtherRobot("x", 0.0, 0.0, 0.0, 0.0, v=0.5, w=1.0)
    x, y, yaw = r.pose_at(math.pi / 2, 10.0)                  # a quarter circle of radius 0.5 m
    assert (x, y, yaw) == pytest.approx((0.5, 0.5, math.pi / 2), abs=1e-9)


def test_path_ahead_gets_the_path_cost_up_to_the_horizon() -> None:
    lay = layer(path_horizon=2.0, path_cost=100)
    path = np.array([[1.0, 1.0], [4.5, 1.0]])
    lay.update(OtherRobot("chefbot2", 0.0, 0.5, 1.0, 0.0, footprint=RECT, radius=0.25, path=path))
    lay.refresh(0.0)
    on = cells_world(lay.cost == 100)
    # 2 m from the robot at x = 0.5, plus the round end of a robot-wide line (the robot's body there)
    assert on[:, 0].max() == pytest.approx(2.5 + 0.25, abs=2 * RES)
    assert np.abs(on[:, 1] - 1.0).max() <= 0.25 + RES                   # as wide as the robot
    assert not (lay.grid & (lay.cost > 0)).any()                        # the footprint stays lethal only
    assert layer(path_horizon=0.0).refresh(0.0) == []


@pytest.mark.parametrize("bad", [
    OtherRobot("chefbot2", 0.0, math.nan, 1.0, 0.0, footprint=RECT),
    OtherRobot("chefbot2", 0.0, 1.0, 1.0, 0.0),                          # no shape at all
    OtherRobot("chefbot2", 0.0, 1.0, 1.0, 0.0, footprint=RECT[:2]),
    OtherRobot("chefbot2", 0.0, 1.0, 1.0, 0.0, footprint=RECT, path=np.array([[1.0, math.inf]])),
    OtherRobot("", 0.0, 1.0, 1.0, 0.0, footprint=RECT),
])
def test_unusable_states_are_refused_and_not_kept(bad: OtherRobot) -> None:
    lay = layer()
    with pytest.raises(ValueError):
        lay.update(bad)
    assert not lay.robots


def test_robots_far_off_the_map_do_not_break_the_fill() -> None:
    lay = layer()
    lay.update(OtherRobot("chefbot2", 0.0, 1e7, -1e7, 0.0, footprint=RECT, path=np.array([[-1e7, 1e7]])))
    lay.refresh(0.0)
    assert not lay.grid.any()


@pytest.mark.parametrize("params", [dict(timeout=0.0), dict(path_cost=253), dict(path_cost=0), dict(topic=""),
                                    dict(footprint_padding=-0.1), dict(max_extrapolation=-1.0)])
def test_bad_params_are_refused(params: dict) -> None:
    with pytest.raises(ValueError):
        RobotsLayerParams(**params)


def corridor() -> LayeredCostmap:
    """A 6 m x 4 m room, walls round it."""
    data = np.zeros((INFO.height, INFO.width), dtype=np.int8)
    data[[0, -1], :] = 100
    data[:, [0, -1]] = 100
    return LayeredCostmap(OccupancyMap(INFO, data), CostmapParams(robot_radius=0.18, inflation_radius=0.4))


def test_costmap_marks_the_other_robot_and_the_planner_goes_round_it() -> None:
    cm = corridor()
    cm.robots_layer = layer()
    cm.robots_layer.update(OtherRobot("chefbot2", 0.0, 2.0, 1.0, math.pi / 2, footprint=RECT))
    cm.robots_layer.refresh(0.0)
    cm.layers_changed()
    assert int(cm.master().cost_at(2.0, 1.0)) == LETHAL
    assert int(cm.window(2.0, 1.0, 2.0, 2.0).cost_at(2.0, 1.0)) == LETHAL
    assert int(cm.window(2.0, 1.0, 2.0, 2.0, static_only=True).cost_at(2.0, 1.0)) < INSCRIBED
    plan = make_planner("dijkstra", PlannerParams(), 0.18).plan(cm.master(), (0.5, 1.0), (3.5, 1.0))
    clearance = np.hypot(plan.points[:, 0] - 2.0, plan.points[:, 1] - 1.0).min()
    assert clearance >= 0.18 + 0.15 - RES            # round the other robot's footprint, not through it
    # clear_obstacles (a recovery) leaves the layer alone: it follows the states, not the sensors
    cm.clear_obstacles()
    assert int(cm.master().cost_at(2.0, 1.0)) == LETHAL


def test_costmap_adds_path_costs_after_inflation_and_only_below_inscribed() -> None:
    cm = corridor()
    cm.robots_layer = layer(path_horizon=5.0, path_cost=100)
    cm.robots_layer.update(OtherRobot("chefbot2", 0.0, 0.5, 1.0, 0.0, footprint=RECT, radius=0.25,
                                      path=np.array([[4.9, 1.0]])))
    cm.robots_layer.refresh(0.0)
    cm.layers_changed()
    master = cm.master()
    assert int(master.cost_at(3.0, 1.0)) == 100           # free space on its path
    assert int(master.cost_at(3.0, 2.0)) < 100            # off its path
    assert int(master.cost_at(4.85, 1.0)) >= INSCRIBED    # by the wall: the inflation's cost wins
    window = cm.window(3.0, 1.0, 1.0, 1.0)
    assert int(window.cost_at(3.0, 1.0)) == 100


def test_footprint_class_agrees_with_the_fill() -> None:
    """The fill covers the same area as the Footprint polygon it draws (sanity of the pixel convention)."""
    lay = layer()
    lay.update(OtherRobot("chefbot2", 0.0, 2.0, 1.0, 0.0, footprint=RECT))
    lay.refresh(0.0)
    inside = Footprint(RECT).contains(to_body(cells_world(np.ones_like(lay.grid)), 2.0, 1.0, 0.0))
    assert np.mean(inside.reshape(lay.grid.shape) == lay.grid) > 0.995


def test_robots_as_cost_opens_the_way_through_a_robot_but_not_through_other_marks() -> None:
    """The fallback when another robot is in the only way: its cells (and what the sensors marked on
    it) cost ROBOT_COST; a sensor mark elsewhere, and the map, stay obstacles."""
    cm = corridor()
    cm.robots_layer = layer()
    cm.robots_layer.update(OtherRobot("chefbot2", 0.0, 2.0, 1.0, 0.0, radius=0.2))
    cm.robots_layer.refresh(0.0)
    cm.mark_points(np.array([2.2, 3.0]), np.array([1.0, 1.0]))    # its surface seen by the scan; a chair
    soft = cm.master(robots_as_cost=True)
    assert int(soft.cost_at(2.0, 1.0)) == ROBOT_COST
    assert int(soft.cost_at(2.2, 1.0)) == ROBOT_COST
    assert int(soft.cost_at(3.0, 1.0)) == LETHAL
    assert int(soft.cost_at(-0.975, 1.0)) == LETHAL                # the wall
    assert int(cm.master().cost_at(2.0, 1.0)) == LETHAL            # the normal costmap is unchanged
    cm.robots_layer.forget("chefbot2")
    cm.robots_layer.refresh(0.0)
    cm.layers_changed()
    assert int(cm.master(robots_as_cost=True).cost_at(2.2, 1.0)) == LETHAL    # no robot: marks are marks


def test_robot_near_measures_to_the_nearest_cell_of_another_robot() -> None:
    """``LayeredCostmap.robot_near``: a robot of radius 0.2 m centred 1.0 m away is within 0.85 m (its
    near edge, 0.8 m, to a cell), not within 0.7 m; off the map or with no layer, no robot is near."""
    layers = LayeredCostmap(OccupancyMap(INFO, np.zeros((INFO.height, INFO.width), dtype=np.int8)),
                            CostmapParams(robot_radius=0.18, inflation_radius=0.4))
    assert not layers.robot_near(1.0, 1.0, 5.0)                    # no robots layer
    layers.robots_layer = RobotsLayer(INFO, RobotsLayerParams(footprint_padding=0.0), "chefbot1")
    layers.robots_layer.update(OtherRobot("chefbot2", 0.0, 2.0, 1.0, 0.0, radius=0.2))
    layers.robots_layer.refresh(0.0)
    assert layers.robot_near(1.0, 1.0, 0.85)
    assert not layers.robot_near(1.0, 1.0, 0.7)
    assert layers.robot_near(2.0, 1.0, 0.0)                        # on it
    assert not layers.robot_near(50.0, 50.0, 1.0)                  # off the map
