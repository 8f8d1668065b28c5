"""Glue between the ROS bridge, the presenter and the window; parameters; screenshots.

No rospy here (the master probe speaks XML-RPC itself, so the window can run
before ``rospy.init_node``, which blocks until a master answers): the node
script reads the ROS parameters with the workspace's shared reader
(``chefbot_common.params.read_config``, which checks types and names the
parameter in its errors) into :class:`GuiParams`, whose own checks cover the values.
"""
from __future__ import annotations

import http.client
import math
import signal
import sys
import threading
import xmlrpc.client
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml
from PyQt5.QtCore import QMetaObject, QObject, Qt, QTimer, pyqtSignal
from PyQt5.QtWidgets import QApplication, QWidget

from chefbot_gui.presenter import Destination, OrderMode

ORDER_NAMES = {"in_order": OrderMode.FIFO, "nearest_first": OrderMode.NEAREST}


@dataclass(frozen=True)
class GuiParams:
    """The node's private parameters (defaults in ``param/robot_gui.yaml``).

    ``tables_file``: the shared delivery-pose YAML; ``action``: move_base action
    name; ``map_frame``/``base_frame``: tf frames of the robot pose;
    ``plan_topic``: ``nav_msgs/Path`` global plan; ``server_timeout``: s of
    "connecting…" before "robot not connected"; ``wait_time``: s at a table
    before moving on (0 = until Served); ``nominal_speed``: m/s for the ETA;
    ``order``: ``in_order`` or ``nearest_first``.
    """

    tables_file: str = ""
    action: str = "move_base"
    map_frame: str = "map"
    base_frame: str = "base_footprint"
    plan_topic: str = "move_base/global_plan"
    server_timeout: float = 5.0
    wait_time: float = 30.0
    nominal_speed: float = 0.3
    order: str = "in_order"

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type == "float" and not math.isfinite(v):
                raise ValueError(f"{f.name} must be a finite number, got {v!r}")
            if f.type == "str" and f.name != "tables_file" and not v.strip():
                raise ValueError(f"{f.name} must be a non-empty string, got {v!r}")
        if self.server_timeout <= 0:
            raise ValueError(f"server_timeout must be > 0 s, got {self.server_timeout}")
        if self.wait_time < 0:
            raise ValueError(f"wait_time must be >= 0 s, got {self.wait_time}")
        if self.nominal_speed <= 0:
            raise ValueError(f"nominal_speed must be > 0 m/s, got {self.nominal_speed}")
        if self.order not in ORDER_NAMES:
            raise ValueError(f"order must be one of {sorted(ORDER_NAMES)}, got {self.order!r}")

    @classmethod
    def param_names(cls) -> dict[str, str]:
        """Field → private ROS parameter, for ``chefbot_common.params.read_config``."""
        return {f.name: "~" + f.name for f in fields(cls)}

    @property
    def order_mode(self) -> OrderMode:
        """The delivery order mode named by the ``order`` param."""
        return ORDER_NAMES[self.order]


def wire(bridge: QObject, window: QObject) -> None:
    """Connect the bridge's signals to the window's slots, queued into the GUI thread.

    Explicitly queued: the bridge emits from rospy threads, and a queued
    connection is what guarantees the slot runs in the window's (GUI) thread.
    """
    q = Qt.QueuedConnection
    bridge.serverConnected.connect(window.on_server, q)
    bridge.goalDone.connect(window.on_goal_done, q)
    bridge.robotPose.connect(window.on_robot_pose, q)
    bridge.planReceived.connect(window.on_plan, q)
    bridge.mapReceived.connect(window.on_map, q)
    bridge.batteryReceived.connect(window.on_battery, q)
    bridge.diagnosticReceived.connect(window.on_diagnostic, q)


def save_screenshot(widget: QWidget, path: str | Path) -> bool:
    """Render ``widget`` to a PNG (works with ``QT_QPA_PLATFORM=offscreen``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return widget.grab().save(str(path), "PNG")


def schedule_screenshot(widget: QWidget, path: str | Path, delay_s: float,
                        done: Callable[[bool], None]) -> QTimer:
    """Save a screenshot ``delay_s`` seconds from now, then call ``done(saved_ok)``."""
    timer = QTimer(widget)
    timer.setSingleShot(True)
    timer.timeout.connect(lambda: done(save_screenshot(widget, path)))
    timer.start(max(0, round(delay_s * 1000)))
    return timer


def quit_later(app: QApplication) -> Callable[..., None]:
    """A callable that makes ``app`` quit from any thread or signal handler (queued into the GUI thread)."""
    return lambda *_args: QMetaObject.invokeMethod(app, "quit", Qt.QueuedConnection)


def run_event_loop(app: QApplication, window: QWidget, prog: str, screenshot: str | None,
                   screenshot_delay_s: float) -> int:
    """Run Qt's loop until quit; SIGINT/SIGTERM quit it; with ``screenshot`` (a PNG path) save
    the window ``screenshot_delay_s`` seconds after start and quit.  Returns the exit code
    (1 if the screenshot failed)."""
    signal.signal(signal.SIGINT, quit_later(app))
    signal.signal(signal.SIGTERM, quit_later(app))
    # Python runs signal handlers only between bytecodes: give it some while Qt sleeps
    wake = QTimer()
    wake.timeout.connect(lambda: None)
    wake.start(200)
    rc = 0
    if screenshot:
        def done(ok: bool) -> None:
            nonlocal rc
            rc = 0 if ok else 1
            print(f"{prog}: screenshot {'saved to' if ok else 'FAILED:'} {screenshot}",
                  file=sys.stdout if ok else sys.stderr)
            app.quit()
        schedule_screenshot(window, screenshot, screenshot_delay_s, done)
    app.exec_()
    wake.stop()
    return rc


def command_line_params(argv: Sequence[str]) -> Callable[[str, Any], Any]:
    """A ``get(name, default)`` over the ``_name:=value`` arguments (YAML-typed, like rospy).

    Used before a ROS master is reachable: then the private parameters can only
    come from the command line (``rosrun chefbot_gui robot_gui _tables_file:=…``).
    """
    params: dict[str, Any] = {}
    for arg in argv:
        src, sep, value = arg.partition(":=")
        if sep and src.startswith("_") and not src.startswith("__") and len(src) > 1:
            try:
                params["~" + src[1:]] = yaml.safe_load(value)
            except yaml.YAMLError as e:
                raise ValueError(f"command-line parameter {src}: invalid value {value!r}: {e}") from e
    return lambda name, default: params.get(name, default)


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout_s: float) -> None:
        super().__init__()
        self._timeout_s = timeout_s

    def make_connection(self, host: Any) -> http.client.HTTPConnection:
        conn = super().make_connection(host)
        conn.timeout = self._timeout_s
        return conn


def master_proxy(uri: str, timeout_s: float) -> xmlrpc.client.ServerProxy:
    """An XML-RPC proxy of the ROS master at ``uri`` whose calls give up after ``timeout_s`` seconds."""
    return xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout_s))


def master_reachable(uri: str, timeout_s: float = 0.5) -> bool:
    """Does a ROS master answer ``getPid`` at ``uri`` within ``timeout_s`` seconds?"""
    try:
        code, _msg, _pid = master_proxy(uri, timeout_s).getPid("/robot_gui")
    except (OSError, xmlrpc.client.Error, ValueError, TypeError):
        return False
    return code == 1


class MasterWatcher(QObject):
    """Probes the ROS master from a thread; ``changed(uri, reachable)`` on every change.

    The first report comes after the first probe.  ``period_s``: time between
    probes (s); ``timeout_s``: how long one probe may take (s).
    """

    changed = pyqtSignal(str, bool)

    def __init__(self, uri: str, period_s: float = 1.0, timeout_s: float = 0.5,
                 parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.uri = uri
        self._period_s = period_s
        self._timeout_s = timeout_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="chefbot_gui_master", daemon=True)

    def start(self) -> None:
        """Start watching the ROS master in the background thread."""
        self._thread.start()

    def stop(self) -> None:
        """Stop watching and wait for the thread to end."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=self._period_s + self._timeout_s + 1.0)

    def _run(self) -> None:
        last: bool | None = None
        while not self._stop.is_set():
            ok = master_reachable(self.uri, self._timeout_s)
            if ok != last and not self._stop.is_set():
                last = ok
                self.changed.emit(self.uri, ok)
            self._stop.wait(self._period_s)


class OfflineRobot:
    """The presenter's robot until the ROS bridge exists: goals go nowhere (buttons are disabled)."""

    def send_goal(self, goal_id: int, dest: Destination) -> None:
        """Nothing to send to without a ROS master."""

    def cancel_goal(self) -> None:
        """Nothing to cancel without a ROS master."""
