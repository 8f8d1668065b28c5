#!/usr/bin/env python3
"""rostest node for amcl_bad_inputs.test: amcl without a simulator.  This node plays the robot (tf
odom->base_footprint, base_footprint->laser, scans ray-cast in a test room) and feeds bad inputs:
no map, a map without obstacles, all-NaN scans, a scan in an unknown frame, an initial pose off the map.
Each gives a clear message on rosout and the node keeps running; then the interface is checked."""
from __future__ import annotations

import math
import os
import sys
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.join(HERE, "unit")]
from amcl_scenes import cast, room_map  # noqa: E402

from chefbot_common.geometry import Pose2D  # noqa: E402
from chefbot_common.grid import GridInfo, OccupancyMap  # noqa: E402
from chefbot_common.rostest_helpers import wait_for as wait_until  # noqa: E402
from chefbot_navigation.ros_io import (  # noqa: E402
    msg_to_pose_cov,
    occupancy_to_msg,
    pose2d_to_transform,
    pose_cov_to_msg,
    pose_to_pose2d,
)

PKG = "chefbot_navigation"
ROOM = room_map()
TRUTH = Pose2D(2.5, 2.5, 0.3)
ANGLES = np.linspace(-0.5, 0.5, 160)


class AmclBadInputsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.lock = threading.Lock()
        cls.logs: list[str] = []
        cls.diag: list[tuple[int, str]] = []
        cls.pose: PoseWithCovarianceStamped | None = None
        cls.cloud: PoseArray | None = None
        rospy.Subscriber("/rosout", Log, cls.on_log, queue_size=100)
        rospy.Subscriber("/diagnostics", DiagnosticArray, cls.on_diag, queue_size=10)
        rospy.Subscriber("amcl_pose", PoseWithCovarianceStamped, cls.on_pose, queue_size=10)
        rospy.Subscriber("particlecloud", PoseArray, cls.on_cloud, queue_size=10)
        cls.pub_map = rospy.Publisher("map", OccupancyGrid, queue_size=1, latch=True)
        cls.pub_scan = rospy.Publisher("scan", LaserScan, queue_size=5)
        cls.pub_init = rospy.Publisher("initialpose", PoseWithCovarianceStamped, queue_size=1, latch=True)
        cls.tf = tf2_ros.TransformBroadcaster()
        static = tf2_ros.StaticTransformBroadcaster()
        static.sendTransform(pose2d_to_transform(Pose2D(0.1, 0.0, 0.0), rospy.Time.now(), "base_footprint", "laser"))
        cls.static = static
        cls.buffer = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.buffer)
        cls.odom = Pose2D(1.0, -0.5, 0.2)    # odometry frame unrelated to the map
        cls.odom_paused = False
        threading.Thread(target=cls.odom_loop, daemon=True).start()
        rospy.wait_for_service("global_localization", 60.0)

    @classmethod
    def odom_loop(cls) -> None:
        rate = rospy.Rate(20)
        while not rospy.is_shutdown():
            if not cls.odom_paused:
                cls.tf.sendTransform(pose2d_to_transform(cls.odom, rospy.Time.now(), "odom", "base_footprint"))
            rate.sleep()

    @classmethod
    def on_log(cls, m: Log) -> None:
        if m.name.endswith("amcl"):
            with cls.lock:
                cls.logs.append(m.msg)

    @classmethod
    def on_diag(cls, m: DiagnosticArray) -> None:
        with cls.lock:
            cls.diag.extend((s.level, s.message) for s in m.status if "localization" in s.name)

    @classmethod
    def on_pose(cls, m: PoseWithCovarianceStamped) -> None:
        cls.pose = m

    @classmethod
    def on_cloud(cls, m: PoseArray) -> None:
        cls.cloud = m

    def logged(self, text: str) -> bool:
        with self.lock:
            return any(text in m for m in self.logs)

    def scan(self, ranges: np.ndarray, frame: str = "laser") -> LaserScan:
        msg = LaserScan()
        msg.header.stamp, msg.header.frame_id = rospy.Time.now(), frame
        msg.angle_min, msg.angle_max = float(ANGLES[0]), float(ANGLES[-1])
        msg.angle_increment = float(ANGLES[1] - ANGLES[0])
        msg.range_min, msg.range_max = 0.45, 8.0
        msg.ranges = ranges.astype(np.float32).tolist()
        return msg

    def good_ranges(self) -> np.ndarray:
        return cast(ROOM, TRUTH.compose(Pose2D(0.1, 0.0, 0.0)), ANGLES, 8.0)

    def feed(self, ranges_fn, frame: str = "laser", seconds: float = 1.0) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.pub_scan.publish(self.scan(ranges_fn(), frame))
            time.sleep(0.1)

    def test_bad_inputs_then_the_interface(self) -> None:
        # 1. no map yet: scans are refused by name, diagnostics say ERROR
        self.feed(self.good_ranges)
        wait_until(lambda: self.logged("no map yet"), 30.0, "'no map yet' warning")
        wait_until(lambda: any(lv == 2 for lv, _ in self.diag), 30.0, "ERROR diagnostics without a map")
        # 2. a map with no obstacles
        empty = OccupancyMap(GridInfo(0.05, 40, 40), np.zeros((40, 40), np.int8))
        self.pub_map.publish(occupancy_to_msg(empty, rospy.Time.now(), "map"))
        wait_until(lambda: self.logged("no occupied cells"), 30.0, "empty-map error")
        # 3. the real map, then an all-NaN scan and a scan in an unknown frame
        self.pub_map.publish(occupancy_to_msg(ROOM, rospy.Time.now(), "map"))
        wait_until(lambda: self.logged("map 160 x 120"), 30.0, "map accepted")
        self.feed(lambda: np.full(len(ANGLES), np.nan))
        wait_until(lambda: self.logged("no valid beam"), 30.0, "all-NaN scan warning")
        self.feed(self.good_ranges, frame="ghost_laser")
        wait_until(lambda: self.logged("'ghost_laser' unknown"), 30.0, "unknown-frame error")
        # 4. initial pose off the map: refused, named
        self.pub_init.publish(pose_cov_to_msg(Pose2D(50.0, 2.0, 0.0), np.eye(3) * 0.01, rospy.Time.now(), "map"))
        wait_until(lambda: self.logged("off the map"), 30.0, "off-map initial pose error")
        # 5. the true pose + good scans: amcl_pose with a real covariance, particlecloud, tf map->odom
        self.pub_init.publish(pose_cov_to_msg(TRUTH, np.diag([0.02, 0.02, 0.01]), rospy.Time.now(), "map"))
        rospy.ServiceProxy("request_nomotion_update", Empty)()
        self.feed(self.good_ranges, seconds=1.5)
        wait_until(lambda: self.pose is not None and self.cloud is not None, 30.0, "amcl_pose and particlecloud")
        est, cov = msg_to_pose_cov(self.pose)
        self.assertLess(math.hypot(est.x - TRUTH.x, est.y - TRUTH.y), 0.2)
        self.assertTrue(np.all(np.linalg.eigvalsh(cov) > 0) and np.all(np.isfinite(cov)), cov)
        self.assertGreaterEqual(len(self.cloud.poses), 500)
        t = self.buffer.lookup_transform("map", "odom", rospy.Time(0), rospy.Duration(5.0))
        tol = rospy.get_param("amcl/transform_tolerance")
        self.assertGreaterEqual(t.header.stamp.to_sec(), self.pose.header.stamp.to_sec() + tol - 1e-3,
                                f"map->odom is future-dated by transform_tolerance ({tol} s)")
        # map->base = map->odom * odom->base = the estimate
        base = pose_to_pose2d(self.pose.pose.pose)
        odom_in_map = Pose2D(t.transform.translation.x, t.transform.translation.y,
                             2.0 * math.atan2(t.transform.rotation.z, t.transform.rotation.w))
        composed = odom_in_map.compose(self.odom)
        self.assertAlmostEqual(composed.x, base.x, places=3)
        self.assertAlmostEqual(composed.y, base.y, places=3)
        # 6. the pose is saved to the parameter server (save_pose_rate)
        wait_until(lambda: abs(rospy.get_param("amcl/initial_pose_x", 0.0) - TRUTH.x) < 0.2, 30.0, "saved pose")
        # 7. scans stop: diagnostics warn, map->odom keeps coming, future-dated
        with self.lock:
            self.diag.clear()
        wait_until(lambda: any("no scan" in msg for _, msg in self.diag), 30.0, "'no scan' diagnostics")
        t2 = self.buffer.lookup_transform("map", "odom", rospy.Time(0), rospy.Duration(5.0))
        self.assertGreater(t2.header.stamp.to_sec(), rospy.Time.now().to_sec())
        # 8. odometry stops (driver died): scans are not paired with stale odometry, and it says so
        type(self).odom_paused = True
        time.sleep(0.5)
        self.feed(self.good_ranges, seconds=1.5)
        type(self).odom_paused = False
        wait_until(lambda: self.logged("no usable tf odom->base_footprint"), 30.0, "stale-odometry warning")
        # 9. global localization spreads the particles
        rospy.ServiceProxy("global_localization", Empty)()
        self.feed(self.good_ranges, seconds=0.5)
        self.assertTrue(self.logged("global localization started"))


if __name__ == "__main__":
    rospy.init_node("amcl_bad_inputs_test")
    rostest.rosrun(PKG, "amcl_bad_inputs", AmclBadInputsTest)
