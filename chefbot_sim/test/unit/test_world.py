"""World loading: our YAML format, Gazebo SDF import, tables, and every error case."""
import math
from pathlib import Path

import pytest

from chefbot_common.tables import load_tables
from chefbot_sim.world import WorldError, load_world, parse_sdf, parse_yaml_world

SDF = """<?xml version="1.0"?>
<sdf version="1.6">
  <world name="mini_hotel">
    <include><uri>model://ground_plane</uri></include>
    <include><uri>model://sun</uri></include>
    <model name="unit_box_1">
      <pose frame="">0 0 0.5 0 0 0</pose>
      <link name="link">
        <collision name="collision"><geometry><box><size>1 1 1</size></box></geometry></collision>
        <visual name="visual"><geometry><box><size>1 1 1</size></box></geometry>
          <material><ambient>1 0 0 1</ambient></material></visual>
      </link>
    </model>
    <model name="unit_box_2">
      <pose frame="">0 0 0.5 0 0 0</pose>
      <link name="link">
        <collision name="collision"><geometry><box><size>1 1 1</size></box></geometry></collision>
      </link>
    </model>
    <model name="unit_cylinder_1">
      <pose frame="">0 0 0.5 0 0 0</pose>
      <link name="link">
        <collision name="collision">
          <geometry><cylinder><radius>0.5</radius><length>1</length></cylinder></geometry>
        </collision>
      </link>
    </model>
    <model name="ball">
      <pose frame="">4 4 0.25 0 0 0</pose>
      <link name="link">
        <collision name="collision"><geometry><sphere><radius>0.25</radius></sphere></geometry></collision>
      </link>
    </model>
    <state world_name="mini_hotel">
      <sim_time>10 0</sim_time>
      <model name="unit_box_1">
        <pose frame="">5 -6 0.5 0 0 1.5708</pose>
        <scale>12 0.2 1</scale>
        <link name="link"><pose frame="">5 -6 0.5 0 0 1.5708</pose></link>
      </model>
      <model name="unit_box_2">
        <pose frame="">3 3 0.375 0 0 0</pose>
        <scale>1 1 0.75</scale>
      </model>
      <model name="unit_cylinder_1">
        <pose frame="">-2 1 0.25 0 0 0</pose>
        <scale>0.4 0.4 0.5</scale>
      </model>
      <model name="ground_plane"><pose frame="">0 0 0 0 0 0</pose></model>
    </state>
  </world>
</sdf>
"""


def test_yaml_world_shapes_and_defaults():
    w = parse_yaml_world("""
name: t
objects:
  - {name: b, shape: box, size: [2, 1, 0.5], pose: [1, 2, 0.3]}
  - {name: c, shape: cylinder, radius: 0.2, height: 1.0, pose: [0, 0]}
  - {name: s, shape: sphere, radius: 0.1, pose: [3, 3, 0.75, 0], colour: [1, 0, 0]}
""")
    b, c, s = w.shapes
    assert b.kind == "box" and b.size == (2, 1, 0.5) and b.position == pytest.approx((1, 2, 0.25)) and b.yaw == 0.3
    assert c.position == pytest.approx((0, 0, 0.5)) and c.size == (0.2, 1.0)
    assert s.position == pytest.approx((3, 3, 0.85)) and s.colour == (1, 0, 0, 1)   # z: pose 0.75 + radius


def test_sdf_state_overrides_pose_and_scales():
    w = parse_sdf(SDF, "mini.world")
    names = [s.name for s in w.shapes]
    assert names == ["unit_box_1", "unit_box_2", "unit_cylinder_1", "ball"]
    wall = w.shape("unit_box_1")
    assert wall.size == pytest.approx((12, 0.2, 1))
    assert wall.position == pytest.approx((5, -6, 0.5))
    assert wall.yaw == pytest.approx(1.5708)
    assert wall.colour == (1, 0, 0, 1)
    table = w.shape("unit_box_2")
    assert table.size == pytest.approx((1, 1, 0.75)) and table.position == pytest.approx((3, 3, 0.375))
    assert table.z_range() == pytest.approx((0.0, 0.75))
    cyl = w.shape("unit_cylinder_1")
    assert cyl.size == pytest.approx((0.2, 0.5)) and cyl.position == pytest.approx((-2, 1, 0.25))
    assert w.shape("ball").position == pytest.approx((4, 4, 0.25))  # no state: model pose


def test_load_world_by_suffix(tmp_path: Path):
    p = tmp_path / "mini.world"
    p.write_text(SDF)
    assert len(load_world(p).shapes) == 4
    y = tmp_path / "w.yaml"
    y.write_text("objects: [{name: a, shape: sphere, radius: 1, pose: [0, 0]}]\n")
    assert load_world(y).shapes[0].kind == "sphere"


@pytest.mark.parametrize("text, words", [
    ("objects: [", ["invalid YAML"]),
    ("- 1\n- 2\n", ["top level"]),
    ("objects: {a: 1}", ["'objects' must be a list"]),
    ("bogus: 1", ["unknown top-level"]),
    ("objects: [{name: x, shape: cone, pose: [0, 0]}]", ["objects[0]", "'x'", "unknown shape 'cone'"]),
    ("objects: [{name: x, pose: [0, 0]}]", ["objects[0]", "missing field 'shape'"]),
    ("objects: [{name: x, shape: box, pose: [0, 0]}]", ["'x'", "missing field 'size'"]),
    ("objects: [{name: x, shape: box, size: [1, -1, 1], pose: [0, 0]}]", ["'x'", "positive"]),
    ("objects: [{name: x, shape: box, size: [1, 1], pose: [0, 0]}]", ["'x'", "size"]),
    ("objects: [{name: x, shape: box, size: [1, a, 1], pose: [0, 0]}]", ["'x'", "expected a number"]),
    ("objects: [{name: x, shape: cylinder, radius: 0, height: 1, pose: [0, 0]}]", ["'x'", "radius must be positive"]),
    ("objects: [{name: x, shape: cylinder, radius: 1, pose: [0, 0]}]", ["missing field 'height'"]),
    ("objects: [{name: x, shape: sphere, radius: 1}]", ["'x'", "missing field 'pose'"]),
    ("objects: [{name: x, shape: sphere, radius: 1, pose: [0]}]", ["'x'", "pose"]),
    ("objects: [{name: x, shape: sphere, radius: 1, pose: [0, .nan]}]", ["finite"]),
    ("objects: [{name: x, shape: sphere, radius: 1, pose: [0, 0], colour: [2, 0, 0]}]", ["colour"]),
    ("objects: [{name: x, shape: sphere, radius: 1, pose: [0, 0], mass: 3}]", ["unknown key"]),
    ("objects: [{name: x, shape: sphere, radius: 1, pose: [0, 0]}, {name: x, shape: sphere, radius: 1, pose: [1, 0]}]",
     ["objects[1]", "duplicate name 'x'"]),
])
def test_yaml_errors_name_file_and_element(tmp_path: Path, text: str, words: list):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(WorldError) as e:
        load_world(p)
    assert str(p) in str(e.value)
    for w in words:
        assert w in str(e.value)


@pytest.mark.parametrize("mutate, words", [
    (lambda s: s.replace("<size>1 1 1</size>", "<size>1 1</size>", 1), ["unit_box_1", "collision", "size"]),
    (lambda s: s.replace("<sphere><radius>0.25</radius></sphere>", "<mesh><uri>x.dae</uri></mesh>"),
     ["'ball'", "unsupported geometry"]),
    (lambda s: s.replace("<scale>12 0.2 1</scale>", "<scale>12 -1 1</scale>"), ["unit_box_1", "scale"]),
    (lambda s: s.replace("4 4 0.25 0 0 0", "4 4 zero 0 0 0"), ["'ball'", "pose"]),
    (lambda s: s.replace("</world>", ""), ["invalid XML"]),
    (lambda s: s.replace("model://sun", "model://cafe_table"), ["include", "cafe_table"]),
    (lambda s: s.replace("<world name", "<notworld name").replace("</world>", "</notworld>"), ["no <world>"]),
])
def test_sdf_errors_name_file_and_element(mutate, words):
    with pytest.raises(WorldError) as e:
        parse_sdf(mutate(SDF), "bad.world")
    assert "bad.world" in str(e.value)
    for w in words:
        assert w in str(e.value)


def test_missing_file_is_a_world_error(tmp_path: Path):
    with pytest.raises(WorldError, match="cannot read"):
        load_world(tmp_path / "nope.yaml")


def test_hotel_world_matches_the_book(pkg: Path):
    w = load_world(pkg / "worlds" / "hotel.yaml")
    tables = sorted((s for s in w.shapes if s.name.startswith("table_")), key=lambda s: s.name)
    assert len(tables) == 9
    centres = sorted((s.position[0], s.position[1]) for s in tables)
    xs = sorted({c[0] for c in centres})
    ys = sorted({c[1] for c in centres})
    assert xs == [3, 6, 9] and ys == [-3, 0, 3]
    for t in tables:
        assert t.size[:2] == (1.0, 1.0) and 0.75 <= t.size[2] <= 1.0
    xmin, ymin, xmax, ymax = w.bounds_xy()
    assert 14.5 <= xmax - xmin <= 16 and 11.5 <= ymax - ymin <= 13
    walls = [s for s in w.shapes if s.name.startswith("wall_")]
    assert all(s.z_range()[1] >= 0.9 for s in walls)  # the camera at 0.26 m sees them
    assert w.clearance(0.0, 0.0) > 1.0  # free start area
    assert len(load_world(pkg / "worlds" / "empty.yaml").shapes) == 0


def test_tables_file(pkg: Path):
    tables = load_tables(pkg.parent / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml")
    assert set(tables) == {"home"} | {f"table_{i}" for i in range(1, 10)}
    assert tables["home"].x == 0.0 and tables["home"].y == 0.0


def test_every_delivery_pose_is_free_and_faces_its_table(pkg: Path):
    w = load_world(pkg / "worlds" / "hotel.yaml")
    tables = load_tables(pkg.parent / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml")
    for name, p in tables.items():
        assert w.clearance(p.x, p.y) >= 0.35, name
        if name == "home":
            continue
        t = w.shape(name)
        bearing = math.atan2(t.position[1] - p.y, t.position[0] - p.x)
        assert abs(math.remainder(bearing - p.yaw, 2 * math.pi)) < 0.2, name
        assert math.hypot(t.position[0] - p.x, t.position[1] - p.y) < 1.5, name


def test_aisles_are_wide_enough(pkg: Path):
    """Every table pose is reachable from home for a 0.18 m robot with 0.2 m inflation."""
    import numpy as np
    from scipy import ndimage

    from chefbot_sim.raster import rasterise
    w = load_world(pkg / "worlds" / "hotel.yaml")
    grid = rasterise(w, 0.05)
    dist = ndimage.distance_transform_edt(~grid.occupied) * grid.resolution
    free = dist > 0.18 + 0.2 - 0.05 / 2
    labels, _ = ndimage.label(free)
    tables = load_tables(pkg.parent / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml")
    home = labels[grid.cell_of(tables["home"].x, tables["home"].y)]
    assert home > 0
    for name, p in tables.items():
        assert labels[grid.cell_of(p.x, p.y)] == home, name
    assert np.count_nonzero(labels == home) > 0.3 * labels.size
