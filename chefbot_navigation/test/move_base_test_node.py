#!/usr/bin/env python3
"""rostest node for move_base.test: this node IS the robot (kinematic_robot.py) and the client.

All durations are measured in sim time (the robot owns /clock); wall-clock
waits are only generous upper bounds for a loaded machine.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
import unittest

import actionlib
import rospy
import rostest
from actionlib_msgs.msg import GoalID, GoalStatus, GoalStatusArray
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PolygonStamped, PoseStamped, Quaternion
from move_base_msgs.msg import MoveBaseAction, MoveBaseActionGoal, MoveBaseGoal
from nav_msgs.msg import OccupancyGrid, Path
from nav_msgs.srv import GetPlan, GetPlanRequest
from rosgraph_msgs.msg import Log
from std_srvs.srv import Empty

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kinematic_robot import KinematicRobot

from chefbot_common.geometry import Pose2D, quaternion_from_yaw, wrap_angle
from chefbot_common.map_io import load_map
from chefbot_common.rostest_helpers import wait_for
from chefbot_msgs.msg import RobotState

PKG = "chefbot_navigation"
WALL_TIMEOUT = 240.0    # s, upper bound for one goal on a loaded machine
START = Pose2D(0.0, 0.0, 0.3)


def make_goal(x: float, y: float, yaw: float | None = 0.0, frame: str = "map",
              quat: tuple[float, float, float, float] | None = None) -> MoveBaseGoal:
    g = MoveBaseGoal()
    g.target_pose.header.frame_id = frame
    g.target_pose.header.stamp = rospy.Time.now()
    g.target_pose.pose.position.x, g.target_pose.pose.position.y = x, y
    g.target_pose.pose.orientation = Quaternion(*(quat if quat is not None else quaternion_from_yaw(yaw)))
    return g


class MoveBaseTest(unittest.TestCase):
    robot: KinematicRobot

    @classmethod
    def setUpClass(cls) -> None:
        occ = load_map(rospy.get_param("~map_file"))
        cls.robot = KinematicRobot(occ, START, rtf=rospy.get_param("~real_time_factor", 3.0))
        cls.client = actionlib.SimpleActionClient("move_base", MoveBaseAction)
        assert cls.client.wait_for_server(rospy.Duration(60.0)), "no move_base action server"
        cls.plans: list[Path] = []
        rospy.Subscriber("move_base/global_plan", Path, cls.plans.append)

    @classmethod
    def tearDownClass(cls) -> None:
        cls.robot.stop()

    def setUp(self) -> None:
        # every test starts with the robot at rest and no goal (no cancel_all_goals here: a cancel-all
        # that reaches the server after the next goal would cancel that goal too)
        if self.client.gh is not None and self.client.get_state() in (GoalStatus.PENDING, GoalStatus.ACTIVE):
            self.client.cancel_goal()
            self.client.wait_for_result(rospy.Duration(30.0))
        wait_for(lambda: self.robot.velocity() == (0.0, 0.0), 30.0, "robot at rest")

    def go(self, goal: MoveBaseGoal) -> int:
        self.client.send_goal(goal)
        self.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)), "no result")
        return self.client.get_state()

    def assert_at(self, x: float, y: float, yaw: float | None) -> None:
        p = self.robot.pose
        self.assertLessEqual(math.hypot(p.x - x, p.y - y), 0.05, f"final pose {p}")
        if yaw is not None:
            self.assertLessEqual(abs(wrap_angle(p.yaw - yaw)), 0.05, f"final pose {p}")

    def test_a_goal_reached_around_box(self) -> None:
        state = self.go(make_goal(4.0, 0.6, math.pi / 2))
        self.assertEqual(state, GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
        self.assert_at(4.0, 0.6, math.pi / 2)
        self.assertTrue(self.plans, "no global plan published")
        self.assertEqual(self.plans[-1].header.frame_id, "map")
        # the command stream ends with one zero Twist (it may arrive just after the result: another topic)
        wait_for(lambda: self.robot.cmd_log[-1][1:] == (0.0, 0.0), 10.0, "the final zero Twist")

    def test_b_book_client_script_unchanged(self) -> None:
        script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "simple_navig_goals.py")
        out = subprocess.run([sys.executable, script, "0.5", "0.0", "__name:=simple_navig_goals"],
                             capture_output=True, text=True, timeout=WALL_TIMEOUT + 60, check=False)
        self.assertEqual(out.returncode, 0, out.stdout + out.stderr)
        self.assert_at(0.5, 0.0, 0.0)

    def test_c_cancel_stops_within_half_a_second(self) -> None:
        self.client.send_goal(make_goal(4.0, 2.0, 0.0))
        wait_for(lambda: self.robot.velocity()[0] > 0.15, 60.0, "robot moving")
        t_cancel = self.robot.now
        self.client.cancel_goal()
        self.assertTrue(self.client.wait_for_result(rospy.Duration(30.0)))
        self.assertEqual(self.client.get_state(), GoalStatus.PREEMPTED)
        wait_for(lambda: self.robot.velocity() == (0.0, 0.0), 30.0, "zero velocity")
        zero_at = next(t for t, v, w in reversed(self.robot.cmd_log) if v == 0.0 and w == 0.0)
        self.assertLessEqual(zero_at - t_cancel, 0.5, "zero cmd_vel later than 0.5 s (sim time) after cancel")
        self.assertTrue(all(t <= zero_at for t, _, _ in self.robot.cmd_log), "commands after the zero Twist")

    def test_d_new_goal_preempts_old(self) -> None:
        first = actionlib.SimpleActionClient("move_base", MoveBaseAction)
        self.assertTrue(first.wait_for_server(rospy.Duration(30.0)))
        first.send_goal(make_goal(4.0, 2.0, 0.0))
        wait_for(lambda: self.robot.velocity()[0] > 0.1, 60.0, "robot moving")
        state = self.go(make_goal(0.0, 2.0, math.pi))
        self.assertEqual(first.get_state(), GoalStatus.PREEMPTED)
        self.assertEqual(state, GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
        self.assert_at(0.0, 2.0, math.pi)

    def test_e_goal_in_obstacle_aborts_with_reason(self) -> None:
        t0 = self.robot.now
        state = self.go(make_goal(2.0, 0.6, 0.0))
        self.assertEqual(state, GoalStatus.ABORTED)
        self.assertIn("obstacle", self.client.get_goal_status_text())
        self.assertLess(self.robot.now - t0, 5.0)

    def test_f_goal_in_unknown_and_off_map_abort(self) -> None:
        for (x, y), word in [((4.55, 2.5), "unknown"), ((20.0, 0.0), "off the map")]:
            state = self.go(make_goal(x, y, 0.0))
            self.assertEqual(state, GoalStatus.ABORTED)
            self.assertIn(word, self.client.get_goal_status_text())

    def test_g_zero_quaternion_means_yaw_zero(self) -> None:
        state = self.go(make_goal(1.0, 2.0, quat=(0.0, 0.0, 0.0, 0.0)))
        self.assertEqual(state, GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
        self.assert_at(1.0, 2.0, 0.0)

    def test_h_nan_quaternion_rejected(self) -> None:
        state = self.go(make_goal(1.0, 2.0, quat=(0.0, 0.0, float("nan"), 1.0)))
        self.assertEqual(state, GoalStatus.ABORTED)
        self.assertIn("orientation", self.client.get_goal_status_text())

    def test_i_goal_in_robot_frame_is_transformed(self) -> None:
        p = self.robot.pose
        state = self.go(make_goal(0.5, 0.0, 0.0, frame="base_footprint",
                                  quat=(0.0, 0.0, 2.0 * math.sin(0.25), 2.0 * math.cos(0.25))))  # not normalised
        self.assertEqual(state, GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
        target = p.compose(Pose2D(0.5, 0.0, 0.5))
        self.assert_at(target.x, target.y, target.yaw)

    def test_j_make_plan_and_clear_costmaps_services(self) -> None:
        rospy.wait_for_service("move_base/make_plan", 30.0)
        req = GetPlanRequest()
        req.start = PoseStamped()
        req.goal = make_goal(4.0, 0.6).target_pose
        resp = rospy.ServiceProxy("move_base/make_plan", GetPlan)(req)
        self.assertGreater(len(resp.plan.poses), 10)
        end = resp.plan.poses[-1].pose.position
        self.assertAlmostEqual(end.x, 4.0, places=3)
        rospy.wait_for_service("move_base/clear_costmaps", 30.0)
        rospy.ServiceProxy("move_base/clear_costmaps", Empty)()

    def test_k_obstacle_on_path_is_avoided(self) -> None:
        # go to the far corner, then drop a box on the straight way there
        self.go(make_goal(0.0, 0.0, 0.0))
        self.client.send_goal(make_goal(4.3, 0.0, 0.0))
        wait_for(lambda: self.robot.pose.x > 0.4, 60.0, "robot under way")
        self.robot.add_box(2.9, -0.6, 3.2, 0.15)
        self.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)))
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
        self.assert_at(4.3, 0.0, 0.0)

    def test_l_lost_scan_stops_robot_and_resumes(self) -> None:
        self.go(make_goal(0.0, 0.0, 0.0))
        self.client.send_goal(make_goal(4.0, -0.4, 0.0))
        wait_for(lambda: self.robot.velocity()[0] > 0.15, 60.0, "robot moving")
        self.robot.publish_scan = False
        t_off = self.robot.now
        try:
            wait_for(lambda: self.robot.velocity() == (0.0, 0.0), 60.0, "stop without scan")
            zero_at = next(t for t, v, w in reversed(self.robot.cmd_log) if v == 0.0 and w == 0.0)
            # sensor_timeout 1 s + one control period + the last scan's age (10 Hz)
            self.assertLess(zero_at - t_off, 1.5)
            self.assertEqual(self.client.get_state(), GoalStatus.ACTIVE)
        finally:
            self.robot.publish_scan = True
        self.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)))
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_goal_status_text())

    def test_n_rviz_simple_goal_topic(self) -> None:
        pub = rospy.Publisher("move_base_simple/goal", PoseStamped, queue_size=1, latch=True)
        ps = make_goal(1.0, -0.3, -math.pi / 2).target_pose
        pub.publish(ps)
        wait_for(lambda: math.hypot(self.robot.pose.x - 1.0, self.robot.pose.y + 0.3) < 0.05
                   and abs(wrap_angle(self.robot.pose.yaw + math.pi / 2)) < 0.05
                   and self.robot.velocity() == (0.0, 0.0), WALL_TIMEOUT, "robot at the RViz goal")
        pub.unregister()

    def test_o_costmaps_published(self) -> None:
        grid = rospy.wait_for_message("move_base/global_costmap/costmap", OccupancyGrid, 60.0)
        self.assertEqual((grid.info.width, grid.info.height), (120, 80))
        self.assertEqual(grid.header.frame_id, "map")
        self.assertIn(100, grid.data)      # walls are lethal
        self.assertIn(99, grid.data)       # inscribed ring
        local = rospy.wait_for_message("move_base/local_costmap/costmap", OccupancyGrid, 60.0)
        self.assertEqual((local.info.width, local.info.height), (60, 60))
        # the footprint (RViz's Polygon display): in map, around the robot (stands still here)
        fp = rospy.wait_for_message("move_base/local_costmap/footprint", PolygonStamped, 60.0)
        self.assertEqual(fp.header.frame_id, "map")
        self.assertGreaterEqual(len(fp.polygon.points), 3)
        pose = self.robot.pose
        dist = [math.hypot(p.x - pose.x, p.y - pose.y) for p in fp.polygon.points]
        self.assertTrue(all(0.1 < d < 0.35 for d in dist), f"footprint vertices {dist} m from the robot")

    def test_p_time_jumping_back_mid_goal_recovers(self) -> None:
        self.go(make_goal(0.0, 0.0, 0.0))
        self.client.send_goal(make_goal(0.0, 2.0, 0.0))
        wait_for(lambda: self.robot.velocity()[0] > 0.15, 60.0, "robot moving")
        self.robot.jump_back(3.0)
        self.assertTrue(self.client.wait_for_result(rospy.Duration(WALL_TIMEOUT)))
        self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
        self.assert_at(0.0, 2.0, 0.0)
        # the periodic publishers survived the jump
        grid = rospy.wait_for_message("move_base/local_costmap/costmap", OccupancyGrid, 30.0)
        self.assertGreater(grid.header.stamp.to_sec(), self.robot.now - 5.0)
        # ... and so did actionlib's periodic status (restarted by move_base)
        t_after = self.robot.now
        wait_for(lambda: rospy.wait_for_message("move_base/status", GoalStatusArray, 30.0).header.stamp.to_sec()
                   > t_after, 60.0, "fresh move_base/status")

    def test_q_cancel_that_overtakes_its_goal_logs_no_error(self) -> None:
        """Goal storms: a cancel reaching the server before its goal (separate topics) left actionlib a
        goal-less tracker, and the next cancel touching it logged "Attempt to get a goal id on an
        uninitialized ServerGoalHandle"."""
        statuses: dict[str, int] = {}
        logs: list[str] = []
        subs = [rospy.Subscriber("move_base/status", GoalStatusArray,
                                 lambda m: statuses.update({s.goal_id.id: s.status for s in m.status_list})),
                rospy.Subscriber("/rosout", Log, lambda m: logs.append(m.msg) if m.name == "/move_base" else None)]
        cancel = rospy.Publisher("move_base/cancel", GoalID, queue_size=10)
        goal_pub = rospy.Publisher("move_base/goal", MoveBaseActionGoal, queue_size=10)
        try:
            wait_for(lambda: cancel.get_num_connections() > 0 and goal_pub.get_num_connections() > 0
                       and subs[1].get_num_connections() > 0, 30.0, "move_base topics connected")
            gid = f"overtaken_{os.getpid()}"
            cancel.publish(GoalID(id=gid))  # stamp 0
            wait_for(lambda: statuses.get(gid) == GoalStatus.RECALLING, 30.0, "cancel stored")
            goal_pub.publish(MoveBaseActionGoal(goal_id=GoalID(id=gid), goal=make_goal(1.0, 0.0)))
            wait_for(lambda: statuses.get(gid) == GoalStatus.RECALLED, 30.0, "goal recalled")
            cancel.publish(GoalID(id=gid))                       # the same cancel again
            cancel.publish(GoalID(stamp=rospy.Time(0, 1)))       # everything stamped before 1 ns: only it
            # the service logs after the cancels were handled (one rosout stream, in order)
            rospy.wait_for_service("move_base/clear_costmaps", 30.0)
            rospy.ServiceProxy("move_base/clear_costmaps", Empty)()
            wait_for(lambda: any("costmaps cleared" in m for m in logs), 30.0, "move_base log after the cancels")
            self.assertFalse([m for m in logs if "uninitialized" in m], logs)
        finally:
            for sub in subs:
                sub.unregister()
            cancel.unregister()
            goal_pub.unregister()

    def test_r_map_above_max_map_cells_refused_goal_aborted_with_reason(self) -> None:
        """issue 10 item 3: a map bigger than ~max_map_cells is refused with a clear error; the node keeps
        running, answers goals with the reason and reports it on diagnostics."""
        diags: list[DiagnosticArray] = []
        sub = rospy.Subscriber("tiny_map_limit/diagnostics", DiagnosticArray, diags.append)
        client = actionlib.SimpleActionClient("tiny_map_limit/move_base", MoveBaseAction)
        try:
            self.assertTrue(client.wait_for_server(rospy.Duration(60.0)), "no tiny_map_limit/move_base server")
            client.send_goal(make_goal(1.0, 0.0))
            self.assertTrue(client.wait_for_result(rospy.Duration(WALL_TIMEOUT)), "no result")
            self.assertEqual(client.get_state(), GoalStatus.ABORTED)
            text = client.get_goal_status_text()
            self.assertIn("map refused", text)
            self.assertIn("more than the maximum of 1,000 cells (param max_map_cells)", text)
            wait_for(lambda: any(st.level == DiagnosticStatus.ERROR and "map refused" in st.message
                                 for d in diags for st in d.status), 60.0, "map refusal on diagnostics")
        finally:
            sub.unregister()

    def test_s_a_fleet_robot_it_cannot_see_is_planned_around_and_dropped_when_silent(self) -> None:
        """/fleet/robots: another robot that no scan sees (it has no body here) stands on the straight
        way below the box; move_base plans round the box instead, never comes near it, and drops it
        once its states stop (~robots_layer/timeout, 2 s).  An unusable state is skipped."""
        ghost = (2.0, -0.4)
        pub = rospy.Publisher("/fleet/robots", RobotState, queue_size=5, latch=True)
        stop = threading.Event()

        def state(name: str, x: float) -> RobotState:
            msg = RobotState(name=name, footprint_radius=0.18, state="idle")
            msg.header.frame_id, msg.header.stamp = "map", rospy.Time.from_sec(self.robot.now)
            msg.pose.x, msg.pose.y = x, ghost[1]
            return msg

        def publish() -> None:
            while not stop.is_set():
                pub.publish(state("chefbot8", math.nan))        # skipped with a warning
                pub.publish(state("chefbot9", ghost[0]))
                stop.wait(0.1)

        def ghost_cost() -> int:
            grid = rospy.wait_for_message("move_base/global_costmap/costmap", OccupancyGrid, 30.0)
            col = int((ghost[0] - grid.info.origin.position.x) / grid.info.resolution)
            row = int((ghost[1] - grid.info.origin.position.y) / grid.info.resolution)
            return grid.data[row * grid.info.width + col]

        self.go(make_goal(0.0, -0.4, 0.0))
        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        try:
            wait_for(lambda: ghost_cost() == 100, 60.0, "the other robot lethal in the global costmap")
            self.plans.clear()
            self.client.send_goal(make_goal(4.0, -0.4, 0.0))
            closest = math.inf
            deadline = rospy.get_time() + 600.0
            while not self.client.wait_for_result(rospy.Duration(0.05)) and rospy.get_time() < deadline:
                closest = min(closest, math.hypot(self.robot.pose.x - ghost[0], self.robot.pose.y - ghost[1]))
            self.assertEqual(self.client.get_state(), GoalStatus.SUCCEEDED, self.client.get_goal_status_text())
            self.assert_at(4.0, -0.4, 0.0)
            # the robot's radius (0.2) + the other's (0.18) + padding (0.05), less a cell of rounding
            self.assertGreaterEqual(closest, 0.43 - 0.05, "drove into the other robot")
            plan = self.plans[0].poses
            self.assertGreater(max(p.pose.position.y for p in plan), 0.95, "the plan did not go round the box")
        finally:
            stop.set()
            thread.join(5.0)
        wait_for(lambda: ghost_cost() < 99, 60.0, "the silent robot dropped from the global costmap")
        pub.unregister()

    def test_m_bad_param_stops_node_naming_it(self) -> None:
        out = subprocess.run(["rosrun", PKG, "move_base", "__name:=bad_move_base", "_controller/max_vel_x:=-1.0"],
                             capture_output=True, text=True, timeout=120, check=False)
        self.assertNotEqual(out.returncode, 0)
        self.assertIn("controller/max_vel_x", out.stderr)


if __name__ == "__main__":
    rospy.init_node("move_base_test")
    rostest.rosrun(PKG, "move_base", MoveBaseTest)
