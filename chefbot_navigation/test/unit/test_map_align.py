"""map_align: rigid registration of two occupancy maps recovers a known rotation + offset (no master)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import FREE, OCCUPIED, UNKNOWN, GridInfo, OccupancyMap
from chefbot_navigation.map_align import AlignError, Alignment, align_maps, local_alignment

RES = 0.05
# An asymmetric room (m, in the "world"): outer walls, an L-shaped partition, a few tables.
BOXES = [(-1.0, -1.0, 9.0, -0.9), (-1.0, 6.9, 9.0, 7.0), (-1.0, -1.0, -0.9, 7.0), (8.9, -1.0, 9.0, 7.0),
         (3.0, -1.0, 3.1, 2.5), (3.0, 2.4, 5.5, 2.5), (1.0, 4.0, 1.8, 4.8), (6.0, 4.5, 6.8, 5.0),
         (6.5, 0.5, 7.3, 1.3), (4.2, 5.6, 4.6, 6.9)]


def raster(pose: Pose2D, origin: tuple[float, float], shape: tuple[int, int], surface_only: bool) -> OccupancyMap:
    """The room drawn in a frame whose pose in the world is ``pose``: occupied where a cell centre lies in a box.

    surface_only: keep only occupied cells next to free ones (what a SLAM map sees), rest unknown.
    """
    h, w = shape
    rows, cols = np.mgrid[0:h, 0:w]
    lx, ly = origin[0] + (cols + 0.5) * RES, origin[1] + (rows + 0.5) * RES
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    wx, wy = pose.x + c * lx - s * ly, pose.y + s * lx + c * ly
    occ = np.zeros((h, w), dtype=bool)
    for x0, y0, x1, y1 in BOXES:
        occ |= (wx >= x0) & (wx <= x1) & (wy >= y0) & (wy <= y1)
    data = np.where(occ, OCCUPIED, FREE).astype(np.int8)
    if surface_only:
        free = ~occ
        near_free = np.zeros_like(occ)
        near_free[1:] |= free[:-1]
        near_free[:-1] |= free[1:]
        near_free[:, 1:] |= free[:, :-1]
        near_free[:, :-1] |= free[:, 1:]
        data[occ & ~near_free] = UNKNOWN
    return OccupancyMap(GridInfo(RES, w, h, origin[0], origin[1], 0.0), data)


@pytest.fixture(scope="module")
def world() -> OccupancyMap:
    return raster(Pose2D(0.0, 0.0, 0.0), (-1.5, -1.5), (180, 220), surface_only=False)


@pytest.mark.parametrize("truth", [Pose2D(0.13, -0.27, math.radians(3.7)), Pose2D(-0.41, 0.08, math.radians(-11.0)),
                                   Pose2D(1.2, 0.9, math.radians(95.0))])
def test_recovers_known_rotation_and_offset(world, truth):
    # the target ("SLAM") map's frame sits at `truth` in the world; it sees wall surfaces only
    target = raster(truth, (-4.0, -4.0), (300, 300), surface_only=True)
    a = align_maps(world, target)
    assert math.hypot(a.x - truth.x, a.y - truth.y) <= RES, a
    assert abs(math.remainder(a.yaw - truth.yaw, math.tau)) <= math.radians(0.5), a
    assert a.inlier_fraction > 0.95 and a.rms_m < RES, a
    # carrying a table pose over and back is the identity, and lands where the truth puts it
    table = Pose2D(6.0, 0.9, 0.0)
    in_target = a.to_target(table)
    back = a.to_source(in_target)
    assert math.hypot(back.x - table.x, back.y - table.y) < 1e-9 and abs(back.yaw - table.yaw) < 1e-9
    exact = Alignment(truth.x, truth.y, truth.yaw, 0, 0, 1, 0).to_target(table)
    assert math.hypot(in_target.x - exact.x, in_target.y - exact.y) <= 2 * RES


def test_local_alignment_agrees_on_an_undistorted_map(world):
    truth = Pose2D(0.2, -0.1, math.radians(2.0))
    target = raster(truth, (-4.0, -4.0), (300, 300), surface_only=True)
    a = align_maps(world, target)
    loc = local_alignment(world, target, a, a.to_target(Pose2D(6.0, 0.9, 0.0)), radius=2.5)
    assert math.hypot(loc.x - truth.x, loc.y - truth.y) <= RES
    assert abs(loc.yaw - truth.yaw) <= math.radians(0.5)


def test_bad_inputs_name_the_problem(world):
    empty = OccupancyMap(GridInfo(RES, 50, 50, 0.0, 0.0, 0.0), np.zeros((50, 50), dtype=np.int8))
    with pytest.raises(AlignError, match="slam.yaml: has no occupied cells"):
        align_maps(world, empty, target_name="slam.yaml")
    with pytest.raises(AlignError, match="raster.yaml: has no occupied cells"):
        align_maps(empty, world, source_name="raster.yaml")
    with pytest.raises(AlignError, match="yaw_step must be a finite positive number"):
        align_maps(world, world, yaw_step=float("nan"))
    with pytest.raises(AlignError, match="nothing to align on"):
        local_alignment(world, world, align_maps(world, world), Pose2D(50.0, 50.0, 0.0), radius=1.0)


NODE = __import__("pathlib").Path(__file__).resolve().parents[2] / "nodes" / "align_tables"


def test_cli_writes_tables_in_the_target_frame(world, tmp_path):
    import subprocess
    import sys

    from chefbot_common.map_io import save_map
    from chefbot_common.tables import load_map_in_world, load_tables
    truth = Pose2D(0.3, -0.2, math.radians(6.0))
    save_map(world, tmp_path / "world")
    save_map(raster(truth, (-4.0, -4.0), (300, 300), surface_only=True), tmp_path / "slam")
    src = tmp_path / "tables.yaml"
    src.write_text("frame: map\nworld: synth\nposes:\n  home: {x: 0, y: 0}\n  table_1: {x: 6.0, y: 0.9, yaw: 0.0}\n")
    out = tmp_path / "tables_slam.yaml"
    run = subprocess.run([sys.executable, str(NODE), str(src), str(tmp_path / "world.yaml"),
                          str(tmp_path / "slam.yaml"), "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    text = out.read_text()
    assert "align_tables tables.yaml world.yaml slam.yaml -o tables_slam.yaml" in text and "RMS" in text
    tables, m_in_w = load_tables(out), load_map_in_world(out)
    assert math.hypot(m_in_w.x - truth.x, m_in_w.y - truth.y) <= RES
    assert abs(m_in_w.yaw - truth.yaw) <= math.radians(0.5)
    exact = truth.inverse().compose(Pose2D(6.0, 0.9, 0.0))
    assert math.hypot(tables["table_1"].x - exact.x, tables["table_1"].y - exact.y) <= 2 * RES
    # bad input: a clear message naming the file, exit 2, nothing written
    bad = subprocess.run([sys.executable, str(NODE), str(src), str(tmp_path / "absent.yaml"),
                          str(tmp_path / "slam.yaml"), "-o", str(tmp_path / "x.yaml")],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "absent.yaml" in bad.stderr and not (tmp_path / "x.yaml").exists()
