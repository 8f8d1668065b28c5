"""tf lookups as planar poses, with amcl's pairing of scans and odometry (ROS side: uses rospy and tf2_ros).

Kept out of the node so that it stays wiring only; the pure localization core never sees tf.
"""
from __future__ import annotations

import rospy
import tf2_ros

from chefbot_common.geometry import Pose2D
from chefbot_navigation.ros_io import transform_to_pose2d

TF_ERRORS = (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException)


class TfPoses:
    """Odometry pose of the base at a stamp, and the (static, cached) pose of sensor frames on the base."""

    def __init__(self, odom_frame: str, base_frame: str, tolerance: float, cache_time: float = 30.0) -> None:
        self.odom_frame, self.base_frame, self.tolerance = odom_frame, base_frame, tolerance
        self.buffer = tf2_ros.Buffer(cache_time=rospy.Duration(cache_time))
        self.listener = tf2_ros.TransformListener(self.buffer)
        self.sensors: dict[str, Pose2D] = {}

    def odom_pose(self, stamp: rospy.Time | None) -> Pose2D | None:
        """odom->base at ``stamp`` (waiting up to ``tolerance`` s for it), or the latest for None.

        amcl's rule: a scan is only paired with odometry of its own time (interpolated);
        pairing it with an older pose would turn the robot's motion in between into a
        localization error.  If odometry does not reach the stamp within ``tolerance``
        the scan is not used (warned, with the odometry's age).
        """
        try:
            if stamp is None:
                return transform_to_pose2d(self.buffer.lookup_transform(self.odom_frame, self.base_frame,
                                                                        rospy.Time(0)))
            return transform_to_pose2d(self.buffer.lookup_transform(self.odom_frame, self.base_frame, stamp,
                                                                    rospy.Duration(self.tolerance)))
        except TF_ERRORS as exc:
            err = str(exc)
        try:
            latest = self.buffer.lookup_transform(self.odom_frame, self.base_frame, rospy.Time(0)).header.stamp
            err = f"the latest is {(stamp - latest).to_sec():.2f} s older than the scan" if stamp else err
        except TF_ERRORS:
            pass
        rospy.logwarn_throttle_identical(5.0, f"no usable tf {self.odom_frame}->{self.base_frame}: {err}")
        return None

    def sensor_pose(self, frame: str) -> Pose2D | None:
        """Pose of ``frame`` in the base frame (looked up once, then cached); None (error logged) if unknown."""
        if frame not in self.sensors:
            try:
                t = self.buffer.lookup_transform(self.base_frame, frame, rospy.Time(0), rospy.Duration(0.5))
            except TF_ERRORS as exc:
                rospy.logerr_throttle_identical(5.0, f"scan frame '{frame}' unknown to tf (no "
                                                     f"{self.base_frame}->{frame}): {exc}")
                return None
            self.sensors[frame] = transform_to_pose2d(t)
        return self.sensors[frame]

    def clear(self) -> None:
        """Forget everything (time jumped backwards)."""
        self.buffer.clear()
        self.sensors.clear()
