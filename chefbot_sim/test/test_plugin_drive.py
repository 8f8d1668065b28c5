#!/usr/bin/env python3
"""rostest: plugin-mode drive, odometry, command timeout and sensors of chefbot_sim_node.

Every wait is a condition on sim time with a wall-clock timeout; cmd_vel is
published from the /clock callback, so commanding follows sim time whatever
the real-time factor.
"""
import math
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Pose2D, Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image, Imu, LaserScan, Range
from std_srvs.srv import Empty

from chefbot_common.rostest_helpers import SimRecorder

WALL_TIMEOUT = 90.0  # s of wall time for any single condition
SONAR_X = 0.1425     # m, ultrasonic_link ahead of base_footprint (chefbot.xacro)
DEPTH_X = 0.1615     # m, camera_depth_frame ahead of base_footprint


class Recorder(SimRecorder):
    wall_timeout = WALL_TIMEOUT
    stopped = staticmethod(rospy.is_shutdown)

    def __init__(self) -> None:
        super().__init__(["gt", "odom", "imu", "sonar", "depth", "scan"])
        self.pub = rospy.Publisher("cmd_vel", Twist, queue_size=10, tcp_nodelay=True)
        self.teleport = rospy.Publisher("chefbot_sim/teleport", Pose2D, queue_size=1, latch=True)
        rospy.Subscriber("/clock", Clock, self.on_clock, tcp_nodelay=True)
        rospy.Subscriber("ground_truth/odom", Odometry, lambda m: self.add("gt", m))
        rospy.Subscriber("odom", Odometry, lambda m: self.add("odom", m))
        rospy.Subscriber("imu/data", Imu, lambda m: self.add("imu", m))
        rospy.Subscriber("ultrasonic", Range, lambda m: self.add("sonar", m))
        rospy.Subscriber("camera/depth/image_raw", Image, lambda m: self.add("depth", m), buff_size=2**22)
        rospy.Subscriber("scan", LaserScan, lambda m: self.add("scan", m))

    def publish_cmd(self, v: float, w: float) -> None:
        t = Twist()
        t.linear.x, t.angular.z = v, w
        self.pub.publish(t)


def xy(m: Odometry) -> np.ndarray:
    p = m.pose.pose.position
    return np.array([p.x, p.y])


class PluginDrive(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("test_plugin_drive")
        cls.r = Recorder()
        cls.wall_x = rospy.get_param("~wall_x")
        cls.r.wait_for(lambda: cls.r.now() > 0.5 and cls.r.between("gt", 0.0, math.inf), "clock and ground truth")
        # the cliff guard holds forward motion until all three cliff sensors have reported
        guard_ok = []
        rospy.Subscriber("diagnostics", DiagnosticArray, lambda m: guard_ok.extend(
            s for s in m.status if s.name == "chefbot: cliff guard" and s.level == DiagnosticStatus.OK))
        cls.r.wait_for(lambda: bool(guard_ok), "the cliff guard to allow forward motion")

    def teleport(self, x: float) -> float:
        t0 = self.r.now()
        self.r.teleport.publish(Pose2D(x=x, y=0.0, theta=0.0))

        def arrived() -> bool:
            gts = self.r.between("gt", t0, math.inf)
            return bool(gts) and abs(gts[-1].pose.pose.position.x - x) < 0.01
        self.r.wait_for(arrived, f"teleport to x={x}")
        t = self.r.now() + 0.3  # let it settle on its wheels
        self.r.wait_until(t)
        return t

    def test_1_drive_odom_timeout(self) -> None:
        r = self.r
        t0 = r.now() + 0.2
        r.wait_until(t0)
        gt0, od0 = r.latest("gt", t0 - 0.05), r.latest("odom", t0 - 0.05)
        with r.lock:
            r.cmd = (0.2, 0.0)
        r.wait_until(t0 + 5.0)
        with r.lock:
            r.cmd = None
        t1 = r.now()
        gt1, od1 = r.at("gt", t1), r.at("odom", t1)
        dist = float(np.linalg.norm(xy(gt1) - xy(gt0)))
        self.assertAlmostEqual(dist, 1.0, delta=0.05, msg=f"ground truth moved {dist:.3f} m in 5 s at 0.2 m/s")
        odist = float(np.linalg.norm(xy(od1) - xy(od0)))
        self.assertLess(abs(odist - dist) / dist, 0.02, f"odom {odist:.4f} m vs ground truth {dist:.4f} m")
        # still moving before the 0.6 s timeout, stopped after it
        r.wait_until(t1 + 0.3)
        v_before = r.at("gt", t1 + 0.3).twist.twist.linear.x
        self.assertGreater(v_before, 0.15, "robot stopped before the 0.6 s command timeout")
        r.wait_until(t1 + 1.2)
        a, b = r.at("gt", t1 + 1.0), r.at("gt", t1 + 1.2)
        self.assertLess(np.linalg.norm(xy(b) - xy(a)), 0.002, "robot still moving 1 s after the last cmd_vel")
        self.assertLess(abs(b.twist.twist.linear.x), 0.01)

    def test_2_range_sensors(self) -> None:
        t = self.teleport(1.0)
        gt = self.r.latest("gt", t)
        x = gt.pose.pose.position.x
        sonar = self.r.latest("sonar", t + 0.15)
        expected = self.wall_x - (x + SONAR_X)
        self.assertAlmostEqual(sonar.range, expected, delta=0.03, msg="ultrasonic range to the wall")
        img = self.r.latest("depth", t + 0.15)
        depth = np.frombuffer(img.data, dtype="<f4").reshape(img.height, img.width)
        h, w = img.height // 2, img.width // 2
        centre = float(np.nanmedian(depth[h - 2:h + 2, w - 2:w + 2]))
        self.assertAlmostEqual(centre, self.wall_x - (x + DEPTH_X), delta=0.02, msg="depth at the image centre")
        scan = self.r.latest("scan", t + 0.25)
        mid = scan.ranges[len(scan.ranges) // 2]
        self.assertAlmostEqual(mid, self.wall_x - (x + DEPTH_X), delta=0.03, msg="scan beam straight ahead")

    def test_3_imu_turning(self) -> None:
        r = self.r
        t = self.teleport(0.0)
        with r.lock:
            r.cmd = (0.0, 0.8)
        r.wait_until(t + 2.5)
        with r.lock:
            r.cmd = None
        imu = [m.angular_velocity.z for m in r.between("imu", t + 1.0, t + 2.5)]
        gt = [m.twist.twist.angular.z for m in r.between("gt", t + 1.0, t + 2.5)]
        self.assertTrue(imu and gt)
        self.assertGreater(abs(np.mean(gt)), 0.5, "robot did not turn")
        self.assertAlmostEqual(float(np.mean(imu)), float(np.mean(gt)), delta=0.02)

    def test_4_fault_injection_refused_in_plugin_drive(self) -> None:
        """~unplug/~replug/~emit_garbage exist in both drives; the plugin drive refuses them by name."""
        for name in ("unplug", "replug", "emit_garbage"):
            srv = rospy.ServiceProxy(f"chefbot_sim/{name}", Empty)
            srv.wait_for_service(30.0)
            with self.assertRaises(rospy.ServiceException) as err:
                srv()
            self.assertIn(f"~{name}", str(err.exception))
            self.assertIn("drive:=firmware", str(err.exception))


if __name__ == "__main__":
    rostest.rosrun("chefbot_sim", "plugin_drive", PluginDrive)
