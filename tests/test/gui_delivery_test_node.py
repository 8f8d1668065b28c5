#!/usr/bin/env python3
"""GUI → move_base → simulated robot: two queued tables delivered, then home.

Watches what the GUI really sends (move_base/goal), what the server answers
(move_base/result) and where the robot really is (ground_truth/odom). Waits
on conditions with wall-clock timeouts; distances from ground truth.
"""
from __future__ import annotations

import math
import threading
import time
import unittest

import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from move_base_msgs.msg import MoveBaseActionGoal, MoveBaseActionResult
from nav_msgs.msg import Odometry
from std_msgs.msg import Bool

from chefbot_common.tables import load_tables

# m, against ground truth: amcl in the loop, as sim_navigation / faults_* (0.08); the 0.05 m goal is the
# demo's and the bench's. Home approached from table_4 ended 5.8 and 6.9 cm off in two runs of the final
# tree: move_base stops at the edge of its 0.03 m tolerance (its estimate 2.9 cm off the pose) and amcl
# is ~4 cm off there -- an open item, not this test's subject (the GUI driving a tour end to end)
XY_TOL = 0.08
WAIT_S = 300.0  # wall time for the whole tour on a loaded machine


class TestGuiDelivery(unittest.TestCase):
    def setUp(self) -> None:
        rospy.init_node("gui_delivery_check")
        self.tables = load_tables(rospy.get_param("~tables_file"))
        self.lock = threading.Lock()
        self.goals: list[tuple[float, float]] = []
        self.goal_checks: list[tuple[float, str]] = []   # (quaternion norm, frame) per goal
        self.results: list[int] = []
        self.truth: Odometry | None = None
        self.bumps = 0
        rospy.Subscriber("move_base/goal", MoveBaseActionGoal, self.on_goal)
        rospy.Subscriber("move_base/result", MoveBaseActionResult, self.on_result)
        rospy.Subscriber("ground_truth/odom", Odometry, self.on_truth, queue_size=1)
        rospy.Subscriber("bumper", Bool, self.on_bumper)

    def on_goal(self, msg: MoveBaseActionGoal) -> None:
        p = msg.goal.target_pose.pose
        q = p.orientation
        norm = math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2)
        with self.lock:  # asserted in the test thread: a failed assert in a callback is only logged
            self.goals.append((p.position.x, p.position.y))
            self.goal_checks.append((norm, msg.goal.target_pose.header.frame_id))

    def on_result(self, msg: MoveBaseActionResult) -> None:
        with self.lock:
            self.results.append(msg.status.status)

    def on_truth(self, msg: Odometry) -> None:
        self.truth = msg

    def on_bumper(self, msg: Bool) -> None:
        if msg.data:
            with self.lock:
                self.bumps += 1

    def near(self, name: str) -> float:
        p = self.truth.pose.pose.position
        t = self.tables[name]
        return math.hypot(p.x - t.x, p.y - t.y)

    def test_two_tables_then_home(self) -> None:
        order = ["table_1", "table_4", "home"]
        deadline = time.monotonic() + WAIT_S
        visited: list[str] = []
        while len(visited) < len(order):
            with self.lock:
                done = len(self.results)
            if done > len(visited):
                # move_base answered the leg: judge it where the robot really stands
                name = order[len(visited)]
                with self.lock:
                    status = self.results[len(visited)]
                self.assertEqual(status, GoalStatus.SUCCEEDED, f"{name}: move_base status {status}")
                time.sleep(0.2)  # one more ground-truth message after the stop
                err = self.near(name)
                rospy.loginfo("gui_delivery: %s reached, ground-truth error %.3f m", name, err)
                self.assertLessEqual(err, XY_TOL, f"{name}: robot {err:.3f} m from the pose")
                visited.append(name)
            self.assertLess(time.monotonic(), deadline,
                            f"tour incomplete after {WAIT_S:.0f} s: visited {visited}, goals {self.goals}")
            time.sleep(0.1)
        with self.lock:
            goals = list(self.goals)
            checks = list(self.goal_checks)
            bumps = self.bumps
        for norm, frame in checks:
            self.assertAlmostEqual(norm, 1.0, places=6)   # the book's GUI sent zero quaternions
            self.assertEqual(frame, "map")
        want = [(self.tables[n].x, self.tables[n].y) for n in order]
        self.assertEqual(len(goals), 3, f"goals sent by the GUI: {goals}")
        for got, expect in zip(goals, want, strict=True):
            self.assertAlmostEqual(got[0], expect[0], places=6)
            self.assertAlmostEqual(got[1], expect[1], places=6)
        self.assertEqual(bumps, 0, "the robot touched something")


if __name__ == "__main__":
    rostest.rosrun("chefbot_tests", "gui_delivery_check", TestGuiDelivery)
