"""Seconds and metres between a site's places (chefbot_fleet.travel): remembered per pair, forgotten when a
place moves, unreachable pairs finite but prohibitive, and the hotel's planned paths."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from chefbot_common.geometry import Pose2D
from chefbot_fleet.travel import UNREACHABLE, Places, map_route, straight_route

MAPS = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps"


def test_routes_are_remembered_and_a_moved_place_is_planned_again() -> None:
    calls = []

    def route(a: Pose2D, b: Pose2D) -> tuple[float, float]:
        calls.append((a, b))
        return straight_route(0.5)(a, b)

    p = Places({"a": Pose2D(0, 0), "b": Pose2D(3, 4)}, route)
    assert p.travel("a", "b") == pytest.approx(10.0) and p.distance("a", "b") == pytest.approx(5.0)
    assert p.travel("a", "b") == pytest.approx(10.0) and len(calls) == 1
    assert p.travel("a", "a") == 0.0 and len(calls) == 1
    p.set("robot", Pose2D(0, 2))
    assert p.distance("robot", "a") == pytest.approx(2.0)
    p.set("robot", Pose2D(0, 2))                   # not moved: still remembered
    n = len(calls)
    p.distance("robot", "a")
    assert len(calls) == n
    p.set("robot", Pose2D(0, 1))
    assert p.distance("robot", "a") == pytest.approx(1.0)
    assert p.distance("a", "b") == pytest.approx(5.0) and len(calls) == n + 1     # other pairs kept
    with pytest.raises(KeyError, match="no place 'c'"):
        p.travel("a", "c")


def test_an_unreachable_pair_is_finite_but_costs_more_than_any_trip() -> None:
    p = Places({"a": Pose2D(0, 0), "b": Pose2D(1, 0)}, lambda a, b: (math.inf, math.inf))
    assert p.travel("a", "b") == UNREACHABLE and p.distance("a", "b") == UNREACHABLE


def test_straight_route_turns_count_when_asked() -> None:
    r = straight_route(1.0, turn_rate=1.0)
    s, m = r(Pose2D(0, 0, 0.0), Pose2D(0, 2, 0.0))         # turn left 90 deg, drive, turn back
    assert m == pytest.approx(2.0) and s == pytest.approx(2.0 + math.pi)
    with pytest.raises(ValueError):
        straight_route(0.0)


def test_the_hotels_planned_paths_go_around_the_tables() -> None:
    from chefbot_common.map_io import load_map

    route = map_route(load_map(MAPS / "hotel_world_map.yaml"))
    # table_1's pose to table_3's: 6 m apart in a straight line, past table_2 in between
    s, m = route(Pose2D(2.05, -3.0, 0.0), Pose2D(8.05, -3.0, 0.0))
    assert m > 6.3                                  # around table_2, not through it
    assert s > m / 0.35                             # never faster than the robot's top speed
    s_in, _ = route(Pose2D(0.0, 0.0), Pose2D(3.0, 0.0))   # into table_4 itself
    assert s_in == math.inf
