#!/usr/bin/env python3
"""rostest node for faults_aisle.test: a box dropped across the only way to a goal (issue 16).

The cafe's aisle between tables n1 and n2 (0.90 m clear, chefbot_sim/worlds/cafe.yaml) is a dead end;
once the robot is under way to table_n1, a box is dropped across its mouth (4 cm from the chairs on
either side).  move_base must stop and abort with a reason, without touching the box; with the box
removed, the same goal is reached (so the abort was the box's doing, and move_base did not hang).
A box in the open that move_base drives round: sim_navigation.test test_c (hotel, amcl).
Durations are sim time; wall-clock bounds are generous timeouts for a loaded machine.
"""
from __future__ import annotations

import math
import os
import sys
import unittest

import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from std_msgs.msg import String

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim_navigation_test_node import connect_sim_client, goal_for

from chefbot_common.rostest_helpers import wait_for

PKG = "chefbot_tests"
WALL_TIMEOUT = 300.0
BOX_X, BOX_Y, BOX_W, BOX_D = 2.15, 3.69, 1.2, 0.18    # m: across the aisle mouth x 1.55..2.75, y 3.60..3.78
REASONS = ("unreachable", "blocked", "inside an obstacle", "closer to an obstacle")


class FaultsAisleTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        connect_sim_client(cls, 180.0)
        cls.spawn = rospy.Publisher("chefbot_sim/spawn", String, queue_size=1, latch=True)
        cls.remove = rospy.Publisher("chefbot_sim/remove", String, queue_size=1, latch=True)

    def result(self) -> tuple[int, str]:
        self.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)), "no result: move_base hung")
        return self.client.get_state(), self.client.get_goal_status_text()

    def at_rest(self) -> tuple[float, float, float, float]:
        wait_for(lambda: self.truth.speed() < 0.01, 60.0, "robot at rest", stop=rospy.is_shutdown)
        return self.truth.latest()

    def test_box_blocking_the_only_aisle_aborts_then_clears(self) -> None:
        target = self.tables["table_n1"]
        self.client.send_goal(goal_for(target))
        wait_for(lambda: self.truth.speed() > 0.15, 120.0, "robot under way", stop=rospy.is_shutdown)
        t_drop, x, y, _ = self.truth.latest()
        self.assertGreater(math.hypot(x - BOX_X, y - BOX_Y), 0.8, "robot already at the aisle")
        with self.truth.lock:
            self.truth.crate = (BOX_X, BOX_Y)
        self.spawn.publish(String(data=f"{{name: aisle_block, shape: box, size: [{BOX_W}, {BOX_D}, 0.5], "
                                       f"pose: [{BOX_X}, {BOX_Y}]}}"))
        state, text = self.result()
        t_end, x, y, _ = self.at_rest()
        print(f"[figure] aisle blocked: {GoalStatus.to_string(state)} {t_end - t_drop:.1f} s sim after the drop, "
              f"robot at ({x:.2f}, {y:.2f}), closest {self.truth.crate_min_dist:.2f} m to the box centre: {text}",
              flush=True)
        self.assertEqual(state, GoalStatus.ABORTED, text)
        self.assertTrue(any(r in text for r in REASONS), f"no reason in {text!r}")
        self.assertEqual(self.truth.contacts, 0, "bumper contact with the dropped box")
        self.assertGreater(math.hypot(x - target.x, y - target.y), 0.3, "robot reached the goal past the box?")
        # the box cleared again, the same goal is reached: the aisle itself is passable, move_base still works
        self.remove.publish(String(data="aisle_block"))
        rospy.sleep(1.0)
        self.client.send_goal(goal_for(target))
        state, text = self.result()
        self.assertEqual(state, GoalStatus.SUCCEEDED, text)
        _, x, y, _ = self.at_rest()
        self.assertLessEqual(math.hypot(x - target.x, y - target.y), 0.08)


if __name__ == "__main__":
    rospy.init_node("faults_aisle_test")
    rostest.rosrun(PKG, "faults_aisle", FaultsAisleTest)
