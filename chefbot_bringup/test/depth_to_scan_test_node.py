#!/usr/bin/env python3
"""rostest node for depth_to_scan.test: publish a synthetic wall + box, check the scan."""
from __future__ import annotations

import math
import threading
import unittest

import numpy as np
import rospy
import rostest
from sensor_msgs.msg import CameraInfo, LaserScan

from chefbot_bringup.ros_io import depth_to_image

W, H, FX, CX, CY = 160, 120, 120.0, 79.5, 59.5
WALL, BOX = 3.0, 1.2          # m
BOX_COLS = slice(20, 30)      # left of centre -> positive bearing


def camera_info(stamp) -> CameraInfo:
    info = CameraInfo()
    info.header.stamp = stamp
    info.header.frame_id = "camera_depth_optical_frame"
    info.width, info.height = W, H
    info.K = [FX, 0, CX, 0, FX, CY, 0, 0, 1]
    info.P = [FX, 0, CX, 0, 0, FX, CY, 0, 0, 0, 1, 0]
    return info


def scene_m() -> np.ndarray:
    depth = np.full((H, W), WALL, dtype=np.float32)
    depth[:, BOX_COLS] = BOX
    depth[:, 100:105] = np.nan     # no return
    return depth


class TestDepthToScan(unittest.TestCase):
    def run_case(self, ns: str, depth: np.ndarray) -> LaserScan:
        got: list[LaserScan] = []
        lock = threading.Lock()

        def on_scan(msg: LaserScan) -> None:
            with lock:
                got.append(msg)

        sub = rospy.Subscriber(f"{ns}scan", LaserScan, on_scan)
        pub_img = rospy.Publisher(f"{ns}camera/depth/image_raw", type(depth_to_image(depth, rospy.Time(), "")),
                                  queue_size=1)
        pub_info = rospy.Publisher(f"{ns}camera/depth/camera_info", CameraInfo, queue_size=1, latch=True)
        deadline = rospy.get_time() + 30.0
        # Re-publish until a scan comes back (the node may still be connecting).
        while not got:
            self.assertLess(rospy.get_time(), deadline, "no scan within 30 s")
            stamp = rospy.Time.now()
            pub_info.publish(camera_info(stamp))
            pub_img.publish(depth_to_image(depth, stamp, "camera_depth_optical_frame"))
            rospy.sleep(0.1)
        sub.unregister()
        with lock:
            return got[-1]

    def check(self, scan: LaserScan) -> None:
        self.assertEqual(scan.header.frame_id, "camera_depth_frame")
        self.assertEqual(len(scan.ranges), W)
        self.assertAlmostEqual(scan.angle_max, math.atan(CX / FX), places=5)
        self.assertAlmostEqual(scan.angle_min, -math.atan((W - 1 - CX) / FX), places=5)
        self.assertAlmostEqual(scan.range_min, 0.45, places=5)
        r = np.array(scan.ranges)
        a = scan.angle_min + scan.angle_increment * np.arange(W)
        centre = int(np.argmin(np.abs(a)))
        self.assertAlmostEqual(r[centre], WALL, delta=0.01)
        box = np.where(r < 2.0)[0]
        self.assertTrue(len(box) >= 8)
        bearing = -math.atan((24.5 - CX) / FX)
        self.assertAlmostEqual(float(np.mean(a[box])), bearing, delta=0.02)
        self.assertAlmostEqual(float(r[box].min()), BOX / math.cos(a[box].min()), delta=0.02)
        self.assertTrue(np.isnan(r[W - 1 - 102]) or np.isnan(r[W - 2 - 102]))

    def test_float_metres(self) -> None:
        self.check(self.run_case("", scene_m()))

    def test_uint16_millimetres(self) -> None:
        mm = np.nan_to_num(scene_m() * 1000.0, nan=0.0).astype(np.uint16)
        self.check(self.run_case("mm/", mm))


if __name__ == "__main__":
    rospy.init_node("depth_to_scan_test")
    rostest.rosrun("chefbot_bringup", "depth_to_scan", TestDepthToScan)
