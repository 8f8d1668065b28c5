"""The robot monitor against a real roscore (pytest-qt, offscreen): console, topic monitor, image view.

The session's roscore (conftest.py) runs rosout, so this process's rospy log
calls come back on ``/rosout_agg``.  Every wait is a condition with a time-out
(qtbot.waitUntil); the rate check has wide bounds (a loaded 2-core machine).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import threading
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from conftest import PKG
from PyQt5.QtCore import Qt
from PyQt5.QtGui import QColor

from chefbot_gui.app import save_screenshot

T = 20_000  # ms: generous for a loaded 2-core CI machine
BUILD = PKG.parent / "build"


class Repeater:
    """Publishes ``make()`` on a topic every ``period_s`` from a thread until stopped."""

    def __init__(self, topic: str, cls: type, make: Callable[[], object], period_s: float, latch: bool = False):
        import rospy

        self.pub = rospy.Publisher(topic, cls, queue_size=10, latch=latch)
        self._make, self._period = make, period_s
        self._stop = threading.Event()
        self.sent = 0
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._period):  # a publisher's pace, not a test wait
            self.pub.publish(self._make())
            self.sent += 1

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.pub.unregister()


@pytest.fixture
def monitor(ros_node: None, qtbot) -> Iterator[object]:
    from chefbot_gui.monitor_window import RobotMonitorWindow
    from chefbot_gui.ros_monitor import MonitorBridge, MonitorParams

    bridge = MonitorBridge(MonitorParams(list_period_s=0.3))
    window = RobotMonitorWindow()
    qtbot.addWidget(window)
    bridge.start()
    window.attach(bridge)
    window.show()
    yield window
    window.stop()
    bridge.shutdown()


@pytest.fixture
def repeaters() -> Iterator[Callable[..., Repeater]]:
    made: list[Repeater] = []

    def make(*args, **kwargs) -> Repeater:
        r = Repeater(*args, **kwargs)
        made.append(r)
        return r

    yield make
    for r in made:
        r.stop()


def ns() -> str:
    return f"/monitor_test_{os.getpid()}"


def rgb_image(width: int = 64, height: int = 48):
    from sensor_msgs.msg import Image

    a = np.zeros((height, width, 3), np.uint8)
    a[:, : width // 2] = (220, 30, 30)   # left half red
    a[:, width // 2:] = (30, 30, 220)    # right half blue
    a[height // 3: 2 * height // 3, width // 3: 2 * width // 3, 1] = 200  # a greenish patch in the middle
    return Image(width=width, height=height, encoding="rgb8", step=3 * width, data=a.tobytes())


def console_rows(window) -> list[tuple[str, ...]]:
    m = window.console.model
    return [tuple(m.index(r, c).data() for c in range(m.columnCount())) for r in range(m.rowCount())]


def subscribers_of(topic: str) -> list[str]:
    """The nodes the master lists as subscribers of ``topic``."""
    import rosgraph

    _pubs, subs, _srvs = rosgraph.Master("/monitor_test_probe").getSystemState()
    return next((nodes for name, nodes in subs if name == topic), [])


def log_until_shown(qtbot, window, log: Callable[[], None], token: str) -> None:
    """Log, and log again every 2 s, until the Console shows ``token``: a line logged while a
    freshly made TCP link (this node → rosout → us) is still connecting is lost, as in ROS."""
    for _ in range(T // 2000):
        log()
        try:
            qtbot.waitUntil(lambda: any(token in r[3] for r in console_rows(window)), timeout=2000)
            return
        except qtbot.TimeoutError:
            continue
    raise AssertionError(f"{token!r} never reached the Console")


def wait_topic(qtbot, window, name: str):
    qtbot.waitUntil(lambda: window.topic_monitor.item(name) is not None, timeout=T)
    return window.topic_monitor.item(name)


def child(item, name: str):
    for i in range(item.childCount()):
        if item.child(i).text(0) == name:
            return item.child(i)
    return None


def rate_hz(item) -> float | None:
    m = re.match(r"([\d.]+) Hz", item.text(2))
    return float(m.group(1)) if m else None


def test_console_topic_monitor_and_image_view_against_a_real_master(qtbot, monitor, repeaters) -> None:
    import rospy
    from sensor_msgs.msg import BatteryState, Image

    w = monitor
    # Console: a warning of this node comes back through rosout's /rosout_agg
    token = f"monitor-test-{os.getpid()}"
    qtbot.waitUntil(lambda: w.port.log_connections() > 0, timeout=T)
    log_until_shown(qtbot, w, lambda: rospy.logwarn("%s: wheel current high", token), token)
    row = next(r for r in console_rows(w) if token in r[3])
    assert row[1] == "Warn" and row[2] == rospy.get_name()
    assert "test_monitor_ros.py" in row[4]
    log_until_shown(qtbot, w, lambda: rospy.logerr("%s: left motor stalled", token), "left motor stalled")
    assert next(r for r in console_rows(w) if "stalled" in r[3])[1] == "Error"

    # Topic Monitor: a 20 Hz battery topic, ticked, shows a plausible rate and the value tree
    topic = f"{ns()}/battery_state"
    repeaters(topic, BatteryState, lambda: BatteryState(voltage=12.25, percentage=0.5, present=True), 0.05)
    item = wait_topic(qtbot, w, topic)
    assert item.text(1) == "sensor_msgs/BatteryState"
    w.topic_monitor.set_ticked(topic, True)
    assert topic in w.port.subscribed()
    qtbot.waitUntil(lambda: rospy.get_name() in subscribers_of(topic), timeout=T)
    qtbot.waitUntil(lambda: w.port.stats(topic).count >= 20, timeout=T)
    qtbot.waitUntil(lambda: rate_hz(item) is not None and child(item, "percentage") is not None, timeout=T)
    assert 5.0 < rate_hz(item) < 40.0, item.text(2)  # nominal 20 Hz; wide: loaded machine
    assert re.match(r"[\d.]+ (B|KB)/s", item.text(3)), item.text(3)
    assert child(item, "percentage").text(4) == "0.5"
    assert child(item, "voltage").text(4) == "12.25"
    assert child(item, "header").childCount() == 3  # seq, stamp, frame_id

    # Image View: the image topic is offered, chosen, and shown with the right colours
    cam = f"{ns()}/camera/rgb/image_raw"
    repeaters(cam, Image, rgb_image, 0.2)
    combo = w.image_view.imageTopicCombo
    qtbot.waitUntil(lambda: combo.findText(cam) >= 0, timeout=T)
    assert combo.findText(topic) < 0  # only Image topics are offered
    combo.setCurrentText(cam)
    qtbot.waitUntil(lambda: w.image_view.image is not None, timeout=T)
    img = w.image_view.image
    assert (img.width(), img.height()) == (64, 48)
    assert QColor(img.pixel(5, 5)).getRgb()[:3] == (220, 30, 30)
    assert QColor(img.pixel(60, 40)).getRgb()[:3] == (30, 30, 220)
    assert not w.image_view.imageLabel.pixmap().isNull()
    qtbot.waitUntil(lambda: "64×48 rgb8" in w.image_view.imageStatus.text(), timeout=T)

    BUILD.mkdir(exist_ok=True)
    png = BUILD / "robot_monitor.png"
    assert save_screenshot(w, png) and png.stat().st_size > 10_000
    if os.environ.get("CHEFBOT_UPDATE_DOC"):  # refresh the README's picture
        shutil.copy(png, PKG / "doc" / "robot_monitor.png")

    # unticking unsubscribes and clears the row
    w.topic_monitor.set_ticked(topic, False)
    assert topic not in w.port.subscribed()
    qtbot.waitUntil(lambda: rospy.get_name() not in subscribers_of(topic), timeout=T)  # the master agrees
    assert item.childCount() == 0 and item.text(2) == ""


def test_bad_inputs_give_a_status_text_not_a_crash(qtbot, monitor, repeaters) -> None:
    import rospy
    from sensor_msgs.msg import Image
    from std_msgs.msg import String

    class Missing(String):  # a type whose package does not exist here
        _type = "chefbot_missing_pkg/Gone"

    w = monitor
    unknown = f"{ns()}/unknown_type"
    r = repeaters(unknown, Missing, lambda: Missing(data="x"), 0.1)
    item = wait_topic(qtbot, w, unknown)
    assert item.text(1) == "chefbot_missing_pkg/Gone"
    w.topic_monitor.set_ticked(unknown, True)
    qtbot.waitUntil(lambda: "is not installed here" in item.text(4), timeout=T)
    assert "rate and bandwidth only" in item.text(4)
    qtbot.waitUntil(lambda: rate_hz(item) is not None, timeout=T)  # still measured

    # the topic disappears from the master: the ticked row stays and says so
    r.stop()
    qtbot.waitUntil(lambda: "no longer published" in item.text(4), timeout=T)
    w.topic_monitor.set_ticked(unknown, False)
    assert w.topic_monitor.item(unknown) is None  # unticked and gone: dropped

    # an unsupported encoding and a 0×0 image: status text, the view keeps running
    cam = f"{ns()}/bad_camera"
    mode = {"img": Image(width=2, height=2, encoding="yuv422", step=4, data=bytes(8))}
    repeaters(cam, Image, lambda: mode["img"], 0.1)
    combo = w.image_view.imageTopicCombo
    qtbot.waitUntil(lambda: combo.findText(cam) >= 0, timeout=T)
    combo.setCurrentText(cam)
    status = w.image_view.imageStatus
    qtbot.waitUntil(lambda: "unsupported encoding 'yuv422'" in status.text(), timeout=T)
    mode["img"] = Image(width=0, height=0, encoding="rgb8", step=0, data=b"")
    qtbot.waitUntil(lambda: "empty image (0×0)" in status.text(), timeout=T)
    mode["img"] = rgb_image(8, 6)
    qtbot.waitUntil(lambda: "8×6 rgb8" in status.text(), timeout=T)
    assert w.image_view.image.width() == 8

    # a topic that is not an image, picked by name (as --image-topic can)
    words = f"{ns()}/not_an_image"
    repeaters(words, String, lambda: String(data="hello"), 0.1)
    w.image_view.choose(words)
    qtbot.waitUntil(lambda: "carries std_msgs/String, not sensor_msgs/Image" in status.text(), timeout=T)
    rospy.loginfo("monitor bad-input test done")  # the node is still alive and logging


def test_node_script_screenshot_and_bad_param(ros_master, tmp_path) -> None:
    """``rosrun chefbot_gui robot_monitor --screenshot`` exits 0 with a PNG; a bad param exits 2."""
    env = dict(os.environ, ROS_MASTER_URI=ros_master, QT_QPA_PLATFORM="offscreen")
    png = tmp_path / "monitor.png"
    ok = subprocess.run(["rosrun", "chefbot_gui", "robot_monitor", "--topics", "rosout",
                         "--screenshot", str(png), "--screenshot-delay", "2"],
                        env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert "Traceback" not in ok.stdout + ok.stderr
    assert png.stat().st_size > 10_000
    bad = subprocess.run(["rosrun", "chefbot_gui", "robot_monitor", "_window_s:=-1"],
                         env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert bad.returncode == 2
    assert "~window_s" in bad.stdout + bad.stderr


def test_delivery_gui_button_opens_the_monitor_sharing_its_subscriptions(qtbot, make_gui, repeaters) -> None:
    """The delivery window's *Robot monitor…* button, wired as nodes/robot_gui wires it: the monitor
    ticks a topic the delivery GUI already subscribes with its real type (rospy shares one
    subscription per topic and process), and both keep working."""
    from sensor_msgs.msg import BatteryState

    from chefbot_gui.monitor_app import MonitorController
    from chefbot_gui.ros_monitor import MonitorBridge, MonitorParams

    gui = make_gui()
    ctl = MonitorController(lambda: MonitorBridge(MonitorParams(list_period_s=0.3)))
    gui.window.monitorRequested.connect(ctl.open)
    ctl.ros_ready()
    try:
        qtbot.mouseClick(gui.window.monitorButton, Qt.LeftButton)
        assert ctl.window is not None and ctl.window.isVisible() and ctl.window.port is ctl.bridge
        topic = f"{gui.ns}/battery_state"
        repeaters(topic, BatteryState, lambda: BatteryState(percentage=0.37, voltage=12.0, present=True), 0.1)
        wait_topic(qtbot, ctl.window, topic)
        ctl.window.topic_monitor.set_ticked(topic, True)
        item = ctl.window.topic_monitor.item(topic)
        qtbot.waitUntil(lambda: child(item, "percentage") is not None, timeout=T)
        assert child(item, "percentage").text(4) == "0.37"
        qtbot.waitUntil(lambda: re.match(r"[\d.]+ B/s", item.text(3)) is not None, timeout=T)  # bytes counted
        qtbot.waitUntil(lambda: gui.window.batteryBar.value() == 37, timeout=T)  # the GUI's own subscriber
        ctl.window.close()  # closing drops the monitor's subscriptions, not the GUI's
        assert ctl.bridge is None
        qtbot.waitUntil(lambda: rospy_name() in subscribers_of(topic), timeout=T)
    finally:
        ctl.shutdown()


def rospy_name() -> str:
    import rospy

    return rospy.get_name()
