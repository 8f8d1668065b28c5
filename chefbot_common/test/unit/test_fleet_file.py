"""load_fleet: a site's robots (name, parking, start, charger), errors naming the file and the entry."""
from __future__ import annotations

from pathlib import Path

import pytest

from chefbot_common.fleet_file import FleetFileError, load_fleet, load_kitchen, select
from chefbot_common.geometry import Pose2D

MAPS = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps"


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "fleet.yaml"
    p.write_text(text)
    return p


def test_valid_file_with_defaults(tmp_path: Path) -> None:
    robots = load_fleet(write(tmp_path, """
robots:
  - {name: chefbot1, parking: {x: 0, y: 0}, charger: {x: -2, y: 0, yaw: 3.14}}
  - {name: tray_2, parking: {x: 0, y: 1}, start: {x: 1, y: 1, yaw: 0.5}}
"""))
    assert [r.name for r in robots] == ["chefbot1", "tray_2"]
    a, b = robots
    assert a.start == a.parking == Pose2D(0.0, 0.0, 0.0)          # start defaults to the parking pose
    assert a.charger == Pose2D(-2.0, 0.0, 3.14) and b.charger is None
    assert b.start == Pose2D(1.0, 1.0, 0.5)


@pytest.mark.parametrize("site", ["hotel", "cafe"])
def test_the_shipped_fleet_files_load_with_three_robots(site: str) -> None:
    robots = load_fleet(MAPS / f"{site}_fleet.yaml")
    assert [r.name for r in robots] == ["chefbot1", "chefbot2", "chefbot3"]
    assert all(r.charger is not None for r in robots)
    assert load_kitchen(MAPS / f"{site}_fleet.yaml") is not None


def test_the_kitchen_is_optional_and_clear_of_the_robots(tmp_path: Path) -> None:
    assert load_kitchen(write(tmp_path, "robots: [{name: a, parking: {x: 0, y: 0}}]")) is None
    text = "kitchen: {x: 2, y: 1, yaw: 3.0}\nrobots: [{name: a, parking: {x: 0, y: 0}}]"
    assert load_kitchen(write(tmp_path, text)) == Pose2D(2.0, 1.0, 3.0)


@pytest.mark.parametrize("text, match", [
    ("robots: []", "lists no robot"),
    ("robots: {a: 1}", "'robots' list"),
    ("robot: []", "'robots' list"),
    ("frame: odom\nrobots: [{name: a, parking: {x: 0, y: 0}}]", "frame must be 'map'"),
    ("fleet: 1\nrobots: [{name: a, parking: {x: 0, y: 0}}]", "unknown top-level"),
    ("robots: [{name: 1bot, parking: {x: 0, y: 0}}]", r"robots\[0\]: name must be a ROS name"),
    ("robots: [{name: a/b, parking: {x: 0, y: 0}}]", "name must be a ROS name"),
    ("robots: [{name: a}]", r"robots\[0\] \(a\): missing the 'parking'"),
    ("robots: [{name: a, parking: {x: .nan, y: 0}}]", r"\(a\).parking.x"),
    ("robots: [{name: a, parking: {x: 0, y: 0}, start: {y: 0}}]", r"\(a\).start: missing field 'x'"),
    ("robots: [{name: a, parking: {x: 0, y: 0}, dock: 1}]", "unknown key"),
    ("robots: [{name: a, parking: {x: 0, y: 0}}, {name: a, parking: {x: 5, y: 0}}]", r"\['a'\] listed twice"),
    ("robots: [{name: a, parking: {x: 0, y: 0}}, {name: b, parking: {x: 0.3, y: 0}}]",
     "parking poses of a and b are 0.30 m apart"),
    ("robots: [{name: a, parking: {x: 0, y: 0}, charger: {x: 3, y: 3}},"
     " {name: b, parking: {x: 1, y: 0}, charger: {x: 3, y: 3.1}}]", "charger poses of a and b"),
    ("robots: [\n  - {name: a, parking: {x: 0, y: 0}", "invalid YAML"),
    ("kitchen: {x: 0.2, y: 0}\nrobots: [{name: a, parking: {x: 0, y: 0}}]", "kitchen is 0.20 m from a's parking"),
    ("kitchen: {y: 0}\nrobots: [{name: a, parking: {x: 0, y: 0}}]", "kitchen: missing field 'x'"),
])
def test_bad_files_are_named(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(FleetFileError, match=match) as e:
        load_fleet(write(tmp_path, text))
    assert "fleet.yaml" in str(e.value)


def test_missing_and_binary_files(tmp_path: Path) -> None:
    with pytest.raises(FleetFileError, match="cannot read"):
        load_fleet(tmp_path / "absent.yaml")
    p = tmp_path / "bin.yaml"
    p.write_bytes(b"\xff\xfe\x00robots")
    with pytest.raises(FleetFileError, match="not UTF-8"):
        load_fleet(p)


def test_select_the_first_n() -> None:
    robots = load_fleet(MAPS / "hotel_fleet.yaml")
    assert [r.name for r in select(robots, 2)] == ["chefbot1", "chefbot2"]
    with pytest.raises(FleetFileError, match="robots:=4 asked, but the file lists 3"):
        select(robots, 4, "hotel_fleet.yaml")
    with pytest.raises(FleetFileError, match=">= 1"):
        select(robots, 0)
