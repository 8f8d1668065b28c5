#!/usr/bin/env python3
"""rostest node of slam_workflow_lidar.test (issue 30): with ``lidar:=360`` the robot's ``scan`` is the
simulated lidar's, not the depth camera's.

Checks the geometry a LaserScan consumer reads (beam count, angle_min + i * angle_increment covering the
circle once, limits, frame), the rate in sim time, that the sim is the only publisher of ``scan`` while
depth_to_scan publishes ``camera_scan``, and that robot_state_publisher gives ``base_link -> laser`` on
the top plate.  Private params: ``beams`` (360), ``fov_deg`` (360), ``frame`` (laser), ``rate`` (Hz, 10),
``laser_z`` (m above base_link)."""
from __future__ import annotations

import math
import unittest

import rosgraph
import rospy
import rostest
import tf2_ros
from sensor_msgs.msg import LaserScan

PKG = "chefbot_tests"


class LidarScanTest(unittest.TestCase):
    def test_scan_is_the_lidar(self) -> None:
        beams, fov = rospy.get_param("~beams", 360), math.radians(rospy.get_param("~fov_deg", 360.0))
        frame, rate = rospy.get_param("~frame", "laser"), rospy.get_param("~rate", 10.0)
        scans: list[LaserScan] = []
        sub = rospy.Subscriber("scan", LaserScan, scans.append, queue_size=50)
        deadline = rospy.get_time() + 60.0   # wall or sim: generous either way
        while len(scans) < 12 and not rospy.is_shutdown():
            self.assertLess(rospy.get_time(), deadline, f"only {len(scans)} scans on 'scan'")
            rospy.sleep(0.1)
        sub.unregister()
        s = scans[-1]
        self.assertEqual(s.header.frame_id, frame)
        self.assertEqual(len(s.ranges), beams)
        self.assertAlmostEqual(s.angle_min, -fov / 2.0, places=5)
        self.assertAlmostEqual(s.angle_increment, fov / beams, places=6)
        self.assertAlmostEqual(s.angle_max, s.angle_min + (beams - 1) * s.angle_increment, places=5)
        self.assertAlmostEqual(s.range_min, 0.12, places=5)
        self.assertEqual(s.time_increment, 0.0)
        finite = [r for r in s.ranges if math.isfinite(r)]
        self.assertGreater(len(finite), beams // 2, "the room's walls are within range of most beams")
        self.assertTrue(all(s.range_min <= r <= s.range_max for r in finite))
        stamps = [m.header.stamp.to_sec() for m in scans[2:]]
        period = (stamps[-1] - stamps[0]) / (len(stamps) - 1)
        print(f"[figure] lidar scan period {period:.4f} s of sim time, {len(finite)}/{beams} returns", flush=True)
        self.assertAlmostEqual(period, 1.0 / rate, delta=0.2 / rate)
        # publishers: the sim alone on scan, depth_to_scan moved to camera_scan
        pubs = dict((t, n) for t, n in rosgraph.Master(rospy.get_name()).getSystemState()[0])
        self.assertEqual(pubs.get(rospy.resolve_name("scan")), ["/chefbot_sim"])
        self.assertEqual(pubs.get(rospy.resolve_name("camera_scan")), ["/depth_to_scan"])
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        t = buf.lookup_transform("base_link", frame, rospy.Time(0), rospy.Duration(10.0)).transform
        self.assertAlmostEqual(t.translation.z, rospy.get_param("~laser_z", 0.4073), delta=0.002)


if __name__ == "__main__":
    rospy.init_node("lidar_scan_test")
    rostest.rosrun(PKG, "lidar_scan_test", LidarScanTest)
