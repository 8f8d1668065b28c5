"""The monitor's widgets with a stand-in port (pytest-qt offscreen, no ROS): filters, pause,
clear, the bounded console, tick/untick, the image view, and opening/closing from the delivery GUI."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import TABLES
from PyQt5.QtCore import Qt

from chefbot_gui.image_convert import ImageFrame, to_display
from chefbot_gui.log_buffer import DEBUG, ERROR, INFO, WARN, LogEntry
from chefbot_gui.monitor_app import MonitorController
from chefbot_gui.monitor_window import NO_IMAGE_TOPIC, RobotMonitorWindow
from chefbot_gui.msg_tree import DecodeError
from chefbot_gui.topic_stats import Stats


class FakePort:
    """Records what the window asks for; the test decides what ROS "delivered"."""

    def __init__(self) -> None:
        self.logs: list[LogEntry] = []
        self.listing: list[tuple[str, str]] | None = []
        self.error = ""
        self.serial = 0
        self.subs: list[str] = []
        self.messages: dict[str, object] = {}
        self.image_topic: str | None = None
        self.frame = ImageFrame()
        self.started = self.stopped = 0

    def start(self) -> None:
        self.started += 1

    def shutdown(self) -> None:
        self.stopped += 1

    def list(self, listing, error: str = "") -> None:
        self.listing, self.error = listing, error
        self.serial += 1

    def drain_logs(self, limit: int = 5000) -> list[LogEntry]:
        out, self.logs = self.logs, []
        return out

    def topics(self):
        return self.serial, self.listing, self.error

    def subscribe(self, name: str) -> None:
        self.subs.append(name)

    def unsubscribe(self, name: str) -> None:
        self.subs.remove(name)

    def stats(self, name: str) -> Stats:
        return Stats(rate_hz=10.0, bandwidth_bps=2000.0, count=10, total=10)

    def last_message(self, name: str, listed_type: str):
        m = self.messages.get(name)
        if isinstance(m, Exception):
            raise m
        return (1, m) if m is not None else (0, None)

    def set_image_topic(self, name: str | None) -> None:
        self.image_topic = name

    def latest_image(self) -> ImageFrame:
        return self.frame


@pytest.fixture
def win(qtbot):
    port = FakePort()
    w = RobotMonitorWindow(capacity=5)
    qtbot.addWidget(w)
    w.attach(port)
    w.show()
    return w, port


def log(msg: str, level: int = INFO, node: str = "/a") -> LogEntry:
    return LogEntry(10.0, level, node, msg)


def shown(w) -> list[str]:
    m = w.console.model
    return [m.index(r, 3).data() for r in range(m.rowCount())]


def test_console_filters_pause_clear_and_capacity(win, qtbot) -> None:
    w, port = win
    c = w.console
    port.logs = [log("d", DEBUG), log("i"), log("w", WARN, "/amcl"), log("e", ERROR, "/move_base")]
    w.refresh()
    assert shown(w) == ["d", "i", "w", "e"]
    assert w.console.model.index(2, 1).data() == "Warn"
    assert w.console.model.index(3, 1).data(Qt.BackgroundRole) is not None  # errors are coloured
    c.severity_boxes[DEBUG].setChecked(False)
    c.severity_boxes[INFO].setChecked(False)
    assert shown(w) == ["w", "e"]
    qtbot.keyClicks(c.nodeFilter, "AMCL")
    assert shown(w) == ["w"]
    c.nodeFilter.clear()
    qtbot.mouseClick(c.pauseButton, Qt.LeftButton)
    assert c.pauseButton.text() == "Resume"
    port.logs = [log("late", ERROR)]
    w.refresh()
    assert shown(w) == ["w", "e"] and "paused, 1 new" in c.consoleStatus.text()
    qtbot.mouseClick(c.pauseButton, Qt.LeftButton)
    assert shown(w) == ["w", "e", "late"]
    port.logs = [log(f"x{i}", ERROR) for i in range(4)]  # capacity 5: the oldest go
    w.refresh()
    assert shown(w) == ["late", "x0", "x1", "x2", "x3"] and c.buffer.dropped == 4  # d, i, w, e went
    assert "4 oldest dropped" in c.consoleStatus.text()
    qtbot.mouseClick(c.clearButton, Qt.LeftButton)
    assert shown(w) == [] and c.consoleStatus.text().startswith("0 of 0")


def test_tick_subscribes_untick_unsubscribes_and_errors_show(win) -> None:
    from std_msgs.msg import Float64

    w, port = win
    tm = w.topic_monitor
    port.list([("/b", "std_msgs/Float64"), ("/a", "x_pkg/Unknown")])
    w.refresh()
    assert [tm.topicTree.topLevelItem(i).text(0) for i in range(2)] == ["/a", "/b"]
    tm.topicTree.topLevelItem(1).setCheckState(0, Qt.Checked)  # as a click on the box does
    assert port.subs == ["/b"]
    port.messages["/b"] = Float64(data=2.5)
    tm.refresh_values()
    item = tm.item("/b")
    assert (item.text(2), item.text(3)) == ("10 Hz", "2 KB/s")
    assert item.child(0).text(0) == "data" and item.child(0).text(4) == "2.5"
    tm.set_ticked("/a", True)
    port.messages["/a"] = DecodeError("/a: message type 'x_pkg/Unknown' is not installed here")
    tm.refresh_values()
    assert "not installed" in tm.item("/a").text(4)
    port.list([("/a", "x_pkg/Unknown")])  # /b vanishes while ticked
    w.refresh()
    assert "no longer published" in tm.item("/b").text(4)
    tm.set_ticked("/b", False)
    assert port.subs == ["/a"] and tm.item("/b") is None
    port.list(None, "cannot list topics from the master at http://x: refused")
    w.refresh()
    assert "cannot list topics" in tm.topicStatus.text() and tm.item("/a") is not None


def test_image_view_shows_frames_and_errors(win) -> None:
    w, port = win
    iv = w.image_view
    port.list([("/cam", "sensor_msgs/Image"), ("/odom", "nav_msgs/Odometry")])
    w.refresh()
    assert [iv.imageTopicCombo.itemText(i) for i in range(iv.imageTopicCombo.count())] == [NO_IMAGE_TOPIC, "/cam"]
    iv.imageTopicCombo.setCurrentText("/cam")
    assert port.image_topic == "/cam"
    rgb = np.zeros((3, 4, 3), np.uint8)
    rgb[0, 0] = (255, 0, 0)
    port.frame = ImageFrame(1, "/cam", to_display("rgb8", 4, 3, 12, rgb.tobytes()), "", Stats(rate_hz=5.0, total=9))
    w.refresh()
    assert (iv.image.width(), iv.image.height()) == (4, 3) and iv.image.pixelColor(0, 0).red() == 255
    assert iv.imageStatus.text() == "/cam: 4×3 rgb8 — 5 Hz"
    port.frame = ImageFrame(2, "/cam", None, "/cam: unsupported encoding 'yuv422'")
    w.refresh()
    assert "unsupported encoding" in iv.imageStatus.text() and "last good image" in iv.imageStatus.text()
    port.list([])  # the topic vanished: still selected, still offered
    w.refresh()
    assert iv.imageTopicCombo.currentText() == "/cam"
    iv.choose(None)
    assert port.image_topic is None and iv.image is None


def test_controller_waits_for_ros_then_closing_drops_the_bridge(qtbot) -> None:
    made: list[FakePort] = []
    ctl = MonitorController(lambda: made.append(FakePort()) or made[-1])
    w = ctl.open()
    qtbot.addWidget(w)
    assert w.port is None and made == []
    ctl.on_master("http://x:1", False)
    assert "no ROS master" in w.statusBar().currentMessage()
    ctl.ros_ready()
    assert len(made) == 1 and made[0].started == 1 and w.port is made[0]
    assert ctl.open() is w  # a second click raises the same window
    with qtbot.waitSignal(ctl.closed, timeout=5000):
        w.close()
    assert made[0].stopped == 1 and ctl.window is None and ctl.bridge is None
    w2 = ctl.open()  # opens again with a fresh bridge
    qtbot.addWidget(w2)
    assert len(made) == 2 and w2.port is made[1]
    ctl.shutdown()
    assert made[1].stopped == 1


def test_delivery_window_has_a_robot_monitor_button(qtbot) -> None:
    import time

    from chefbot_common.tables import load_tables
    from chefbot_gui.app import OfflineRobot
    from chefbot_gui.presenter import DeliveryPresenter
    from chefbot_gui.window import RobotGuiWindow

    w = RobotGuiWindow(DeliveryPresenter(load_tables(TABLES), OfflineRobot(), time.monotonic))
    qtbot.addWidget(w)
    assert w.monitorButton.isEnabled()
    with qtbot.waitSignal(w.monitorRequested, timeout=5000):
        qtbot.mouseClick(w.monitorButton, Qt.LeftButton)
