#!/usr/bin/env python3
"""rostest node of sources.test: image_read and cam publish what they read; missing sources are named."""
from __future__ import annotations

import os
import subprocess
import threading
import unittest

import rospy
import rostest
from cv_bridge import CvBridge
from sensor_msgs.msg import CameraInfo, Image

from chefbot_common.rostest_helpers import wait_for

PKG = "chefbot_vision"
WALL = 60.0


class SourcesTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.lock = threading.Lock()
        cls.got: dict[str, list] = {"image": [], "video": [], "info": []}
        rospy.Subscriber("image", Image, lambda m: cls.got["image"].append(m), queue_size=5)
        rospy.Subscriber("video/image_raw", Image, lambda m: cls.got["video"].append(m), queue_size=50)
        rospy.Subscriber("video/camera_info", CameraInfo, lambda m: cls.got["info"].append(m), queue_size=50)

    def test_image_read_publishes_and_saves(self) -> None:
        wait_for(lambda: self.got["image"], WALL, "image from image_read", rospy.is_shutdown)
        m = self.got["image"][-1]
        self.assertEqual((m.width, m.height, m.encoding), (320, 240, "bgr8"))
        save_as = rospy.get_param("/image_read/save_as")   # in a directory that did not exist: created
        self.assertTrue(os.path.isfile(save_as), save_as)

    def test_cam_streams_a_video_file_in_a_loop(self) -> None:
        wait_for(lambda: len(self.got["video"]) >= 12, WALL, "12 frames (the 5-frame clip loops)", rospy.is_shutdown)
        img, info = self.got["video"][-1], self.got["info"][-1]
        self.assertEqual((img.width, img.height, img.encoding), (160, 120, "bgr8"))
        self.assertEqual((info.width, info.height), (160, 120))
        self.assertEqual(img.header.frame_id, info.header.frame_id)
        frame = CvBridge().imgmsg_to_cv2(img, "bgr8")
        self.assertGreater(frame[..., 2].max(), 150)      # the red dot of the clip

    def test_missing_sources_are_named(self) -> None:
        image = rospy.get_param("/image_read/image")   # a good image, so that only the save directory is bad
        for node, params, text in (("cam", ["_device:=/nonexistent/chefbot_clip.avi"],
                                    "no such video file: /nonexistent/chefbot_clip.avi"),
                                   ("cam", ["_device:=57"], "camera 57 does not exist"),
                                   ("image_read", ["_image:=/nonexistent/chefbot.png"],
                                    "no such file: /nonexistent/chefbot.png"),
                                   ("image_read", [f"_image:={image}", f"_save_as:={os.devnull}/chefbot/copy.png"],
                                    f"cannot create the directory {os.devnull}/chefbot for ~save_as")):
            out = subprocess.run(["rosrun", PKG, node, f"__name:={node}_missing", *params], capture_output=True,
                                 text=True, timeout=WALL)
            self.assertEqual(out.returncode, 1, f"{node} {params}: exit {out.returncode}, {out.stderr[-300:]}")
            self.assertIn(text, out.stderr)


if __name__ == "__main__":
    rospy.init_node("sources_test")
    rostest.rosrun(PKG, "sources_test", SourcesTest)
