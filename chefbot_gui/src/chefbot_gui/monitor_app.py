"""Opening and closing the robot monitor: one window + one ROS bridge, for both entry points.

``rosrun chefbot_gui robot_monitor`` and the delivery window's *Robot monitor…*
button both use :class:`MonitorController`.  The bridge exists only while the
window is open and rospy is initialised, so closing the monitor drops every
subscription it made.
"""
from __future__ import annotations

from collections.abc import Callable

from PyQt5.QtCore import QObject, pyqtSignal

from chefbot_gui.monitor_window import RobotMonitorWindow


class MonitorController(QObject):
    """Owns the monitor window and its bridge.

    ``make_bridge``: builds a bridge (``start``/``shutdown`` and the window's
    ``MonitorPort``), called only after :meth:`ros_ready`; default: a
    ``MonitorBridge`` with default params (imported then, so this module loads
    without rospy).  ``closed`` is emitted when the user closes the window.
    """

    closed = pyqtSignal()

    def __init__(self, make_bridge: Callable[[], object] | None = None, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._make_bridge = make_bridge
        self._ros = False
        self.window: RobotMonitorWindow | None = None
        self.bridge: object | None = None

    def open(self) -> RobotMonitorWindow:
        """Show the monitor (create it if needed) and bring it to the front."""
        if self.window is None:
            self.window = RobotMonitorWindow()
            self.window.closed.connect(self._on_closed)
            if self._ros:
                self._attach()
        self.window.show()
        self.window.raise_()
        self.window.activateWindow()
        return self.window

    def ros_ready(self) -> None:
        """rospy is initialised: an open window starts collecting now."""
        self._ros = True
        if self.window is not None and self.bridge is None:
            self._attach()

    def on_master(self, uri: str, reachable: bool) -> None:
        """Forward the master probe's state to an open window."""
        if self.window is not None:
            self.window.on_master(uri, reachable)

    def _attach(self) -> None:
        if self._make_bridge is None:
            from chefbot_gui.ros_monitor import MonitorBridge  # rospy: only once ROS is up
            self._make_bridge = MonitorBridge
        self.bridge = self._make_bridge()
        self.bridge.start()
        self.window.attach(self.bridge)

    def _on_closed(self) -> None:
        self.shutdown()
        self.closed.emit()

    def shutdown(self) -> None:
        """Close the window (if open) and drop the bridge's subscriptions."""
        window, self.window = self.window, None
        if window is not None:
            window.stop()
            window.closed.disconnect(self._on_closed)
            window.close()
            window.deleteLater()
        if self.bridge is not None:
            self.bridge.shutdown()
            self.bridge = None
