#!/usr/bin/env python3
"""rostest node for manual/slam_workflow.test: explore -> map quality -> map_saver ->
map_server -> (SLAM stopped) amcl on the saved map, started at SLAM's last pose -> three table deliveries."""
from __future__ import annotations

import math
import os
import subprocess
import tempfile
import time
import unittest

import actionlib
import numpy as np
import rospy
import rostest
import tf2_ros
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Quaternion
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
from nav_msgs.msg import OccupancyGrid, Odometry
from std_msgs.msg import Bool

from chefbot_common.geometry import quaternion_from_yaw, wrap_angle, yaw_from_quaternion
from chefbot_common.map_io import load_map
from chefbot_common.rostest_helpers import wait_for as wait_until
from chefbot_common.tables import load_tables
from chefbot_navigation.ros_io import msg_to_occupancy
from chefbot_navigation.slam.metrics import map_quality

PKG = "chefbot_navigation"


class SlamWorkflowTest(unittest.TestCase):
    procs: list[subprocess.Popen] = []

    @classmethod
    def setUpClass(cls) -> None:
        cls.done: list[bool] = []
        cls.maps: list[OccupancyGrid] = []
        cls.truth: list[tuple[float, float, float]] = []
        rospy.Subscriber("explore/done", Bool, lambda m: cls.done.append(m.data), queue_size=1)
        rospy.Subscriber("map", OccupancyGrid, lambda m: cls.maps.append(m), queue_size=1)
        rospy.Subscriber("ground_truth/odom", Odometry, cls.on_truth, queue_size=5)
        cls.tmp = tempfile.mkdtemp(prefix="slam_workflow_")
        cls.tf = tf2_ros.Buffer()
        cls.tf_listener = tf2_ros.TransformListener(cls.tf)

    @classmethod
    def tearDownClass(cls) -> None:
        for p in cls.procs:
            p.terminate()

    @classmethod
    def on_truth(cls, m: Odometry) -> None:
        q = m.pose.pose.orientation
        cls.truth.append((m.pose.pose.position.x, m.pose.pose.position.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)))
        del cls.truth[:-10]

    def test_workflow(self) -> None:
        # 1. exploration ends by itself (explore/done true) within 10 min of sim time
        t0 = rospy.get_time()
        wait_until(lambda: bool(self.done), 2000.0, "explore/done")
        took = rospy.get_time() - t0
        wait_until(lambda: bool(self.maps) and self.maps[-1].header.stamp.to_sec() > t0 + took - 3, 60, "last map")
        q = map_quality(msg_to_occupancy(self.maps[-1]), load_map(rospy.get_param("~truth_map")))
        print(f"[figure] exploration {took:.0f} s sim, complete: {self.done[-1]}; matched {100 * q.matched:.1f} %, "
              f"false occupied {100 * q.false_occupied:.2f} %, reachable free area mapped {100 * q.coverage:.1f} %",
              flush=True)
        # issue 17: >= 95 % of the reachable free area within 10 min of sim time (measured 326-452 s, 98-99 %);
        # matched/false-occupied looser than the benchmark goals (measured 92.6-96.6 % / 0.1-1.8 %)
        self.assertTrue(self.done[-1], "exploration did not complete (frontiers left at max_duration)")
        self.assertLess(took, 600.0)
        self.assertGreater(q.coverage, 0.95)
        self.assertGreater(q.matched, 0.88)
        self.assertLess(q.false_occupied, 0.03)
        # 2. map_saver -> files -> map_server gives the same grid
        prefix = os.path.join(self.tmp, "hotel")
        r = subprocess.run(["rosrun", PKG, "map_saver", "-f", prefix], capture_output=True, text=True, timeout=120)
        self.assertEqual(r.returncode, 0, r.stderr)
        saved = msg_to_occupancy(self.maps[-1])
        # 3. SLAM stops; map_server serves the saved map as `map`; amcl on it, started where SLAM last put
        #    the robot (the saved map's frame is SLAM's map frame)
        t = self.tf.lookup_transform("map", "base_footprint", rospy.Time(0), rospy.Duration(10.0)).transform
        start = (t.translation.x, t.translation.y,
                 yaw_from_quaternion(t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w))
        subprocess.run(["rosnode", "kill", "/slam", "/explore"], capture_output=True, timeout=60)
        self.maps.clear()
        self.procs.append(subprocess.Popen(["rosrun", PKG, "map_server", f"{prefix}.yaml"]))
        wait_until(lambda: bool(self.maps), 60, "map from map_server")
        served = msg_to_occupancy(self.maps[-1])
        self.assertEqual(served.data.shape, saved.data.shape)
        self.assertTrue(np.array_equal(served.data, load_map(f"{prefix}.yaml").data))
        self.assertGreater(np.mean(served.data == saved.data), 0.99)   # the map may have changed after saving
        amcl = os.path.join(rospy.get_param("~launch_dir"), "includes", "amcl.launch.xml")
        self.procs.append(subprocess.Popen(["roslaunch", amcl, f"initial_pose_x:={start[0]}",
                                            f"initial_pose_y:={start[1]}", f"initial_pose_a:={start[2]}"]))
        # 4. deliveries on the saved map
        client = actionlib.SimpleActionClient("move_base", MoveBaseAction)
        self.assertTrue(client.wait_for_server(rospy.Duration(60.0)))
        tables = load_tables(rospy.get_param("~tables"))
        for name in ("table_4", "table_1", "table_8"):
            target = tables[name]
            g = MoveBaseGoal()
            g.target_pose.header.frame_id = "map"
            g.target_pose.header.stamp = rospy.Time.now()
            g.target_pose.pose.position.x, g.target_pose.pose.position.y = target.x, target.y
            g.target_pose.pose.orientation = Quaternion(*quaternion_from_yaw(target.yaw))
            client.send_goal(g)
            self.assertTrue(client.wait_for_result(rospy.Duration(600.0)), f"{name}: no result")
            self.assertEqual(client.get_state(), GoalStatus.SUCCEEDED, f"{name}: {client.get_goal_status_text()}")
            time.sleep(1.0)
            x, y, yaw = self.truth[-1]
            err = math.hypot(x - target.x, y - target.y)
            print(f"[figure] {name} on the SLAM map: error {err:.3f} m / {abs(wrap_angle(yaw - target.yaw)):.3f} rad",
                  flush=True)
            self.assertLess(err, 0.1, name)


if __name__ == "__main__":
    rospy.init_node("slam_workflow_test")
    rostest.rosrun(PKG, "slam_workflow_test", SlamWorkflowTest)
