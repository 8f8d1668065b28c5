#!/usr/bin/env python3
"""robot_standalone.launch end to end against a virtual LaunchPad on a pty.

Real time (no sim time): the board is stepped by wall clock in a thread.
Every wait is a condition with a timeout; the 0.5 s stop budget is measured
from the board's own record of applied commands, not asserted by sleeping.
"""
from __future__ import annotations

import math
import threading
import time
import unittest
from collections import deque

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from std_msgs.msg import Int32

from chefbot_common.geometry import yaw_from_quaternion
from chefbot_common.rostest_helpers import wait_for
from chefbot_firmware.virtual_board import VirtualBoard


def odom_yaw(msg: Odometry) -> float:
    """Yaw (rad) of an odometry message."""
    q = msg.pose.pose.orientation
    return yaw_from_quaternion(q.x, q.y, q.z, q.w)


class BoardThread(threading.Thread):
    """Steps the virtual board in real time and records (t, left_cmd, right_cmd)."""

    def __init__(self, link: str) -> None:
        super().__init__(daemon=True)
        self.lock = threading.Lock()
        self.board = VirtualBoard(link)
        self.history: deque = deque(maxlen=20000)
        self.running = True

    def run(self) -> None:
        last = time.monotonic()
        while self.running:
            time.sleep(0.002)
            now = time.monotonic()
            with self.lock:
                self.board.step(now - last)
                self.history.append((now, self.board.fw.command(0), self.board.fw.command(1)))
            last = now

    def commands(self) -> tuple[int, int]:
        with self.lock:
            return self.board.fw.command(0), self.board.fw.command(1)

    def stop(self) -> None:
        self.running = False
        self.join(timeout=2)
        with self.lock:
            self.board.close()


class TestRobotStandalone(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("robot_standalone_check")
        cls.link = rospy.get_param("~link")
        cls.board = BoardThread(cls.link)
        cls.board.start()
        cls.odom: Odometry | None = None
        cls.diag: DiagnosticStatus | None = None
        cls.lwheel_count = 0
        rospy.Subscriber("odom", Odometry, cls._on_odom, tcp_nodelay=True)
        rospy.Subscriber("diagnostics", DiagnosticArray, cls._on_diag)
        rospy.Subscriber("lwheel", Int32, cls._on_lwheel)
        cls.pub = rospy.Publisher("cmd_vel", Twist, queue_size=1, tcp_nodelay=True)

    @classmethod
    def tearDownClass(cls) -> None:
        cls.board.stop()

    @classmethod
    def _on_odom(cls, msg: Odometry) -> None:
        cls.odom = msg

    @classmethod
    def _on_diag(cls, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == "chefbot: launchpad":
                cls.diag = st

    @classmethod
    def _on_lwheel(cls, _msg: Int32) -> None:
        cls.lwheel_count += 1

    def diag_value(self, key: str) -> str | None:
        d = self.diag
        return next((kv.value for kv in d.values if kv.key == key), None) if d else None

    def drive(self, v: float, w: float, seconds: float, check=None) -> float:
        """Publish cmd_vel at 5 Hz (navigation's rate) for `seconds`; returns the last send time."""
        twist = Twist()
        twist.linear.x, twist.angular.z = v, w
        end = time.monotonic() + seconds
        last = time.monotonic()
        while time.monotonic() < end:
            self.pub.publish(twist)
            last = time.monotonic()
            if check:
                check()
            time.sleep(0.2)
        return last

    def test_1_connects(self) -> None:
        wait_for(lambda: self.diag is not None and self.diag.level == DiagnosticStatus.OK
                 and self.diag_value("connected") == "True", 30, "launchpad_node connected (diagnostics OK)")
        wait_for(lambda: self.odom is not None, 20, "odom from diff_tf")
        wait_for(lambda: self.pub.get_num_connections() > 0, 20, "twist_to_motors subscribed to cmd_vel")

    def test_2_forward(self) -> None:
        x0 = self.odom.pose.pose.position.x
        seen = []
        self.drive(0.15, 0.0, 3.0, check=lambda: seen.append(self.board.commands()))
        left, right = seen[-1]
        self.assertGreater(left, 0)
        self.assertGreater(right, 0)
        self.assertLess(abs(left - right), 0.1 * max(left, right) + 20, f"unequal commands {left} {right}")
        wait_for(lambda: self.odom.pose.pose.position.x - x0 > 0.2, 10, "odom x to grow by 0.2 m")
        self.assertLess(abs(odom_yaw(self.odom)), 0.1)

    def test_3_turn_left(self) -> None:
        wait_for(lambda: self.board.commands() == (0, 0), 5, "robot stopped before turning")
        yaw0 = odom_yaw(self.odom)
        seen = []
        self.drive(0.0, 1.0, 2.0, check=lambda: seen.append(self.board.commands()))
        left, right = seen[-1]
        self.assertLess(left, 0)
        self.assertGreater(right, 0)
        wait_for(lambda: math.remainder(odom_yaw(self.odom) - yaw0, 2 * math.pi) > 0.5, 10,
                 "odom yaw to grow counter-clockwise by 0.5 rad")

    def test_4_stops_within_half_a_second_of_silence(self) -> None:
        last = self.drive(0.15, 0.0, 1.5)
        wait_for(lambda: self.board.commands() == (0, 0), 5, "motors stopped after cmd_vel silence")
        with self.board.lock:
            hist = list(self.board.history)
        moving_after = [t for t, left, right in hist if t > last and (left or right)]
        stop_delay = (max(moving_after) - last) if moving_after else 0.0
        rospy.loginfo("robot_standalone: motors stopped %.3f s after the last cmd_vel", stop_delay)
        self.assertLessEqual(stop_delay, 0.5)

    def test_5_garbage_is_counted_and_odometry_unaffected(self) -> None:
        wait_for(lambda: self.board.commands() == (0, 0), 5, "robot stopped")
        time.sleep(0.3)  # let the last odom of the stop arrive; the assertion below waits on conditions
        pose0 = self.odom.pose.pose.position
        bad0 = int(self.diag_value("lines_bad") or 0)
        with self.board.lock:
            self.board.board.port.write(b"\ngarbage line\n\xff\xfe\x00\x01\ne\tnan\t5\ne\t99999999999\t0\n"
                                        b"e\t123456\t-123456\n" + b"x" * 500 + b"\n")
        wait_for(lambda: int(self.diag_value("lines_bad") or 0) >= bad0 + 5, 10, "bad lines counted")
        time.sleep(0.5)
        pose1 = self.odom.pose.pose.position
        self.assertLess(math.hypot(pose1.x - pose0.x, pose1.y - pose0.y), 0.002,
                        "odometry moved although the robot stood still")

    def test_6_unplug_and_replug(self) -> None:
        reconnects0 = int(self.diag_value("reconnects") or 0)
        with self.board.lock:
            self.board.board.port.close()
        wait_for(lambda: self.diag.level == DiagnosticStatus.ERROR, 10, "ERROR diagnostic after unplug")
        self.assertEqual(self.diag_value("connected"), "False")
        stamp = self.diag.values  # the node keeps reporting while the board is gone
        wait_for(lambda: self.diag.values is not stamp, 5, "diagnostics still published (node alive)")
        with self.board.lock:
            self.board.board.reconnect(self.link)
        wait_for(lambda: self.diag.level == DiagnosticStatus.OK and self.diag_value("connected") == "True",
                 20, "reconnected under the same symlink")
        self.assertGreaterEqual(int(self.diag_value("reconnects")), reconnects0 + 1)
        n0 = self.lwheel_count
        wait_for(lambda: self.lwheel_count > n0 + 10, 10, "encoder topics flowing again")
        p0 = self.odom.pose.pose.position
        seen = []
        self.drive(0.15, 0.0, 2.0, check=lambda: seen.append(self.board.commands()))
        self.assertTrue(all(left > 0 and right > 0 for left, right in seen[2:]), f"board commands {seen}")

        def travelled() -> float:  # the robot faces wherever test 3 left it: distance, not x
            p = self.odom.pose.pose.position
            return math.hypot(p.x - p0.x, p.y - p0.y)
        wait_for(lambda: travelled() > 0.1, 10, "driving again after the replug")


if __name__ == "__main__":
    rostest.rosrun("chefbot_bringup", "robot_standalone_check", TestRobotStandalone)
