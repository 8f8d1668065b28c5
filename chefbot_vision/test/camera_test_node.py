#!/usr/bin/env python3
"""rostest node of camera.test: the simulated RGB-D camera, cv_bridge_demo and depth_image_proc together.

Rates are counted by header stamps over a window of SIM time, so the test holds however fast the
sim runs; wall-clock limits are only timeouts for a loaded machine.
"""
from __future__ import annotations

import math
import threading
import unittest

import numpy as np
import rospy
import rostest
from cv_bridge import CvBridge
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from chefbot_common.rostest_helpers import wait_for
from chefbot_vision.ros_io import cloud_xyz

PKG = "chefbot_vision"
WALL = 180.0
WINDOW = 3.0         # s of sim time over which rates are counted
TOPICS = {
    "rgb": ("camera/rgb/image_raw", Image), "rgb_info": ("camera/rgb/camera_info", CameraInfo),
    "depth": ("camera/depth/image_raw", Image), "depth_info": ("camera/depth/camera_info", CameraInfo),
    "points": ("camera/depth/points", PointCloud2), "registered": ("camera/depth_registered/points", PointCloud2),
    "edges": ("cv_bridge_demo/edges", Image), "depth_view": ("cv_bridge_demo/depth_view", Image),
    "dip": ("depth_image_proc/points", PointCloud2),
}


class Recorder:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.msgs: dict[str, list] = {k: [] for k in TOPICS}
        self.logs: list[str] = []
        for key, (topic, typ) in TOPICS.items():
            rospy.Subscriber(topic, typ, self.add, key, queue_size=20, buff_size=2 ** 25)
        rospy.Subscriber("/rosout", Log, lambda m: self.logs.append(m.msg), queue_size=100)

    def add(self, msg, key: str) -> None:
        with self.lock:
            self.msgs[key].append(msg)
            del self.msgs[key][:-60]

    def stamped(self, key: str, t0: float, t1: float) -> list:
        with self.lock:
            return [m for m in self.msgs[key] if t0 <= m.header.stamp.to_sec() < t1]


class CameraTest(unittest.TestCase):
    rec: Recorder

    @classmethod
    def setUpClass(cls) -> None:
        cls.rec = Recorder()
        cls.bridge = CvBridge()
        wait_for(lambda: all(cls.rec.msgs[k] for k in TOPICS), WALL, "every camera, demo and cloud topic",
                 rospy.is_shutdown)

    def test_rates_in_sim_time(self) -> None:
        t0 = rospy.get_time() + 0.5
        wait_for(lambda: rospy.get_time() > t0 + WINDOW + 0.5, WALL, "a window of sim time", rospy.is_shutdown)
        for key in ("rgb", "rgb_info", "depth", "depth_info", "points", "registered"):
            n = len(self.rec.stamped(key, t0, t0 + WINDOW))
            self.assertTrue(9.0 * WINDOW <= n <= 11.0 * WINDOW + 1, f"{TOPICS[key][0]}: {n} in {WINDOW} s of sim time "
                                                                     "(expected 10 Hz)")

    def test_camera_info_and_frames_consistent(self) -> None:
        rgb, info = self.rec.msgs["rgb"][-1], self.rec.msgs["rgb_info"][-1]
        self.assertGreaterEqual((rgb.width, rgb.height), (320, 240))
        self.assertEqual((info.width, info.height), (rgb.width, rgb.height))
        self.assertIn(rgb.encoding, ("rgb8", "bgr8"))
        self.assertEqual(rgb.header.frame_id, "camera_rgb_optical_frame")
        self.assertEqual(info.header.frame_id, rgb.header.frame_id)
        depth, dinfo = self.rec.msgs["depth"][-1], self.rec.msgs["depth_info"][-1]
        self.assertEqual((depth.encoding, depth.header.frame_id), ("32FC1", "camera_depth_optical_frame"))
        self.assertEqual((dinfo.width, dinfo.height, dinfo.header.frame_id), (depth.width, depth.height,
                                                                              depth.header.frame_id))
        # both cameras: the same horizontal field of view (the Kinect's), principal point at the centre
        hfov = [2 * math.atan(i.width / 2 / i.K[0]) for i in (info, dinfo)]
        self.assertAlmostEqual(hfov[0], hfov[1], places=6)
        self.assertAlmostEqual(info.K[2], (info.width - 1) / 2)
        pts, reg = self.rec.msgs["points"][-1], self.rec.msgs["registered"][-1]
        self.assertEqual((pts.header.frame_id, pts.width, pts.height), ("camera_depth_optical_frame", depth.width,
                                                                        depth.height))
        self.assertEqual(reg.header.frame_id, "camera_rgb_optical_frame")
        self.assertEqual([f.name for f in reg.fields], ["x", "y", "z", "rgb"])

    def test_our_cloud_equals_depth_image_procs(self) -> None:
        """depth_image_proc's point_cloud_xyz from our depth image = the cloud the sim publishes with it."""
        def pair():
            ours = {m.header.stamp: m for m in list(self.rec.msgs["points"])}
            for m in reversed(list(self.rec.msgs["dip"])):
                if m.header.stamp in ours:
                    return ours[m.header.stamp], m
            return None
        wait_for(lambda: pair() is not None, WALL, "clouds with the same stamp", rospy.is_shutdown)
        ours, dip = pair()
        a, b = cloud_xyz(ours), cloud_xyz(dip)
        self.assertEqual(a.shape, b.shape)
        both = np.isfinite(a).all(1) & np.isfinite(b).all(1)
        self.assertGreater(both.mean(), 0.5)
        np.testing.assert_allclose(a[both], b[both], atol=2e-3)

    def test_demo_edges_of_the_scene(self) -> None:
        edges, rgb = self.rec.msgs["edges"][-1], self.rec.msgs["rgb"][-1]
        self.assertEqual((edges.encoding, edges.width, edges.height), ("mono8", rgb.width, rgb.height))
        e = self.bridge.imgmsg_to_cv2(edges)
        frac = (e > 0).mean()
        # tables, chair legs and the floor line make edges, but not everywhere
        self.assertTrue(0.005 < frac < 0.2, f"edge pixels {frac:.3%}")
        view = self.bridge.imgmsg_to_cv2(self.rec.msgs["depth_view"][-1])
        self.assertEqual(view.dtype, np.float32)
        # NORM_MINMAX in float32: the farthest reading maps to 1 within rounding
        self.assertTrue(np.isfinite(view).all() and view.min() >= 0.0, (view.min(), view.max()))
        self.assertAlmostEqual(float(view.max()), 1.0, places=5)

    def test_demo_survives_bad_images(self) -> None:
        pub_rgb = rospy.Publisher("camera/rgb/image_raw", Image, queue_size=5)
        wait_for(lambda: pub_rgb.get_num_connections() > 1, 30, "cv_bridge_demo on camera/rgb/image_raw",
                 rospy.is_shutdown)
        depth_as_rgb = self.bridge.cv2_to_imgmsg(np.ones((4, 4), np.float32), "32FC1")
        empty = Image(encoding="bgr8", width=0, height=0, step=0)
        for bad in (depth_as_rgb, empty):
            pub_rgb.publish(bad)
            rospy.sleep(0.2)
        wait_for(lambda: any("RGB image skipped" in m for m in self.rec.logs), 30, "an error naming the bad image",
                 rospy.is_shutdown)
        t = rospy.get_time()
        wait_for(lambda: self.rec.stamped("edges", t, math.inf), 60, "edges again after the bad images",
                 rospy.is_shutdown)


if __name__ == "__main__":
    rospy.init_node("camera_test")
    rostest.rosrun(PKG, "camera_test", CameraTest)
