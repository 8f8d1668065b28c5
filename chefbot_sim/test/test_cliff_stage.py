#!/usr/bin/env python3
"""rostest: the cliff sensors' Range topics on the stage world, and the cliff guard stopping a robot
that is commanded straight at the stage's edge.

Ground truth (test only) says where the robot really is.  Every wait is a condition on sim time
with a wall-clock timeout; cmd_vel goes out on every /clock tick, so commanding follows sim time
whatever the real-time factor.
"""
import math
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Range

from chefbot_common.rostest_helpers import SimRecorder

WALL_TIMEOUT = 90.0   # s of wall time for any single condition
TOPICS = {"left": "cliff_left_link", "center": "cliff_front_link", "right": "cliff_right_link"}   # topic -> frame
GUARD = "chefbot: cliff guard"


class Recorder(SimRecorder):
    wall_timeout = WALL_TIMEOUT
    stopped = staticmethod(rospy.is_shutdown)

    def __init__(self) -> None:
        super().__init__(["gt", "diag", *TOPICS])
        self.pub = rospy.Publisher("cmd_vel", Twist, queue_size=10, tcp_nodelay=True)
        rospy.Subscriber("/clock", Clock, self.on_clock, tcp_nodelay=True)
        rospy.Subscriber("ground_truth/odom", Odometry, lambda m: self.add("gt", m), queue_size=200)
        rospy.Subscriber("diagnostics", DiagnosticArray, self.on_diag, queue_size=50)
        for key in TOPICS:
            rospy.Subscriber(f"cliff/{key}", Range, lambda m, k=key: self.add(k, m), queue_size=200)

    def on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == GUARD:
                with self.lock:
                    self.logs["diag"].append((self.clock, st))

    def publish_cmd(self, v: float, w: float) -> None:
        t = Twist()
        t.linear.x, t.angular.z = v, w
        self.pub.publish(t)


def tilt(m: Odometry) -> float:
    """Angle (rad) between the base's up axis and the vertical, from the ground-truth quaternion."""
    q = m.pose.pose.orientation
    return math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (q.x * q.x + q.y * q.y))))


class CliffStage(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("test_cliff_stage")
        cls.r = Recorder()
        cls.top = rospy.get_param("~stage_top")
        cls.edge = rospy.get_param("~edge_x")
        cls.speed = rospy.get_param("~speed")
        cls.r.wait_for(lambda: cls.r.now() > 0.5 and cls.r.between("gt", 0.3), "clock and ground truth")

    def diag_after(self, t: float) -> list:
        with self.r.lock:
            return [st for s, st in self.r.logs["diag"] if s >= t]

    def test_1_readings_on_the_stage(self) -> None:
        r = self.r
        t0 = r.now()
        r.wait_until(t0 + 1.0)
        gt = r.latest("gt", t0 - 0.1)
        self.assertAlmostEqual(gt.pose.pose.position.z, self.top, delta=0.005, msg="spawned on the stage top")
        for key, frame in TOPICS.items():
            m = r.latest(key, t0)
            self.assertEqual(m.radiation_type, Range.INFRARED)
            self.assertEqual(m.header.frame_id, frame)
            self.assertAlmostEqual(m.min_range, 0.01, places=6)
            self.assertAlmostEqual(m.max_range, 0.15, places=6)
            self.assertAlmostEqual(m.field_of_view, math.radians(5.0), places=4)
            self.assertTrue(0.02 < m.range < 0.04, f"cliff/{key} on the flat stage reads {m.range} m")
            n = len(r.between(key, t0, t0 + 1.0))
            self.assertGreaterEqual(n, 45, f"cliff/{key}: {n} readings in 1 s of sim time (50 Hz)")

    def test_2_stops_at_the_edge(self) -> None:
        r = self.r
        t0 = r.now()
        r.set_cmd((self.speed, 0.0))   # plain forward, on every clock tick, never stopping by itself

        def stopped_near_edge() -> bool:
            gts = r.between("gt", r.now() - 1.0)
            if r.now() < t0 + 2.0 or len(gts) < 20:
                return False
            moved = math.hypot(gts[-1].pose.pose.position.x - gts[0].pose.pose.position.x,
                               gts[-1].pose.pose.position.y - gts[0].pose.pose.position.y)
            return moved < 0.01 or gts[-1].pose.pose.position.z < self.top - 0.05
        try:
            r.wait_for(stopped_near_edge, "the robot standing still (1 s of sim time) while commanded forward")
            t_end = r.now()
        finally:
            r.set_cmd(None)
        gts = r.between("gt", t0, t_end)
        lowest = min(m.pose.pose.position.z for m in gts)
        most = max(tilt(m) for m in gts)
        front_x = max(m.pose.pose.position.x for m in gts)
        final = gts[-1].pose.pose.position
        seen = [s for s, m in r.logs["center"] if s >= t0 and m.range == math.inf]
        x_seen = r.between("gt", seen[0])[0].pose.pose.position.x if seen else math.nan
        rospy.loginfo("cliff_stage: at %.2f m/s the front sensor saw the drop at x=%.3f m, the robot stopped at "
                      "x=%.3f m (%.3f m later; edge %.2f m), lowest base z %.3f m, max tilt %.3f rad",
                      self.speed, x_seen, final.x, final.x - x_seen, self.edge, lowest, most)
        self.assertGreater(lowest, self.top - 0.01, f"the base fell off the stage (z down to {lowest:.3f} m)")
        self.assertLess(most, 0.05, f"the base tipped over the edge ({most:.3f} rad)")
        self.assertLess(front_x, self.edge, "the robot's centre passed the edge")
        self.assertGreater(final.x, self.edge - 0.3, f"stopped at x={final.x:.3f}, far before the edge")
        self.assertEqual(r.latest("center", t_end - 0.1).range, math.inf, "the front sensor sees the drop")
        errors = [st for st in self.diag_after(t0) if st.level == DiagnosticStatus.ERROR]
        self.assertTrue(errors, "no ERROR diagnostic from the cliff guard")
        self.assertIn("cliff/center", errors[0].message)
        self.assertIn("drop", errors[0].message)

    def test_3_backs_away(self) -> None:
        r = self.r
        t0 = r.now()
        x0 = r.latest("gt", t0 - 0.1).pose.pose.position.x
        r.set_cmd((-0.1, 0.0))
        try:
            r.wait_for(lambda: r.latest("gt", t0).pose.pose.position.x < x0 - 0.1, "the robot backing away 0.1 m")
        finally:
            r.set_cmd(None)
        t1 = r.now()
        r.wait_for(lambda: any(st.level == DiagnosticStatus.OK for st in self.diag_after(t1)),
                   "the cliff guard's OK once the front sensor sees the stage again")
        self.assertTrue(math.isfinite(r.latest("center", t1).range))


if __name__ == "__main__":
    rostest.rosrun("chefbot_sim", "cliff_stage", CliffStage)
