"""The GUI without a ROS master: the window opens, says so, and joins ROS once a master appears.

No session roscore here: every test brings its own master URI on a free loopback port.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import PKG, TABLES, _free_port

from chefbot_common.tables import load_tables
from chefbot_gui.app import MasterWatcher, OfflineRobot, command_line_params, master_reachable
from chefbot_gui.presenter import DeliveryPresenter
from chefbot_gui.window import RobotGuiWindow

sys.path.insert(0, str(PKG.parent / "tools"))
import procs  # the workspace's process-group helpers

HANG_GUARD_S = 90.0  # only against hangs; nothing here is timed


def _free_uri() -> str:
    return f"http://127.0.0.1:{_free_port()}"


def test_master_probe_on_a_free_port_is_false() -> None:
    assert not master_reachable(_free_uri(), timeout_s=0.5)
    assert not master_reachable("not a uri", timeout_s=0.5)


def test_command_line_params_are_yaml_typed_private_only() -> None:
    get = command_line_params(["robot_gui", "_tables_file:=/x.yaml", "_wait_time:=5", "__ns:=/a", "foo:=bar"])
    assert get("~tables_file", None) == "/x.yaml"
    assert get("~wait_time", None) == 5
    assert get("~ns", "missing") == "missing"
    assert get("foo", "missing") == "missing"


def test_window_without_master_disables_every_robot_button(qtbot) -> None:
    uri = _free_uri()
    presenter = DeliveryPresenter(load_tables(TABLES), OfflineRobot(), time.monotonic, connect_timeout_s=0.1)
    window = RobotGuiWindow(presenter)
    qtbot.addWidget(window)
    watcher = MasterWatcher(uri, period_s=0.2, timeout_s=0.2)
    watcher.changed.connect(window.on_master)
    try:
        with qtbot.waitSignal(watcher.changed, timeout=int(HANG_GUARD_S * 1000)) as sig:
            watcher.start()
        assert sig.args == [uri, False]
    finally:
        watcher.stop()
    presenter.select("table_3")
    presenter.tick()
    assert window.statusLabel.text() == f"no ROS master at {uri} — retrying"
    for b in (window.goButton, window.homeButton, window.cancelButton):
        assert not b.isEnabled(), b.objectName()


def _rosrun_gui(uri: str, ns: str, *extra: str) -> list[str]:
    return ["rosrun", "chefbot_gui", "robot_gui", f"__ns:={ns}", f"_tables_file:={TABLES}", *extra]


def test_node_screenshot_without_master(tmp_path: Path) -> None:
    """The issue's command: it used to block in init_node (or die with ConnectionRefusedError)."""
    uri = _free_uri()
    png = tmp_path / "shot.png"
    env = dict(os.environ, ROS_MASTER_URI=uri, QT_QPA_PLATFORM="offscreen")
    r = subprocess.run(_rosrun_gui(uri, "/nm", "--screenshot", str(png), "--screenshot-delay", "0.5"),
                       env=env, capture_output=True, text=True, timeout=HANG_GUARD_S, start_new_session=True)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert f"no ROS master at {uri} — retrying" in out
    assert "Traceback" not in out and "ConnectionRefused" not in out
    assert png.stat().st_size > 5000


def test_node_bad_tables_file_without_master_names_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "latin1_tables.yaml"
    bad.write_bytes(b"poses:\n  home: {x: 0, y: 0}\n  caf\xe9: {x: 1, y: 1}\n")
    env = dict(os.environ, ROS_MASTER_URI=_free_uri(), QT_QPA_PLATFORM="offscreen")
    r = subprocess.run(["rosrun", "chefbot_gui", "robot_gui", f"_tables_file:={bad}"], env=env,
                       capture_output=True, text=True, timeout=HANG_GUARD_S, start_new_session=True)
    assert r.returncode == 2
    assert str(bad) in r.stderr and "UTF-8" in r.stderr


def _wait(cond, what: str, proc: procs.ProcessGroup | None = None) -> None:
    deadline = time.monotonic() + HANG_GUARD_S
    while not cond():
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"{what}: the process exited with {proc.poll()}")
        if time.monotonic() > deadline:
            pytest.fail(f"{what}: not within {HANG_GUARD_S} s")
        time.sleep(0.1)


def test_node_joins_ros_when_the_master_appears_later(tmp_path: Path) -> None:
    import rosgraph

    port = procs.free_port()
    uri = f"http://127.0.0.1:{port}"
    env = dict(os.environ, ROS_MASTER_URI=uri, QT_QPA_PLATFORM="offscreen")
    ns = f"/late_{os.getpid()}"
    log = tmp_path / "gui.log"
    with procs.ProcessGroup(_rosrun_gui(uri, ns, "_server_timeout:=0.5"), env=env, log=log) as gui:
        _wait(lambda: "no ROS master" in log.read_text(), "GUI says there is no master", gui)
        with procs.ProcessGroup(["roscore", "-p", str(port)], env=env, log=tmp_path / "roscore.log"):
            master = rosgraph.Master("/chefbot_gui_late_probe", master_uri=uri)

            def registered() -> bool:
                try:
                    return bool(master.lookupNode(f"{ns}/robot_gui"))
                except (rosgraph.MasterError, OSError):
                    return False
            _wait(registered, "the GUI registers with the late master", gui)
            # the command-line params were uploaded by init_node once the master answered
            assert master.getParam(f"{ns}/robot_gui/tables_file") == str(TABLES)
            assert gui.poll() is None


def test_monitor_screenshot_without_master(tmp_path: Path) -> None:
    """``rosrun chefbot_gui robot_monitor`` with no master: the window opens, says so, exits 0."""
    uri = _free_uri()
    png = tmp_path / "monitor.png"
    env = dict(os.environ, ROS_MASTER_URI=uri, QT_QPA_PLATFORM="offscreen")
    r = subprocess.run(["rosrun", "chefbot_gui", "robot_monitor", "--screenshot", str(png),
                        "--screenshot-delay", "1.5"],
                       env=env, capture_output=True, text=True, timeout=HANG_GUARD_S, start_new_session=True)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert f"no ROS master at {uri} — retrying" in out
    assert "Traceback" not in out
    assert png.stat().st_size > 5000
