"""Simulator readings -> ROS messages (message types, no rospy; stamps passed in).

Odometry and depth images use bringup's builders (``chefbot_bringup.ros_io``),
so the simulated robot's messages are built exactly like the real robot's.
"""
from __future__ import annotations

import numpy as np
import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import BatteryState, CameraInfo, Image, Imu, JointState, LaserScan, Range

from chefbot_bringup.depth_scan import Scan
from chefbot_bringup.odometry import OdometryState
from chefbot_bringup.ros_io import depth_to_image, odometry_to_msgs, scan_to_msg
from chefbot_sim.events import CliffData, GroundTruthData, ImuData, JointStatesData, LidarData, OdomData, UltrasonicData
from chefbot_vision.ros_io import camera_info

_ZERO_COV = np.zeros((6, 6))

__all__ = ["camera_info_msg", "cliff_msgs", "depth_to_image", "ground_truth_msg", "imu_msg", "joint_state_msg",
           "laser_scan_msg", "odom_msgs", "range_msg", "rgb_to_image"]


def sim_stamp(t: float) -> rospy.Time:
    """ROS time of sim time ``t`` (s), rounded to the nanosecond.  rospy.Time.from_sec truncates, and
    the sim clock is a float sum of physics steps, so 125.3 would become 125.299999999: a tf stamped
    (scan stamp + tolerance) then misses a scan stamped exactly there by 1 ns ("extrapolation into
    the future")."""
    return rospy.Time(0, round(t * 1e9))


def _diag3(v: float) -> list[float]:
    """Row-major 3x3 covariance with ``v`` on the diagonal."""
    return [v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v]


def joint_state_msg(d: JointStatesData, stamp) -> JointState:
    """sensor_msgs/JointState of the wheel (and other) joints."""
    m = JointState()
    m.header.stamp = stamp
    m.name = d["name"]
    m.position, m.velocity = d["position"].tolist(), d["velocity"].tolist()
    return m


def ground_truth_msg(d: GroundTruthData, stamp, world_frame: str, base_frame: str) -> Odometry:
    """nav_msgs/Odometry of the true pose in the world frame (tests and benchmarks only)."""
    m = Odometry()
    m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, world_frame, base_frame
    p, o, tw = m.pose.pose.position, m.pose.pose.orientation, m.twist.twist
    p.x, p.y, p.z = d["position"].tolist()
    o.x, o.y, o.z, o.w = d["orientation"].tolist()
    tw.linear.x, tw.linear.y, tw.linear.z = d["linear"].tolist()
    tw.angular.x, tw.angular.y, tw.angular.z = d["angular"].tolist()
    return m


def odom_msgs(d: OdomData, stamp, odom_frame: str, base_frame: str):
    """Wheel odometry as nav_msgs/Odometry plus the odom -> base transform (bringup's builder)."""
    st = OdometryState(stamp.to_sec(), d["x"], d["y"], d["yaw"], d["v"], d["w"], _ZERO_COV, _ZERO_COV)
    return odometry_to_msgs(st, stamp, odom_frame, base_frame)


def imu_msg(d: ImuData, stamp, frame: str) -> Imu:
    """sensor_msgs/Imu with the simulated noise as covariances."""
    m = Imu()
    m.header.stamp, m.header.frame_id = stamp, frame
    o, g, a = m.orientation, m.angular_velocity, m.linear_acceleration
    o.x, o.y, o.z, o.w = d["orientation"].tolist()
    g.x, g.y, g.z = d["angular_velocity"].tolist()
    a.x, a.y, a.z = d["linear_acceleration"].tolist()
    m.orientation_covariance = _diag3(1e-6)
    m.angular_velocity_covariance = _diag3(d["gyro_variance"])
    m.linear_acceleration_covariance = _diag3(d["accel_variance"])
    return m


def range_msg(d: UltrasonicData, stamp, frame: str, radiation_type: int = Range.ULTRASOUND) -> Range:
    """sensor_msgs/Range of the ultrasonic sensor (or, with ``Range.INFRARED``, one cliff sensor)."""
    m = Range()
    m.header.stamp, m.header.frame_id = stamp, frame
    m.radiation_type = radiation_type
    m.field_of_view, m.min_range, m.max_range, m.range = (d["field_of_view"], d["min_range"], d["max_range"],
                                                          d["range"])
    return m


def cliff_msgs(d: CliffData, stamp) -> list[Range]:
    """One sensor_msgs/Range (INFRARED) per cliff sensor, in the order of ``d``, stamped with the
    sensor's URDF frame (``cliff_left_link`` ..., x along the beam)."""
    return [range_msg({"range": float(d["range"][i]), "min_range": float(d["min_range"][i]),
                       "max_range": float(d["max_range"][i]), "field_of_view": float(d["field_of_view"][i])},
                      stamp, frame, Range.INFRARED)
            for i, frame in enumerate(d["frames"])]


def battery_msg(d: dict, stamp) -> BatteryState:
    """The simulated pack (``Simulator`` reading ``battery``) as sensor_msgs/BatteryState: percentage is the
    state of charge 0..1, current negative while discharging (the message's convention)."""
    b = BatteryState(voltage=float(d["volts"]), current=-float(d["current"]), present=True,
                     percentage=float(d["soc"]), capacity=float(d["capacity_ah"]),
                     design_capacity=float(d["capacity_ah"]), charge=float(d["soc"] * d["capacity_ah"]))
    b.header.stamp = stamp
    b.power_supply_status = (BatteryState.POWER_SUPPLY_STATUS_CHARGING if d["charging"]
                             else BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
    return b


def laser_scan_msg(d: LidarData, stamp) -> LaserScan:
    """sensor_msgs/LaserScan of one lidar scan, in the lidar's frame (all beams at one instant:
    time_increment 0)."""
    scan = Scan(d["angle_min"], d["angle_max"], d["angle_increment"], d["ranges"])
    return scan_to_msg(scan, stamp, d["frame"], d["range_min"], d["range_max"], d["scan_time"])


def camera_info_msg(info: dict, frame: str) -> CameraInfo:
    """sensor_msgs/CameraInfo from :meth:`chefbot_sim.sim.CameraModel.info` (no rectification; built by
    chefbot_vision's builder, the one ``cam`` uses)."""
    k = info["K"]
    return camera_info(info["width"], info["height"], k[0], k[4], k[2], k[5], frame)


def rgb_to_image(rgb: np.ndarray, stamp, frame: str) -> Image:
    """sensor_msgs/Image (rgb8) of an (H, W, 3) uint8 array."""
    m = Image()
    m.header.stamp, m.header.frame_id = stamp, frame
    m.height, m.width = rgb.shape[:2]
    m.encoding, m.is_bigendian, m.step = "rgb8", 0, 3 * rgb.shape[1]
    m.data = rgb.tobytes()
    return m
