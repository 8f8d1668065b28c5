#!/usr/bin/env python3
"""rostest node for robot_gui_launch.test: a move_base stand-in that records the GUI's goals."""
from __future__ import annotations

import math
import threading
import unittest

import actionlib
import rospy
import rostest
from move_base_msgs.msg import MoveBaseAction

from chefbot_common.tables import load_tables


class RobotGuiLaunchTest(unittest.TestCase):
    def setUp(self) -> None:
        self.poses = load_tables(rospy.get_param("~tables_file"))
        self.goals: list = []
        self.cond = threading.Condition()
        self.server = actionlib.SimpleActionServer("move_base", MoveBaseAction, self.execute, auto_start=False)
        self.server.start()

    def execute(self, goal) -> None:
        with self.cond:
            self.goals.append(goal)
            self.cond.notify_all()
        self.server.set_succeeded(text="arrived")

    def test_queued_table_delivered_then_home(self) -> None:
        with self.cond:
            ok = self.cond.wait_for(lambda: len(self.goals) >= 2, timeout=60.0)
        self.assertTrue(ok, f"GUI sent {len(self.goals)} goal(s), expected table_2 then home")
        for goal, key in zip(self.goals, ("table_2", "home"), strict=False):
            p = goal.target_pose
            want = self.poses[key]
            self.assertEqual(p.header.frame_id, "map")
            self.assertAlmostEqual(p.pose.position.x, want.x, places=6)
            self.assertAlmostEqual(p.pose.position.y, want.y, places=6)
            q = p.pose.orientation
            self.assertAlmostEqual(math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2), 1.0, places=9)


if __name__ == "__main__":
    rospy.init_node("robot_gui_launch_test")
    rostest.rosrun("chefbot_gui", "robot_gui_launch", RobotGuiLaunchTest)
