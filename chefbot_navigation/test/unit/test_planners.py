"""Global planners: optimality against exact Dijkstra, validity, error cases."""
from __future__ import annotations

import numpy as np
import pytest
from maps_gen import office_map
from planner_reference import exact_cost

from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.costmap import INSCRIBED, LETHAL, NO_INFORMATION, Costmap, CostmapParams, LayeredCostmap
from chefbot_navigation.planners import PlannerParams, PlanningError, cell_costs, make_planner, path_cost


def random_costmap(seed: int, n: int = 60) -> Costmap:
    rng = np.random.default_rng(seed)
    data = np.zeros((n, n), dtype=np.int8)
    for _ in range(12):
        r, c = rng.integers(0, n - 8, 2)
        h, w = rng.integers(1, 8, 2)
        data[r:r + h, c:c + w] = 100
    data[rng.random((n, n)) < 0.03] = 100
    occ = OccupancyMap(GridInfo(0.05, n, n, 0.0, 0.0, 0.0), data)
    return LayeredCostmap(occ, CostmapParams(robot_radius=0.05, inflation_radius=0.3)).master()


def free_cells(cm: Costmap, rng, k: int) -> np.ndarray:
    free = np.argwhere(cm.cost < INSCRIBED)
    return free[rng.choice(len(free), size=k, replace=False)]


@pytest.mark.parametrize("name", ["dijkstra", "hierarchical"])
@pytest.mark.parametrize("seed", range(8))
def test_optimal_against_exact_dijkstra(name: str, seed: int) -> None:
    cm = random_costmap(seed)
    params = PlannerParams(full_search_cells=1000 if name == "hierarchical" else 250_000)
    planner = make_planner(name, params, robot_radius=0.05)
    costs = cell_costs(cm.cost, params)
    rng = np.random.default_rng(100 + seed)
    a, b = free_cells(cm, rng, 2)
    ref = exact_cost(costs, tuple(a), tuple(b))
    start = tuple(float(v) for v in cm.info.cell_to_world(a[0], a[1]))
    goal = tuple(float(v) for v in cm.info.cell_to_world(b[0], b[1]))
    if not np.isfinite(ref):
        with pytest.raises(PlanningError) as err:
            planner.plan(cm, start, goal)
        assert err.value.kind == "no_path"
        return
    plan = planner.plan(cm, start, goal)
    if name == "dijkstra":
        assert plan.cost == pytest.approx(ref, rel=1e-9)
    else:
        assert ref - 1e-9 <= plan.cost <= 1.02 * ref
    assert path_cost(plan.cells, costs) == pytest.approx(plan.cost)
    # grid path: 8-connected, only passable cells
    steps = np.abs(np.diff(plan.cells, axis=0))
    assert steps.max() <= 1
    assert np.all(np.isfinite(costs[plan.cells[:, 0], plan.cells[:, 1]]))
    # smoothed, resampled path: never through an impassable cell, exact end points
    assert np.all(cm.cost_at(plan.points[:, 0], plan.points[:, 1]) < INSCRIBED)
    np.testing.assert_allclose(plan.points[0], start)
    np.testing.assert_allclose(plan.points[-1], goal)
    assert np.all(np.hypot(*np.diff(plan.points, axis=0).T) <= 0.05 + 1e-9)


def corridor_map() -> Costmap:
    cost = np.zeros((40, 80), dtype=np.uint8)
    cost[:, 38:42] = LETHAL          # a wall splitting the map in two
    cost[30:35, 60:65] = NO_INFORMATION
    cost[10, 20] = INSCRIBED
    return Costmap(GridInfo(0.05, 80, 40, 0.0, 0.0, 0.0), cost)


@pytest.mark.parametrize("goal,kind", [
    ((3.0, 1.0), "no_path"),            # behind the wall: unreachable
    ((1.95, 1.0), "goal_in_obstacle"),
    ((3.1, 1.6), "goal_unknown"),
    ((1.02, 0.52), "goal_too_close"),
    ((10.0, 1.0), "goal_off_map"),
    ((-0.1, 1.0), "goal_off_map"),
])
def test_invalid_goals(goal: tuple[float, float], kind: str) -> None:
    planner = make_planner("dijkstra", PlannerParams())
    with pytest.raises(PlanningError) as err:
        planner.plan(corridor_map(), (0.5, 1.0), goal)
    assert err.value.kind == kind
    assert err.value.reason


def test_start_inside_inscribed_zone_escapes() -> None:
    cost = np.zeros((40, 40), dtype=np.uint8)
    cost[:, 20] = LETHAL
    cost[:, 17:20] = INSCRIBED
    cost[:, 21:24] = INSCRIBED
    cm = Costmap(GridInfo(0.05, 40, 40, 0.0, 0.0, 0.0), cost)
    plan = make_planner("dijkstra", PlannerParams()).plan(cm, (0.93, 1.0), (0.2, 1.0))
    assert plan.points[-1][0] == pytest.approx(0.2)


def test_unknown_allowed_when_configured() -> None:
    planner = make_planner("dijkstra", PlannerParams(allow_unknown=True))
    plan = planner.plan(corridor_map(), (2.5, 1.0), (3.1, 1.6))
    assert len(plan.points) > 2


def test_unknown_planner_name() -> None:
    with pytest.raises(ValueError, match="unknown planner 'navfn'"):
        make_planner("navfn", PlannerParams())


def test_hierarchical_close_to_exact_on_office_map() -> None:
    occ = office_map(size=600, seed=2)
    cm = LayeredCostmap(occ, CostmapParams()).master()
    params = PlannerParams(full_search_cells=10_000)
    planner = make_planner("hierarchical", params)
    costs = cell_costs(cm.cost, params)
    rng = np.random.default_rng(7)
    for _ in range(3):
        a, b = free_cells(cm, rng, 2)
        ref = exact_cost(costs, tuple(a), tuple(b))
        start = tuple(float(v) for v in cm.info.cell_to_world(a[0], a[1]))
        goal = tuple(float(v) for v in cm.info.cell_to_world(b[0], b[1]))
        plan = planner.plan(cm, start, goal)
        assert plan.cost <= 1.02 * ref


def walled_map(n: int = 200) -> Costmap:
    """Free square with a thick wall (cols 95-104) from the top down to row 185: the way round is far."""
    cost = np.zeros((n, n), dtype=np.uint8)
    cost[:186, 95:105] = LETHAL
    return Costmap(GridInfo(0.05, n, n, 0.0, 0.0, 0.0), cost)


def test_cache_reused_while_costmap_unchanged_and_rebuilt_when_it_changes() -> None:
    cm = walled_map()
    planner = make_planner("hierarchical", PlannerParams(full_search_cells=1000))
    a, b = (1.0, 9.5), (9.0, 9.5)              # (x, y): below the wall's end, either side
    first = planner.plan(cm, a, b)
    assert planner.cache.builds == 1
    # an equal costmap in a new object (move_base's master() each cycle): no rebuild, same plan
    again = planner.plan(Costmap(cm.info, cm.cost.copy()), a, b)
    assert planner.cache.builds == 1
    np.testing.assert_array_equal(again.cells, first.cells)
    # changed in place: close the gap below the wall -> rebuilt, the goal is now unreachable
    cm.cost[186:, 95:105] = LETHAL
    with pytest.raises(PlanningError) as err:
        planner.plan(cm, a, b)
    assert err.value.kind == "no_path" and "unreachable" in err.value.reason
    assert planner.cache.builds == 2
    # reopened: a plan again, through the gap, from the rebuilt grid
    cm.cost[186:, 95:105] = 0
    plan = planner.plan(cm, a, b)
    assert planner.cache.builds == 3
    assert plan.cost == pytest.approx(first.cost)
    # a new geometry (origin moved) is a new map even with equal cells
    shifted = Costmap(GridInfo(0.05, 200, 200, 1.0, 0.0, 0.0), cm.cost.copy())
    planner.plan(shifted, (2.0, 9.5), (10.0, 9.5))
    assert planner.cache.builds == 4


def test_cached_grid_is_read_only_and_not_changed_by_a_start_in_the_inscribed_zone() -> None:
    cost = np.zeros((40, 40), dtype=np.uint8)
    cost[:, 20] = LETHAL
    cost[:, 17:20] = INSCRIBED
    cm = Costmap(GridInfo(0.05, 40, 40, 0.0, 0.0, 0.0), cost)
    planner = make_planner("dijkstra", PlannerParams())
    planner.plan(cm, (0.93, 1.0), (0.2, 1.0))               # starts in the inscribed zone
    costs = planner.cache.costs(cm, planner.params)
    assert planner.cache.builds == 1
    assert not costs.flags.writeable
    assert np.all(np.isinf(costs[:, 17:21]))                # the way out was made on a copy
    with pytest.raises(PlanningError) as err:               # so a goal in that zone is still refused
        planner.plan(cm, (0.2, 1.0), (0.93, 1.0))
    assert err.value.kind == "goal_too_close"


def test_coarse_search_box_without_a_path_falls_back_to_the_whole_grid() -> None:
    """Start and goal either side of a long wall: the cropped coarse box holds no way round."""
    cm = walled_map()
    params = PlannerParams(full_search_cells=1000)
    costs = cell_costs(cm.cost, params)
    s, g = (10, 80), (10, 120)                               # (row, col), near the top
    ref = exact_cost(costs, s, g)
    start = tuple(float(v) for v in cm.info.cell_to_world(*s))
    goal = tuple(float(v) for v in cm.info.cell_to_world(*g))
    plan = make_planner("hierarchical", params).plan(cm, start, goal)
    assert plan.cells[:, 0].max() >= 186                     # round the wall's end
    assert ref - 1e-9 <= plan.cost <= 1.02 * ref


@pytest.mark.parametrize("crop", [0.0, 0.2])
def test_hierarchical_unreachable_goal_reported(crop: float) -> None:
    cm = walled_map()
    cm.cost[150:170, 150:170] = LETHAL
    cm.cost[155:165, 155:165] = 0                            # a free pocket walled all round
    planner = make_planner("hierarchical", PlannerParams(full_search_cells=1000, coarse_crop=crop))
    with pytest.raises(PlanningError) as err:
        planner.plan(cm, (1.0, 1.0), (8.0, 8.0))
    assert err.value.kind == "no_path"
    assert "unreachable" in err.value.reason


@pytest.mark.parametrize("crop", [-0.1, float("nan"), float("inf")])
def test_bad_coarse_crop_named(crop: float) -> None:
    with pytest.raises(ValueError, match="coarse_crop must be a finite number >= 0"):
        PlannerParams(coarse_crop=crop)
