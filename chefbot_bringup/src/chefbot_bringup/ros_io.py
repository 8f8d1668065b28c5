"""Conversions between ROS messages and the pure cores (message types, no rospy).

Kept apart from the cores so those stay importable and testable without ROS
message packages; time stamps are passed in by the caller.
"""
from __future__ import annotations

import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Quaternion, TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import BatteryState, CameraInfo, Image, Imu, LaserScan, Range

from chefbot_bringup.cliff_guard import CliffStatus
from chefbot_bringup.depth_scan import Intrinsics, Scan
from chefbot_bringup.launchpad import LaunchpadConfig, LaunchpadCore, battery_status, link_status
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


# ---------------------------------------------------------------- launchpad_node's messages
def ultrasonic_to_range(cm: float, stamp, frame_id: str) -> Range:
    """The board's ultrasonic reading (cm; 0 = no echo) as sensor_msgs/Range (m; no echo = +inf, REP 117)."""
    r = Range(radiation_type=Range.ULTRASOUND, field_of_view=math.radians(15.0), min_range=0.02, max_range=4.0)
    r.header.stamp, r.header.frame_id = stamp, frame_id
    r.range = float("inf") if cm <= 0 else cm / 100.0
    return r


def board_quaternion_to_imu(x: float, y: float, z: float, w: float, stamp, frame_id: str) -> Imu | None:
    """The board's DMP orientation as sensor_msgs/Imu (normalised); None if the quaternion's norm is < 0.5."""
    norm = math.sqrt(x ** 2 + y ** 2 + z ** 2 + w ** 2)
    if norm < 0.5:
        return None
    imu = Imu()
    imu.header.stamp, imu.header.frame_id = stamp, frame_id
    imu.orientation.x, imu.orientation.y, imu.orientation.z, imu.orientation.w = x / norm, y / norm, z / norm, w / norm
    # DMP orientation: ~0.05 rad (≈3°) standard deviation; rates and accelerations are
    # not sent by the board: covariance[0] = -1 marks them unknown (sensor_msgs/Imu).
    imu.orientation_covariance = [0.0025, 0, 0, 0, 0.0025, 0, 0, 0, 0.0025]
    imu.angular_velocity_covariance[0] = -1.0
    imu.linear_acceleration_covariance[0] = -1.0
    return imu


def battery_to_state(volts: float, fraction: float, stamp) -> BatteryState:
    """The board's battery voltage (V) as sensor_msgs/BatteryState; ``fraction`` (0..1) of charge if present."""
    b = BatteryState(voltage=volts, present=volts > 0.5)
    b.header.stamp = stamp
    b.percentage = fraction if b.present else float("nan")
    b.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_UNKNOWN
    return b


def launchpad_diagnostics(core: LaunchpadCore, p: LaunchpadConfig, now: float, last_error: str,
                          battery_volts: float | None, stamp) -> DiagnosticArray:
    """The link's and the battery's diagnostic statuses; ``now`` is monotonic time (s) as the core's."""
    s = core.stats
    level, text = link_status(core, now, p.port, last_error)
    st = DiagnosticStatus(level=level, name="chefbot: launchpad", message=text, hardware_id=p.port)
    # connected = the board is heard from (port open alone is port_open)
    values = {"port": p.port, "connected": core.alive(now), "port_open": core.connected,
              "lines_ok": s.lines_ok,
              "lines_bad": s.bad_total, "lines_with_crc": s.crc_lines, "reconnects": s.reconnects,
              "encoder_resets": s.encoder_resets, "encoder_jumps": s.encoder_jumps,
              "commands_sent": s.commands_sent, "commands_zeroed_link_silent": s.commands_zeroed,
              "board_drive_state": s.board_state,
              "board_hello": " ".join(s.hello) if s.hello else None, "last_error": last_error}
    values.update({f"bad_{k}": v for k, v in sorted(s.lines_bad.items())})
    st.values = [KeyValue(k, str(v)) for k, v in values.items()]
    b_level, b_text = battery_status(p, battery_volts)
    bat = DiagnosticStatus(level=b_level, name="chefbot: battery", message=b_text, hardware_id=p.port)
    arr = DiagnosticArray(status=[st, bat])
    arr.header.stamp = stamp
    return arr


def cliff_diagnostics(status: CliffStatus, topics: list[str], stamp) -> DiagnosticArray:
    """The cliff guard's verdict as a diagnostic: OK, or ERROR with the unsafe sensors' reasons."""
    level = DiagnosticStatus.OK if status.safe else DiagnosticStatus.ERROR
    text = status.message if status.safe else "forward motion blocked: " + status.message
    st = DiagnosticStatus(level=level, name="chefbot: cliff guard", message=text, hardware_id="cliff sensors")
    st.values = [KeyValue("sensors", " ".join(topics)), KeyValue("forward_allowed", str(status.safe))]
    arr = DiagnosticArray(status=[st])
    arr.header.stamp = stamp
    return arr

