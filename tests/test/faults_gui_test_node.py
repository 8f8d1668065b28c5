#!/usr/bin/env python3
"""rostest node for faults_gui.test: the delivery GUI survives a move_base crash (issue 16).

The node hosts the GUI (window + presenter + ROS bridge, as robot_gui wires them) and starts
move_base itself (``roslaunch chefbot_navigation move_base.launch`` in its own process group).
Mid-delivery move_base is killed (SIGKILL: a crash, no zero Twist): the robot must stop (the
drive's command timeout), the GUI must say "robot not connected" and keep the table queued; a new
move_base is started: the GUI reconnects by itself, Go (staff confirm after a lost goal, by design)
delivers the table.  Ground truth judges the robot; durations in sim time, wall-clock timeouts.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
import unittest

import rosnode
import rospy
import rostest
from PyQt5.QtCore import Qt
from PyQt5.QtTest import QTest
from PyQt5.QtWidgets import QApplication

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from faults_nav_test_node import answers, node_pid, process_alive
from sim_navigation_test_node import Truth

from chefbot_common.rostest_helpers import wait_for
from chefbot_common.tables import load_tables
from chefbot_gui.app import wire
from chefbot_gui.presenter import DeliveryPresenter
from chefbot_gui.ros_bridge import BridgeParams, RosBridge
from chefbot_gui.window import RobotGuiWindow

PKG = "chefbot_tests"
NAME = "/faults_gui_test"
WALL_TIMEOUT = 240.0


class MoveBaseProcess:
    """``roslaunch chefbot_navigation move_base.launch`` in its own process group; output to a temp file."""

    def __init__(self) -> None:
        self.out = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(["roslaunch", "--disable-title", "chefbot_navigation", "move_base.launch"],
                                     stdin=subprocess.DEVNULL, stdout=self.out, stderr=subprocess.STDOUT,
                                     start_new_session=True)

    def crash(self) -> None:
        """SIGKILL the move_base node (roslaunch puts each node in a session of its own); move_base is
        ``required``, so its roslaunch then ends by itself."""
        pid = node_pid("/move_base")
        os.kill(pid, signal.SIGKILL)
        wait_for(lambda: not process_alive(pid), 30.0, "move_base gone", stop=rospy.is_shutdown)
        self.proc.wait(timeout=60.0)

    def stop(self) -> None:
        """SIGINT to roslaunch (it stops its nodes), SIGKILL to the group if it hangs."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()

    def output(self) -> str:
        self.out.seek(0)
        return self.out.read().decode(errors="replace")[-2000:]


class FaultsGuiTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.app = QApplication.instance() or QApplication(["faults_gui_test"])
        cls.tables = load_tables(rospy.get_param("~tables"))
        cls.truth = Truth()
        cls.bridge = RosBridge(BridgeParams())
        cls.presenter = DeliveryPresenter(cls.tables, cls.bridge, time.monotonic, connect_timeout_s=5.0,
                                          wait_time_s=0.0)
        cls.window = RobotGuiWindow(cls.presenter)
        wire(cls.bridge, cls.window)
        cls.bridge.start()
        cls.window.show()
        cls.move_bases: list[MoveBaseProcess] = []

    @classmethod
    def tearDownClass(cls) -> None:
        for mb in cls.move_bases:
            mb.stop()
        cls.bridge.shutdown()
        cls.window.close()

    def pump_until(self, cond, what: str, timeout: float = WALL_TIMEOUT) -> None:
        """Run Qt's event loop (the bridge's signals are queued into it) until ``cond()`` holds."""
        deadline = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > deadline or rospy.is_shutdown():
                extra = "".join(f"\n--- move_base #{i}:\n{mb.output()}" for i, mb in enumerate(self.move_bases))
                self.fail(f"timed out after {timeout:.0f} s waiting for {what}; GUI says "
                          f"{self.window.statusLabel.text()!r} / {self.window.hintLabel.text()!r}{extra}")
            self.app.processEvents()
            time.sleep(0.02)

    def click_table(self, key: str) -> None:
        item, lst = self.window.table_item(key), self.window.tableList
        if item is None:
            self.fail(f"{key} not in the GUI's table list")
        lst.scrollToItem(item)
        QTest.mouseClick(lst.viewport(), Qt.LeftButton, pos=lst.visualItemRect(item).center())

    def click_go(self) -> None:
        self.pump_until(self.window.goButton.isEnabled, "Go enabled")
        QTest.mouseClick(self.window.goButton, Qt.LeftButton)

    def status(self) -> str:
        return self.window.statusLabel.text()

    def test_move_base_crash_and_restart_mid_delivery(self) -> None:
        self.pump_until(lambda: bool(self.truth.hist), "ground truth")
        self.move_bases.append(MoveBaseProcess())
        self.pump_until(lambda: self.status() == "ready", "GUI ready with move_base #1")
        self.click_table("table_4")
        self.click_go()
        self.pump_until(lambda: self.truth.speed() > 0.15, "robot under way to table_4")
        t_kill = rospy.get_time()
        self.move_bases[0].crash()                # no zero Twist from move_base
        self.pump_until(lambda: self.truth.speed() < 0.01, "robot at rest after the crash", 60.0)
        t_stop = self.truth.latest()[0]
        print(f"[figure] move_base killed: robot at rest {t_stop - t_kill:.2f} s sim later", flush=True)
        # the drive's command_timeout (0.6 s) + braking
        self.assertLess(t_stop - t_kill, 2.5, "robot kept driving without move_base")
        self.pump_until(lambda: self.status() == "robot not connected", "GUI: robot not connected", 60.0)
        self.assertFalse(self.window.goButton.isEnabled(), "Go enabled without a server")
        self.assertEqual(self.presenter.queue, ["table_4"], "the interrupted table left the queue")
        # a new move_base: the GUI finds it by itself
        t_restart = time.monotonic()
        self.move_bases.append(MoveBaseProcess())
        self.pump_until(self.window.goButton.isEnabled, "GUI reconnected to move_base #2")
        print(f"[figure] GUI reconnected {time.monotonic() - t_restart:.1f} s wall after the restart", flush=True)
        self.assertIn("press Go to continue", self.window.hintLabel.text())
        self.click_go()
        self.pump_until(lambda: self.status().startswith("arrived at"), "arrived at table_4")
        self.pump_until(lambda: self.truth.speed() < 0.01, "robot at rest at table_4", 60.0)
        _, x, y, _ = self.truth.latest()
        target = self.tables["table_4"]
        self.assertLessEqual(((x - target.x) ** 2 + (y - target.y) ** 2) ** 0.5, 0.05, f"robot at ({x}, {y})")
        self.assertEqual(self.truth.contacts, 0, "bumper contact")
        # every node of the graph (the launch's and move_base #2) still answers, its process alive
        dead = [n for n in rosnode.get_node_names() if n != NAME and not answers(n)]
        self.assertEqual(dead, [], "nodes that no longer answer")


if __name__ == "__main__":
    rospy.init_node("faults_gui_test")
    rostest.rosrun(PKG, "faults_gui", FaultsGuiTest)
