#!/usr/bin/env python3
"""rostest node for fleet_gui.test: a second fleet window whose button presses must reach the
stand-in dispatcher's action and services, and whose order table must show the order that the
launched fleet_gui sent at start."""
from __future__ import annotations

import time
import unittest

import rospy
import rostest
from PyQt5.QtCore import Qt
from PyQt5.QtTest import QTest
from PyQt5.QtWidgets import QApplication

from chefbot_common.tables import load_tables
from chefbot_gui.fleet_app import wire_fleet
from chefbot_gui.fleet_presenter import FleetPresenter
from chefbot_gui.fleet_window import FleetWindow
from chefbot_gui.ros_fleet_bridge import FleetBridge

TIMEOUT_S = 20.0


class FleetGuiTest(unittest.TestCase):
    def setUp(self) -> None:
        self.app = QApplication.instance() or QApplication([])
        self.bridge = FleetBridge()
        self.presenter = FleetPresenter(load_tables(rospy.get_param("~tables_file")), self.bridge, time.monotonic,
                                        connect_timeout_s=TIMEOUT_S)
        self.w = FleetWindow(self.presenter)
        wire_fleet(self.bridge, self.w)
        self.bridge.start()
        self.w.show()

    def tearDown(self) -> None:
        self.bridge.shutdown()
        self.w.close()

    def wait(self, cond, what: str) -> None:
        deadline = time.monotonic() + TIMEOUT_S
        while not cond():
            self.assertLess(time.monotonic(), deadline, f"timed out waiting for {what}")
            QTest.qWait(50)

    def rows(self, table) -> list[list[str]]:
        return self.w.cell_texts(table)

    def click_row(self, table, col0: str) -> None:
        row = next(r for r in range(table.rowCount()) if table.item(r, 0).text() == col0)
        QTest.mouseClick(table.viewport(), Qt.LeftButton, pos=table.visualItemRect(table.item(row, 0)).center())

    def test_buttons_reach_the_dispatcher_and_the_queue_comes_back(self) -> None:
        w = self.w
        self.wait(lambda: w.statusLabel.text().startswith("fleet:"), "the dispatcher")
        # the launched fleet_gui's start-up order
        self.wait(lambda: any(r[1] == "Table 8" for r in self.rows(w.orderTable)), "the order for Table 8")
        # Add order: Table 3 + Table 6 in one goal
        for key in ("table_3", "table_6"):
            item = w.table_item(key)
            QTest.mouseClick(w.tableList.viewport(), Qt.LeftButton, pos=w.tableList.visualItemRect(item).center())
        QTest.mouseClick(w.addOrderButton, Qt.LeftButton)
        self.wait(lambda: "accepted as" in w.replyLabel.text(), "the order's acceptance")
        oid = w.replyLabel.text().split()[-1]
        self.wait(lambda: any(r[0] == oid and r[1] == "Table 3, Table 6" for r in self.rows(w.orderTable)),
                  f"{oid} on /fleet/orders")
        # Cancel order
        self.click_row(w.orderTable, oid)
        self.wait(w.cancelOrderButton.isEnabled, "Cancel order enabled")
        QTest.mouseClick(w.cancelOrderButton, Qt.LeftButton)
        self.wait(lambda: w.replyLabel.text() == f"cancel {oid}: cancelled {oid}", "the cancel reply")
        self.wait(lambda: any(r[0] == oid and r[2] == "cancelled" for r in self.rows(w.orderTable)),
                  f"{oid} cancelled on /fleet/orders")
        # Pause a robot
        self.click_row(w.robotTable, "● chefbot1")
        self.wait(w.pauseButton.isEnabled, "Pause enabled")
        QTest.mouseClick(w.pauseButton, Qt.LeftButton)
        self.wait(lambda: w.replyLabel.text() == "pause chefbot1: chefbot1 paused", "the pause reply")
        self.wait(lambda: self.rows(w.robotTable)[0][1].startswith("paused"), "chefbot1 paused on /fleet/orders")


if __name__ == "__main__":
    rospy.init_node("fleet_gui_test", disable_signals=True)
    rostest.rosrun("chefbot_gui", "fleet_gui", FleetGuiTest)
