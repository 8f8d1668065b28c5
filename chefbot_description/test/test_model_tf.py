#!/usr/bin/env python3
"""rostest node: every required frame is published on /tf or /tf_static with the right parent."""
from __future__ import annotations

import threading
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from tf2_msgs.msg import TFMessage

from chefbot_description import model

PKG = "chefbot_description"
WAIT_S = 30.0  # wall-clock budget for frames to appear


class TestModelTf(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("test_model_tf")
        cls.lock = threading.Condition()
        cls.edges: dict[str, set[str]] = {}  # child -> parents seen
        cls.subs = [rospy.Subscriber(topic, TFMessage, cls._on_tf, queue_size=100)
                    for topic in ("/tf", "/tf_static")]
        cls.buffer = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.buffer)

    @classmethod
    def tearDownClass(cls) -> None:
        for sub in cls.subs:
            sub.unregister()

    @classmethod
    def _on_tf(cls, msg: TFMessage) -> None:
        with cls.lock:
            for t in msg.transforms:
                cls.edges.setdefault(t.child_frame_id.lstrip("/"), set()).add(t.header.frame_id.lstrip("/"))
            cls.lock.notify_all()

    def _wait_for_frames(self) -> dict[str, set[str]]:
        with self.lock:
            self.lock.wait_for(lambda: set(model.FRAME_TREE) <= set(self.edges) or rospy.is_shutdown(),
                               timeout=WAIT_S)
            return {k: set(v) for k, v in self.edges.items()}

    def test_every_frame_has_required_parent(self) -> None:
        edges = self._wait_for_frames()
        missing = sorted(set(model.FRAME_TREE) - set(edges))
        self.assertEqual(missing, [], f"frames never published within {WAIT_S} s: {missing}")
        for child, parent in model.FRAME_TREE.items():
            self.assertEqual(edges[child], {parent}, f"{child} published with parent(s) {edges[child]}")

    def test_optical_frame_pose_matches_urdf(self) -> None:
        urdf = rospy.get_param("robot_description")
        expected = model.frame_transform(model.parse_urdf(urdf), "camera_depth_optical_frame")
        tf = self.buffer.lookup_transform("base_footprint", "camera_depth_optical_frame", rospy.Time(0),
                                          rospy.Duration(WAIT_S))
        t, q = tf.transform.translation, tf.transform.rotation
        np.testing.assert_allclose([t.x, t.y, t.z], expected[:3, 3], atol=1e-6)
        x, y, z, w = q.x, q.y, q.z, q.w
        rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        np.testing.assert_allclose(rot, expected[:3, :3], atol=1e-6)
        # optical convention: z forward (= base x), x right (= -base y), y down (= -base z)
        np.testing.assert_allclose(rot[:, 2], [1, 0, 0], atol=1e-6)
        np.testing.assert_allclose(rot[:, 0], [0, -1, 0], atol=1e-6)

    def test_uploaded_description_carries_sim_block(self) -> None:
        params = model.load_sim_params(rospy.get_param("robot_description"))
        self.assertAlmostEqual(params.drive.wheel_separation, 0.30)


if __name__ == "__main__":
    rostest.rosrun(PKG, "model_tf", TestModelTf)
