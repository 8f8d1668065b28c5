"""map_server YAML + PGM reading and writing (chefbot_common.map_io)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_common.map_io import MAX_MAP_CELLS, MapError, load_map, save_map, write_pgm

HOTEL = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"


def make_map(tmp_path: Path, pixels: np.ndarray, name: str = "m", ext: str = ".pgm", **fields) -> Path:
    img_path = tmp_path / f"{name}{ext}"
    if ext == ".pgm" and pixels.ndim == 2:
        write_pgm(img_path, pixels)
    else:
        assert cv2.imwrite(str(img_path), pixels)
    meta = {"image": img_path.name, "resolution": 0.05, "origin": "[-1.0, -2.0, 0.0]", "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.196}
    meta.update(fields)
    yml = tmp_path / f"{name}.yaml"
    yml.write_text("".join(f"{k}: {v}\n" for k, v in meta.items() if v is not None))
    return yml


def test_trinary_values_and_row_order(tmp_path: Path) -> None:
    img = np.array([[0, 254, 205],
                    [100, 250, 128]], dtype=np.uint8)
    m = load_map(make_map(tmp_path, img))
    assert (m.info.width, m.info.height) == (3, 2)
    assert m.info.resolution == 0.05 and (m.info.origin_x, m.info.origin_y) == (-1.0, -2.0)
    # image top row = largest y = last OccupancyGrid row
    np.testing.assert_array_equal(m.data[1], [100, 0, -1])
    # 100 -> p = 0.608 (unknown), 250 -> 0.0196 (free), 128 -> 0.498 (unknown)
    np.testing.assert_array_equal(m.data[0], [-1, 0, -1])
    assert m.data.dtype == np.int8


def test_threshold_boundaries_are_strict(tmp_path: Path) -> None:
    # p = (255 - v)/255; v = 51 -> p = 0.8 exactly above 0.65; choose thresholds equal to p
    img = np.array([[51, 204]], dtype=np.uint8)   # p = 0.8 and 0.2
    m = load_map(make_map(tmp_path, img, occupied_thresh=0.8, free_thresh=0.2))
    np.testing.assert_array_equal(m.data[0], [-1, -1])


def test_negate(tmp_path: Path) -> None:
    img = np.array([[0, 254, 205]], dtype=np.uint8)
    m = load_map(make_map(tmp_path, img, negate=1))
    # negated: 0 -> 255 (free), 254 -> 1 (occupied), 205 -> 50 (p = 0.80, occupied)
    np.testing.assert_array_equal(m.data[0], [0, 100, 100])


def test_scale_mode(tmp_path: Path) -> None:
    img = np.array([[0, 254, 128]], dtype=np.uint8)
    m = load_map(make_map(tmp_path, img, mode="scale"))
    p = (255 - 128) / 255
    expected = int(1 + 98 * (p - 0.196) / (0.65 - 0.196))
    np.testing.assert_array_equal(m.data[0], [100, 0, expected])


def test_scale_mode_alpha_is_unknown(tmp_path: Path) -> None:
    img = np.zeros((1, 2, 4), dtype=np.uint8)
    img[..., :3] = 128
    img[0, 0, 3] = 255
    img[0, 1, 3] = 0
    m = load_map(make_map(tmp_path, img, ext=".png", mode="scale"))
    assert m.data[0, 0] > 0 and m.data[0, 1] == -1


def test_raw_mode(tmp_path: Path) -> None:
    img = np.array([[0, 37, 100, 255]], dtype=np.uint8)
    m = load_map(make_map(tmp_path, img, mode="raw"))
    np.testing.assert_array_equal(m.data[0], [0, 37, 100, -1])


def test_colour_image_is_averaged(tmp_path: Path) -> None:
    img = np.zeros((1, 2, 3), dtype=np.uint8)
    img[0, 0] = (254, 254, 254)
    img[0, 1] = (0, 0, 30)     # mean 10 -> p = 0.96 -> occupied
    m = load_map(make_map(tmp_path, img, ext=".png"))
    np.testing.assert_array_equal(m.data[0], [0, 100])


def test_round_trip_is_identity(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    data = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(37, 53))
    occ = OccupancyMap(GridInfo(0.05, 53, 37, -3.7, -6.7, 0.0), data)
    yml, pgm = save_map(occ, tmp_path / "out" / "saved")
    assert yml.name == "saved.yaml" and pgm.is_file()
    back = load_map(yml)
    np.testing.assert_array_equal(back.data, data)
    assert back.info == occ.info
    yml2, _ = save_map(back, tmp_path / "again")
    assert (tmp_path / "again.pgm").read_bytes() == pgm.read_bytes()
    again = load_map(yml2)
    np.testing.assert_array_equal(again.data, data)


@pytest.mark.skipif(not HOTEL.exists(), reason="hotel map not present")
def test_round_trip_hotel(tmp_path: Path) -> None:
    m = load_map(HOTEL)
    yml, _ = save_map(m, tmp_path / "hotel")
    np.testing.assert_array_equal(load_map(yml).data, m.data)


def test_absolute_image_path(tmp_path: Path) -> None:
    img = np.full((4, 4), 254, dtype=np.uint8)
    write_pgm(tmp_path / "abs.pgm", img)
    yml = make_map(tmp_path, img, image=str(tmp_path / "abs.pgm"))
    assert load_map(yml).data.sum() == 0


def test_largest_allowed_map_loads(tmp_path: Path) -> None:
    # its load time is measured in make bench (bench_planner), not asserted here
    rng = np.random.default_rng(0)
    img = rng.choice(np.array([0, 205, 254], dtype=np.uint8), size=(4000, 4000))
    m = load_map(make_map(tmp_path, img))
    assert m.data.shape == (4000, 4000) and MAX_MAP_CELLS == 4000 * 4000
    assert set(np.unique(m.data)) == {-1, 0, 100}


def test_map_over_the_cell_limit_is_refused_from_the_header(tmp_path: Path) -> None:
    yml = make_map(tmp_path, np.zeros((2, 2), dtype=np.uint8))
    # a header claiming 60000 x 60000 with no pixels behind it: refused before decoding
    (tmp_path / "m.pgm").write_bytes(b"P5\n60000 60000\n255\n\x00\x01")
    with pytest.raises(MapError) as err:
        load_map(yml)
    msg = str(err.value)
    assert str(yml) in msg and "'image'" in msg and "60000 x 60000" in msg and "max_map_cells" in msg
    # the limit is a parameter: a small one refuses a small map
    write_pgm(tmp_path / "m.pgm", np.zeros((10, 20), dtype=np.uint8))
    with pytest.raises(MapError, match="20 x 10 = 200 cells, more than the maximum of 199"):
        load_map(yml, max_cells=199)
    assert load_map(yml, max_cells=200).data.shape == (10, 20)


@pytest.mark.parametrize("fields,needle", [
    ({"resolution": None}, "'resolution'"),
    ({"resolution": -0.05}, "'resolution'"),
    ({"resolution": "abc"}, "'resolution'"),
    ({"resolution": 1e-300}, "between 0.001 and 100 m/cell, got 1e-300"),
    ({"resolution": "1e300"}, "between 0.001 and 100 m/cell, got 1e+300"),
    ({"origin": "[1, 2]"}, "'origin'"),
    ({"origin": "[1, 2, .nan]"}, "'origin'"),
    ({"negate": 2}, "'negate'"),
    ({"negate": None}, "'negate'"),
    ({"occupied_thresh": 1.5}, "'occupied_thresh'"),
    ({"free_thresh": None}, "'free_thresh'"),
    ({"free_thresh": 0.9}, "'free_thresh'"),
    ({"mode": "fancy"}, "'mode'"),
    ({"image": None}, "'image'"),
    ({"image": "missing.pgm"}, "missing.pgm"),
    ({"image": "/nonexistent/dir/map.pgm"}, "/nonexistent/dir/map.pgm"),
])
def test_bad_fields_name_file_and_field(tmp_path: Path, fields: dict, needle: str) -> None:
    yml = make_map(tmp_path, np.zeros((2, 2), dtype=np.uint8), **fields)
    with pytest.raises(MapError) as err:
        load_map(yml)
    assert str(yml) in str(err.value)
    assert needle in str(err.value)


def test_resolution_without_a_dot_is_a_number(tmp_path: Path) -> None:
    # PyYAML reads 5e-2 as a string (YAML 1.1); map_server (yaml-cpp) as a number
    yml = make_map(tmp_path, np.zeros((2, 2), dtype=np.uint8), resolution="5e-2", origin="[-1, 2e0, 0]")
    m = load_map(yml)
    assert m.info.resolution == 0.05 and m.info.origin_y == 2.0


def test_image_is_a_directory(tmp_path: Path) -> None:
    (tmp_path / "adir").mkdir()
    yml = make_map(tmp_path, np.zeros((2, 2), dtype=np.uint8), image="adir")
    with pytest.raises(MapError, match=r"field 'image': .*adir is a directory, not an image file"):
        load_map(yml)


def test_yaml_that_is_not_utf8_or_is_a_directory(tmp_path: Path) -> None:
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes("image: carte_\xe9t\xe9.pgm\nresolution: 0.05\n".encode("latin-1"))
    with pytest.raises(MapError) as err:
        load_map(bad)
    assert str(bad) in str(err.value) and "not UTF-8" in str(err.value)
    with pytest.raises(MapError, match="is a directory, not a map YAML file"):
        load_map(tmp_path)


def test_corrupt_image(tmp_path: Path) -> None:
    yml = make_map(tmp_path, np.zeros((2, 2), dtype=np.uint8))
    (tmp_path / "m.pgm").write_bytes(b"P5\n99999 3\n255\n\x00\x01")
    with pytest.raises(MapError, match="not a readable image"):
        load_map(yml)


def test_corrupt_yaml_and_missing_yaml(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("image: [unclosed\n")
    with pytest.raises(MapError, match="not valid YAML"):
        load_map(bad)
    bad.write_text("- just\n- a list\n")
    with pytest.raises(MapError, match="mapping"):
        load_map(bad)
    with pytest.raises(MapError, match="nope.yaml"):
        load_map(tmp_path / "nope.yaml")
