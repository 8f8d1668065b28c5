#!/usr/bin/env python3
"""rostest node for faults_nav.test: navigation fault injection in the pybullet hotel (issue 16).

Each scenario checks that the robot ends stopped (ground truth), that move_base answered with a
result state and a status text naming the reason, and that nothing hung; the last one kills amcl
and then checks every other node still answers.  Durations are sim time; wall-clock bounds are only
generous timeouts for a loaded machine.  Covered elsewhere (not repeated): cancel mid-route in the
sim (sim_navigation.test test_b), a box in the open avoided (sim_navigation.test test_c, move_base.test
test_k), goals off the map / in unknown space / bad orientation (move_base.test).
"""
from __future__ import annotations

import math
import os
import signal
import sys
import unittest
import xmlrpc.client

import actionlib
import rosgraph
import rosnode
import rospy
import rostest
import tf2_ros
from actionlib_msgs.msg import GoalStatus, GoalStatusArray
from move_base_msgs.msg import MoveBaseAction

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim_navigation_test_node import connect_sim_client, goal_for

from chefbot_common.geometry import Pose2D
from chefbot_common.rostest_helpers import wait_for

PKG = "chefbot_tests"
NAME = "/faults_nav_test"
WALL_TIMEOUT = 240.0      # s, one leg on a loaded machine
STOP_SPEED = 0.01         # m/s over 0.2 s sim: at rest


def node_pid(name: str) -> int:
    """The pid a node reports through its XML-RPC API (found via the master); raises if it does not answer."""
    uri = rosgraph.Master(NAME).lookupNode(name)
    code, msg, pid = xmlrpc.client.ServerProxy(uri).getPid(NAME)
    if code != 1:
        raise RuntimeError(f"{name}: getPid failed: {msg}")
    return int(pid)


def process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def answers(name: str) -> bool:
    """Does node ``name`` answer getPid through the master, and is that process alive?"""
    try:
        return process_alive(node_pid(name))
    except Exception:   # noqa: BLE001 -- unknown to the master, connection refused, ...: not alive
        return False


class FaultsNavTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        connect_sim_client(cls)
        # amcl (scipy import, map service) may come up after move_base: wait for its map -> odom
        buffer = tf2_ros.Buffer()
        cls.tf_listener = tf2_ros.TransformListener(buffer)
        wait_for(lambda: buffer.can_transform("map", "base_footprint", rospy.Time(0)), 120.0,
                 "tf map -> base_footprint (amcl up)", stop=rospy.is_shutdown)
        cls.nodes = sorted(n for n in rosnode.get_node_names() if n != NAME)
        assert "/amcl" in cls.nodes and "/move_base" in cls.nodes, cls.nodes

    def result(self, client: actionlib.SimpleActionClient | None = None) -> tuple[int, str]:
        client = client or self.client
        self.assertTrue(client.wait_for_result(rospy.Duration(WALL_TIMEOUT)), "no result: move_base hung")
        return client.get_state(), client.get_goal_status_text()

    def wait_stopped(self, what: str) -> float:
        """Wait until the robot is at rest (ground truth); returns that sim time (s)."""
        wait_for(lambda: self.truth.speed() < STOP_SPEED, 60.0, f"robot at rest ({what})", stop=rospy.is_shutdown)
        return self.truth.latest()[0]

    def assert_at(self, name: str, tol: float = 0.08) -> None:
        _, x, y, _ = self.truth.latest()
        target = self.tables[name]
        self.assertLessEqual(math.hypot(x - target.x, y - target.y), tol, f"{name}: robot at ({x:.3f}, {y:.3f})")

    def test_a_goal_inside_a_table_aborts_at_once_robot_stays(self) -> None:
        self.wait_stopped("start")
        t0, x0, y0, _ = self.truth.latest()
        table = Pose2D(3.0, 0.0, 0.0)          # centre of table_4 (hotel.yaml): an occupied cell
        self.client.send_goal(goal_for(table))
        state, text = self.result()
        took = rospy.get_time() - t0
        print(f"[figure] goal in table: {GoalStatus.to_string(state)} after {took:.2f} s sim: {text}", flush=True)
        self.assertEqual(state, GoalStatus.ABORTED, text)
        self.assertIn("inside an obstacle", text)
        self.assertIn("goal (3, 0)", text)
        self.assertLess(took, 3.0, "goal in a table not rejected at once")
        with self.truth.lock:
            moved = max(math.hypot(x - x0, y - y0) for t, x, y, _ in self.truth.hist if t >= t0)
        self.assertLess(moved, 0.01, "robot moved for a goal inside a table")

    def test_b_new_goal_preempts_active_one(self) -> None:
        first = actionlib.SimpleActionClient("move_base", MoveBaseAction)
        self.assertTrue(first.wait_for_server(rospy.Duration(60.0)))
        first.send_goal(goal_for(self.tables["table_7"]))
        wait_for(lambda: self.truth.speed() > 0.15, 120.0, "robot under way to table_7", stop=rospy.is_shutdown)
        self.client.send_goal(goal_for(self.tables["table_4"]))
        state, text = self.result()
        self.assertEqual(first.get_state(), GoalStatus.PREEMPTED, first.get_goal_status_text())
        self.assertEqual(state, GoalStatus.SUCCEEDED, text)
        self.wait_stopped("at table_4")
        self.assert_at("table_4")

    def test_z_amcl_killed_mid_route_stops_and_aborts_naming_it(self) -> None:
        statuses: list[float] = []
        sub = rospy.Subscriber("move_base/status", GoalStatusArray, lambda m: statuses.append(m.header.stamp.to_sec()))
        self.client.send_goal(goal_for(self.tables["home"]))
        wait_for(lambda: self.truth.speed() > 0.15, 120.0, "robot under way home", stop=rospy.is_shutdown)
        pid = node_pid("/amcl")
        t_kill = rospy.get_time()
        os.kill(pid, signal.SIGKILL)           # a crash: no goodbye to the master, map -> odom just stops
        wait_for(lambda: not process_alive(pid), 30.0, "amcl gone", stop=rospy.is_shutdown)
        t_stop = self.wait_stopped("after amcl died")
        print(f"[figure] amcl killed: robot at rest {t_stop - t_kill:.2f} s sim later", flush=True)
        # pose stale after transform_tolerance 0.5 s (amcl post-dates map->odom by 0.3 s) + braking
        self.assertLess(t_stop - t_kill, 2.0, "robot kept driving on a dead localization")
        _, xs, ys, _ = self.truth.latest()
        state, text = self.result()
        t_end = rospy.get_time()
        print(f"[figure] amcl killed: {GoalStatus.to_string(state)} {t_end - t_kill:.1f} s sim after the kill: "
              f"{text}", flush=True)
        self.assertEqual(state, GoalStatus.ABORTED, text)
        self.assertIn("stale link map -> odom (from /amcl)", text)
        self.assertLess(t_end - t_kill, 15.0 + 5.0, "abort later than controller_patience (15 s) + 5 s")
        with self.truth.lock:
            drift = max(math.hypot(x - xs, y - ys) for t, x, y, _ in self.truth.hist if t >= t_stop)
        self.assertLess(drift, 0.02, "robot moved while localization was dead")
        # nothing hung: move_base keeps publishing its status, every other node still answers
        t_res = rospy.get_time()
        wait_for(lambda: statuses and statuses[-1] > t_res, 60.0, "fresh move_base/status", stop=rospy.is_shutdown)
        sub.unregister()
        # (one assertion over a list: rosunit's XML runner does not report subTest failures)
        dead = [n for n in self.nodes if n != "/amcl" and not answers(n)]
        self.assertEqual(dead, [], "nodes that died with amcl")


if __name__ == "__main__":
    rospy.init_node("faults_nav_test")
    rostest.rosrun(PKG, "faults_nav", FaultsNavTest)
