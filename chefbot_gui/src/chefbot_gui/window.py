"""The delivery window: loads ``ui/robot_gui.ui`` and renders the presenter's state.

Qt only (no rospy).  Widget signals call presenter actions; the presenter's
:class:`~chefbot_gui.presenter.ViewState` is rendered in :meth:`render`.  The
``on_*`` slots receive the ROS bridge's signals (queued into the GUI thread)
and forward them to the presenter, so ROS never touches a widget.
"""
from __future__ import annotations

import math
from pathlib import Path

from PyQt5 import uic
from PyQt5.QtCore import Qt, QTimer, pyqtSignal, pyqtSlot
from PyQt5.QtWidgets import QListView, QListWidgetItem, QWidget

from chefbot_common.grid import GridInfo
from chefbot_gui.map_view import Marker
from chefbot_gui.presenter import DeliveryPresenter, OrderMode, Outcome, Phase, Pose, ViewState, fmt_eta, fmt_metres

TICK_MS = 200  # presenter clock: wait countdown, connection time-out, stale diagnostics
STATUS_COLOURS = {  # status-line backgrounds by tone (the fleet window uses them too)
    "bad": "#ffcdd2",
    "busy": "#bbdefb",
    "good": "#c8e6c9",
    "wait": "#fff9c4",
    "neutral": "#e8e8e8",
}


def ui_path(name: str = "robot_gui.ui") -> Path:
    """The Designer file ``name``: the source tree's ``ui/`` (devel space) or the installed share dir."""
    here = Path(__file__).resolve()
    source = here.parents[2] / "ui" / name
    if source.exists():
        return source
    try:
        import rospkg  # only to find the installed share directory
        return Path(rospkg.RosPack().get_path("chefbot_gui")) / "ui" / name
    except Exception as e:  # rospkg raises several types; all mean "not found"
        raise FileNotFoundError(f"{name} not found next to {here} nor via rospkg: {e}") from e


class RobotGuiWindow(QWidget):
    """The staff window.  Stable objectNames: ``tableList``, ``goButton``, ``homeButton``,
    ``cancelButton``, ``batteryBar``, ``statusLabel``, ``mapView``, ``queueList``,
    ``servedButton``, ``removeButton``, ``orderCombo``, ``waitSpinBox``, ``hintLabel``,
    ``healthLabel``, ``routeProgress``, ``monitorButton``.

    ``monitorRequested`` is emitted by the *Robot monitor…* button; the node script
    opens the monitor (``chefbot_gui.monitor_app``), so this window needs no ROS.
    """

    monitorRequested = pyqtSignal()

    def __init__(self, presenter: DeliveryPresenter, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        uic.loadUi(str(ui_path()), self)
        self.presenter = presenter
        self.state: ViewState | None = None
        self._rendering = False
        self._queue_offset = 0  # rows of queueList above the pending entries (the running delivery)
        # the .ui sets the label's look; render() only swaps the background colour
        self._status_style = self.statusLabel.styleSheet().split("background")[0].strip()

        self.tableList.setFlow(QListView.LeftToRight)
        self.tableList.setWrapping(True)
        # with keyboard focus at start-up Qt would highlight Table 1 as "current",
        # which staff read as selected; the list takes focus when clicked
        self.tableList.setFocusPolicy(Qt.ClickFocus)
        for dest in presenter.tables:
            item = QListWidgetItem(dest.label)
            item.setData(Qt.UserRole, dest.key)
            item.setTextAlignment(Qt.AlignCenter)
            self.tableList.addItem(item)
        self.mapView.set_markers(
            Marker("home", "Home", presenter.home.pose.x, presenter.home.pose.y, presenter.home.pose.yaw),
            [Marker(d.key, d.label, d.pose.x, d.pose.y, d.pose.yaw) for d in presenter.tables])
        self.orderCombo.setCurrentIndex(0 if presenter.order_mode == OrderMode.FIFO else 1)
        self.waitSpinBox.setValue(round(presenter.wait_time_s))

        # selection, not "current item": Qt makes the first item current on focus,
        # which must not pick a table behind the staff's back
        self.tableList.itemSelectionChanged.connect(self._table_changed)
        self.mapView.tableClicked.connect(self._map_clicked)
        self.goButton.clicked.connect(presenter.go)
        self.homeButton.clicked.connect(presenter.home_now)
        self.cancelButton.clicked.connect(presenter.cancel)
        self.servedButton.clicked.connect(presenter.served)
        self.removeButton.clicked.connect(self._remove_clicked)
        self.orderCombo.currentIndexChanged.connect(self._order_changed)
        self.waitSpinBox.valueChanged.connect(lambda v: presenter.set_wait_time(float(v)))
        self.queueList.itemSelectionChanged.connect(self._queue_selection_changed)
        self.monitorButton.clicked.connect(self.monitorRequested)

        self._timer = QTimer(self)
        self._timer.timeout.connect(presenter.tick)
        self._timer.start(TICK_MS)
        presenter.subscribe(self.render)

    # ------------------------------------------------------------------ widgets → presenter
    def _table_changed(self) -> None:
        if not self._rendering:
            items = self.tableList.selectedItems()
            self.presenter.select(items[0].data(Qt.UserRole) if items else None)

    def _map_clicked(self, key: str) -> None:
        self.presenter.select(key)

    def _remove_clicked(self) -> None:
        row = self.queueList.currentRow() - self._queue_offset
        # nothing (or the running delivery) selected: remove the last queued table
        self.presenter.remove(row if row >= 0 else self.queueList.count() - 1 - self._queue_offset)

    def _order_changed(self, index: int) -> None:
        self.presenter.set_order_mode(OrderMode.FIFO if index == 0 else OrderMode.NEAREST)

    def _queue_selection_changed(self) -> None:
        if self.state is not None:
            self.removeButton.setEnabled(self.state.remove_enabled)

    # ------------------------------------------------------------------ ROS bridge → presenter
    @pyqtSlot(str, bool)
    def on_master(self, uri: str, reachable: bool) -> None:
        """Slot: the ROS master at ``uri`` became reachable or not."""
        self.presenter.on_master(uri, reachable)

    @pyqtSlot(bool)
    def on_server(self, connected: bool) -> None:
        """Slot: the move_base action server connected or went away."""
        self.presenter.on_server(connected)

    @pyqtSlot(int, str, str)
    def on_goal_done(self, goal_id: int, outcome: str, text: str) -> None:
        """Slot: a goal ended with ``outcome`` and move_base's text."""
        self.presenter.on_goal_done(goal_id, Outcome(outcome), text)

    @pyqtSlot(float, float, float)
    def on_robot_pose(self, x: float, y: float, yaw: float) -> None:
        """Slot: the robot's pose in the map frame (m, rad)."""
        self.presenter.on_robot_pose(Pose(x, y, yaw))

    @pyqtSlot(object)
    def on_plan(self, points: list) -> None:
        """Slot: a new global plan (map-frame points, m)."""
        self.presenter.on_plan(points)

    @pyqtSlot(object, object)
    def on_map(self, grey: bytes, grid: GridInfo) -> None:
        """Slot: a new map image and its grid geometry."""
        self.mapView.set_map(grey, grid)

    @pyqtSlot(float, float, bool)
    def on_battery(self, percentage: float, voltage: float, present: bool) -> None:
        """Slot: the battery state (fraction 0..1, V, present)."""
        self.presenter.on_battery(percentage, voltage, present)

    @pyqtSlot(str, int, str)
    def on_diagnostic(self, name: str, level: int, message: str) -> None:
        """Slot: one diagnostic status (name, level, message)."""
        self.presenter.on_diagnostic(name, level, message)

    # ------------------------------------------------------------------ presenter → widgets
    def render(self, st: ViewState) -> None:
        """Show a presenter snapshot (called in the GUI thread only)."""
        self.state = st
        self._rendering = True
        try:
            self.statusLabel.setText(st.status)
            self.statusLabel.setStyleSheet(f"{self._status_style} background: {STATUS_COLOURS[self._tone(st)]};")
            self.hintLabel.setText(st.hint)
            self.goButton.setEnabled(st.go_enabled)
            self.homeButton.setEnabled(st.home_enabled)
            self.cancelButton.setEnabled(st.cancel_enabled)
            self.servedButton.setEnabled(st.served_enabled)
            self.removeButton.setEnabled(st.remove_enabled)

            self._render_selection(st.selected)
            self._render_queue(st)

            if st.progress is not None:
                self.routeProgress.setValue(round(st.progress * 100))
                self.routeProgress.setFormat(f"{fmt_metres(st.remaining_m)} m to go" + (
                    f", {fmt_eta(st.eta_s)}" if st.eta_s is not None and math.isfinite(st.eta_s) else ""))
            else:
                self.routeProgress.setValue(0)
                self.routeProgress.setFormat("no route")
            self.batteryBar.setValue(st.battery_percent if st.battery_percent is not None else 0)
            self.batteryBar.setFormat(st.battery_text)
            self.batteryBar.setStyleSheet("QProgressBar::chunk { background: %s; }"
                                          % ("#c62828" if st.battery_low else "#43a047"))
            self.healthLabel.setText(st.health_text)
            self.healthLabel.setStyleSheet("color: #b71c1c;" if (st.health_level or 0) >= 2 else "")

            pose = st.robot_pose
            self.mapView.set_robot((pose.x, pose.y, pose.yaw) if pose else None)
            self.mapView.set_route(st.plan, st.selected, st.current, st.queue)
        finally:
            self._rendering = False

    @staticmethod
    def _tone(st: ViewState) -> str:
        if not st.connected or st.phase == Phase.FAILED:
            return "bad" if st.connected is not None else "neutral"
        if st.phase in (Phase.DRIVING, Phase.CANCELLING):
            return "busy"
        if st.phase == Phase.WAITING:
            return "wait"
        return "good"

    def table_item(self, key: str):
        """The table list's row of destination ``key`` (a QListWidgetItem), or None."""
        for i in range(self.tableList.count()):
            item = self.tableList.item(i)
            if item.data(Qt.UserRole) == key:
                return item
        return None

    def _render_selection(self, key: str | None) -> None:
        for i in range(self.tableList.count()):
            item = self.tableList.item(i)
            want = item.data(Qt.UserRole) == key
            if item.isSelected() != want:
                item.setSelected(want)
            if want:
                self.tableList.scrollToItem(item)

    def _render_queue(self, st: ViewState) -> None:
        labels = list(st.queue_labels)
        shown = [self.queueList.item(i).text() for i in range(self.queueList.count())]
        wanted = [f"{i + 1}. {label}" for i, label in enumerate(labels)]
        if st.current and st.current != "home" and st.phase in (Phase.DRIVING, Phase.WAITING):
            doing = "now: " + self.presenter.destination(st.current).label
            wanted_all = [doing, *wanted]
        else:
            wanted_all = wanted
        if shown == wanted_all:
            return
        self._queue_offset = len(wanted_all) - len(wanted)
        row = self.queueList.currentRow()
        self.queueList.clear()
        offset = self._queue_offset = len(wanted_all) - len(wanted)
        for i, text in enumerate(wanted_all):
            item = QListWidgetItem(text)
            if i < offset:
                item.setFlags(Qt.ItemIsEnabled)  # the running delivery cannot be removed here
            self.queueList.addItem(item)
        if 0 <= row < self.queueList.count():
            self.queueList.setCurrentRow(row)
