"""Odometry that does not move the robot: the IMU heading track, the bumper, mapped obstacles, stalls."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_navigation.slam.imu_heading import HeadingTrack
from chefbot_navigation.slam.mapper import Slam, SlamConfig
from chefbot_navigation.slam.scan import scan_from_ranges
from chefbot_navigation.slam.synthetic import box_segments, cast

# a depth camera's scan: 58 deg, 160 beams, nothing inside 0.45 m (REP 117 "no return")
FOV, BEAMS, RANGE_MIN, RANGE_MAX = math.radians(58), 160, 0.45, 8.0
ROOM = np.vstack([box_segments(-3, -2, 4, 3), box_segments(1.0, 0.5, 1.6, 1.1),
                  box_segments(-2.0, -1.5, -1.5, -1.3)])


def _scan(pose: Pose2D, blind: bool = False, segs: np.ndarray = ROOM):
    angles = -FOV / 2 + FOV * np.arange(BEAMS) / BEAMS
    r = np.full(BEAMS, np.inf) if blind else cast(segs, (pose.x, pose.y), angles + pose.yaw, RANGE_MAX)
    r = np.where(r < RANGE_MIN, np.inf, r)
    return scan_from_ranges(r, -FOV / 2, FOV / BEAMS, RANGE_MIN, RANGE_MAX, Pose2D(), RANGE_MAX - 0.5)


def _live(slam: Slam, odom: Pose2D) -> Pose2D:
    """The pose the live node publishes: map->odom composed with the odometry."""
    return slam.map_to_odom().compose(odom)


# ---------------------------------------------------------------- HeadingTrack
def test_heading_track_unwraps_and_interpolates():
    h = HeadingTrack(max_gap=0.25)
    assert h.at(0.0) is None
    yaws = [3.0, -3.1, -2.9, 2.9]          # across +-pi and back: +0.18, +0.2, -0.48 rad
    for k, y in enumerate(yaws):
        h.add_yaw(0.1 * k, y)
    assert h.at(0.1) - h.at(0.0) == pytest.approx(2 * math.pi - 6.1, abs=1e-9)
    assert h.at(0.2) - h.at(0.1) == pytest.approx(0.2, abs=1e-9)
    assert h.at(0.3) == pytest.approx(2.9, abs=1e-9)            # turned back: the first turn's branch again
    assert h.at(0.05) == pytest.approx(0.5 * (h.at(0.0) + h.at(0.1)), abs=1e-9)
    assert h.at(0.3 + 0.2) == pytest.approx(h.at(0.3))       # within max_gap after the last sample
    assert h.at(0.3 + 0.3) is None and h.at(-0.3) is None     # beyond it: the IMU stopped / not yet started


def test_heading_track_rejects_bad_samples_and_gaps():
    h = HeadingTrack(max_gap=0.25)
    h.add_yaw(1.0, 0.0)
    h.add_yaw(1.0, 0.1)                   # not after the last sample
    h.add_yaw(0.5, 0.1)                   # out of order
    h.add_yaw(1.1, math.nan)
    assert h.rejected == 3
    h.add_yaw(2.0, 0.5)                   # a 1 s gap: nothing in between is known
    assert h.at(1.5) is None and h.at(2.0) == pytest.approx(0.5)


def test_heading_track_integrates_a_rate_only_imu_and_restarts_after_a_gap():
    h = HeadingTrack(max_gap=0.25)
    for k in range(21):                   # 0.5 rad/s for 2 s at 10 Hz
        h.add_rate(0.1 * k, 0.5)
    assert h.at(2.0) - h.at(0.0) == pytest.approx(1.0, abs=1e-9)
    h.add_rate(3.0, 0.5)                  # after a 1 s gap the turn in it is unknown: the heading carries on
    assert h.at(3.0) == pytest.approx(h.at(2.0), abs=1e-9)


def test_heading_track_keeps_only_recent_history():
    h = HeadingTrack(keep=1.0)
    for k in range(50):
        h.add_yaw(0.1 * k, 0.0)
    assert h.at(1.0) is None and h.at(4.5) == pytest.approx(0.0)


# ---------------------------------------------------------------- whole SLAM
def _swing(cfg: SlamConfig, imu: bool, imu_sign: float = 1.0):
    """Spin 2 turns on the spot and drive 1 m along x seeing the room, then a collision swings the body
    +0.5 rad while the wheels report 0.1 m straight on and the camera (pressed against the obstacle) sees
    nothing.  The IMU's heading has an arbitrary offset and turns ``imu_sign`` times the body.  Returns the
    SLAM, the last odometry pose and the true yaw."""
    slam, t = Slam(cfg), 0.0

    def add(true: Pose2D, odom: Pose2D, turned: float, blind: bool = False) -> None:
        nonlocal t              # turned: the body's unwrapped heading (rad)
        slam.add_scan(t, _scan(true, blind), odom, 0.7 + imu_sign * turned if imu else None)
        t += 0.1
    for k in range(145):                  # 5 deg per scan: two turns
        p = Pose2D(-1.0, -0.5, wrap_angle(math.radians(5 * k)))
        add(p, p, math.radians(5 * k))
    for k in range(21):
        p = Pose2D(-1.0 + 0.05 * k, -0.5, 0.0)
        add(p, p, 4 * math.pi)
    yaw = 0.0
    for k in range(1, 6):
        yaw = 0.1 * k
        odom = Pose2D(0.02 * k, -0.5, 0.0)
        add(Pose2D(odom.x, odom.y, yaw), odom, 4 * math.pi + yaw, blind=True)
    return slam, odom, yaw


def test_the_imu_turns_the_pose_when_the_wheels_miss_a_swing():
    slam, odom, yaw = _swing(SlamConfig(), imu=True)
    assert abs(wrap_angle(_live(slam, odom).yaw - yaw)) < 0.02, _live(slam, odom)
    assert slam.stats.imu_turns >= 1
    off, odom, yaw = _swing(SlamConfig(imu_slip_yaw=0.0), imu=True)       # 0: the IMU is not used
    assert abs(wrap_angle(_live(off, odom).yaw - yaw)) > 0.4
    none, odom, yaw = _swing(SlamConfig(), imu=False)
    assert abs(wrap_angle(_live(none, odom).yaw - yaw)) > 0.4 and none.stats.imu_turns == 0
    assert slam.stats.imu == "in use" and slam.stats.imu_ratio == pytest.approx(1.0, abs=0.05)
    assert none.stats.imu == "none"


@pytest.mark.parametrize("sign", [-1.0, 0.0])
def test_an_imu_upside_down_or_frozen_is_not_used(sign):
    slam, odom, yaw = _swing(SlamConfig(), imu=True, imu_sign=sign)
    assert slam.stats.imu == "rejected" and slam.stats.imu_ratio == pytest.approx(sign, abs=0.1)
    assert any(e.startswith("imu/data rejected") and "upside down" in e for e in slam.stats.events), slam.stats.events
    assert slam.stats.imu_turns == 0
    assert abs(wrap_angle(_live(slam, odom).yaw)) < 0.02       # the wheels' heading: it missed the swing


def _push(cfg: SlamConfig, bumper: bool):
    """Drive at the room's wall x = 4 (the camera goes blind within 0.45 m of it); the robot stops at
    x = 3.8 touching it while the wheels slip on to x = 5.  Returns the live x and the SLAM."""
    slam, t, odo = Slam(cfg), 0.0, 1.5
    while odo < 5.0:
        true_x = min(odo, 3.8)
        slam.add_scan(t, _scan(Pose2D(true_x, -0.5, 0.0)), Pose2D(odo, -0.5, 0.0), None, bumper and odo >= 3.8)
        t, odo = t + 0.1, odo + 0.05
    return _live(slam, Pose2D(odo - 0.05, -0.5, 0.0)).x, slam


def test_pushing_a_wall_with_the_bumper_pressed_holds_the_pose():
    x, slam = _push(SlamConfig(contact_radius=0.0, bumper_hold_after=0.0), bumper=True)
    assert x == pytest.approx(3.8, abs=0.05) and slam.stats.bumper_holds > 0
    assert slam.stats.slip_held > 0.9                # of the 1.2 m the wheels counted against the wall
    # the first bumper_hold_after (0.3 s) of a contact is believed: here 0.15 m of odometry
    x, slam = _push(SlamConfig(contact_radius=0.0), bumper=True)
    assert x == pytest.approx(3.8 + 0.15, abs=0.05) and slam.stats.bumper_holds > 0


def test_a_graze_while_driving_along_a_corridor_holds_nothing():
    corridor = np.array([[-5.0, -1.2, 9.0, -1.2], [-5.0, 0.2, 9.0, 0.2], [8.0, -1.2, 8.0, 0.2]])
    slam, t = Slam(SlamConfig()), 0.0
    for k in range(60):                             # 3 m at 0.05 m per scan, touching something for 0.25 s
        p = Pose2D(0.05 * k, -0.5, 0.0)
        slam.add_scan(t, _scan(p, segs=corridor), p, None, 20 <= k < 23)
        t += 0.1
    assert _live(slam, p).x == pytest.approx(p.x, abs=0.05) and slam.stats.bumper_holds == 0


def test_pushing_a_mapped_wall_stops_at_it_without_a_bumper():
    x, slam = _push(SlamConfig(), bumper=False)
    assert 3.75 < x < 4.0 - 0.1 and slam.stats.contact_stops > 0      # contact_radius 0.12 from the wall


def test_without_the_checks_the_pose_runs_through_the_wall():
    x, _ = _push(SlamConfig(contact_radius=0.0, bumper_hold=False), bumper=True)
    assert x > 4.5


def test_a_mapped_obstacle_stops_motion_into_it_only():
    _, slam = _push(SlamConfig(), bumper=False)
    at = Pose2D(3.85, -0.5, 0.0)                      # touching the wall x = 4 (disk 0.12 m)
    for end in (Pose2D(3.85, 0.3, 0.0), Pose2D(3.2, -0.5, 0.0), Pose2D(3.5, 0.2, 1.0)):     # along, away
        assert slam._stop_at_obstacles(at, end) is end
    stopped = slam._stop_at_obstacles(Pose2D(3.5, -0.5, 0.0), Pose2D(4.5, -0.5, 0.3))
    assert 3.75 < stopped.x < 3.9 and stopped.y == pytest.approx(-0.5) and stopped.yaw == pytest.approx(0.3)
    assert slam._stop_at_obstacles(Pose2D(-1.0, 0.0, 0.0), Pose2D(0.0, 0.0, 0.0)).x == pytest.approx(0.0)   # free
    assert Slam(SlamConfig(contact_radius=0.0))._stop_at_obstacles(at, Pose2D(4.5, -0.5, 0.0)).x == 4.5


def test_stalled_sees_an_unchanged_scan_only():
    slam = Slam(SlamConfig())
    here = Pose2D(2.5, -0.5, 0.0)
    slam.add_scan(0.0, _scan(here), here)
    step = Pose2D(0.3, 0.0, 0.0)
    assert slam._stalled(_scan(here), step)                          # wheels said 0.3 m, the scene did not move
    assert not slam._stalled(_scan(here.compose(step)), step)        # it did move
    assert not slam._stalled(_scan(here, blind=True), step)           # nothing to tell
    corridor = np.array([[-5.0, -1.2, 9.0, -1.2], [-5.0, 0.2, 9.0, 0.2]])     # walls along the motion only
    along = Slam(SlamConfig())
    along.add_scan(0.0, _scan(here, segs=corridor), here)
    assert not along._stalled(_scan(here, segs=corridor), step)


def test_config_rejects_negative_slip_settings():
    for name in ("imu_slip_yaw", "contact_radius", "bumper_hold_after"):
        with pytest.raises(ValueError, match=name):
            Slam(SlamConfig(**{name: -0.1}))
