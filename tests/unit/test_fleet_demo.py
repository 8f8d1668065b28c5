"""tools/fleet_demo.py's pure parts: splitting the tables into runs, giving each run to a robot, settings."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from fleet_demo import FleetDemoError, assign_runs, settings, split_runs

from chefbot_common.geometry import Pose2D


@pytest.mark.parametrize("n, sizes", [(1, [7]), (2, [4, 3]), (3, [3, 2, 2]), (7, [1] * 7), (9, [1] * 7 + [0, 0])])
def test_runs_are_neighbours_in_file_order_sizes_differ_by_one_at_most(n: int, sizes: list[int]) -> None:
    names = [f"t{i}" for i in range(7)]
    runs = split_runs(names, n)
    assert [len(r) for r in runs] == sizes
    assert [t for r in runs for t in r] == names


def test_each_run_goes_to_the_robot_parked_nearest_to_it() -> None:
    tables = {"s1": Pose2D(2, -3), "s2": Pose2D(5, -3), "n1": Pose2D(2, 3), "n2": Pose2D(5, 3)}
    runs = [["s1", "s2"], ["n1", "n2"]]
    parkings = [Pose2D(0, 1.5), Pose2D(0, -1.5)]          # the first robot parks north
    assert assign_runs(runs, tables, parkings) == [["n1", "n2"], ["s1", "s2"]]


@pytest.mark.parametrize("env, match", [
    ({"CHEFBOT_DEMO_ROBOTS": "two"}, "whole number"),
    ({"CHEFBOT_DEMO_ROBOTS": "1"}, "needs 2 or more"),
    ({"CHEFBOT_DEMO_ROBOTS": "4"}, "robots:=4 asked, but the file lists 3"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_WORLD": "chefbot_sim/worlds/cafe.yaml"}, "needs FLEET_FILE"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_DRIVE": "magic"}, "plugin or firmware"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_FLEET_FILE": "/nonexistent.yaml"}, "does not exist"),
    ({"CHEFBOT_DEMO_ROBOTS": "2", "CHEFBOT_DEMO_TABLES": "table_1,bar_9"}, "unknown tables .'bar_9'."),
])
def test_bad_settings_are_named(monkeypatch: pytest.MonkeyPatch, env: dict, match: str) -> None:
    for k in ("CHEFBOT_DEMO_WORLD", "CHEFBOT_DEMO_MAP", "CHEFBOT_DEMO_TABLES_FILE", "CHEFBOT_DEMO_FLEET_FILE",
              "CHEFBOT_DEMO_TABLES", "CHEFBOT_DEMO_DRIVE"):
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    with pytest.raises(FleetDemoError, match=match):
        settings()


def test_the_hotel_default_three_robots_each_serve_one_row(monkeypatch: pytest.MonkeyPatch) -> None:
    for k in ("CHEFBOT_DEMO_WORLD", "CHEFBOT_DEMO_MAP", "CHEFBOT_DEMO_TABLES_FILE", "CHEFBOT_DEMO_FLEET_FILE",
              "CHEFBOT_DEMO_TABLES", "CHEFBOT_DEMO_DRIVE"):
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("CHEFBOT_DEMO_ROBOTS", "3")
    cfg = settings()
    assert [r.name for r in cfg["robots"]] == ["chefbot1", "chefbot2", "chefbot3"]
    # chefbot1 parks at y 0 (the middle row), chefbot2 at -1.5 (south), chefbot3 at 1.5 (north)
    assert cfg["runs"] == [["table_4", "table_5", "table_6"], ["table_1", "table_2", "table_3"],
                           ["table_7", "table_8", "table_9"]]
    assert cfg["n_tables"] == 9 and cfg["drive"] == "plugin"
