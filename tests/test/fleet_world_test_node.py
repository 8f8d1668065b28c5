#!/usr/bin/env python3
"""rostest node for fleet_world.test: two ChefBots in one simulated hotel (fleet_world.launch robots:=2).

Checks that one simulator node holds both robots on one /clock, each robot's stack lives in its
namespace with prefixed tf frames, fleet_member put each amcl at its fleet-file start pose, and
that a robot standing in another's way is an obstacle like any other: chefbot2 parks on
chefbot1's straight line to table_4; chefbot1's costmap marks chefbot2's body (seen by its
depth camera), chefbot1 drives around it to the table, and neither bumper is ever pressed.
Everything is judged on sim time and ground truth (the test's oracle).
"""
from __future__ import annotations

import math
import threading
import unittest

import actionlib
import numpy as np
import rosgraph
import rospy
import rostest
import tf2_ros
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from move_base_msgs.msg import MoveBaseAction
from nav_msgs.msg import OccupancyGrid, Odometry
from sim_navigation_test_node import goal_for
from std_msgs.msg import Bool

from chefbot_common.fleet_file import load_fleet
from chefbot_common.geometry import Pose2D
from chefbot_common.rostest_helpers import wait_for
from chefbot_common.tables import load_tables
from chefbot_msgs.msg import RobotState

PKG = "chefbot_tests"
WALL_TIMEOUT = 240.0          # s per goal: a bound for a loaded 2-core machine running two stacks
START_TOL = 0.10              # m: amcl's first estimate against the fleet file's start pose
XY_TOL = 0.08                 # m: final ground-truth error at a goal
BODY_GAP = 0.36               # m: two ChefBot bases (0.178 m radius) touch below this centre distance
BLOCK = Pose2D(1.0, 0.0, math.pi / 2)   # where chefbot2 parks: on chefbot1's straight line to table_4


class Robot:
    """One robot's ground truth, bumper, amcl pose and costmap, through its namespace."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.lock = threading.Lock()
        self.pose: tuple[float, float, float] | None = None      # (t, x, y) ground truth
        self.track: list[tuple[float, float, float]] = []
        self.pressed_with: set[str] = set()
        self.contacts = 0
        self.amcl: tuple[float, float] | None = None
        self.watch: tuple[float, float] | None = None   # a spot whose lethal cells are counted in each costmap
        self.most_marked = 0                             # the most lethal cells near it in one costmap
        rospy.Subscriber(f"/{name}/ground_truth/odom", Odometry, self._on_truth, queue_size=50)
        rospy.Subscriber(f"/{name}/bumper", Bool, self._on_bumper, queue_size=50)
        rospy.Subscriber(f"/{name}/amcl_pose", PoseWithCovarianceStamped, self._on_amcl, queue_size=5)
        rospy.Subscriber(f"/{name}/move_base/local_costmap/costmap", OccupancyGrid, self._on_costmap, queue_size=1)
        self.client = actionlib.SimpleActionClient(f"/{name}/move_base", MoveBaseAction)

    def _on_truth(self, m: Odometry) -> None:
        p = m.pose.pose.position
        with self.lock:
            self.pose = (m.header.stamp.to_sec(), p.x, p.y)
            self.track.append(self.pose)

    def _on_bumper(self, m: Bool) -> None:
        if m.data:
            with self.lock:
                self.contacts += 1

    def _on_amcl(self, m: PoseWithCovarianceStamped) -> None:
        with self.lock:
            self.amcl = (m.pose.pose.position.x, m.pose.pose.position.y)

    def _on_costmap(self, m: OccupancyGrid) -> None:
        with self.lock:
            watch = self.watch
        if watch is not None:
            n = marked_near(m, watch[0], watch[1], 0.25)
            with self.lock:
                self.most_marked = max(self.most_marked, n)

    def xy(self) -> tuple[float, float]:
        with self.lock:
            return self.pose[1], self.pose[2]

    def go(self, test: unittest.TestCase, target: Pose2D, what: str) -> None:
        self.client.send_goal(goal_for(target))
        test.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)), f"{self.name} {what}: no result")
        test.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED,
                         f"{self.name} {what}: {self.client.get_goal_status_text()}")
        x, y = self.xy()
        test.assertLess(math.hypot(x - target.x, y - target.y), XY_TOL, f"{self.name} {what}: ended at ({x:.3f}, "
                        f"{y:.3f})")


def marked_near(grid: OccupancyGrid, x: float, y: float, radius: float) -> int:
    """Cells of ``grid`` within ``radius`` m of (x, y) marked lethal (100)."""
    info = grid.info
    data = np.asarray(grid.data, dtype=np.int16).reshape(info.height, info.width)
    cols = (np.arange(info.width) + 0.5) * info.resolution + info.origin.position.x
    rows = (np.arange(info.height) + 0.5) * info.resolution + info.origin.position.y
    near = (cols[None, :] - x) ** 2 + (rows[:, None] - y) ** 2 <= radius ** 2
    return int(np.count_nonzero(near & (data >= 100)))


class FleetWorldTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.fleet = {r.name: r for r in load_fleet(rospy.get_param("~fleet_file"))}
        cls.tables = load_tables(rospy.get_param("~tables"))
        cls.robots = {n: Robot(n) for n in ("chefbot1", "chefbot2")}
        for r in cls.robots.values():
            assert r.client.wait_for_server(rospy.Duration(180.0)), f"no /{r.name}/move_base"
            wait_for(lambda r=r: r.pose is not None, 60.0, f"{r.name} ground truth", stop=rospy.is_shutdown)

    def test_1_one_sim_one_clock_and_each_robot_in_its_namespace(self) -> None:
        master = rosgraph.Master("/fleet_world_test")
        pubs = dict(master.getSystemState()[0])
        self.assertEqual(pubs.get("/clock"), ["/chefbot_sim"], "one /clock, from the one simulator")
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        for name in self.robots:
            for parent, child in (("map", f"{name}/odom"), (f"{name}/odom", f"{name}/base_footprint"),
                                  (f"{name}/base_footprint", f"{name}/camera_depth_frame")):
                self.assertTrue(buf.can_transform(parent, child, rospy.Time(0), rospy.Duration(20.0)),
                                f"tf {parent} -> {child}")

    def test_2_fleet_member_put_amcl_at_each_start_pose(self) -> None:
        for name, r in self.robots.items():
            start = self.fleet[name].start
            wait_for(lambda r=r, s=start: r.amcl is not None and math.hypot(r.amcl[0] - s.x, r.amcl[1] - s.y)
                     < START_TOL, 60.0, f"{name}'s amcl at its start pose {start}", stop=rospy.is_shutdown)

    def test_2b_each_robot_tells_the_others_where_it_is_on_fleet_robots(self) -> None:
        """fleet_member's RobotState on /fleet/robots: one per robot, in the map frame, at the robot's
        localized pose (near its ground truth), with the URDF footprint, idle without a goal."""
        states: dict[str, RobotState] = {}
        sub = rospy.Subscriber("/fleet/robots", RobotState, lambda m: states.__setitem__(m.name, m), queue_size=10)
        try:
            def near(name: str) -> bool:
                m, (x, y) = states.get(name), self.robots[name].xy()
                return m is not None and math.hypot(m.pose.x - x, m.pose.y - y) < START_TOL

            # the pose is the robot's own localization: wait for it to settle, as for amcl above
            wait_for(lambda: all(near(n) for n in self.robots), 60.0,
                     "a RobotState from every robot at its ground-truth pose", stop=rospy.is_shutdown)
            for name in self.robots:
                m = states[name]
                self.assertEqual(m.header.frame_id, "map")
                self.assertGreaterEqual(len(m.footprint), 3, f"{name}'s footprint")
                self.assertAlmostEqual(m.footprint_radius, 0.21, delta=0.03)   # ChefBot's URDF, unpadded
                self.assertEqual((m.state, len(m.path)), ("idle", 0))
        finally:
            sub.unregister()

    def test_3_a_robot_in_the_way_is_an_obstacle_driven_around_without_contact(self) -> None:
        one, two = self.robots["chefbot1"], self.robots["chefbot2"]
        two.go(self, BLOCK, "to its blocking spot")
        bx, by = two.xy()
        with one.lock:
            one.watch = (bx, by)
        t0 = rospy.get_time()
        one.go(self, self.tables["table_4"], "to table_4 past chefbot2")
        with one.lock:
            track = [p for p in one.track if p[0] >= t0]
            marked = one.most_marked
        closest = min(math.hypot(x - bx, y - by) for _, x, y in track)
        self.assertGreater(closest, BODY_GAP, f"chefbot1 came {closest:.3f} m from chefbot2's centre")
        detour = max(abs(y) for _, x, y in track if 0.6 < x < 1.4)
        self.assertGreater(detour, 0.3, "chefbot1 passed chefbot2's spot without leaving its straight line")
        self.assertGreater(marked, 0, "chefbot1's costmap never marked chefbot2's body")
        self.assertEqual((one.contacts, two.contacts), (0, 0), "a bumper was pressed")


if __name__ == "__main__":
    rospy.init_node("fleet_world_test")
    rostest.rosrun(PKG, "fleet_world_test", FleetWorldTest)
