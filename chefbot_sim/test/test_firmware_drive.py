#!/usr/bin/env python3
"""rostest: firmware-in-the-loop drive through the unmodified robot_standalone.launch.

cmd_vel -> twist_to_motors -> pid_velocity x2 -> launchpad_node -> pty -> our
firmware core inside the sim -> DC-motor model -> pybullet wheels -> encoder
edges -> firmware -> pty -> launchpad_node -> lwheel/rwheel -> diff_tf -> odom.

Every wait is a condition on sim time with a generous wall-clock timeout;
cmd_vel is published from the /clock callback, so commanding follows sim time
whatever the real-time factor.  Speeds and delays are measured in sim time.
"""
import math
import os
import signal
import unittest
import xmlrpc.client

import numpy as np
import rosgraph
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from chefbot_common.geometry import yaw_from_quaternion
from chefbot_common.rostest_helpers import SimRecorder

WALL_TIMEOUT = 120.0  # s of wall time for any single condition
WATCHDOG = 0.5        # s, the firmware's watchdog_ms (PROTOCOL.md)
STOP_MARGIN = 0.35    # s of sim time allowed for pid/twist_to_motors ramps + braking to a stop


def yaw_of(m: Odometry) -> float:
    """Yaw (rad) of an odometry message."""
    q = m.pose.pose.orientation
    return yaw_from_quaternion(q.x, q.y, q.z, q.w)


def xy(m: Odometry) -> np.ndarray:
    p = m.pose.pose.position
    return np.array([p.x, p.y])


class Recorder(SimRecorder):
    wall_timeout = WALL_TIMEOUT
    stopped = staticmethod(rospy.is_shutdown)

    def __init__(self) -> None:
        super().__init__(["gt", "odom"])
        self.fw_state: list[tuple[float, str]] = []
        self.pub = rospy.Publisher("cmd_vel", Twist, queue_size=10, tcp_nodelay=True)
        rospy.Subscriber("/clock", Clock, self.on_clock, tcp_nodelay=True)
        rospy.Subscriber("ground_truth/odom", Odometry, lambda m: self.add("gt", m), tcp_nodelay=True)
        rospy.Subscriber("odom", Odometry, lambda m: self.add("odom", m), tcp_nodelay=True)
        rospy.Subscriber("chefbot_sim/firmware_state", String, self.on_fw_state)

    def on_fw_state(self, msg: String) -> None:
        with self.lock:
            self.fw_state.append((self.clock, msg.data))

    def publish_cmd(self, v: float, w: float) -> None:
        t = Twist()
        t.linear.x, t.angular.z = v, w
        self.pub.publish(t)

    def wait_stopped(self, after: float) -> float:
        """Sim time from which ground truth has stood still for 0.3 s (|v| < 1 cm/s)."""
        def still() -> bool:
            gts = self.between("gt", after)
            if not gts or gts[-1].header.stamp.to_sec() < after + 0.3:
                return False
            tail = [m for m in gts if m.header.stamp.to_sec() >= gts[-1].header.stamp.to_sec() - 0.3]
            return all(abs(m.twist.twist.linear.x) < 0.01 and abs(m.twist.twist.angular.z) < 0.02 for m in tail)
        self.wait_for(still, f"robot at rest after t={after:.2f}")
        return self.now()


class FirmwareDrive(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("test_firmware_drive")
        cls.r = Recorder()
        r = cls.r
        r.wait_for(lambda: r.now() > 0.5 and r.between("gt", 0.0), "clock and ground truth")
        r.wait_for(lambda: bool(r.between("odom", 0.0)), "odom from diff_tf (launchpad_node connected)")
        r.wait_for(lambda: r.pub.get_num_connections() > 0, "twist_to_motors subscribed to cmd_vel")
        # the cliff guard holds forward motion until all three cliff sensors have reported
        guard_ok = []
        rospy.Subscriber("diagnostics", DiagnosticArray, lambda m: guard_ok.extend(
            s for s in m.status if s.name == "chefbot: cliff guard" and s.level == DiagnosticStatus.OK))
        r.wait_for(lambda: bool(guard_ok), "the cliff guard to allow forward motion")

    def test_0_params_and_no_competing_odom(self) -> None:
        link = rospy.get_param("~pty_link")
        path = rospy.get_param("chefbot_sim/pty_path")
        self.assertTrue(path.startswith("/dev/"), path)
        self.assertEqual(os.path.realpath(link), path, "the symlink points at the published pty path")
        master = rosgraph.Master("/test_firmware_drive")
        pubs = dict(master.getSystemState()[0])
        self.assertEqual(pubs.get("/odom"), ["/diff_tf"], "only diff_tf publishes odom in firmware mode")
        subs = dict(master.getSystemState()[1])
        self.assertNotIn("/chefbot_sim", subs.get("/cmd_vel", []), "the sim must not take cmd_vel")

    def test_1_forward(self) -> None:
        r = self.r
        t0 = r.wait_stopped(r.now())
        gt0, od0 = r.latest("gt", t0 - 0.1), r.latest("odom", t0 - 0.2)
        r.set_cmd((0.2, 0.0))
        r.wait_until(t0 + 5.0)
        r.set_cmd(None)
        t1 = r.now()
        speeds = [m.twist.twist.linear.x for m in r.between("gt", t0 + 2.0, t1)]
        v = float(np.mean(speeds))
        rospy.loginfo("firmware drive: ground-truth speed %.4f m/s (cmd 0.2)", v)
        self.assertAlmostEqual(v, 0.2, delta=0.02, msg=f"mean ground-truth speed {v:.3f} m/s for cmd_vel 0.2")
        t2 = r.wait_stopped(t1)
        gt1, od1 = r.latest("gt", t2 - 0.1), r.latest("odom", t2 - 0.2)
        dist = float(np.linalg.norm(xy(gt1) - xy(gt0)))
        odist = float(np.linalg.norm(xy(od1) - xy(od0)))
        rospy.loginfo("firmware drive: ground truth %.4f m, wheel odometry %.4f m", dist, odist)
        self.assertGreater(dist, 0.85, f"ground truth moved only {dist:.3f} m in 5 s at 0.2 m/s")
        self.assertLess(dist, 1.15, f"ground truth moved {dist:.3f} m in 5 s at 0.2 m/s")
        self.assertLess(abs(odist - dist) / dist, 0.03, f"odom {odist:.4f} m vs ground truth {dist:.4f} m")
        self.assertLess(abs(yaw_of(gt1) - yaw_of(gt0)), 0.05, "the robot turned while driving straight")

    def test_2_turn(self) -> None:
        r = self.r
        t0 = r.wait_stopped(r.now())
        gt0, od0 = r.latest("gt", t0 - 0.1), r.latest("odom", t0 - 0.2)
        r.set_cmd((0.0, 0.8))
        r.wait_until(t0 + 3.0)
        r.set_cmd(None)
        t1 = r.wait_stopped(r.now())
        gt1, od1 = r.latest("gt", t1 - 0.1), r.latest("odom", t1 - 0.2)
        dyaw = math.remainder(yaw_of(gt1) - yaw_of(gt0), 2 * math.pi)
        doyaw = math.remainder(yaw_of(od1) - yaw_of(od0), 2 * math.pi)
        rospy.loginfo("firmware drive: turned %.4f rad (ground truth), %.4f rad (odom)", dyaw, doyaw)
        self.assertGreater(dyaw, 1.5, f"turned only {dyaw:.3f} rad in 3 s at 0.8 rad/s")
        self.assertLess(abs(doyaw - dyaw) / dyaw, 0.05, f"odom yaw {doyaw:.4f} vs ground truth {dyaw:.4f}")
        self.assertLess(float(np.linalg.norm(xy(gt1) - xy(gt0))), 0.05, "turning on the spot drifted")

    def test_3_watchdog_after_driver_killed(self) -> None:
        r = self.r
        t0 = r.wait_stopped(r.now())
        r.set_cmd((0.2, 0.0))
        r.wait_until(t0 + 2.0)
        self.assertEqual(r.fw_state[-1][1], "run")
        self.assertGreater(r.latest("gt", t0 + 1.9).twist.twist.linear.x, 0.15, "not driving before the kill")
        # SIGKILL: the driver cannot send its shutdown stop/reset; only the watchdog can stop the robot
        master = rosgraph.Master("/test_firmware_drive")
        uri = master.lookupNode("/launchpad_node")
        code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/test_firmware_drive")
        self.assertEqual(code, 1)
        t_kill = r.now()
        os.kill(pid, signal.SIGKILL)
        r.set_cmd((0.2, 0.0))  # cmd_vel keeps coming: only the dead link must stop the robot
        r.wait_for(lambda: r.fw_state[-1][1] == "timeout", "the firmware's drive state to become 'timeout'")
        t_timeout = r.fw_state[-1][0]
        rospy.loginfo("firmware drive: watchdog tripped %.3f s of sim time after the kill", t_timeout - t_kill)
        # observed through the next status cycle (1/30 s) and the 100 Hz /clock: allow 0.15 s
        self.assertLess(t_timeout - t_kill, WATCHDOG + 0.15)
        r.wait_until(t_kill + WATCHDOG + STOP_MARGIN + 0.3)
        late = r.between("gt", t_kill + WATCHDOG + STOP_MARGIN)
        self.assertTrue(late)
        vmax = max(abs(m.twist.twist.linear.x) for m in late)
        moving = [m.header.stamp.to_sec() - t_kill for m in r.between("gt", t_kill)
                  if abs(m.twist.twist.linear.x) > 0.01]
        rospy.loginfo("firmware drive: last ground-truth speed > 1 cm/s %.3f s of sim time after the kill",
                      max(moving) if moving else 0.0)
        self.assertLess(vmax, 0.01, f"still moving at {vmax:.3f} m/s {WATCHDOG + STOP_MARGIN:.2f} s after the kill")
        r.set_cmd(None)


if __name__ == "__main__":
    rostest.rosrun("chefbot_sim", "firmware_drive", FirmwareDrive)
