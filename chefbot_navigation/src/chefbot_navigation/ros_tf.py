"""tf lookups as planar poses (on ros_util.PlanarTf), with amcl's pairing of scans and odometry
(ROS side: uses rospy and tf2_ros).

Kept out of the node so that it stays wiring only; the pure localization core never sees tf.
"""
from __future__ import annotations

import rospy

from chefbot_common.geometry import Pose2D
from chefbot_navigation.ros_io import transform_to_pose2d
from chefbot_navigation.ros_util import TF_ERRORS, PlanarTf, lookup_transform_wall


class TfPoses(PlanarTf):
    """Odometry pose of the base at a stamp, and the (static, cached) pose of sensor frames on the base
    (a :class:`PlanarTf` whose global frame is the odometry frame)."""

    def __init__(self, odom_frame: str, base_frame: str, tolerance: float, cache_time: float = 30.0) -> None:
        super().__init__(odom_frame, cache_time)
        self.odom_frame, self.base_frame, self.tolerance = odom_frame, base_frame, tolerance
        self.sensors: dict[str, Pose2D] = {}

    def odom_pose(self, stamp: rospy.Time | None) -> Pose2D | None:
        """odom->base at ``stamp`` (waiting up to ``tolerance`` s for it), or the latest for None.

        amcl's rule: a scan is only paired with odometry of its own time (interpolated);
        pairing it with an older pose would turn the robot's motion in between into a
        localization error.  If odometry does not reach the stamp within ``tolerance``
        the scan is not used (warned, with the odometry's age).
        """
        pose, _, err = self.lookup(self.base_frame, stamp, self.tolerance if stamp is not None else 0.0)
        if pose is not None:
            return pose
        err = err.split(": ", 1)[-1]   # PlanarTf's "no transform a -> b: " is said below
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
                t = lookup_transform_wall(self.buffer, self.base_frame, frame, rospy.Time(0), 0.5)
            except TF_ERRORS as exc:
                rospy.logerr_throttle_identical(5.0, f"scan frame '{frame}' unknown to tf (no "
                                                     f"{self.base_frame}->{frame}): {exc}")
                return None
            self.sensors[frame] = transform_to_pose2d(t)
        return self.sensors[frame]

    def clear(self) -> None:
        """Forget everything (time jumped backwards)."""
        super().clear()
        self.sensors.clear()
