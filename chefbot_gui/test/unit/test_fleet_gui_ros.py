"""pytest-qt tests of the fleet window against a real roscore and a stand-in dispatcher.

The stand-in serves the real interface (``deliver`` action, ``cancel_order`` and ``set_robot``
services, ``orders`` and ``robots`` topics) in a namespace of its own per test; the window is
wired to a real :class:`~chefbot_gui.ros_fleet_bridge.FleetBridge`.  Offscreen; every wait is
on a condition with a time-out (qtbot.waitUntil).
"""
from __future__ import annotations

import os
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest
from conftest import TABLES
from PyQt5.QtCore import Qt

from chefbot_common.tables import load_tables

T = 15_000  # ms: generous for a loaded 2-core CI machine
FLEET = TABLES.parent / "hotel_fleet.yaml"
_counter = iter(range(1, 10_000))


class FakeDispatcher:
    """The dispatcher's ROS interface under ``ns``, recording what it is asked.

    ``refuse``: tables it refuses orders for (REJECTED with a reason, as the dispatcher does);
    ``service_delay_s``: how long each service call takes.  Robots' states are published at 5 Hz
    from ``robots`` (name -> (x, y)); ``silence(name)`` stops one.
    """

    def __init__(self, ns: str, refuse: tuple[str, ...] = (), service_delay_s: float = 0.0) -> None:
        import rospy
        from actionlib import ActionServer

        from chefbot_fleet.msg import DeliverAction, OrderQueue
        from chefbot_fleet.srv import CancelOrder, SetRobot
        from chefbot_msgs.msg import RobotState

        self.ns, self.refuse, self.delay = ns, refuse, service_delay_s
        self.goals: list = []
        self.cancels: list[str] = []
        self.commands: list[tuple[str, str]] = []
        self.robots: dict[str, tuple[float, float]] = {"chefbot1": (3.0, -3.0), "chefbot2": (-1.0, -3.5)}
        self._silent: set[str] = set()
        self._stop = threading.Event()
        self.server = ActionServer(f"{ns}/deliver", DeliverAction, self._on_goal, lambda gh: None, auto_start=False)
        self.server.start()
        self.srvs = [rospy.Service(f"{ns}/cancel_order", CancelOrder, self._on_cancel),
                     rospy.Service(f"{ns}/set_robot", SetRobot, self._on_set_robot)]
        self.orders_pub = rospy.Publisher(f"{ns}/orders", OrderQueue, queue_size=1, latch=True)
        self.robots_pub = rospy.Publisher(f"{ns}/robots", RobotState, queue_size=10)
        self.orders_pub.publish(self.queue())
        self._thread = threading.Thread(target=self._publish_robots, daemon=True)
        self._thread.start()

    @staticmethod
    def queue():
        from chefbot_fleet.msg import FleetRobot, Order, OrderQueue

        return OrderQueue(orders=[
            Order(id="o1", tables=["table_2"], state="on_the_way", assigned="chefbot1", eta=30.0),
            Order(id="o2", tables=["table_6", "table_9"], state="queued", eta=-1.0),
        ], robots=[FleetRobot(name="chefbot1", state="delivering", place="table_2", stops=["table_2"],
                              orders=["o1"], battery=0.7),
                   FleetRobot(name="chefbot2", state="idle", battery=0.9)])

    def _publish_robots(self) -> None:
        from geometry_msgs.msg import Point32, Pose2D

        from chefbot_msgs.msg import RobotState

        while not self._stop.wait(0.2):
            for name, (x, y) in list(self.robots.items()):
                if name in self._silent:
                    continue
                msg = RobotState(name=name, pose=Pose2D(x=x, y=y), footprint_radius=0.2, state="driving",
                                 path=[Point32(x=x + 1.0, y=y), Point32(x=x + 2.0, y=y)])
                msg.header.frame_id = "map"
                self.robots_pub.publish(msg)

    def silence(self, name: str) -> None:
        self._silent.add(name)

    def _on_goal(self, gh) -> None:
        from chefbot_fleet.msg import DeliverResult

        goal = gh.get_goal()
        self.goals.append(goal)
        bad = [t for t in goal.tables if t in self.refuse]
        if bad:
            why = f"unknown table {bad[0]!r}"
            gh.set_rejected(DeliverResult(state="failed", reason=why), why)
            return
        oid = f"o{len(self.goals) + 10}"
        gh.set_accepted(f"order {oid}")
        threading.Timer(0.3, lambda: gh.set_succeeded(DeliverResult(order_id=oid, state="served"))).start()

    def _on_cancel(self, req):
        from chefbot_fleet.srv import CancelOrderResponse

        time.sleep(self.delay)
        self.cancels.append(req.order_id)
        return CancelOrderResponse(True, f"cancelled {req.order_id}")

    def _on_set_robot(self, req):
        from chefbot_fleet.srv import SetRobotResponse

        time.sleep(self.delay)
        self.commands.append((req.robot, req.command))
        return SetRobotResponse(True, f"{req.robot}: {req.command} done")

    def stop(self) -> None:
        """Vanish as a crashed dispatcher would: action server, services and topics gone."""
        self._stop.set()
        asv = self.server
        asv.stop()
        asv.publish_result = asv.publish_feedback = asv.publish_status = lambda *a, **k: None
        for s in self.srvs:
            s.shutdown()
        self.orders_pub.unregister()
        self.robots_pub.unregister()


@dataclass
class FleetGui:
    ns: str
    window: object
    presenter: object
    bridge: object


@pytest.fixture
def make_fleet(ros_node: None, qtbot) -> Iterator[Callable[..., tuple[FleetGui, Callable[..., FakeDispatcher]]]]:
    """Factory: a fleet window + presenter + bridge in a fresh namespace, and a factory of its
    stand-in dispatchers; everything shut down after the test."""
    from chefbot_gui.fleet_app import wire_fleet
    from chefbot_gui.fleet_presenter import FleetPresenter
    from chefbot_gui.fleet_window import FleetWindow
    from chefbot_gui.ros_fleet_bridge import FleetBridge, FleetBridgeParams

    guis: list[FleetGui] = []
    dispatchers: list[FakeDispatcher] = []

    def make(server_timeout: float = 10.0, stale_timeout: float = 5.0):
        ns = f"/fleet_test_{os.getpid()}_{next(_counter)}"
        bridge = FleetBridge(FleetBridgeParams(fleet_ns=ns, robots_topic=f"{ns}/robots", map_topic=f"{ns}/map",
                                               poll_s=0.2, service_timeout_s=2.0))
        presenter = FleetPresenter(load_tables(TABLES), bridge, time.monotonic, fleet=("chefbot1", "chefbot2"),
                                   fleet_ns=ns, connect_timeout_s=server_timeout, stale_timeout_s=stale_timeout)
        window = FleetWindow(presenter)
        qtbot.addWidget(window)
        wire_fleet(bridge, window)
        bridge.start()
        window.show()
        gui = FleetGui(ns, window, presenter, bridge)
        guis.append(gui)

        def dispatcher(**kw) -> FakeDispatcher:
            d = FakeDispatcher(ns, **kw)
            dispatchers.append(d)
            return d
        return gui, dispatcher

    yield make
    for d in dispatchers:
        if not d._stop.is_set():
            d.stop()
    for g in guis:
        g.bridge.shutdown()
        g.window.close()


def status(w) -> str:
    return w.statusLabel.text()


def click_table(qtbot, w, key: str) -> None:
    item = w.table_item(key)
    qtbot.mouseClick(w.tableList.viewport(), Qt.LeftButton, pos=w.tableList.visualItemRect(item).center())


def click_row(qtbot, table, row: int) -> None:
    qtbot.mouseClick(table.viewport(), Qt.LeftButton, pos=table.visualItemRect(table.item(row, 0)).center())


def test_queue_and_robots_arrive_from_the_topics(qtbot, make_fleet) -> None:
    gui, dispatcher = make_fleet()
    dispatcher()
    w = gui.window
    qtbot.waitUntil(lambda: status(w) == "fleet: 2 of 2 robots in service, 2 open orders", timeout=T)
    qtbot.waitUntil(lambda: len(w.mapView.fleet()) == 2, timeout=T)
    assert [row[:2] for row in w.cell_texts(w.robotTable)] == [["● chefbot1", "delivering — Table 2"],
                                                               ["● chefbot2", "idle"]]
    assert [row[:4] for row in w.cell_texts(w.orderTable)] == [["o1", "Table 2", "on the way", "chefbot1"],
                                                               ["o2", "Table 6, Table 9", "queued", "—"]]
    c1 = next(m for m in w.mapView.fleet() if m.name == "chefbot1")
    assert (c1.x, c1.y) == (3.0, -3.0) and c1.path == ((4.0, -3.0), (5.0, -3.0))


def test_add_order_click_sends_one_deliver_goal_and_shows_the_answers(qtbot, make_fleet) -> None:
    gui, dispatcher = make_fleet()
    d = dispatcher(refuse=("table_9",))
    w = gui.window
    qtbot.waitUntil(lambda: status(w).startswith("fleet:"), timeout=T)
    click_table(qtbot, w, "table_3")
    click_table(qtbot, w, "table_1")
    w.prioritySpin.setValue(2)
    w.robotCombo.setCurrentIndex(w.robotCombo.findText("chefbot2"))
    qtbot.mouseClick(w.addOrderButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: len(d.goals) == 1, timeout=T)
    g = d.goals[0]
    assert (list(g.tables), g.priority, g.robot) == (["table_3", "table_1"], 2.0, "chefbot2")
    qtbot.waitUntil(lambda: w.replyLabel.text() == "order o11 served", timeout=T)
    # a refused order shows the dispatcher's reason
    click_table(qtbot, w, "table_9")
    qtbot.mouseClick(w.addOrderButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: w.replyLabel.text() == "order for Table 9: refused: unknown table 'table_9'", timeout=T)


def test_an_answer_that_comes_before_send_goal_returns_is_not_lost(qtbot, make_fleet) -> None:
    """The dispatcher refuses at once, on rospy's thread; the GUI thread may not have the goal's
    handle back yet.  Made certain here: send_goal returns only after the answer is in."""
    import actionlib

    gui, dispatcher = make_fleet()
    dispatcher(refuse=("table_9",))
    w = gui.window
    qtbot.waitUntil(lambda: status(w).startswith("fleet:"), timeout=T)
    client = gui.bridge._client
    send = client.send_goal

    def send_then_wait_for_the_answer(*a, **kw):
        gh = send(*a, **kw)
        deadline = time.monotonic() + T / 1000
        while gh.get_comm_state() != actionlib.CommState.DONE and time.monotonic() < deadline:
            time.sleep(0.01)
        assert gh.get_comm_state() == actionlib.CommState.DONE
        return gh

    client.send_goal = send_then_wait_for_the_answer
    click_table(qtbot, w, "table_9")
    qtbot.mouseClick(w.addOrderButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: w.replyLabel.text() == "order for Table 9: refused: unknown table 'table_9'", timeout=T)


def test_cancel_and_robot_buttons_reach_the_services_without_freezing(qtbot, make_fleet) -> None:
    gui, dispatcher = make_fleet()
    d = dispatcher(service_delay_s=1.0)
    w = gui.window
    qtbot.waitUntil(lambda: w.orderTable.rowCount() == 2 and status(w).startswith("fleet:"), timeout=T)
    click_row(qtbot, w.orderTable, 1)
    qtbot.waitUntil(w.cancelOrderButton.isEnabled, timeout=T)
    t0 = time.monotonic()
    qtbot.mouseClick(w.cancelOrderButton, Qt.LeftButton)
    assert time.monotonic() - t0 < 0.5       # the 1 s call runs off the GUI thread
    assert w.replyLabel.text() == "cancel o2…"
    qtbot.waitUntil(lambda: w.replyLabel.text() == "cancel o2: cancelled o2", timeout=T)
    assert d.cancels == ["o2"]
    click_row(qtbot, w.robotTable, 0)
    qtbot.waitUntil(w.pauseButton.isEnabled, timeout=T)
    qtbot.mouseClick(w.pauseButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: w.replyLabel.text() == "pause chefbot1: chefbot1: pause done", timeout=T)
    qtbot.mouseClick(w.chargeButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: d.commands == [("chefbot1", "pause"), ("chefbot1", "charge")], timeout=T)


def test_no_dispatcher_then_it_comes_then_it_dies(qtbot, make_fleet) -> None:
    gui, dispatcher = make_fleet(server_timeout=1.0)
    w = gui.window
    qtbot.waitUntil(lambda: "is dispatcher.launch running?" in status(w), timeout=T)
    assert status(w) == f"no dispatcher on {gui.ns} — is dispatcher.launch running?"
    click_table(qtbot, w, "table_2")
    assert not w.addOrderButton.isEnabled()
    d = dispatcher()
    qtbot.waitUntil(lambda: status(w).startswith("fleet:"), timeout=T)
    assert w.addOrderButton.isEnabled()
    d.stop()
    qtbot.waitUntil(lambda: "is dispatcher.launch running?" in status(w), timeout=T)
    assert not w.addOrderButton.isEnabled()
    # a call that slipped through meets no dispatcher: a clear reply after the time-out, no hang
    with qtbot.waitSignal(gui.bridge.replyReceived, timeout=T) as sig:
        gui.bridge.cancel_order(99, "o1")
    request, ok, message = sig.args
    assert (request, ok) == (99, False) and message.startswith(f"{gui.ns}/cancel_order does not answer")


def test_a_robot_that_stops_reporting_is_shown_stale(qtbot, make_fleet) -> None:
    gui, dispatcher = make_fleet(stale_timeout=1.0)
    d = dispatcher()
    w = gui.window
    qtbot.waitUntil(lambda: len(w.mapView.fleet()) == 2 and not any(m.stale for m in w.mapView.fleet()), timeout=T)
    d.silence("chefbot2")
    qtbot.waitUntil(lambda: any(m.stale and m.name == "chefbot2" for m in w.mapView.fleet()), timeout=T)
    assert "no report for" in w.robotTable.item(1, 1).text()
    assert not next(m for m in w.mapView.fleet() if m.name == "chefbot1").stale


def test_node_script_screenshot_and_bad_param(ros_master, tmp_path) -> None:
    """``rosrun chefbot_gui fleet_gui --screenshot`` exits 0 with a PNG; a bad param exits 2 naming it."""
    env = dict(os.environ, ROS_MASTER_URI=ros_master, QT_QPA_PLATFORM="offscreen")
    png = tmp_path / "shot.png"
    ns = f"__ns:=/fleet_node_test_{os.getpid()}"
    ok = subprocess.run(["rosrun", "chefbot_gui", "fleet_gui", ns, f"_tables_file:={TABLES}",
                         f"_fleet_file:={FLEET}", "_server_timeout:=0.5", "--screenshot", str(png),
                         "--screenshot-delay", "1.5"],
                        env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert png.stat().st_size > 5000
    bad = subprocess.run(["rosrun", "chefbot_gui", "fleet_gui", ns, f"_tables_file:={TABLES}", "_stale_timeout:=-1"],
                         env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert bad.returncode == 2
    assert "~stale_timeout" in bad.stdout + bad.stderr
    orders = subprocess.run(["rosrun", "chefbot_gui", "fleet_gui", ns + "_orders", f"_tables_file:={TABLES}",
                             "--orders", "table_1,table_42"],
                            env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert orders.returncode == 2 and "table_42" in orders.stdout + orders.stderr
