"""Conversions between ROS messages and the pure cores (message types, no rospy).

Kept apart from the cores so those stay importable and testable without ROS
message packages; time stamps are passed in by the caller.
"""
from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Quaternion, TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image, LaserScan

from chefbot_bringup.depth_scan import Intrinsics, Scan
from chefbot_bringup.odometry import OdometryState
from chefbot_common.geometry import quaternion_from_yaw, yaw_from_quaternion

_DEPTH_DTYPES = {"32FC1": np.float32, "16UC1": np.uint16, "mono16": np.uint16}


def yaw_to_quaternion(yaw: float) -> Quaternion:
    """Quaternion message for a rotation of ``yaw`` rad about +z."""
    return Quaternion(*quaternion_from_yaw(yaw))


def quaternion_to_yaw(q: Quaternion) -> float:
    """Yaw (rad) of a quaternion message (zero quaternion -> 0; non-finite raises QuaternionError)."""
    return yaw_from_quaternion(q.x, q.y, q.z, q.w, zero_policy="identity")


def image_to_depth(msg: Image) -> np.ndarray:
    """Depth image as an H x W array (float32 m or uint16 mm) without cv_bridge.

    Honours ``step`` (row padding) and ``is_bigendian``.
    """
    try:
        base = _DEPTH_DTYPES[msg.encoding]
    except KeyError:
        raise ValueError(f"unsupported depth encoding {msg.encoding!r} (need 32FC1 or 16UC1)") from None
    dtype = np.dtype(base).newbyteorder(">" if msg.is_bigendian else "<")
    item = dtype.itemsize
    if msg.step < msg.width * item or msg.step % item:
        raise ValueError(f"bad step {msg.step} for width {msg.width} and {msg.encoding}")
    if len(msg.data) < msg.step * msg.height:
        raise ValueError(f"image data has {len(msg.data)} bytes, need {msg.step * msg.height}")
    flat = np.frombuffer(msg.data, dtype=dtype, count=msg.step // item * msg.height)
    arr = flat.reshape(msg.height, msg.step // item)[:, : msg.width]
    return arr.astype(base, copy=False)


def depth_to_image(depth: np.ndarray, stamp, frame_id: str) -> Image:
    """Inverse of :func:`image_to_depth` (for tests and the simulator)."""
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = depth.shape
    if depth.dtype == np.uint16:
        msg.encoding, arr = "16UC1", depth.astype("<u2")
    else:
        msg.encoding, arr = "32FC1", depth.astype("<f4")
    msg.is_bigendian = 0
    msg.step = msg.width * arr.itemsize
    msg.data = arr.tobytes()
    return msg


def intrinsics_from_camera_info(msg: CameraInfo) -> Intrinsics:
    """Depth-camera intrinsics from a CameraInfo message."""
    return Intrinsics.from_matrices(list(msg.K), list(msg.P), msg.width, msg.height)


def scan_to_msg(scan: Scan, stamp, frame_id: str, range_min: float, range_max: float,
                scan_time: float) -> LaserScan:
    """sensor_msgs/LaserScan of a :class:`Scan`."""
    msg = LaserScan()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.angle_min = scan.angle_min
    msg.angle_max = scan.angle_max
    msg.angle_increment = scan.angle_increment
    msg.time_increment = 0.0
    msg.scan_time = scan_time
    msg.range_min = range_min
    msg.range_max = range_max
    msg.ranges = scan.ranges.tolist()
    return msg


def odometry_to_msgs(st: OdometryState, stamp, odom_frame: str,
                     base_frame: str) -> tuple[Odometry, TransformStamped]:
    """nav_msgs/Odometry and the matching odom -> base transform."""
    q = yaw_to_quaternion(st.theta)
    odom = Odometry()
    odom.header.stamp = stamp
    odom.header.frame_id = odom_frame
    odom.child_frame_id = base_frame
    odom.pose.pose.position.x = st.x
    odom.pose.pose.position.y = st.y
    odom.pose.pose.orientation = q
    odom.pose.covariance = st.pose_cov.reshape(-1).tolist()
    odom.twist.twist.linear.x = st.v
    odom.twist.twist.angular.z = st.w
    odom.twist.covariance = st.twist_cov.reshape(-1).tolist()
    tf = TransformStamped()
    tf.header.stamp = stamp
    tf.header.frame_id = odom_frame
    tf.child_frame_id = base_frame
    tf.transform.translation.x = st.x
    tf.transform.translation.y = st.y
    tf.transform.rotation = q
    return odom, tf
