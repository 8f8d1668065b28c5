"""slam_offline and the shared front end on the committed hotel bag (no master needed)."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rosbag
import rospy
from geometry_msgs.msg import TransformStamped
from hotel_bag import hotel_bag_head
from sensor_msgs.msg import Imu, LaserScan
from std_msgs.msg import Bool

from chefbot_common.map_io import load_map
from chefbot_navigation.ros_slam_bag import BagError, run_bag
from chefbot_navigation.slam.mapper import SlamConfig
from chefbot_navigation.slam.metrics import map_quality
from chefbot_navigation.slam_io import SeqGaps, SlamFrontend, SlamInputError

PKG = Path(__file__).resolve().parents[2]
BAG = PKG / "test" / "fixtures" / "hotel_route.bag"
NODE = PKG / "nodes" / "slam_offline"
TRUTH = PKG.parent / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    """The first 60 s of the hotel bag (the start spin and the first leg)."""
    return hotel_bag_head(tmp_path_factory.mktemp("bags") / "short.bag", 60.0)


def test_cli_writes_map_and_tum_trajectory(short_bag, tmp_path):
    prefix, traj = tmp_path / "m", tmp_path / "traj.txt"
    r = subprocess.run([sys.executable, str(NODE), str(short_bag), str(prefix), "--trajectory", str(traj),
                        "--refine", "1", "--no-turn-calibration"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "x real time" in r.stdout and "%" in r.stderr            # summary + progress bar
    assert "slam_offline: odometry bias: " in r.stdout, r.stdout    # what the SLAM learned of the wheels
    assert "turn scale" not in r.stdout                             # --no-turn-calibration: none learned
    occ = load_map(f"{prefix}.yaml")
    assert set(np.unique(occ.data)) <= {-1, 0, 100} and (occ.data == 100).sum() > 100
    lines = traj.read_text().split()
    rows = np.array(lines, dtype=float).reshape(-1, 8)
    with rosbag.Bag(str(short_bag)) as b:
        stamps = [m.header.stamp.to_sec() for _, m, _ in b.read_messages(topics=["/scan"])]
    assert np.allclose(rows[:, 0], stamps)                          # one pose per scan, the scan's stamp
    assert np.allclose(rows[:, 4:6], 0.0) and np.allclose(np.hypot(rows[:, 6], rows[:, 7]), 1.0)


def test_cli_bad_inputs(tmp_path, short_bag):
    r = subprocess.run([sys.executable, str(NODE), str(tmp_path / "none.bag"), str(tmp_path / "m")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "no such bag file" in r.stderr
    r = subprocess.run([sys.executable, str(NODE), str(short_bag), str(tmp_path / "m"), "--scan-topic", "laser"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "has no topic '/laser'" in r.stderr and "/scan" in r.stderr
    r = subprocess.run([sys.executable, str(NODE), str(short_bag), str(tmp_path / "m"), "--base-frame", "base_link",
                        "--odom-frame", "wheel_odom"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "no usable scan" in r.stderr and "wheel_odom" in r.stderr
    r = subprocess.run([sys.executable, str(NODE), str(short_bag), str(tmp_path / "m"), "--refine", "-1"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "refine_passes" in r.stderr, r.stderr


def test_offline_map_quality_on_whole_route():
    res = run_bag(BAG, SlamConfig())
    q = map_quality(res.front.slam.occupancy(), load_map(TRUTH))
    assert q.matched > 0.85 and q.false_occupied < 0.02, q
    raw = run_bag(BAG, SlamConfig(scan_matching=False, loop_closure=False))
    q_raw = map_quality(raw.front.slam.occupancy(), load_map(TRUTH))
    assert q_raw.false_occupied > 0.3                               # raw odometry: what matching buys


def test_bag_without_scan_topic(tmp_path):
    bag = tmp_path / "noscan.bag"
    with rosbag.Bag(str(bag), "w") as b:
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = "odom", "base_footprint"
        t.transform.rotation.w = 1.0
        from tf2_msgs.msg import TFMessage
        b.write("/tf", TFMessage([t]), rospy.Time(1))
    with pytest.raises(BagError, match="no topic '/scan'"):
        run_bag(bag, SlamConfig())


def _scan(frame: str = "laser", n: int = 10, stamp: float = 1.0) -> LaserScan:
    s = LaserScan()
    s.header.frame_id, s.header.stamp = frame, rospy.Time(stamp)
    s.angle_min, s.angle_increment = -0.5, 1.0 / max(n, 1)
    s.range_min, s.range_max = 0.1, 5.0
    s.ranges = [2.0] * n
    return s


def _lookup_factory(known: dict[tuple[str, str], TransformStamped]):
    def lookup(target, source, stamp):
        if (target, source) not in known:
            raise LookupError(f'"{target}" passed to lookupTransform argument target_frame does not exist')
        return known[(target, source)]
    return lookup


def _identity(parent: str, child: str) -> TransformStamped:
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.rotation.w = 1.0
    return t


def test_frontend_bad_inputs_name_the_problem():
    known = {("base_footprint", "laser"): _identity("base_footprint", "laser"),
             ("odom", "base_footprint"): _identity("odom", "base_footprint")}
    front = SlamFrontend(SlamConfig(), _lookup_factory(known))
    front.process(_scan())                                           # fine
    with pytest.raises(SlamInputError, match="frame 'camera_x'"):
        front.process(_scan(frame="camera_x"))
    with pytest.raises(SlamInputError, match="zero beams"):
        front.process(_scan(n=0))
    no_odom = SlamFrontend(SlamConfig(), _lookup_factory({("base_footprint", "laser"): known[("base_footprint",
                                                                                                "laser")]}))
    with pytest.raises(SlamInputError, match="no odometry tf odom -> base_footprint"):
        no_odom.process(_scan())
    bad = _scan()
    bad.angle_increment = math.nan
    with pytest.raises(SlamInputError, match="angle"):
        front.process(bad)


def test_false_occupied_clusters_finds_a_phantom_wall():
    """The failure report's clusters: a 20-cell phantom wall is the largest, at its centre."""
    import numpy as np

    from chefbot_common.grid import GridInfo, OccupancyMap
    from chefbot_navigation.slam.metrics import false_occupied_clusters

    info = GridInfo(0.05, 60, 40)
    truth = np.zeros((40, 60), dtype=np.int8)
    truth[0, :] = 100                        # the wall along y = 0
    est = truth.copy()
    est[20, 10:30] = 100                     # a phantom wall at y ~ 1.0 m, x 0.5..1.5 m
    est[35, 50] = 100                        # one speckle
    clusters = false_occupied_clusters(OccupancyMap(info, est), OccupancyMap(info, truth))
    assert [n for n, _, _ in clusters] == [20, 1]
    assert clusters[0][1] == pytest.approx(1.0, abs=0.05) and clusters[0][2] == pytest.approx(1.025, abs=0.03)
    assert false_occupied_clusters(OccupancyMap(info, truth), OccupancyMap(info, truth)) == []


def test_seq_gaps_count_lost_scans_and_restart_on_a_seq_going_back():
    g = SeqGaps()
    assert [g.update(s) for s in (5, 6, 7)] == [0, 0, 0]      # the first seen seq is no gap
    assert g.update(10) == 2 and g.update(11) == 0 and g.lost == 2
    assert g.update(0) == 0 and g.update(1) == 0              # publisher restarted / bag replayed
    assert g.update(4) == 2 and g.lost == 4


def _imu(stamp: float, yaw: float | None = None, rate: float = 0.0) -> Imu:
    m = Imu()
    m.header.stamp = rospy.Time(stamp)
    if yaw is None:
        m.orientation_covariance[0] = -1.0                          # REP 145: no orientation
    else:
        m.orientation.z, m.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    m.angular_velocity.z = rate
    return m


def test_frontend_gives_the_core_the_imu_heading_and_the_bumper():
    known = {("base_footprint", "laser"): _identity("base_footprint", "laser"),
             ("odom", "base_footprint"): _identity("odom", "base_footprint")}
    front = SlamFrontend(SlamConfig(), _lookup_factory(known))
    seen = []
    front.slam.add_scan = lambda t, scan, odom, heading, contact: seen.append((t, heading, contact))
    front.add_imu(_imu(0.9, 3.1))
    front.add_imu(_imu(1.1, -3.1))                                   # across +-pi: +0.083 rad
    front.add_imu(Imu())                                             # all-zero quaternion: unset, not used
    front.process(_scan(stamp=1.0))
    front.add_bumper(True)
    front.add_bumper(False)                                          # released before the scan: still a contact
    front.process(_scan(stamp=1.05))
    front.process(_scan(stamp=1.08))
    assert front.scans_without_imu == 0
    front.process(_scan(stamp=3.0))                                  # the IMU stopped (or another clock)
    assert seen[-1][1] is None and front.scans_without_imu == 1
    assert [s[2] for s in seen] == [False, True, False, False]
    assert seen[0][1] == pytest.approx(3.1 + (math.pi - 3.1), abs=1e-9)       # interpolated half way
    assert front.imu_samples == 2 and front.heading.rejected == 1 and front.bumper_samples == 2
    front.add_bumper(True)                                           # pressed, then its messages stop
    for t in (3.1, 3.2, 3.5, 3.7):
        front.process(_scan(stamp=t))
    assert [s[2] for s in seen[-4:]] == [True, True, True, False]   # held up to 0.5 s after the last message
    rate = SlamFrontend(SlamConfig(), _lookup_factory(known))
    for k in range(11):
        rate.add_imu(_imu(0.1 * k, None, 0.5))
    assert rate.heading.at(1.0) - rate.heading.at(0.0) == pytest.approx(0.5, abs=1e-9)


def test_bag_imu_and_bumper_are_used_when_recorded(tmp_path, short_bag):
    bag = tmp_path / "imu.bag"
    with rosbag.Bag(str(short_bag)) as src, rosbag.Bag(str(bag), "w") as dst:
        for topic, msg, t in src.read_messages():
            dst.write(topic, msg, t)
        for k in range(int(20 * 50)):                                # 20 s of a still IMU at 50 Hz, bumper 20 Hz
            t = src.get_start_time() + 0.02 * k
            dst.write("/imu/data", _imu(t, 0.3), rospy.Time(t))
            if k % 5 == 0:
                dst.write("/bumper", Bool(False), rospy.Time(t))
    res = run_bag(bag, SlamConfig())
    assert res.front.imu_samples == 1000 and res.front.bumper_samples == 200
    none = run_bag(bag, SlamConfig(), imu_topic="", bumper_topic="")
    assert none.front.imu_samples == 0 and none.front.bumper_samples == 0
    r = subprocess.run([sys.executable, str(NODE), str(bag), str(tmp_path / "m"), "--quiet"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "1000 IMU and 200 bumper messages used" in r.stdout, r.stdout + r.stderr
    with pytest.raises(BagError, match="'/scan' is sensor_msgs/LaserScan, not std_msgs/Bool"):
        run_bag(bag, SlamConfig(), bumper_topic="scan")
