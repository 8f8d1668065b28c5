"""Unit tests of the GUI demo world helpers (map file reading, routes)."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from chefbot_gui.demo_world import aisle_route, load_map, point_along
from chefbot_gui.geometry import path_length

HOTEL_MAP = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"


def test_hotel_map_loads_with_walls_and_free_aisles() -> None:
    m = load_map(HOTEL_MAP)
    assert (m.resolution, m.width, m.height) == (0.05, 328, 268)
    assert len(m.data) == m.width * m.height
    assert set(m.data) <= {-1, 0, 100}

    def cell(x: float, y: float) -> int:
        c, r = int((x - m.origin[0]) / m.resolution), int((y - m.origin[1]) / m.resolution)
        return m.data[r * m.width + c]

    assert cell(0.0, 0.0) == 0            # home is free
    assert cell(3.0, 0.0) == 100          # table 4's cube (west face at 2.5 m)


def test_pgm_errors(tmp_path: Path) -> None:
    (tmp_path / "m.pgm").write_bytes(b"not an image at all")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n"
                                     "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    with pytest.raises(ValueError, match="not a readable image"):
        load_map(tmp_path / "m.yaml")


def test_aisle_route_and_point_along() -> None:
    route = aisle_route((0.0, 0.0), (5.05, 3.0))
    assert route == [(0.0, 0.0), (0.0, 1.5), (5.05, 1.5), (5.05, 3.0)]
    assert aisle_route((0.0, 0.0), (2.0, 0.0)) == [(0.0, 0.0), (2.0, 0.0)]
    assert point_along(route, 1.0) == pytest.approx((0.0, 1.0, math.pi / 2))
    end = point_along(route, path_length(route) + 5)
    assert end == pytest.approx((5.05, 3.0, math.pi / 2))
