"""pytest-qt tests of the GUI against a real roscore and a real actionlib move_base server.

Offscreen (QT_QPA_PLATFORM=offscreen).  Every wait is on a condition with a
timeout (qtbot.waitUntil); nothing sleeps and hopes.
"""
from __future__ import annotations

import math
import os
import subprocess
import threading

import pytest
from conftest import TABLES, FakeMoveBase
from PyQt5.QtCore import Qt

from chefbot_common.tables import load_tables
from chefbot_gui.app import save_screenshot

T = 15_000  # ms: generous for a loaded 2-core CI machine
POSES = load_tables(TABLES)


def click_table(qtbot, window, key: str) -> None:
    item = window.table_item(key)
    assert item is not None, f"{key} not in the table list"
    window.tableList.scrollToItem(item)
    qtbot.mouseClick(window.tableList.viewport(), Qt.LeftButton, pos=window.tableList.visualItemRect(item).center())


def click_when_enabled(qtbot, button) -> None:
    qtbot.waitUntil(button.isEnabled, timeout=T)
    qtbot.mouseClick(button, Qt.LeftButton)


def status(window) -> str:
    return window.statusLabel.text()


def test_select_table_3_and_go_sends_the_yaml_pose(qtbot, make_gui, fake_servers) -> None:
    gui = make_gui()
    server = fake_servers(gui.action)
    w = gui.window
    qtbot.waitUntil(lambda: status(w) == "ready", timeout=T)
    click_table(qtbot, w, "table_3")
    assert gui.presenter.selected == "table_3"
    click_when_enabled(qtbot, w.goButton)
    qtbot.waitUntil(lambda: len(server.goals) == 1, timeout=T)
    pose = server.goals[0].target_pose
    want = POSES["table_3"]
    assert pose.header.frame_id == "map"
    assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == pytest.approx((want.x, want.y, 0))
    q = pose.pose.orientation
    assert math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2) == pytest.approx(1.0, abs=1e-9)
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(want.yaw, abs=1e-9)
    qtbot.waitUntil(lambda: status(w).startswith("driving to Table 3"), timeout=T)
    assert w.cancelButton.isEnabled()


def test_cancel_reaches_the_server(qtbot, make_gui, fake_servers) -> None:
    gui = make_gui()
    server = fake_servers(gui.action)
    w = gui.window
    click_table(qtbot, w, "table_2")
    click_when_enabled(qtbot, w.goButton)
    qtbot.waitUntil(lambda: len(server.goals) == 1, timeout=T)
    click_when_enabled(qtbot, w.cancelButton)
    qtbot.waitUntil(server.cancelled.is_set, timeout=T)
    qtbot.waitUntil(lambda: status(w) == "cancelled", timeout=T)
    assert not w.cancelButton.isEnabled()


def test_battery_message_sets_the_bar_in_the_gui_thread(qtbot, make_gui, monkeypatch) -> None:
    import rospy
    from sensor_msgs.msg import BatteryState

    gui = make_gui()
    threads: list[threading.Thread] = []
    original = gui.presenter.on_battery

    def spy(*args) -> None:
        threads.append(threading.current_thread())
        original(*args)

    monkeypatch.setattr(gui.presenter, "on_battery", spy)
    pub = rospy.Publisher(f"{gui.ns}/battery_state", BatteryState, queue_size=1, latch=True)
    try:
        pub.publish(BatteryState(percentage=0.42, voltage=12.3, present=True))
        qtbot.waitUntil(lambda: gui.window.batteryBar.value() == 42, timeout=T)
        assert "42 %" in gui.window.batteryBar.format()
        assert threads and all(t is threading.main_thread() for t in threads)
    finally:
        pub.unregister()


def test_server_absent_disables_buttons_then_recovers_and_loses_again(qtbot, make_gui, fake_servers) -> None:
    gui = make_gui(server_timeout=1.0)
    w = gui.window
    assert status(w) == "connecting…"
    qtbot.waitUntil(lambda: status(w) == "robot not connected", timeout=T)
    click_table(qtbot, w, "table_1")
    assert not (w.goButton.isEnabled() or w.homeButton.isEnabled() or w.cancelButton.isEnabled())
    assert "not running" in w.hintLabel.text()
    # the server comes (back): the GUI recovers by itself
    server = fake_servers(gui.action)
    qtbot.waitUntil(lambda: status(w) == "ready", timeout=T)
    assert w.goButton.isEnabled() and w.homeButton.isEnabled()
    click_when_enabled(qtbot, w.goButton)
    qtbot.waitUntil(lambda: len(server.goals) == 1, timeout=T)
    # ... and dies mid-delivery: the table goes back to the queue, buttons off
    server.stop()
    qtbot.waitUntil(lambda: status(w) == "robot not connected", timeout=T)
    assert not (w.goButton.isEnabled() or w.cancelButton.isEnabled())
    assert gui.presenter.queue == ["table_1"]
    fake_servers(gui.action)
    qtbot.waitUntil(lambda: w.goButton.isEnabled(), timeout=T)
    assert "press Go to continue" in w.hintLabel.text()


def test_server_abort_shows_its_reason(qtbot, make_gui, fake_servers) -> None:
    gui = make_gui()
    fake_servers(gui.action, mode="abort", reason="no path to the goal: blocked by an obstacle")
    w = gui.window
    click_table(qtbot, w, "table_5")
    click_when_enabled(qtbot, w.goButton)
    qtbot.waitUntil(lambda: status(w) == "failed: no path to the goal: blocked by an obstacle", timeout=T)
    assert w.goButton.isEnabled() and w.homeButton.isEnabled() and not w.cancelButton.isEnabled()


def test_queue_of_two_tables_served_then_home(qtbot, make_gui, fake_servers) -> None:
    gui = make_gui(wait_time=0.0)  # wait at each table until Served is clicked
    server: FakeMoveBase = fake_servers(gui.action, mode="hold")
    w = gui.window
    click_table(qtbot, w, "table_7")
    click_when_enabled(qtbot, w.goButton)
    click_table(qtbot, w, "table_4")
    click_when_enabled(qtbot, w.goButton)
    qtbot.waitUntil(lambda: len(server.goals) == 1, timeout=T)
    assert [w.queueList.item(i).text() for i in range(w.queueList.count())] == ["now: Table 7", "1. Table 4"]
    server.set_mode("succeed")
    qtbot.waitUntil(lambda: status(w) == "arrived at Table 7", timeout=T)
    click_when_enabled(qtbot, w.servedButton)
    qtbot.waitUntil(lambda: status(w) == "arrived at Table 4", timeout=T)
    click_when_enabled(qtbot, w.servedButton)
    qtbot.waitUntil(lambda: status(w) == "arrived home — ready", timeout=T)
    got = [c for g in server.goals for c in (g.target_pose.pose.position.x, g.target_pose.pose.position.y)]
    want = [c for k in ("table_7", "table_4", "home") for c in (POSES[k].x, POSES[k].y)]
    assert got == pytest.approx(want)


def test_map_pose_plan_and_click_on_a_table(qtbot, make_gui, fake_servers, tmp_path) -> None:
    import rospy
    import tf2_ros
    from geometry_msgs.msg import PoseStamped, TransformStamped
    from nav_msgs.msg import OccupancyGrid, Path

    gui = make_gui()
    fake_servers(gui.action)
    w = gui.window
    grid = OccupancyGrid()
    grid.header.frame_id = "map"
    grid.info.resolution, grid.info.width, grid.info.height = 0.1, 120, 100
    grid.info.origin.position.x, grid.info.origin.position.y = -2.0, -5.0
    grid.info.origin.orientation.w = 1.0
    grid.data = [100 if (i % 120) in (0, 119) or (i // 120) in (0, 99) else 0 for i in range(120 * 100)]
    map_pub = rospy.Publisher(f"{gui.ns}/map", OccupancyGrid, queue_size=1, latch=True)
    plan_pub = rospy.Publisher(f"{gui.ns}/plan", Path, queue_size=1, latch=True)
    tf_pub = tf2_ros.StaticTransformBroadcaster()
    try:
        map_pub.publish(grid)
        qtbot.waitUntil(w.mapView.has_map, timeout=T)
        t = TransformStamped()
        t.header.stamp = rospy.Time.now()
        t.header.frame_id, t.child_frame_id = "map", gui.bridge.p.base_frame
        t.transform.translation.x, t.transform.translation.y = 1.0, 0.5
        t.transform.rotation.z, t.transform.rotation.w = math.sin(0.25), math.cos(0.25)
        tf_pub.sendTransform(t)
        qtbot.waitUntil(lambda: gui.presenter.state().robot_pose is not None, timeout=T)
        pose = gui.presenter.state().robot_pose
        assert (pose.x, pose.y, pose.yaw) == pytest.approx((1.0, 0.5, 0.5))

        # a click on the table 7 marker selects table 7 in the list too
        target = POSES["table_7"]
        pt = w.mapView.world_to_widget(target.x, target.y)
        qtbot.mouseClick(w.mapView, Qt.LeftButton, pos=pt.toPoint())
        qtbot.waitUntil(lambda: gui.presenter.selected == "table_7", timeout=T)
        assert [i.text() for i in w.tableList.selectedItems()] == ["Table 7"]

        click_when_enabled(qtbot, w.goButton)
        path = Path()
        path.header.frame_id = "map"
        for x, y in ((1.0, 0.5), (1.0, 3.0), (target.x, target.y)):
            ps = PoseStamped()
            ps.pose.position.x, ps.pose.position.y = x, y
            path.poses.append(ps)
        plan_pub.publish(path)
        want = 2.5 + abs(target.x - 1.0)
        qtbot.waitUntil(lambda: f"({want:.1f} m" in status(w), timeout=T)
        assert "driving to Table 7" in status(w)
        png = tmp_path / "gui.png"
        assert save_screenshot(w, png) and png.stat().st_size > 5000
    finally:
        map_pub.unregister()
        plan_pub.unregister()


def test_node_script_screenshot_and_bad_param(ros_master, tmp_path) -> None:
    """``rosrun chefbot_gui robot_gui --screenshot`` exits 0 with a PNG; a bad param exits 2."""
    env = dict(os.environ, ROS_MASTER_URI=ros_master, QT_QPA_PLATFORM="offscreen")
    png = tmp_path / "shot.png"
    ns = f"__ns:=/node_test_{os.getpid()}"
    ok = subprocess.run(["rosrun", "chefbot_gui", "robot_gui", ns, f"_tables_file:={TABLES}",
                         "_server_timeout:=0.5", "--screenshot", str(png), "--screenshot-delay", "1.5"],
                        env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert png.stat().st_size > 5000
    bad = subprocess.run(["rosrun", "chefbot_gui", "robot_gui", ns, f"_tables_file:={TABLES}", "_wait_time:=-1"],
                         env=env, capture_output=True, text=True, timeout=60, start_new_session=True)
    assert bad.returncode == 2
    assert "~wait_time" in bad.stdout + bad.stderr
