#!/usr/bin/env python3
"""rostest node for sim_navigation.test: deliveries in the pybullet hotel, judged by ground truth.

Durations are sim time (ground_truth stamps / rospy time with /use_sim_time);
wall-clock bounds are only generous timeouts for a loaded machine.
"""
from __future__ import annotations

import math
import threading
import unittest

import actionlib
import numpy as np
import rospy
import rostest
import tf2_ros
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Quaternion
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
from nav_msgs.msg import Odometry, Path
from std_msgs.msg import Bool, String

from chefbot_common.geometry import quaternion_from_yaw, wrap_angle, yaw_from_quaternion
from chefbot_common.rostest_helpers import wait_for
from chefbot_common.tables import load_tables

PKG = "chefbot_tests"
WALL_TIMEOUT = 600.0
XY_TOL, YAW_TOL = 0.08, 0.08     # m, rad: final ground-truth error with amcl localizing


class Truth:
    """Latest ground-truth pose, a short history for speeds, and bumper contacts."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.hist: list[tuple[float, float, float, float]] = []   # (t, x, y, yaw)
        self.contacts = 0
        self.pressed = False
        self.plan: Path | None = None
        self.crate: tuple[float, float] | None = None
        self.crate_min_dist = math.inf     # m, closest approach of base_footprint to the crate centre
        rospy.Subscriber("ground_truth/odom", Odometry, self.on_odom, queue_size=50, tcp_nodelay=True)
        rospy.Subscriber("bumper", Bool, self.on_bumper, queue_size=50, tcp_nodelay=True)
        rospy.Subscriber("move_base/global_plan", Path, self.on_plan, queue_size=2)

    def on_odom(self, m: Odometry) -> None:
        q = m.pose.pose.orientation
        yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w)
        with self.lock:
            x, y = m.pose.pose.position.x, m.pose.pose.position.y
            self.hist.append((m.header.stamp.to_sec(), x, y, yaw))
            if self.crate is not None:
                self.crate_min_dist = min(self.crate_min_dist, math.hypot(x - self.crate[0], y - self.crate[1]))
            del self.hist[:-400]

    def on_bumper(self, m: Bool) -> None:
        with self.lock:
            if m.data and not self.pressed:
                self.contacts += 1
            self.pressed = m.data

    def on_plan(self, p: Path) -> None:
        with self.lock:
            self.plan = p

    def latest(self) -> tuple[float, float, float, float]:
        with self.lock:
            return self.hist[-1]

    def speed(self, window: float = 0.2) -> float:
        """Mean speed (m/s) over the last ``window`` s of sim time."""
        with self.lock:
            h = list(self.hist)
        if len(h) < 2:
            return 0.0
        t1, x1, y1, _ = h[-1]
        old = [e for e in h if e[0] <= t1 - window]
        if not old:
            return 0.0
        t0, x0, y0, _ = old[-1]
        return math.hypot(x1 - x0, y1 - y0) / max(t1 - t0, 1e-6)

    def still_since(self, tol: float = 0.002) -> float:
        """Sim time from which the robot has stayed within ``tol`` m of its latest position (from the
        stamps, so independent of when a test thread happened to look)."""
        with self.lock:
            h = list(self.hist)
        _, xe, ye, _ = h[-1]
        since = h[-1][0]
        for t, x, y, _ in reversed(h):
            if math.hypot(x - xe, y - ye) > tol:
                break
            since = t
        return since


def goal_for(pose) -> MoveBaseGoal:
    g = MoveBaseGoal()
    g.target_pose.header.frame_id = "map"
    g.target_pose.header.stamp = rospy.Time.now()
    g.target_pose.pose.position.x, g.target_pose.pose.position.y = pose.x, pose.y
    g.target_pose.pose.orientation = Quaternion(*quaternion_from_yaw(pose.yaw))
    return g


def connect_sim_client(cls: type, timeout: float = 120.0) -> None:
    """Shared setUpClass of the sim scenario tests: ``cls.tables`` (from ``~tables``), ``cls.truth``
    and ``cls.client`` (move_base), waiting (wall-clock ``timeout`` s) for the server and ground truth."""
    cls.tables = load_tables(rospy.get_param("~tables"))
    cls.truth = Truth()
    cls.client = actionlib.SimpleActionClient("move_base", MoveBaseAction)
    assert cls.client.wait_for_server(rospy.Duration(timeout)), "no move_base"
    wait_for(lambda: bool(cls.truth.hist), timeout, "ground truth", stop=rospy.is_shutdown)


def estimate_error(tf_buffer, x: float, y: float, yaw: float) -> str:
    """How far the pose move_base steers by (tf map -> base_footprint: localization + odometry) is from
    the ground truth (x, y, yaw) at rest: tells a localization miss from a controller that stopped short."""
    try:
        tr = tf_buffer.lookup_transform("map", "base_footprint", rospy.Time(0), rospy.Duration(2.0)).transform
    except tf2_ros.TransformException as exc:
        return f"no map -> base_footprint ({exc})"
    q = tr.rotation
    return (f"estimate off by {math.hypot(tr.translation.x - x, tr.translation.y - y):.3f} m / "
            f"{abs(wrap_angle(yaw_from_quaternion(q.x, q.y, q.z, q.w) - yaw)):.3f} rad")


def reach(test: unittest.TestCase, client: actionlib.SimpleActionClient, truth: Truth, name: str, target,
          sent_at: float | None = None, wall_timeout: float = WALL_TIMEOUT) -> tuple[float, float, float]:
    """Send the robot to ``target`` (unless already sent at sim time ``sent_at``), require SUCCEEDED and
    wait until it is at rest; returns (sim s taken, ground-truth position error m, heading error rad)."""
    t0 = rospy.get_time() if sent_at is None else sent_at
    if sent_at is None:
        client.send_goal(goal_for(target))
    test.assertTrue(client.wait_for_result(rospy.Duration(wall_timeout)), f"{name}: no result")
    took = rospy.get_time() - t0
    test.assertEqual(client.get_state(), GoalStatus.SUCCEEDED, f"{name}: {client.get_goal_status_text()}")
    # judge after the robot has settled (the sim's wheels coast a little after the zero command)
    wait_for(lambda: truth.speed() < 0.005, 60.0, "robot at rest")
    _, x, y, yaw = truth.latest()
    return took, math.hypot(x - target.x, y - target.y), abs(wrap_angle(yaw - target.yaw))


class SimNavigationTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        connect_sim_client(cls)
        cls.spawn = rospy.Publisher("chefbot_sim/spawn", String, queue_size=1, latch=True)

    def deliver(self, name: str, sent_at: float | None = None) -> float:
        """Send the robot to a named pose (unless already sent at ``sent_at``); returns the sim time it took."""
        took, err_xy, err_yaw = reach(self, self.client, self.truth, name, self.tables[name], sent_at)
        rospy.loginfo("sim_navigation: %s reached in %.1f s sim time, error %.3f m %.3f rad", name, took,
                      err_xy, err_yaw)
        print(f"[figure] {name}: {took:.1f} s sim, error {err_xy:.3f} m / {err_yaw:.3f} rad", flush=True)
        # amcl in the loop (not the ground-truth oracle): the 0.05 m / 0.05 rad figure is measured
        # by `make demo` / bench; the test holds the looser bound
        self.assertLessEqual(err_xy, XY_TOL, f"{name}: final position error {err_xy:.3f} m")
        self.assertLessEqual(err_yaw, YAW_TOL, f"{name}: final yaw error {err_yaw:.3f} rad")
        return took

    def test_b_cancel_mid_route_stops_within_half_a_second(self) -> None:
        self.client.send_goal(goal_for(self.tables["table_9"]))
        wait_for(lambda: self.truth.speed() > 0.2, 120.0, "robot at cruising speed")
        t_cancel = rospy.get_time()
        self.client.cancel_goal()
        wait_for(lambda: self.truth.speed(0.3) < 0.005, 60.0, "robot stopped")
        stopped = self.truth.still_since()
        print(f"[figure] cancel: stopped {stopped - t_cancel:.2f} s sim after cancel", flush=True)
        self.assertLessEqual(stopped - t_cancel, 0.5, "cancel: the robot took too long to stop")
        # move_base stops the robot from actionlib's cancel callback; the PREEMPTED result comes from its
        # control loop at the next cycle and may reach us after the robot stood still: wait for it
        self.assertTrue(self.client.wait_for_result(rospy.Duration(60.0)), "cancel: no result")
        state = self.client.get_state()
        self.assertEqual(state, GoalStatus.PREEMPTED,
                         f"cancel: goal {GoalStatus.to_string(state)} ({self.client.get_goal_status_text()!r})")
        self.deliver("home")

    def test_c_spawned_obstacle_on_path_is_avoided(self) -> None:
        self.truth.plan = None
        sent = rospy.get_time()
        self.client.send_goal(goal_for(self.tables["table_7"]))
        wait_for(lambda: self.truth.plan is not None and self.truth.speed() > 0.2, 120.0, "robot under way")
        _, x, y, _ = self.truth.latest()
        pts = np.array([(p.pose.position.x, p.pose.position.y) for p in self.truth.plan.poses])
        d = np.hypot(pts[:, 0] - x, pts[:, 1] - y)
        i = int(np.argmin(d))
        along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts[i:], axis=0).T))))
        k = i + int(np.searchsorted(along, 1.3))
        self.assertLess(k, len(pts) - 5, "path too short for the obstacle test")
        bx, by = pts[k]
        with self.truth.lock:
            self.truth.crate = (float(bx), float(by))
        self.spawn.publish(String(data=f"{{name: crate, shape: box, size: [0.3, 0.3, 0.5], "
                                       f"pose: [{bx:.3f}, {by:.3f}]}}"))
        self.deliver("table_7", sent_at=sent)
        self.assertEqual(self.truth.contacts, 0, "bumper contact with the spawned obstacle")
        # the track kept clear of the crate: half its side (0.15 m) + the base radius 0.178 m
        print(f"[figure] crate: closest approach {self.truth.crate_min_dist:.2f} m", flush=True)
        self.assertGreaterEqual(self.truth.crate_min_dist, 0.15 + 0.178)
        self.assertLess(self.truth.crate_min_dist, 1.0, "crate was not near the route (test did not test)")


if __name__ == "__main__":
    rospy.init_node("sim_navigation_test")
    rostest.rosrun(PKG, "sim_navigation", SimNavigationTest)
