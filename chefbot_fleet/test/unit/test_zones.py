"""Single-lane zones from hand-made grids: widths, lengths, holding points, and what is no zone."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_common.map_io import load_map
from chefbot_fleet.traffic import ZoneGeometry
from chefbot_fleet.zones import ZoneConfig, extract_zones

RES = 0.05
CFG = ZoneConfig()          # ChefBot: 0.356 m wide, two pass in 0.862 m
MAPS = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps"


def grid_from(free_boxes: list[tuple[float, float, float, float]], size=(10.0, 6.0)) -> OccupancyMap:
    """A map of ``size`` m, all obstacle but the free (x0, y0, x1, y1) boxes (m)."""
    w, h = int(round(size[0] / RES)), int(round(size[1] / RES))
    data = np.full((h, w), 100, np.int8)
    for x0, y0, x1, y1 in free_boxes:
        data[int(round(y0 / RES)):int(round(y1 / RES)), int(round(x0 / RES)):int(round(x1 / RES))] = 0
    return OccupancyMap(GridInfo(RES, w, h), data)


def two_rooms(corridor_width: float, corridor_length: float = 2.0) -> OccupancyMap:
    """Two 3 x 4 m rooms joined by a corridor centred on y = 3."""
    x0 = 0.5 + 3.0
    half = corridor_width / 2
    return grid_from([(0.5, 1.0, 3.5, 5.0), (x0, 3.0 - half, x0 + corridor_length, 3.0 + half),
                      (x0 + corridor_length, 1.0, x0 + corridor_length + 3.0, 5.0)])


@pytest.mark.parametrize("width", [0.45, 0.6, 0.8])
def test_a_corridor_one_robot_wide_is_one_zone_with_a_holding_point_in_each_room(width: float) -> None:
    g = two_rooms(width)
    zm = extract_zones(g, CFG)
    assert len(zm.zones) == 1
    z = zm.zones[0]
    assert z.min_width == pytest.approx(width, abs=2 * RES)
    assert z.max_width < CFG.two_lane_width
    assert 2.0 - 2 * RES <= z.length <= 2.0 + 1.2        # the corridor and the narrow ends of the mouths
    assert zm.zone_at(4.5, 3.0) == z.id                  # the corridor's middle
    assert zm.zone_at(2.0, 3.0) == 0 and zm.zone_at(7.0, 3.0) == 0
    holds = sorted(z.holding_points)
    assert len(holds) == 2
    (xw, yw), (xe, ye) = holds
    assert xw < 3.5 and xe > 5.5                         # one in each room ...
    area = z.cells
    ax, ay = g.info.cell_to_world(area[:, 0], area[:, 1])
    for hx, hy in holds:                                  # ... far enough out for a robot to leave the zone
        assert np.min(np.hypot(ax - hx, ay - hy)) >= CFG.hold_distance - RES
        assert abs(hy - 3.0) < 0.3                        # on the line the corridor leaves along
    assert zm.zones_along(np.array([[2.0, 3.0], [4.0, 3.0], [5.0, 3.0], [7.0, 3.0]])) == [z.id]


@pytest.mark.parametrize("width, why", [(1.2, "two robots pass"), (0.30, "no robot fits")])
def test_corridors_too_wide_or_too_narrow_are_no_zone(width: float, why: str) -> None:
    assert extract_zones(two_rooms(width), CFG).zones == [], why


def test_an_empty_room_has_no_zone_in_its_corners() -> None:
    assert extract_zones(grid_from([(0.5, 0.5, 5.5, 4.5)]), CFG).zones == []


def test_a_dead_end_aisle_has_one_holding_point_outside_it() -> None:
    # a 4 x 2 m room with a 0.6 x 1.5 m aisle going north from its middle
    g = grid_from([(0.5, 0.5, 4.5, 2.5), (2.2, 2.5, 2.8, 4.0)])
    zm = extract_zones(g, CFG)
    assert len(zm.zones) == 1
    z = zm.zones[0]
    assert zm.zone_at(2.5, 3.5) == z.id
    assert len(z.holding_points) == 1
    hx, hy = z.holding_points[0]
    assert hy < 2.5 and abs(hx - 2.5) < 0.3


def test_unknown_cells_are_obstacles() -> None:
    g = two_rooms(1.2)
    rows = slice(int(2.7 / RES), int(3.3 / RES) + 1)
    outside = g.data.copy()
    outside[int(2.4 / RES):int(2.7 / RES), int(3.5 / RES):int(5.5 / RES)] = -1   # unknown narrows it to 0.6
    outside[int(3.3 / RES):int(3.6 / RES), int(3.5 / RES):int(5.5 / RES)] = -1
    assert rows.start > 0
    zm = extract_zones(OccupancyMap(g.info, outside), CFG)
    assert len(zm.zones) == 1


def test_the_cafe_aisles_are_zones_exactly_where_two_robots_cannot_pass() -> None:
    """The café's dead-end aisles (cafe.yaml): 0.90 m (n1|n2) is two-lane, the 0.50-0.75 m ones are zones;
    neighbouring aisles one table (0.8 m) apart are one zone, and no two zones are closer than
    merge_distance."""
    zm = extract_zones(load_map(MAPS / "cafe_map.yaml"), CFG)
    assert zm.zone_at(2.15, 4.2) == 0                   # table_n1's pose, in the 0.90 m aisle
    south = [zm.zone_at(x, 0.4) for x in (2.025, 3.425, 4.75)]       # table_s1, _s2, _s3
    north = [zm.zone_at(x, 4.2) for x in (3.775, 5.25, 6.66)]        # table_n2, _n3, _n4
    assert all(south) and len(set(south)) == 1, south
    assert all(north) and len(set(north)) == 1, north
    assert south[0] != north[0]
    assert zm.zone_at(3.5, 2.3) == 0                     # the 2 m corridor
    geom = ZoneGeometry(zm)
    for y in (1.55, 3.05):        # a robot driving along the corridor beside the chairs passes the aisles' mouths
        touched = {x: geom.touching(x, y, CFG.robot_radius) for x in np.arange(0.4, 6.6, 0.05)}
        assert not any(touched.values()), {round(x, 2): z for x, z in touched.items() if z}
    for z in zm.zones:
        for hx, hy in z.holding_points:
            assert 1.2 < hy < 3.4 and zm.zone_at(hx, hy) == 0, (z.id, hx, hy)     # waiting in the corridor
    info = zm.info
    for a in zm.zones:
        ax, ay = info.cell_to_world(a.cells[:, 0], a.cells[:, 1])
        for b in zm.zones:
            if b.id > a.id:
                bx, by = info.cell_to_world(b.cells[::7, 0], b.cells[::7, 1])
                gap = np.min(np.hypot(ax[:, None] - bx[None, :], ay[:, None] - by[None, :]))
                assert gap >= CFG.merge_distance - 2 * RES, (a.id, b.id, gap)


def test_bad_settings_are_named() -> None:
    with pytest.raises(ValueError, match="robot_radius"):
        ZoneConfig(robot_radius=0.0)
    with pytest.raises(ValueError, match=">= 0"):
        ZoneConfig(passing_margin=-0.1)
    assert ZoneConfig().two_lane_width == pytest.approx(4 * 0.178 + 0.15)
    assert math.isclose(ZoneConfig().hold_distance, 3 * 0.178 + 0.1)


def test_the_same_map_always_gives_the_same_zones() -> None:
    """medial_axis breaks ties at random unless seeded: the traffic node and the tests need one answer."""
    g = load_map(MAPS / "cafe_map.yaml")
    first = extract_zones(g, CFG)
    for _ in range(3):
        again = extract_zones(g, CFG)
        assert np.array_equal(again.labels, first.labels)
        assert [z.length for z in again.zones] == [z.length for z in first.zones]
