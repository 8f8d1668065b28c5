"""Frontier exploration core (no master)."""
from __future__ import annotations

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import FREE, OCCUPIED, UNKNOWN, GridInfo, OccupancyMap
from chefbot_navigation.exploration import ExploreConfig, ExploreNodeParams, find_frontiers, frontier_mask, known_area


def _room(known_cols: int) -> OccupancyMap:
    """A 6 x 4 m walled room (0.05 m cells) known up to column ``known_cols``."""
    data = np.full((80, 120), FREE, dtype=np.int8)
    data[0, :] = data[-1, :] = OCCUPIED
    data[:, 0] = data[:, -1] = OCCUPIED
    data[:, known_cols:] = UNKNOWN
    return OccupancyMap(GridInfo(0.05, 120, 80, 0.0, 0.0), data)


def test_frontier_of_a_half_known_room():
    occ = _room(60)
    fr = find_frontiers(occ, Pose2D(1.0, 2.0, 0.0), ExploreConfig())
    assert len(fr) == 1
    f = fr[0]
    assert f.centroid[0] == pytest.approx(2.975, abs=0.05) and f.length > 3.0
    assert occ.data[occ.info.world_to_cell(f.goal.x, f.goal.y)] == FREE
    assert 0.0 < f.goal.x < 3.0 and f.travel > 0
    assert abs(f.goal.yaw) < 1.0                          # faces the unknown (+x)


def test_closed_known_room_has_no_frontier_and_blacklist_removes_goals():
    assert find_frontiers(_room(120), Pose2D(1.0, 2.0, 0.0), ExploreConfig()) == []
    occ = _room(60)
    first = find_frontiers(occ, Pose2D(1.0, 2.0, 0.0), ExploreConfig())[0]
    again = find_frontiers(occ, Pose2D(1.0, 2.0, 0.0), ExploreConfig(), [(first.goal.x, first.goal.y)])
    assert all(np.hypot(f.goal.x - first.goal.x, f.goal.y - first.goal.y) > 0.5 for f in again)


def test_unreachable_frontier_is_skipped():
    occ = _room(60)
    occ.data[:, 30] = OCCUPIED                              # a wall between the robot and the frontier
    assert find_frontiers(occ, Pose2D(0.5, 2.0, 0.0), ExploreConfig()) == []


def test_mask_area_and_params():
    occ = _room(60)
    assert frontier_mask(occ)[:, 59].sum() == 78
    known, free = known_area(occ)
    assert known == pytest.approx(80 * 60 * 0.0025) and free < known
    with pytest.raises(ValueError, match="clearance"):
        ExploreConfig(clearance=0.0)
    with pytest.raises(ValueError, match="mode"):
        ExploreNodeParams(mode="random")
