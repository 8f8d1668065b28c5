#!/usr/bin/env python3
"""rostest node for namespaced.test: the sim navigation stack with ns:=chefbot1.

Runs inside the robot's namespace (relative names resolve to /chefbot1/...).  Checks that
every node, topic, service and param of the robot lives under /chefbot1 (only /tf,
/tf_static, /clock, /rosout*, the shared map_server's /map and ROS's own names outside),
that tf carries chefbot1/odom -> chefbot1/base_footprint and map -> chefbot1/odom with
only 'map' unprefixed, that the robot's messages are stamped with prefixed frames, and
that /chefbot1/move_base delivers to two tables (``~deliveries``; ground truth, sim time).
"""
from __future__ import annotations

import math
import unittest

import actionlib
import rosgraph
import rospy
import rostest
import tf2_ros
import yaml
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from move_base_msgs.msg import MoveBaseAction
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Imu, LaserScan, Range
from sim_navigation_test_node import Truth, goal_for

from chefbot_common.geometry import wrap_angle
from chefbot_common.rostest_helpers import wait_for
from chefbot_common.tables import load_tables

PKG = "chefbot_tests"
WALL_TIMEOUT = 150.0              # s, per delivery: a bound for a loaded machine, not a figure
# m, rad: final ground-truth error.  Yaw holds sim_navigation's amcl-in-the-loop bound: move_base
# stops within its yaw_goal_tolerance (0.05 rad) of amcl's estimate, whose own heading error adds
# to it (measured up to 0.061 rad; a 0.05 bound failed 2 of 15 plugin-drive deliveries)
XY_TOL, YAW_TOL = 0.05, 0.08
# default of ~deliveries (table names, space-separated; '' = none): table_4 first (straight ahead, on
# a barely moved amcl) ended 0.038 m off once; after table_1 it stays within 0.016 m
DELIVERIES = "table_1 table_4"
# names a namespaced robot leaves outside its namespace, by design (chefbot_sim README)
# /fleet/robots: the site's shared fleet state (chefbot_msgs/RobotState), which every move_base reads
SHARED_TOPICS = {"/tf", "/tf_static", "/clock", "/rosout", "/rosout_agg", "/map", "/map_metadata", "/fleet/robots"}
SHARED_NODES = {"/rosout", "/map_server"}
SHARED_SERVICES_PREFIXES = ("/rosout/", "/map_server/", "/static_map")
ROS_PARAMS_PREFIXES = ("/run_id", "/rosdistro", "/rosversion", "/roslaunch/", "/use_sim_time", "/map_server/")
ROBOT_FRAMES = ("base_link", "camera_link", "camera_depth_frame", "camera_depth_optical_frame",
                "camera_rgb_optical_frame", "gyro_link", "ultrasonic_link", "wheel_left_link",
                "wheel_right_link", "cliff_front_link")


class NamespacedStackTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.ns = "/" + rospy.get_param("~ns").strip("/")
        cls.prefix = cls.ns[1:] + "/"
        assert rospy.get_namespace() == cls.ns + "/", f"run the test node in {cls.ns} (is {rospy.get_namespace()})"
        cls.tables = load_tables(rospy.get_param("~tables"))
        cls.deliveries = rospy.get_param("~deliveries", DELIVERIES).split()
        cls.truth = Truth()
        cls.tf = tf2_ros.Buffer(cache_time=rospy.Duration(30.0))
        cls.listener = tf2_ros.TransformListener(cls.tf)
        cls.client = actionlib.SimpleActionClient("move_base", MoveBaseAction)
        assert cls.client.wait_for_server(rospy.Duration(120.0)), f"no action server {cls.ns}/move_base"
        wait_for(lambda: bool(cls.truth.hist), 120.0, "ground truth", stop=rospy.is_shutdown)

    def frame(self, name: str) -> str:
        return self.prefix + name

    def can_transform(self, target: str, source: str) -> bool:
        return self.tf.can_transform(target, source, rospy.Time(0))

    def test_a_tf_frames_prefixed_map_shared(self) -> None:
        for target, source in (("map", self.frame("odom")), (self.frame("odom"), self.frame("base_footprint"))):
            wait_for(lambda t=target, s=source: self.can_transform(t, s), 60.0, f"tf {target} -> {source}",
                     stop=rospy.is_shutdown)
        for name in ROBOT_FRAMES:
            wait_for(lambda n=name: self.can_transform(self.frame("base_footprint"), self.frame(n)), 30.0,
                     f"tf {self.frame('base_footprint')} -> {self.frame(name)}", stop=rospy.is_shutdown)
        frames = yaml.safe_load(self.tf.all_frames_as_yaml()) or {}
        names = set(frames) | {f["parent"] for f in frames.values()}
        stray = sorted(n for n in names if n != "map" and not n.startswith(self.prefix))
        self.assertEqual(stray, [], f"tf frames neither 'map' nor under '{self.prefix}'")

    def test_b_messages_stamped_with_prefixed_frames(self) -> None:
        expect = {"scan": (LaserScan, "camera_depth_frame"), "odom": (Odometry, "odom"),
                  "imu/data": (Imu, "gyro_link"), "ultrasonic": (Range, "ultrasonic_link"),
                  "cliff/center": (Range, "cliff_front_link"),
                  "camera/depth/camera_info": (CameraInfo, "camera_depth_optical_frame")}
        for topic, (kind, frame) in expect.items():
            msg = rospy.wait_for_message(topic, kind, timeout=60.0)
            self.assertEqual(msg.header.frame_id, self.frame(frame), f"{self.ns}/{topic}")
        odom = rospy.wait_for_message("odom", Odometry, timeout=60.0)
        self.assertEqual(odom.child_frame_id, self.frame("base_footprint"))
        pose = rospy.wait_for_message("amcl_pose", PoseWithCovarianceStamped, timeout=60.0)
        self.assertEqual(pose.header.frame_id, "map")

    def deliver(self, name: str) -> None:
        target = self.tables[name]
        t0 = rospy.get_time()
        self.client.send_goal(goal_for(target))
        self.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)), f"{name}: no result")
        took = rospy.get_time() - t0
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED,
                         f"{name}: {self.client.get_goal_status_text()}")
        wait_for(lambda: self.truth.speed() < 0.005, 60.0, "robot at rest", stop=rospy.is_shutdown)
        _, x, y, yaw = self.truth.latest()
        err_xy, err_yaw = math.hypot(x - target.x, y - target.y), abs(wrap_angle(yaw - target.yaw))
        print(f"[figure] {self.ns} {name}: {took:.1f} s sim, error {err_xy:.3f} m / {err_yaw:.3f} rad", flush=True)
        self.assertLessEqual(err_xy, XY_TOL, f"{name}: final position error {err_xy:.3f} m")
        self.assertLessEqual(err_yaw, YAW_TOL, f"{name}: final yaw error {err_yaw:.3f} rad")

    def test_c_delivers_two_tables_through_namespaced_move_base(self) -> None:
        if not self.deliveries:
            self.skipTest("~deliveries is empty")
        for name in self.deliveries:
            self.deliver(name)

    def test_d_every_robot_name_under_namespace(self) -> None:
        """After the deliveries (every sensor has been subscribed, every topic advertised)."""
        pubs, subs, srvs = rosgraph.Master(rospy.get_name()).getSystemState()
        me = rospy.get_name()
        inside = self.ns + "/"
        topics = {t for t, _ in pubs + subs}
        nodes = {n for _, ns in pubs + subs + srvs for n in ns} - {me}
        self.assertIn(inside + "move_base/goal", topics)
        self.assertIn(inside + "scan", topics)
        self.assertEqual(sorted(t for t in topics - SHARED_TOPICS if not t.startswith(inside)), [],
                         "topics outside the robot namespace")
        self.assertEqual(sorted(n for n in nodes - SHARED_NODES if not n.startswith(inside)), [],
                         "nodes outside the robot namespace")
        self.assertEqual(sorted(s for s, _ in srvs if not s.startswith(inside)
                                and not s.startswith(SHARED_SERVICES_PREFIXES)), [],
                         "services outside the robot namespace")
        self.assertEqual(sorted(p for p in rospy.get_param_names() if not p.startswith(inside)
                                and not p.startswith(ROS_PARAMS_PREFIXES)), [],
                         "params outside the robot namespace")


if __name__ == "__main__":
    rospy.init_node("namespaced_test")
    rostest.rosrun(PKG, "namespaced", NamespacedStackTest)
