#!/usr/bin/env python3
"""robot_gui with sim time and a stopped clock reports the missing server (from its log)."""
from __future__ import annotations

import threading
import time
import unittest

import rospy
import rostest
from rosgraph_msgs.msg import Log


class TestGuiSimTime(unittest.TestCase):
    def test_not_connected_is_reported_without_a_clock(self) -> None:
        rospy.init_node("gui_sim_time_check")
        seen = threading.Event()

        def on_log(msg: Log) -> None:
            if "robot_gui" in msg.name and "navigation server not connected" in msg.msg:
                seen.set()

        rospy.Subscriber("/rosout", Log, on_log)
        # wall-clock wait: ROS time is frozen at 0 in this test by design
        deadline = time.monotonic() + 30.0
        while not seen.is_set() and time.monotonic() < deadline:
            time.sleep(0.1)
        self.assertTrue(seen.is_set(), "the GUI never reported the missing server (stuck waiting on ROS time?)")


if __name__ == "__main__":
    rostest.rosrun("chefbot_gui", "gui_sim_time_check", TestGuiSimTime)
