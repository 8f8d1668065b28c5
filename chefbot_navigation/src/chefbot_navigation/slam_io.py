"""What the live ``slam`` node and ``slam_offline`` share: LaserScan + tf (+ Imu, bumper) in, SLAM core out.

Message types only, no rospy: the caller passes a tf lookup
``lookup(target, source, stamp) -> TransformStamped`` (tf2's BufferCore in
the offline tool, a tf2_ros.Buffer with a timeout in the live node), so both
feed the core exactly the same numbers and a recorded bag reproduces the
live map.  IMU and bumper messages may arrive on other threads than the
scans (the live node's subscribers): they only touch state behind a small
lock of their own.
"""
from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable

import numpy as np
from sensor_msgs.msg import Imu, LaserScan

from chefbot_common.geometry import Pose2D
from chefbot_navigation.ros_io import transform_to_pose2d
from chefbot_navigation.slam.imu_heading import HeadingTrack
from chefbot_navigation.slam.mapper import Slam, SlamConfig
from chefbot_navigation.slam.scan import ScanError, scan_from_ranges

Lookup = Callable[[str, str, object], object]

# s: a pressed bumper whose messages stopped this long ago no longer counts (its driver died while pressed)
BUMPER_STALE = 0.5
# parameter name (gmapping's where one exists) -> SlamConfig field; all private (~)
PARAM_FIELDS = tuple(f.name for f in dataclasses.fields(SlamConfig))


class SlamInputError(RuntimeError):
    """A scan could not be used (frame unknown, no odometry tf, bad scan); the message says why."""


class SlamFrontend:
    """Turn LaserScan messages into core updates, resolving frames through ``lookup``."""

    def __init__(self, cfg: SlamConfig, lookup: Lookup, base_frame: str = "base_footprint",
                 odom_frame: str = "odom") -> None:
        self.slam = Slam(cfg)
        self.lookup = lookup
        self.base_frame = base_frame
        self.odom_frame = odom_frame
        self._sensor: dict[str, Pose2D] = {}
        self.heading = HeadingTrack()     # the IMU's heading (add_imu); none: the wheels' turns only
        self.imu_samples = 0
        self.scans_without_imu = 0        # scans with no IMU sample within max_gap, once the IMU had sent some
        self.bumper_samples = 0
        self._pressed = False             # the bumper's last state
        self._contact = False             # the bumper was pressed since the last scan
        self._bumper_new = False          # a bumper message came since the last scan
        self._bumper_t = -math.inf        # stamp of the last scan after which a bumper message came
        self._aux = threading.Lock()      # heading and bumper state (other subscriber threads)

    def add_imu(self, msg: Imu) -> None:
        """An IMU sample: its orientation's heading, or (orientation_covariance[0] == -1, REP 145: no
        orientation) its integrated z rate.  The IMU must be mounted with z up (any heading offset)."""
        t = msg.header.stamp.to_sec()
        q = msg.orientation
        with self._aux:
            if msg.orientation_covariance[0] == -1.0:
                used = self.heading.add_rate(t, msg.angular_velocity.z)
            elif abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 0.1:
                self.heading.rejected += 1          # not a rotation (an all-zero quaternion: unset)
                used = False
            else:
                used = self.heading.add_yaw(t, math.atan2(2.0 * (q.w * q.z + q.x * q.y),
                                                          1.0 - 2.0 * (q.y * q.y + q.z * q.z)))
            self.imu_samples += int(used)

    def add_bumper(self, pressed: bool) -> None:
        """The bumper's state (std_msgs/Bool data): pressed at any time between two scans counts."""
        with self._aux:
            self._pressed = bool(pressed)
            self._contact = self._contact or self._pressed
            self._bumper_new = True
            self.bumper_samples += 1

    def sensor_pose(self, frame: str, stamp) -> Pose2D:
        """Pose of the scan frame in the base frame (static, cached per frame)."""
        if frame not in self._sensor:
            if not frame:
                raise SlamInputError("scan has an empty header.frame_id")
            try:
                t = self.lookup(self.base_frame, frame, stamp)
            except Exception as exc:  # tf2 raises several unrelated types
                raise SlamInputError(f"scan is in frame '{frame}', which tf cannot relate to the base "
                                     f"frame '{self.base_frame}': {exc}") from exc
            self._sensor[frame] = transform_to_pose2d(t)
        return self._sensor[frame]

    def odom_pose(self, stamp) -> Pose2D:
        """Pose of the base in the odometry frame at ``stamp``."""
        try:
            return transform_to_pose2d(self.lookup(self.odom_frame, self.base_frame, stamp))
        except Exception as exc:
            raise SlamInputError(f"no odometry tf {self.odom_frame} -> {self.base_frame} at "
                                 f"t = {stamp.to_sec():.3f} s: {exc}") from exc

    def process(self, msg: LaserScan) -> Pose2D:
        """Feed one scan; returns the base pose in the map.  Raises :class:`SlamInputError`."""
        if len(msg.ranges) == 0:
            raise SlamInputError(f"scan at t = {msg.header.stamp.to_sec():.3f} s has zero beams")
        sensor = self.sensor_pose(msg.header.frame_id, msg.header.stamp)
        odom = self.odom_pose(msg.header.stamp)
        cfg = self.slam.cfg
        try:
            scan = scan_from_ranges(np.asarray(msg.ranges, dtype=float), msg.angle_min, msg.angle_increment,
                                    msg.range_min, msg.range_max, sensor,
                                    max_usable_range=min(cfg.maxUrange, msg.range_max),
                                    max_range=cfg.maxRange or None)
        except ScanError as exc:
            raise SlamInputError(f"scan at t = {msg.header.stamp.to_sec():.3f} s: {exc}") from exc
        t = msg.header.stamp.to_sec()
        with self._aux:
            if self._bumper_new:
                self._bumper_t, self._bumper_new = t, False
            # the last state holds between messages (scans faster than the bumper), not once they stop
            held = self._pressed and t - self._bumper_t <= BUMPER_STALE
            heading, contact = self.heading.at(t), self._contact or held
            self._contact = False
            if heading is None and self.imu_samples:
                self.scans_without_imu += 1
        return self.slam.add_scan(t, scan, odom, heading, contact)


class SeqGaps:
    """Scans lost before the node saw them, from gaps in ``header.seq`` (a full subscriber queue while
    a loop closure re-optimises, or the transport).  A seq that goes back (a restarted publisher, a
    replayed bag) starts the count afresh without counting a gap."""

    def __init__(self) -> None:
        self.last: int | None = None
        self.lost = 0

    def update(self, seq: int) -> int:
        """Record a scan's seq; returns how many scans were missing just before it."""
        gap = seq - self.last - 1 if self.last is not None and seq > self.last + 1 else 0
        self.last = seq
        self.lost += gap
        return gap


def tum_lines(trajectory: list[tuple[float, Pose2D]]) -> list[str]:
    """TUM trajectory lines ``t x y z qx qy qz qw`` (one per scan, the scan's stamp)."""
    out = []
    for t, p in trajectory:
        out.append(f"{t:.9f} {p.x:.6f} {p.y:.6f} 0 0 0 {math.sin(p.yaw / 2):.9f} {math.cos(p.yaw / 2):.9f}")
    return out
