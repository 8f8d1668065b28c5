"""tools/slam_workflow.py's map judging (no master): the saved map carried into the world through the
registration, and its quality against the world raster (the `make demo SLAM=1` / slam_workflow.test oracle)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_common.map_io import load_map
from chefbot_navigation.slam.mapper import Slam, SlamConfig
from chefbot_navigation.slam.synthetic import drive_square_corridor

ROOT = Path(__file__).resolve().parents[2]
ROOM_MAP = ROOT / "tests" / "test" / "worlds" / "slam_room_map.yaml"


sys.path.insert(0, str(ROOT / "tools"))
import slam_workflow as wf  # noqa: E402  (tools/ is no package)


def _seen_from(truth: OccupancyMap, frame: Pose2D) -> OccupancyMap:
    """The raster as a SLAM map whose frame sits at ``frame`` in the world, on a grid 1 m larger each way."""
    info = GridInfo(truth.info.resolution, truth.info.width + 40, truth.info.height + 40,
                    truth.info.origin_x - 1.0, truth.info.origin_y - 1.0)
    return wf.in_world(truth, OccupancyMap(info, np.full((info.height, info.width), -1, dtype=np.int8)),
                       frame.inverse())


def test_a_rotated_but_good_map_is_judged_good_and_its_frame_found():
    truth = load_map(ROOM_MAP)
    frame = Pose2D(0.12, -0.08, math.radians(2.5))
    saved = _seen_from(truth, frame)
    q, align = wf.judge_map(saved, truth, (0.0, 0.0))
    assert abs(align.x - frame.x) < 0.03 and abs(align.y - frame.y) < 0.03 and abs(align.yaw - frame.yaw) < 0.005
    assert q.matched > 0.97 and q.false_occupied < 0.02 and q.coverage > 0.95
    back = wf.in_world(saved, truth, align.pose)
    assert back.info == truth.info and np.mean((back.data > 50) == (truth.data > 50)) > 0.99


def test_a_doubled_wall_and_an_unseen_corner_show_in_the_figures():
    truth = load_map(ROOM_MAP)
    bad = OccupancyMap(truth.info, truth.data.copy())
    occupied = np.argwhere(truth.data > 50)
    ghost = occupied + [0, 8]                                # every wall drawn a second time 0.4 m east
    ghost = ghost[(ghost[:, 1] < truth.info.width) & (truth.data[ghost[:, 0], ghost[:, 1]] == 0)]
    bad.data[ghost[::2, 0], ghost[::2, 1]] = 100
    free = truth.data == 0
    corner = np.zeros_like(free)
    corner[: truth.info.height // 3, : truth.info.width // 3] = True
    bad.data[corner & free] = -1
    q, _ = wf.judge_map(bad, truth, (0.0, 0.0))
    assert q.false_occupied > 0.1 and q.coverage < 0.95


def test_demo_slam_rejects_a_bad_seed_before_starting_anything(tmp_path):
    """`make demo SLAM=1` with CHEFBOT_DEMO_SEED that is no whole number: exit 2 and a message naming it,
    before any roscore or simulator is started."""
    import os
    import subprocess

    env = dict(os.environ, CHEFBOT_DEMO_SLAM="1", CHEFBOT_DEMO_SLAM_DIR=str(tmp_path / "out"),
               CHEFBOT_DEMO_SEED="-3")
    out = subprocess.run([sys.executable, str(ROOT / "tools" / "demo.py")], env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "CHEFBOT_DEMO_SEED must be a whole number >= 0, got '-3'" in out.stdout
    assert not (tmp_path / "out" / "roslaunch.log").exists()


def test_track_figures_give_the_live_error_in_the_registered_frame_and_the_fitted_ate():
    """SLAM's live track against the truth: a map frame 1 m / 90 deg off in the world is undone by the
    registration; a 0.2 m jump for the last quarter of the run shows as the max (and when) and in the RMS."""
    frame = Pose2D(1.0, -2.0, math.pi / 2)
    samples = []
    for i in range(40):
        est = Pose2D(0.1 * i, 0.0, 0.05 * i)
        if i >= 30:
            est = Pose2D(est.x, 0.2, est.yaw)
        samples.append((100.0 + 0.5 * i, est, frame.compose(Pose2D(0.1 * i, 0.0, 0.05 * i))))
    f = wf.track_figures(samples, frame)
    assert f["track_samples"] == 40
    assert f["live_error_max_m"] == pytest.approx(0.2, abs=1e-9) and f["live_error_max_at_s"] == pytest.approx(15.0)
    assert f["live_error_rms_m"] == pytest.approx(0.1, abs=1e-9)          # sqrt(10/40 * 0.04)
    assert f["live_yaw_error_max_deg"] == pytest.approx(0.0, abs=1e-6)
    assert 0.0 < f["live_ate_rms_m"] < f["live_error_rms_m"]             # a best fit can only do better
    assert len(f["track"]["t"]) == 40 and f["track"]["truth"][5] == pytest.approx([0.5, 0.0, 0.25], abs=1e-4)
    assert wf.track_figures(samples[:1], frame) == {"track_samples": 1}


def test_slam_events_summary_names_the_largest_closure_and_counts_the_rest() -> None:
    lines = ["slam: mapping at 0.050 m/cell, frames map -> odom -> base_footprint",
             "slam: loop closure keyframe 12 -> 3: corrected 0.041 m, 1.2 deg (score 0.97, fit before 0.81)",
             "slam: loop closure keyframe 30 -> 5: corrected 0.425 m, 9.4 deg (score 0.78, fit before 0.37, "
             "recentred 1x)",
             "slam: loop match keyframe 31 dropped: still on the search window's edge after 2 searches around it, "
             "0.612 m off (score 0.70)",
             "slam: large correction at scan 400: 0.120 m, 2.0 deg off the odometry (score 0.90)",
             "slam: large correction at scan 410: 0.110 m, 1.0 deg off the odometry (score 0.90)",
             "slam: imu/data in use: its turns are +1.00x the matched turns",
             "slam: imu/data rejected: its turns are -0.98x the matched turns (mounted upside down, ...)"]
    assert wf.slam_events_summary(lines) == (
        "slam: 2 loop closures (largest 0.425 m / 9.4 deg: score 0.78, fit before 0.37, recentred 1x), "
        "1 loop match(es) dropped, 2 large correction(s), 1 IMU rejection(s)")
    assert wf.slam_events_summary([]) == "slam: 0 loop closures"
    # a closure line in another wording is still counted, and says so
    assert wf.slam_events_summary(["slam: loop closure keyframe 9 -> 2: moved by 0.1 m"]) == (
        "slam: 1 loop closure, 1 closure line(s) not understood: slam: loop closure keyframe 9 -> 2: moved by 0.1 m")


def test_slam_events_summary_reads_the_mappers_own_events() -> None:
    """The events a real Slam run writes (the square-corridor loop closure of chefbot_navigation's unit
    tests) are counted as the run counted them: the summary follows the mapper's wording."""
    slam = Slam(SlamConfig(scan_matching=False, loop_min_travel=8.0, loop_xy=0.6, loop_yaw=0.3))
    drive_square_corridor(slam, seed=3, yaw_bias=0.006)
    assert slam.stats.optimisations >= 1, slam.stats
    summary = wf.slam_events_summary([f"slam: {e}" for e in slam.stats.events])
    assert summary.startswith(f"slam: {slam.stats.optimisations} loop closure"), (summary, slam.stats.events)
    assert "not understood" not in summary and "(largest " in summary, summary
