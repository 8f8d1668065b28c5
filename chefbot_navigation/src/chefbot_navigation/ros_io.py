"""Conversions between ROS messages and the pure cores (message types, no rospy).

Time stamps are passed in by the caller (a ``rospy.Time`` or ``genpy.Time``).
"""
from __future__ import annotations

import array
import math
import threading

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovarianceStamped,
    Quaternion,
    TransformStamped,
    Twist,
)
from nav_msgs.msg import MapMetaData, OccupancyGrid, Path
from sensor_msgs.msg import LaserScan

from chefbot_common.geometry import Pose2D, quaternion_from_yaw, yaw_from_quaternion
from chefbot_common.grid import GridInfo, OccupancyMap


def yaw_to_quaternion(yaw: float) -> Quaternion:
    """Quaternion message for a rotation of ``yaw`` rad about +z."""
    return Quaternion(*quaternion_from_yaw(yaw))


def pose_to_pose2d(p: Pose) -> Pose2D:
    """Planar part of a Pose message (quaternion normalised; zero quaternion -> yaw 0)."""
    q = p.orientation
    yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w, zero_policy="identity")
    return Pose2D(p.position.x, p.position.y, yaw or 0.0)


def pose2d_to_pose(p: Pose2D) -> Pose:
    """Pose message (z = 0) from a :class:`Pose2D`."""
    return Pose(Point(p.x, p.y, 0.0), yaw_to_quaternion(p.yaw))


def transform_to_pose2d(t: TransformStamped) -> Pose2D:
    """Planar part of a TransformStamped (child frame in the parent frame)."""
    q = t.transform.rotation
    yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w, zero_policy="identity")
    return Pose2D(t.transform.translation.x, t.transform.translation.y, yaw or 0.0)


def pose2d_to_transform(p: Pose2D, stamp, parent: str, child: str) -> TransformStamped:
    """TransformStamped of ``child`` in ``parent``."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y = p.x, p.y
    t.transform.rotation = yaw_to_quaternion(p.yaw)
    return t


def info_to_metadata(info: GridInfo, stamp) -> MapMetaData:
    """MapMetaData from a :class:`GridInfo`."""
    meta = MapMetaData()
    meta.map_load_time = stamp
    meta.resolution = info.resolution
    meta.width, meta.height = info.width, info.height
    meta.origin.position.x, meta.origin.position.y = info.origin_x, info.origin_y
    meta.origin.orientation = yaw_to_quaternion(info.origin_yaw)
    return meta


def int8_array(data: np.ndarray) -> array.array:
    """An int8[] message field value built without a per-cell Python loop.

    genpy serialises int8[] with ``struct.pack(*data)``; an ``array('b')``
    iterates as Python ints in -128..127 like the list it expects, and is
    built from the raw bytes in one copy (``bytes`` would iterate as 0..255).
    """
    return array.array("b", np.ascontiguousarray(data, dtype=np.int8).tobytes())


def occupancy_to_msg(occ: OccupancyMap, stamp, frame_id: str) -> OccupancyGrid:
    """OccupancyGrid message of an :class:`OccupancyMap` (data row-major, row 0 = min y)."""
    msg = OccupancyGrid()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.info = info_to_metadata(occ.info, stamp)
    msg.data = int8_array(occ.data)
    return msg


def msg_to_occupancy(msg: OccupancyGrid) -> OccupancyMap:
    """:class:`OccupancyMap` of an OccupancyGrid message (rejects inconsistent sizes)."""
    info = msg.info
    q = info.origin.orientation
    yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w, zero_policy="identity") or 0.0
    # resolution is float32 on the wire: take its shortest decimal form (0.05, not 0.0500000007)
    gi = GridInfo(float(str(np.float32(info.resolution))), int(info.width), int(info.height),
                  float(info.origin.position.x), float(info.origin.position.y), yaw)
    if isinstance(msg.data, (bytes, bytearray, array.array)):
        data = np.frombuffer(msg.data, dtype=np.int8)
    else:
        data = np.asarray(msg.data, dtype=np.int8)
    if data.size != gi.width * gi.height:
        raise ValueError(f"OccupancyGrid has {data.size} cells, expected {gi.width} x {gi.height}")
    return OccupancyMap(gi, data.reshape(gi.height, gi.width).copy())


def path_to_msg(points: np.ndarray, yaws: np.ndarray | None, stamp, frame_id: str) -> Path:
    """nav_msgs/Path through ``points`` (N, 2) m; yaws (N,) rad or along the path."""
    msg = Path()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if yaws is None:
        d = np.diff(pts, axis=0)
        yaws = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
        yaws = np.append(yaws, yaws[-1] if len(yaws) else 0.0)
    for (x, y), yaw in zip(pts, yaws, strict=True):
        ps = PoseStamped()
        ps.header = msg.header
        ps.pose = pose2d_to_pose(Pose2D(float(x), float(y), float(yaw)))
        msg.poses.append(ps)
    return msg


class CommandGate:
    """``cmd_vel`` output of a navigation node: publishes commands, and one zero Twist when going
    from moving to stopped (so other sources may take over).  ``halt()`` (a cancel, from another
    thread) blocks further commands until ``resume()`` (a new goal).  ``pub`` has ``publish(Twist)``."""

    def __init__(self, pub) -> None:
        self.pub = pub
        self.lock = threading.Lock()
        self.moving = False
        self.halted = False

    def send(self, v: float, w: float) -> None:
        """Publish (v m/s, w rad/s) unless halted; a zero command is a :meth:`stop`."""
        if v == 0.0 and w == 0.0:
            self.stop()
            return
        cmd = Twist()
        cmd.linear.x, cmd.angular.z = v, w
        with self.lock:
            if self.halted:
                return
            self.pub.publish(cmd)
            self.moving = True

    def stop(self) -> None:
        """One zero Twist if the last command moved the robot."""
        with self.lock:
            if self.moving:
                self.pub.publish(Twist())
                self.moving = False

    def halt(self) -> None:
        """Stop now and send nothing more until :meth:`resume`."""
        with self.lock:
            self.halted = True
        self.stop()

    def resume(self) -> None:
        """Allow commands again (a new goal was accepted)."""
        with self.lock:
            self.halted = False


# (row, col) of x, y, yaw in a 6x6 ROS pose covariance (x y z roll pitch yaw)
_COV_INDEX = (0, 1, 5)


def scan_arrays(msg: LaserScan) -> tuple[np.ndarray, np.ndarray]:
    """(ranges, angles) of a LaserScan as float arrays (rad in the scan frame); ValueError if unusable."""
    ranges = np.asarray(msg.ranges, dtype=np.float64)
    if ranges.size == 0:
        raise ValueError("scan has no ranges")
    if not (math.isfinite(msg.angle_min) and math.isfinite(msg.angle_increment) and msg.angle_increment != 0.0):
        raise ValueError(f"scan angle_min {msg.angle_min} / angle_increment {msg.angle_increment} unusable")
    return ranges, msg.angle_min + msg.angle_increment * np.arange(ranges.size)


def pose_cov_to_msg(pose: Pose2D, cov: np.ndarray, stamp, frame_id: str) -> PoseWithCovarianceStamped:
    """PoseWithCovarianceStamped from a planar pose and its 3x3 (x, y, yaw) covariance (m², rad²)."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.pose.pose = pose2d_to_pose(pose)
    c = [0.0] * 36
    for i, a in enumerate(_COV_INDEX):
        for j, b in enumerate(_COV_INDEX):
            c[6 * a + b] = float(cov[i, j])
    msg.pose.covariance = c
    return msg


def msg_to_pose_cov(msg: PoseWithCovarianceStamped) -> tuple[Pose2D, np.ndarray]:
    """Planar pose and 3x3 covariance of a PoseWithCovarianceStamped (e.g. RViz's 2D Pose Estimate)."""
    c = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)
    return pose_to_pose2d(msg.pose.pose), c[np.ix_(_COV_INDEX, _COV_INDEX)]


def particles_to_msg(particles: np.ndarray, stamp, frame_id: str) -> PoseArray:
    """PoseArray of (N, 3) particles (x m, y m, yaw rad)."""
    msg = PoseArray()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    half = 0.5 * particles[:, 2]
    sz, cz = np.sin(half), np.cos(half)
    msg.poses = [Pose(Point(x, y, 0.0), Quaternion(0.0, 0.0, s, c))
                 for x, y, s, c in zip(particles[:, 0].tolist(), particles[:, 1].tolist(), sz.tolist(), cz.tolist(),
                                       strict=True)]
    return msg


def diagnostics_msg(name: str, hardware_id: str, level: int, message: str, values: dict[str, float],
                    stamp) -> DiagnosticArray:
    """A DiagnosticArray with one status (level 0 OK, 1 WARN, 2 ERROR)."""
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                              values=[KeyValue(k, f"{v:.4g}") for k, v in values.items()])
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = stamp
    return msg
