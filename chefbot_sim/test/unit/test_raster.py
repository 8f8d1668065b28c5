"""Rasteriser: map_server format, geometry, height band, determinism of the shipped map."""
import filecmp
from pathlib import Path

import numpy as np
import yaml

from chefbot_common.map_io import read_pgm
from chefbot_sim.raster import FREE, OCCUPIED, rasterise, write_map
from chefbot_sim.world import load_world, parse_yaml_world

WORLD = """
objects:
  - {name: block, shape: box, size: [1.0, 0.5, 1.0], pose: [1.0, 1.0, 0.0]}
  - {name: post, shape: cylinder, radius: 0.25, height: 1.0, pose: [3.0, 1.0]}
  - {name: shelf, shape: box, size: [0.5, 0.5, 0.1], pose: [1.0, 3.0, 0.8, 0.0]}
"""

SITE = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps"  # the shipped site map


def test_cells_and_band(tmp_path: Path):
    w = parse_yaml_world(WORLD)
    g = rasterise(w, 0.1, z_band=(0.02, 0.45), bounds=(0.0, 0.0, 4.0, 4.0))
    assert g.shape == (40, 40) and g.origin == (0.0, 0.0)
    assert g.occupied[g.cell_of(1.0, 1.0)] and g.occupied[g.cell_of(1.45, 1.2)]
    assert not g.occupied[g.cell_of(1.0, 1.4)]
    assert g.occupied[g.cell_of(3.0, 1.0)] and g.occupied[g.cell_of(3.2, 1.0)]
    assert not g.occupied[g.cell_of(3.24, 1.24)]  # outside the circle, inside its box
    assert not g.occupied[g.cell_of(1.0, 3.0)]  # the shelf floats above the robot band
    g_high = rasterise(w, 0.1, z_band=(0.02, 1.0), bounds=(0.0, 0.0, 4.0, 4.0))
    assert g_high.occupied[g_high.cell_of(1.0, 3.0)]
    # block: 1.0 x 0.5 m at 0.1 m -> 10 x 5 cells (+ the cells its edges touch)
    assert 50 <= np.count_nonzero(g.occupied[:20, :20]) <= 12 * 7


def test_map_server_files(tmp_path: Path):
    g = rasterise(parse_yaml_world(WORLD), 0.1, bounds=(0.0, 0.0, 4.0, 4.0))
    y, p = write_map(g, tmp_path / "m.yaml")
    meta = yaml.safe_load(y.read_text())
    assert meta == {"image": "m.pgm", "resolution": 0.1, "origin": [0.0, 0.0, 0.0], "negate": 0,
                    "occupied_thresh": 0.65, "free_thresh": 0.196}
    img = read_pgm(p)
    assert img.shape == (40, 40) and set(np.unique(img)) == {OCCUPIED, FREE}
    # row 0 of the image is the top (largest y)
    r, c = g.cell_of(1.0, 1.0)
    assert img[39 - r, c] == OCCUPIED


def test_shipped_hotel_map_regenerates_identically(pkg: Path, tmp_path: Path):
    g = rasterise(load_world(pkg / "worlds" / "hotel.yaml"), 0.05)
    y, p = write_map(g, tmp_path / "hotel_world_map.yaml")
    assert filecmp.cmp(y, SITE / "hotel_world_map.yaml", shallow=False)
    assert filecmp.cmp(p, SITE / "hotel_world_map.pgm", shallow=False)


def test_cli(pkg: Path, tmp_path: Path):
    import subprocess
    import sys
    out = tmp_path / "m.yaml"
    res = subprocess.run([sys.executable, str(pkg / "nodes" / "world_to_map"), str(pkg / "worlds" / "hotel.yaml"),
                          str(out)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert filecmp.cmp(out.with_suffix(".pgm"), SITE / "hotel_world_map.pgm", shallow=False)
    bad = tmp_path / "bad.yaml"
    bad.write_text("objects: [{shape: cone, pose: [0, 0]}]")
    res = subprocess.run([sys.executable, str(pkg / "nodes" / "world_to_map"), str(bad), str(out)],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 1 and "unknown shape" in res.stderr and str(bad) in res.stderr
