"""The benchmark's hard-case variants (issue 30): ``Decimate``, ``OdometryNoise.miscalibrated`` and
``run_bag``'s ``scan_filter`` on the first 20 s of the committed hotel bag."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from hotel_bag import hotel_bag_head

from chefbot_common.geometry import Pose2D
from chefbot_navigation.ros_slam_bag import run_bag
from chefbot_navigation.slam.mapper import SlamConfig
from chefbot_navigation.slam.synthetic import Decimate, OdometryNoise

BAG = Path(__file__).resolve().parents[2] / "test" / "fixtures" / "hotel_route.bag"


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    """The first 20 s of the hotel bag (the start spin and some driving)."""
    return hotel_bag_head(tmp_path_factory.mktemp("bags") / "short.bag", 20.0)


def test_decimate_keeps_a_scan_per_distance_or_turn():
    d = Decimate(0.35, math.radians(25))
    straight = [d(0.1 * k, Pose2D(0.1 * k, 0.0, 0.0)) for k in range(10)]
    assert [k for k, keep in enumerate(straight) if keep] == [0, 4, 8]
    spin = [d(1.0 + 0.1 * k, Pose2D(0.8, 0.0, 0.2 * k)) for k in range(1, 8)]
    assert [k for k, keep in zip(range(1, 8), spin, strict=True) if keep] == [3, 6]     # 0.6, 1.2 rad from 0
    assert d.kept == 5
    with pytest.raises(ValueError, match="min_dist"):
        Decimate(0.0, 0.1)


def test_miscalibrated_odometry_is_a_deterministic_bias_unless_seeded():
    path = [Pose2D(), Pose2D(1.0, 0.0, 0.0), Pose2D(1.0, 0.0, 1.0)]
    a, b = OdometryNoise.miscalibrated(), OdometryNoise.miscalibrated()
    out_a = [a(float(k), p) for k, p in enumerate(path)]
    out_b = [b(float(k), p) for k, p in enumerate(path)]
    assert out_a == out_b
    assert out_a[1].x == pytest.approx(1.03) and out_a[1].yaw == pytest.approx(math.radians(1.5))   # 3 %, 1.5 deg/m
    assert out_a[2].yaw - out_a[1].yaw == pytest.approx(1.02)                                     # 2 % of the turn
    noisy = OdometryNoise.miscalibrated(seed=1)
    assert [noisy(float(k), p) for k, p in enumerate(path)][1] != out_a[1]


def test_scan_filter_leaves_scans_out_and_sees_recorded_odometry(short_bag):
    cfg = SlamConfig(loop_closure=False)
    recorded: dict[float, Pose2D] = {}

    def record(t: float, pose: Pose2D) -> Pose2D:
        recorded[t] = pose
        return pose

    full = run_bag(short_bag, cfg, odom_filter=record)
    assert full.decimated == 0 and len(recorded) == full.scans

    seen: list[tuple[float, Pose2D]] = []
    decimate = Decimate(0.3, math.radians(30))

    def scan_filter(t: float, pose: Pose2D) -> bool:
        seen.append((t, pose))
        return decimate(t, pose)

    fed: list[float] = []

    def odom_filter(t: float, pose: Pose2D) -> Pose2D:       # stateful filters must see the kept scans in order
        fed.append(t)
        return Pose2D(pose.x + 100.0, pose.y, pose.yaw)     # the scan filter must not see this

    res = run_bag(short_bag, cfg, odom_filter=odom_filter, scan_filter=scan_filter)
    assert res.skipped == 0 and res.decimated > 0 and res.scans == decimate.kept
    assert res.scans + res.decimated == full.scans
    assert len(fed) == res.scans and fed == sorted(fed)
    assert [t for t, _ in res.front.slam.trajectory()] == fed
    assert fed == [t for t, p in seen if t in set(fed)]
    assert all(recorded[t] == p for t, p in seen)             # the recorded odometry, not odom_filter's
