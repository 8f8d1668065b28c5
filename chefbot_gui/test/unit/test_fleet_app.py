"""The fleet node's glue without ROS: its parameters, the fleet file's places, start-up orders."""
from __future__ import annotations

import math

import pytest
from conftest import TABLES

from chefbot_common.fleet_file import FleetFileError
from chefbot_gui.fleet_app import FleetGuiParams, fleet_places, parse_orders

FLEET = TABLES.parent / "hotel_fleet.yaml"


def test_fleet_places_of_the_hotel() -> None:
    names, places = fleet_places(str(FLEET))
    assert names == ["chefbot1", "chefbot2", "chefbot3"]
    assert [(m.key, m.label) for m in places] == [("kitchen", "Kitchen"), ("charger_chefbot1", "charger"),
                                                  ("charger_chefbot2", "charger"), ("charger_chefbot3", "charger")]
    assert (places[0].x, places[0].y) == (-1.6, -3.5)
    assert fleet_places("") == ([], [])


def test_a_bad_fleet_file_is_named(tmp_path) -> None:
    bad = tmp_path / "f.yaml"
    bad.write_text("robots: 3\n")
    with pytest.raises(FleetFileError, match="f.yaml"):
        fleet_places(str(bad))


def test_parse_orders() -> None:
    assert parse_orders("table_2,table_5 table_7") == [["table_2", "table_5"], ["table_7"]]
    assert parse_orders("  table_1,  ,, ") == [["table_1"]]
    assert parse_orders("") == []


@pytest.mark.parametrize("field,value", [("server_timeout", 0.0), ("stale_timeout", -1.0),
                                         ("service_timeout", math.nan), ("final_rows", -1), ("fleet_ns", " ")])
def test_bad_params_are_refused_naming_the_field(field, value) -> None:
    with pytest.raises(ValueError, match=field):
        FleetGuiParams(tables_file="t.yaml", **{field: value})


def test_the_node_opens_without_a_master_and_says_so(tmp_path) -> None:
    """``fleet_gui`` with no ROS master: params from the command line, a screenshot, exit 0."""
    import os
    import subprocess

    from conftest import _free_port

    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{_free_port()}", QT_QPA_PLATFORM="offscreen")
    png = tmp_path / "offline.png"
    out = subprocess.run(["rosrun", "chefbot_gui", "fleet_gui", f"_tables_file:={TABLES}", f"_fleet_file:={FLEET}",
                          "--screenshot", str(png), "--screenshot-delay", "1.0"],
                         env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "no ROS master at" in out.stderr and png.stat().st_size > 5000
