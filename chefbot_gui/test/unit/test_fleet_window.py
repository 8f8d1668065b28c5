"""pytest-qt tests of the fleet window with real widgets and no ROS master (offscreen).

The dispatcher's real message classes (``chefbot_fleet/OrderQueue``, ``chefbot_msgs/RobotState``)
go through the bridge's converters into the window's slots, as the bridge's signals deliver
them; staff commands end at a fake port (the ROS boundary).  The same window against a real
roscore and a real action server and services: ``test_fleet_gui_ros.py``.
"""
from __future__ import annotations

import pytest
from conftest import TABLES
from geometry_msgs.msg import Point32, Pose2D
from PyQt5.QtCore import Qt

from chefbot_common.tables import load_tables
from chefbot_fleet.msg import FleetRobot, Order, OrderQueue
from chefbot_gui.app import save_screenshot
from chefbot_gui.fleet_presenter import PALETTE, FleetPresenter
from chefbot_gui.fleet_window import FleetWindow
from chefbot_gui.ros_fleet_bridge import queue_from_message, report_from_message
from chefbot_msgs.msg import RobotState

POSES = load_tables(TABLES)


class Clock:
    def __init__(self) -> None:
        self.t = 50.0

    def __call__(self) -> float:
        return self.t


class FakePort:
    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def send_order(self, request, tables, priority, robot) -> None:
        self.calls.append(("order", list(tables), priority, robot))

    def cancel_order(self, request, order_id) -> None:
        self.calls.append(("cancel", order_id))

    def set_robot(self, request, robot, command) -> None:
        self.calls.append(("robot", robot, command))


def queue_msg() -> OrderQueue:
    msg = OrderQueue()
    msg.orders = [
        Order(id="o1", tables=["table_3"], state="served", eta=-1.0),
        Order(id="o2", tables=["table_2", "table_5"], state="on_the_way", assigned="chefbot1", eta=95.0),
        Order(id="o3", tables=["table_7"], state="assigned", assigned="chefbot2", eta=40.0),
        Order(id="o4", tables=["table_9"], state="queued", reason="chefbot3 paused", eta=-1.0),
    ]
    msg.robots = [
        FleetRobot(name="chefbot1", state="delivering", place="table_2", stops=["table_2", "table_5"],
                   orders=["o2"], battery=0.81),
        FleetRobot(name="chefbot2", state="to_kitchen", place="kitchen", stops=["table_7"], orders=["o3"],
                   battery=0.12),
        FleetRobot(name="chefbot3", state="paused", reason="paused by staff", battery=-1.0),
    ]
    return msg


def robot_msg(name: str, x: float, y: float, path: list[tuple[float, float]] = ()) -> RobotState:
    msg = RobotState(name=name, pose=Pose2D(x=x, y=y, theta=0.0), footprint_radius=0.2, state="driving")
    msg.header.frame_id = "map"
    msg.path = [Point32(x=px, y=py) for px, py in path]
    return msg


@pytest.fixture
def gui(qtbot):
    clock, port = Clock(), FakePort()
    presenter = FleetPresenter(POSES, port, clock, fleet=("chefbot1", "chefbot2", "chefbot3"), stale_timeout_s=3.0)
    window = FleetWindow(presenter)
    qtbot.addWidget(window)
    window.show()
    window.on_dispatcher(True, True)
    window.on_queue(queue_from_message(queue_msg()))
    window.on_robot(report_from_message(robot_msg("chefbot1", 3.0, -3.0, [(4.0, -3.0), (5.05, -3.0)])))
    window.on_robot(report_from_message(robot_msg("chefbot2", -1.0, -3.5)))
    window.on_robot(report_from_message(robot_msg("chefbot3", 0.0, 1.5)))
    return window, presenter, port, clock


def click_table(qtbot, window, key: str) -> None:
    item = window.table_item(key)
    qtbot.mouseClick(window.tableList.viewport(), Qt.LeftButton, pos=window.tableList.visualItemRect(item).center())


def click_row(qtbot, table, row: int) -> None:
    rect = table.visualItemRect(table.item(row, 0))
    qtbot.mouseClick(table.viewport(), Qt.LeftButton, pos=rect.center())


def test_robots_and_orders_are_listed(gui) -> None:
    w, *_ = gui
    assert w.statusLabel.text() == "fleet: 2 of 3 robots in service, 3 open orders"
    assert w.cell_texts(w.robotTable) == [
        ["● chefbot1", "delivering — Table 2", "81 %", "Table 2 → Table 5 (o2)"],
        ["● chefbot2", "to the kitchen — Kitchen", "12 %", "Table 7 (o3)"],
        ["● chefbot3", "paused (paused by staff)", "?", "—"],
    ]
    assert w.robotTable.item(0, 0).foreground().color().name() == PALETTE[0]
    assert w.robotTable.item(1, 2).foreground().color().name() == "#c62828"     # low battery in red
    assert w.cell_texts(w.orderTable) == [
        ["o2", "Table 2, Table 5", "on the way", "chefbot1", "~2 min", ""],
        ["o3", "Table 7", "assigned", "chefbot2", "~40 s", ""],
        ["o4", "Table 9", "queued", "—", "—", "chefbot3 paused"],
        ["o1", "Table 3", "served", "—", "—", ""],
    ]
    assert w.orderTable.item(1, 3).foreground().color().name() == PALETTE[1]


def test_map_shows_every_robot_in_its_colour_with_its_path(gui, tmp_path) -> None:
    w, *_ = gui
    fleet = {m.name: m for m in w.mapView.fleet()}
    assert set(fleet) == {"chefbot1", "chefbot2", "chefbot3"}
    assert fleet["chefbot1"].colour == PALETTE[0] and fleet["chefbot2"].colour == PALETTE[1]
    assert (fleet["chefbot1"].x, fleet["chefbot1"].y) == (3.0, -3.0)
    assert fleet["chefbot1"].path == ((4.0, -3.0), (5.05, -3.0))
    assert not any(m.stale for m in fleet.values())
    # the painted pixel at chefbot1's centre is its colour
    png = tmp_path / "fleet.png"
    assert save_screenshot(w, png)
    img = w.mapView.grab().toImage()
    c = w.mapView.world_to_widget(3.0, -3.0).toPoint()
    assert img.pixelColor(c).name() == PALETTE[0]


def test_stale_robot_is_marked_and_drawn_hollow(gui) -> None:
    w, presenter, _, clock = gui
    clock.t += 2.0
    w.on_robot(report_from_message(robot_msg("chefbot2", -1.0, -3.4)))
    clock.t += 2.0
    presenter.tick()
    fleet = {m.name: m for m in w.mapView.fleet()}
    assert fleet["chefbot1"].stale and fleet["chefbot1"].path == () and not fleet["chefbot2"].stale
    assert w.robotTable.item(0, 1).text() == "delivering — Table 2 — no report for 4 s"
    assert "no position from chefbot1, chefbot3" == w.hintLabel.text()


def test_pick_tables_in_the_list_and_on_the_map_then_add_order(qtbot, gui) -> None:
    w, presenter, port, _ = gui
    assert not w.addOrderButton.isEnabled()
    click_table(qtbot, w, "table_4")
    pt = w.mapView.world_to_widget(POSES["table_8"].x, POSES["table_8"].y)
    qtbot.mouseClick(w.mapView, Qt.LeftButton, pos=pt.toPoint())
    assert presenter.selected_tables == ["table_4", "table_8"]
    assert sorted(i.data(Qt.UserRole) for i in w.tableList.selectedItems()) == ["table_4", "table_8"]
    w.prioritySpin.setValue(2)
    w.robotCombo.setCurrentIndex(w.robotCombo.findText("chefbot3"))
    qtbot.mouseClick(w.addOrderButton, Qt.LeftButton)
    assert port.calls == [("order", ["table_4", "table_8"], 2.0, "chefbot3")]
    assert w.replyLabel.text() == "order for Table 4, Table 8…"
    assert w.tableList.selectedItems() == [] and not w.addOrderButton.isEnabled()
    w.on_order_refused(1, "chefbot3 is paused")
    assert w.replyLabel.text() == "order for Table 4, Table 8: refused: chefbot3 is paused"


def test_cancel_selected_order(qtbot, gui) -> None:
    w, _, port, _ = gui
    assert not w.cancelOrderButton.isEnabled()
    click_row(qtbot, w.orderTable, 1)                   # o3
    assert w.cancelOrderButton.isEnabled()
    qtbot.mouseClick(w.cancelOrderButton, Qt.LeftButton)
    assert port.calls == [("cancel", "o3")]
    w.on_reply(1, True, "cancelled o3")
    assert w.replyLabel.text() == "cancel o3: cancelled o3"
    click_row(qtbot, w.orderTable, 3)                   # o1: served
    assert not w.cancelOrderButton.isEnabled()


def test_robot_buttons_pause_resume_charge(qtbot, gui) -> None:
    w, _, port, _ = gui
    click_row(qtbot, w.robotTable, 0)                   # chefbot1, delivering
    assert (w.pauseButton.isEnabled(), w.resumeButton.isEnabled(), w.chargeButton.isEnabled()) == (True, False, True)
    qtbot.mouseClick(w.pauseButton, Qt.LeftButton)
    qtbot.mouseClick(w.chargeButton, Qt.LeftButton)
    click_row(qtbot, w.robotTable, 2)                   # chefbot3, paused
    assert (w.pauseButton.isEnabled(), w.resumeButton.isEnabled()) == (False, True)
    qtbot.mouseClick(w.resumeButton, Qt.LeftButton)
    assert port.calls == [("robot", "chefbot1", "pause"), ("robot", "chefbot1", "charge"),
                          ("robot", "chefbot3", "resume")]


def test_selection_survives_a_new_queue(qtbot, gui) -> None:
    w, presenter, _, _ = gui
    click_row(qtbot, w.orderTable, 2)                   # o4
    msg = queue_msg()
    msg.orders[3].state = "assigned"
    msg.orders[3].assigned = "chefbot1"
    w.on_queue(queue_from_message(msg))
    assert presenter.selected_order == "o4"
    rows = w.orderTable.selectionModel().selectedRows()
    assert [w.orderTable.item(r.row(), 0).text() for r in rows] == ["o4"]


def test_no_dispatcher_greys_every_button(qtbot, gui) -> None:
    w, *_ = gui
    click_table(qtbot, w, "table_1")
    click_row(qtbot, w.robotTable, 0)
    click_row(qtbot, w.orderTable, 0)
    w.on_dispatcher(False, False)
    assert w.statusLabel.text() == "no dispatcher on /fleet — is dispatcher.launch running?"
    for b in (w.addOrderButton, w.cancelOrderButton, w.pauseButton, w.resumeButton, w.chargeButton):
        assert not b.isEnabled(), b.objectName()


def test_unknown_robot_in_the_queue_and_robot_the_dispatcher_does_not_list(gui) -> None:
    w, *_ = gui
    msg = queue_msg()
    msg.orders[2].assigned = "ghost"       # o3, the second row
    w.on_queue(queue_from_message(msg))
    w.on_robot(report_from_message(robot_msg("visitor", 6.0, 1.5)))
    assert w.orderTable.item(1, 3).text() == "ghost (unknown robot)"
    rows = w.cell_texts(w.robotTable)
    assert rows[-1][:2] == ["● visitor", "not dispatched (driving)"]
    assert "visitor" in {m.name for m in w.mapView.fleet()}
    assert [w.robotCombo.itemText(i) for i in range(w.robotCombo.count())] == [
        "any robot", "chefbot1", "chefbot2", "chefbot3"]


def test_a_click_on_a_robot_on_the_map_selects_its_row(qtbot, gui) -> None:
    w, presenter, port, _ = gui
    pt = w.mapView.world_to_widget(0.0, 1.5).toPoint()          # chefbot3, paused
    qtbot.mouseClick(w.mapView, Qt.LeftButton, pos=pt)
    assert presenter.selected_robot == "chefbot3"
    rows = w.robotTable.selectionModel().selectedRows()
    assert [w.robotTable.item(r.row(), 0).text() for r in rows] == ["● chefbot3"]
    qtbot.mouseClick(w.resumeButton, Qt.LeftButton)
    assert port.calls == [("robot", "chefbot3", "resume")]
