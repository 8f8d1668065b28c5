"""load_tables: the delivery poses file, and errors that name the file and the entry."""
from __future__ import annotations

from pathlib import Path

import pytest

from chefbot_common.tables import TablesError, load_tables


def test_valid_file(tmp_path: Path) -> None:
    p = tmp_path / "t.yaml"
    p.write_text("frame: map\nposes:\n  home: {x: 0, y: 0}\n  table_1: {x: 2.5, y: -1, yaw: 1.5}\n")
    tables = load_tables(p)
    assert set(tables) == {"home", "table_1"}
    assert (tables["table_1"].x, tables["table_1"].y, tables["table_1"].yaw) == (2.5, -1.0, 1.5)
    assert tables["home"].yaw == 0.0


def test_non_finite_rejected(tmp_path: Path) -> None:
    p = tmp_path / "t.yaml"
    p.write_text("poses: {home: {x: .nan, y: 0}}")
    with pytest.raises(TablesError, match="poses.home.x"):
        load_tables(p)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TablesError, match="cannot read"):
        load_tables(tmp_path / "absent.yaml")


def test_not_utf8_names_the_file(tmp_path: Path) -> None:
    p = tmp_path / "t.yaml"
    p.write_bytes("poses: {home: {x: 0, y: 0}}  # caf\xe9\n".encode("latin-1"))
    with pytest.raises(TablesError, match="not UTF-8 text") as err:
        load_tables(p)
    assert str(p) in str(err.value)


# (text, words in the message, whether load_tables refuses it too: a file with only 'home' is a valid
# tables file, only not one to deliver to)
@pytest.mark.parametrize("text, words, tables_too", [
    ("poses: {table_1: {x: 1, y: 2}}", ["missing the 'home'"], True),
    ("poses: {home: {x: 1}}", ["poses.home", "missing field 'y'"], True),
    ("poses: {home: {x: a, y: 0}}", ["poses.home.x", "number"], True),
    ("poses: {home: [1, 2]}", ["poses.home", "mapping"], True),
    ("poses: {home: {x: 0, y: 0, z: 1}}", ["unknown key"], True),
    ("frame: odom\nposes: {home: {x: 0, y: 0}}", ["frame must be 'map'"], True),
    ("poses: [", ["invalid YAML"], True),
    ("home: 1", ["poses"], True),
    ("poses: {home: {x: 0, y: 0}}\nextra: 1", ["unknown top-level"], True),
    ("poses: {home: {x: 0, y: 0}}", ["no destinations", "besides 'home'"], False),
    ("destinations: []\nposes: {home: {x: 0, y: 0}, bar: {x: 1, y: 0}}", ["no destinations"], True),
    ("destinations: [bar, sofa]\nposes: {home: {x: 0, y: 0}, bar: {x: 1, y: 0}}", ["unknown pose", "sofa"], True),
    ("destinations: [home]\nposes: {home: {x: 0, y: 0}, bar: {x: 1, y: 0}}", ["cannot be a destination"], True),
    ("destinations: bar\nposes: {home: {x: 0, y: 0}, bar: {x: 1, y: 0}}", ["must be a list"], True),
    ("destinations: [bar, bar]\nposes: {home: {x: 0, y: 0}, bar: {x: 1, y: 0}}", ["twice"], True),
])
def test_tables_errors_name_the_file(tmp_path: Path, text: str, words: list, tables_too: bool) -> None:
    from chefbot_common.tables import load_destinations
    p = tmp_path / "t.yaml"
    p.write_text(text)
    for load in (load_tables, load_destinations) if tables_too else (load_destinations,):
        with pytest.raises(TablesError) as e:
            load(p)
        assert str(p) in str(e.value)
        for w in words:
            assert w in str(e.value)
    if not tables_too:
        assert load_tables(p)


def test_format_round_trips_with_map_in_world(tmp_path: Path) -> None:
    from chefbot_common.geometry import Pose2D
    from chefbot_common.tables import format_tables, load_map_in_world
    poses = {"home": Pose2D(-0.041, 0.0054, 0.0044), "table_1": Pose2D(2.0221, -2.9856, 0.0044)}
    p = tmp_path / "t.yaml"
    p.write_text(format_tables(poses, "made by a test\nsecond line", world="hotel",
                               map_in_world=Pose2D(0.041, -0.0056, -0.0044)))
    assert p.read_text().startswith("# made by a test\n# second line\nframe: map\n")
    assert load_tables(p) == poses
    assert load_map_in_world(p) == Pose2D(0.041, -0.0056, -0.0044)
    plain = tmp_path / "plain.yaml"
    plain.write_text(format_tables(poses, ""))
    assert load_map_in_world(plain) == Pose2D()
    bad = tmp_path / "bad.yaml"
    bad.write_text("poses: {home: {x: 0, y: 0}}\nmap_in_world: {x: 1, yaw: 0}\n")
    with pytest.raises(TablesError, match="map_in_world: missing field 'y'"):
        load_tables(bad)


def test_every_pose_but_home_is_a_destination_whatever_its_name(tmp_path: Path) -> None:
    from chefbot_common.tables import load_destinations
    p = tmp_path / "bistro.yaml"
    p.write_text("poses:\n  round_1: {x: 1, y: 0}\n  home: {x: 0, y: 0}\n  bar: {x: 2, y: 1}\n")
    assert load_destinations(p) == ["round_1", "bar"]            # the file's order


def test_the_file_may_list_its_destinations(tmp_path: Path) -> None:
    from chefbot_common.tables import load_destinations
    p = tmp_path / "t.yaml"
    p.write_text("destinations: [bar, round_1]\n"
                 "poses: {home: {x: 0, y: 0}, kitchen: {x: 3, y: 0}, round_1: {x: 1, y: 0}, bar: {x: 2, y: 1}}\n")
    assert load_destinations(p) == ["bar", "round_1"]
    assert set(load_tables(p)) == {"home", "kitchen", "round_1", "bar"}
