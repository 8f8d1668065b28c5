"""The robot monitor window (the book's ch. 9 rqt_gui with Console, Topic Monitor and Image View).

Qt only (no rospy).  The window pulls from a :class:`MonitorPort` (the ROS
bridge, or a test double) on a ``QTimer`` in the GUI thread: ROS threads only
fill thread-safe buffers, so a log flood or a large image never blocks or
floods Qt's event loop.  The logic lives in the pure modules ``log_buffer``,
``topic_stats``, ``msg_tree`` and ``image_convert``; this module only draws.

Stable objectNames: ``consoleDock``, ``logTable``, ``sevDebug`` … ``sevFatal``,
``nodeFilter``, ``textFilter``, ``pauseButton``, ``clearButton``,
``consoleStatus``; ``topicTree``, ``topicStatus``; ``imageDock``,
``imageTopicCombo``, ``imageLabel``, ``imageStatus``.
"""
from __future__ import annotations

from typing import Any, Protocol

from PyQt5.QtCore import QAbstractTableModel, QModelIndex, Qt, QTimer, pyqtSignal, pyqtSlot
from PyQt5.QtGui import QBrush, QColor, QImage, QPixmap
from PyQt5.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QDockWidget,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QMainWindow,
    QPushButton,
    QSizePolicy,
    QTableView,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from chefbot_gui.image_convert import IMAGE_TYPE, ImageFrame
from chefbot_gui.log_buffer import (
    DEFAULT_CAPACITY,
    ERROR,
    FATAL,
    SEVERITY_NAMES,
    WARN,
    LogBuffer,
    LogEntry,
    LogFilter,
    ViewChange,
    fmt_stamp,
    severity_name,
)
from chefbot_gui.msg_tree import DecodeError, TreeNode, message_tree
from chefbot_gui.topic_stats import Stats, TopicList, fmt_bandwidth, fmt_rate

TICK_MS = 250          # logs and image pulled at 4 Hz
TOPIC_EVERY_TICKS = 2  # topic rates and trees at 2 Hz (rqt_topic: 1 Hz)
_SEVERITY_COLOURS = {WARN: "#fff3c4", ERROR: "#ffcdd2", FATAL: "#ef9a9a"}


class MonitorPort(Protocol):
    """What the window needs from ROS (implemented by ``ros_monitor.MonitorBridge``)."""

    def drain_logs(self, limit: int = ...) -> list[LogEntry]:
        """Log entries received since the last call, oldest first."""

    def topics(self) -> tuple[int, list[tuple[str, str]] | None, str]:
        """(serial, the master's ``(name, type)`` list or None, error text or '')."""

    def subscribe(self, name: str) -> None:
        """Start measuring ``name``."""

    def unsubscribe(self, name: str) -> None:
        """Stop measuring ``name``."""

    def stats(self, name: str) -> Stats:
        """Rate and bandwidth of ``name`` now."""

    def last_message(self, name: str, listed_type: str) -> tuple[int, object | None]:
        """(serial, last decoded message or None); raises ``DecodeError`` saying why not."""

    def set_image_topic(self, name: str | None) -> None:
        """Show ``name`` in the image view (None: nothing)."""

    def latest_image(self) -> ImageFrame:
        """The image view's latest frame or error."""


# ---------------------------------------------------------------------- Console
class LogTableModel(QAbstractTableModel):
    """The rows the Console shows: a copy of the buffer's view, changed by row inserts/removals."""

    COLUMNS = ("Time", "Severity", "Node", "Message", "Location")

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._rows: list[LogEntry] = []

    def rowCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: B008 - Qt's signature
        """Rows shown (Qt model API)."""
        return 0 if parent.isValid() else len(self._rows)

    def columnCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: B008 - Qt's signature
        """Time, Severity, Node, Message, Location (Qt model API)."""
        return 0 if parent.isValid() else len(self.COLUMNS)

    def headerData(self, section: int, orientation: Qt.Orientation, role: int = Qt.DisplayRole) -> Any:
        """Column titles (Qt model API)."""
        if role == Qt.DisplayRole and orientation == Qt.Horizontal:
            return self.COLUMNS[section]
        return None

    def data(self, index: QModelIndex, role: int = Qt.DisplayRole) -> Any:
        """Cell text, tooltip and severity colour (Qt model API)."""
        if not index.isValid():
            return None
        e = self._rows[index.row()]
        if role in (Qt.DisplayRole, Qt.ToolTipRole):
            return (fmt_stamp(e.stamp), severity_name(e.level), e.node, e.message, e.location)[index.column()]
        if role == Qt.BackgroundRole and e.level in _SEVERITY_COLOURS:
            return QBrush(QColor(_SEVERITY_COLOURS[e.level]))
        return None

    def entry(self, row: int) -> LogEntry:
        """The entry shown in ``row``."""
        return self._rows[row]

    def apply(self, change: ViewChange, view: Any) -> None:
        """Follow the buffer's view (``view``: its entries, oldest first)."""
        if change.reset:
            self.beginResetModel()
            self._rows = list(view)
            self.endResetModel()
            return
        if change.removed:
            self.beginRemoveRows(QModelIndex(), 0, change.removed - 1)
            del self._rows[:change.removed]
            self.endRemoveRows()
        if change.added:
            n = len(self._rows)
            self.beginInsertRows(QModelIndex(), n, n + change.added - 1)
            self._rows.extend(list(view)[-change.added:])
            self.endInsertRows()


class ConsoleWidget(QWidget):
    """``/rosout_agg`` as a table with severity/node/text filters, pause and clear."""

    def __init__(self, capacity: int = DEFAULT_CAPACITY, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.buffer = LogBuffer(capacity=capacity)
        self.model = LogTableModel(self)
        bar = QHBoxLayout()
        self.severity_boxes: dict[int, QCheckBox] = {}
        for level, name in SEVERITY_NAMES.items():
            box = QCheckBox(name, self)
            box.setObjectName(f"sev{name}")
            box.setChecked(True)
            box.toggled.connect(self._filter_changed)
            self.severity_boxes[level] = box
            bar.addWidget(box)
        self.nodeFilter = QLineEdit(self, objectName="nodeFilter", placeholderText="node contains…")
        self.textFilter = QLineEdit(self, objectName="textFilter", placeholderText="message contains…")
        for edit in (self.nodeFilter, self.textFilter):
            edit.setClearButtonEnabled(True)
            edit.textChanged.connect(self._filter_changed)
            bar.addWidget(edit)
        self.pauseButton = QPushButton("Pause", self, objectName="pauseButton", checkable=True)
        self.pauseButton.toggled.connect(self._pause_toggled)
        self.clearButton = QPushButton("Clear", self, objectName="clearButton")
        self.clearButton.clicked.connect(self.clear)
        bar.addWidget(self.pauseButton)
        bar.addWidget(self.clearButton)

        self.logTable = QTableView(self, objectName="logTable")
        self.logTable.setModel(self.model)
        self.logTable.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.logTable.setWordWrap(False)
        self.logTable.verticalHeader().setVisible(False)
        self.logTable.verticalHeader().setDefaultSectionSize(20)
        header = self.logTable.horizontalHeader()
        for col, width in enumerate((110, 70, 180, 0, 260)):
            if width:
                self.logTable.setColumnWidth(col, width)
        header.setSectionResizeMode(3, QHeaderView.Stretch)
        self.consoleStatus = QLabel(self, objectName="consoleStatus")
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addLayout(bar)
        lay.addWidget(self.logTable)
        lay.addWidget(self.consoleStatus)
        self._show_status()

    def add_entries(self, entries: list[LogEntry]) -> None:
        """Append new log lines (GUI thread); keeps the view at the bottom if it was there."""
        if not entries:
            return
        bar = self.logTable.verticalScrollBar()
        at_bottom = bar.value() >= bar.maximum() - 2
        self.model.apply(self.buffer.add(entries), self.buffer.view)
        if at_bottom and not self.buffer.paused:
            self.logTable.scrollToBottom()
        self._show_status()

    def clear(self) -> None:
        """Forget every line."""
        self.model.apply(self.buffer.clear(), self.buffer.view)
        self._show_status()

    def _filter_changed(self, *_args: object) -> None:
        f = LogFilter(severities=frozenset(lv for lv, b in self.severity_boxes.items() if b.isChecked()),
                      node=self.nodeFilter.text().strip(), text=self.textFilter.text().strip())
        self.model.apply(self.buffer.set_filter(f), self.buffer.view)
        self._show_status()

    def _pause_toggled(self, paused: bool) -> None:
        self.pauseButton.setText("Resume" if paused else "Pause")
        if paused:
            self.buffer.pause()
        else:
            self.model.apply(self.buffer.resume(), self.buffer.view)
            self.logTable.scrollToBottom()
        self._show_status()

    def _show_status(self) -> None:
        self.consoleStatus.setText(self.buffer.status())


# ---------------------------------------------------------------------- Topic Monitor
COL_TOPIC, COL_TYPE, COL_RATE, COL_BW, COL_VALUE = range(5)


def _set_text(item: QTreeWidgetItem, col: int, text: str) -> None:
    if item.text(col) != text:
        item.setText(col, text)


def sync_tree(parent: QTreeWidgetItem, nodes: tuple[TreeNode, ...]) -> None:
    """Make ``parent``'s children show ``nodes``, reusing items (expansion survives updates)."""
    for i, node in enumerate(nodes):
        item = parent.child(i) if i < parent.childCount() else QTreeWidgetItem(parent)
        _set_text(item, COL_TOPIC, node.name)
        _set_text(item, COL_TYPE, node.type)
        _set_text(item, COL_VALUE, node.value)
        sync_tree(item, node.children)
    while parent.childCount() > len(nodes):
        parent.takeChild(len(nodes))


class TopicMonitorWidget(QWidget):
    """Every topic on the master; ticked ones subscribed, with rate, bandwidth and the last value."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.port: MonitorPort | None = None
        self.topics = TopicList()
        self._serials: dict[str, int] = {}
        self._items: dict[str, QTreeWidgetItem] = {}
        self._updating = False
        self._tick_later: set[str] = set()
        self.topicTree = QTreeWidget(self, objectName="topicTree")
        self.topicTree.setHeaderLabels(["Topic", "Type", "Rate", "Bandwidth", "Value"])
        self.topicTree.setUniformRowHeights(True)
        for col, width in ((COL_TOPIC, 230), (COL_TYPE, 175), (COL_RATE, 75), (COL_BW, 95)):
            self.topicTree.setColumnWidth(col, width)
        self.topicTree.itemChanged.connect(self._item_changed)
        self.topicStatus = QLabel("no ROS master yet", self, objectName="topicStatus")
        self.topicStatus.setWordWrap(True)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(QLabel("<b>Topic Monitor</b> — tick a topic to measure it and see its last message", self))
        lay.addWidget(self.topicTree)
        lay.addWidget(self.topicStatus)

    def item(self, name: str) -> QTreeWidgetItem | None:
        """The top-level row of topic ``name``."""
        return self._items.get(name)

    def set_ticked(self, name: str, ticked: bool) -> None:
        """Tick or untick a topic as the user would."""
        self._items[name].setCheckState(COL_TOPIC, Qt.Checked if ticked else Qt.Unchecked)

    def tick_when_listed(self, names: list[str]) -> None:
        """Tick these topics as soon as the master lists them (``--topics`` at start-up)."""
        self._tick_later.update(names)

    def update_listing(self, listing: list[tuple[str, str]] | None, error: str) -> None:
        """Merge the master's topic list into the tree."""
        if listing is not None:
            for name in self.topics.update(listing):  # type changed: subscribe afresh
                if self.port is not None and self.topics.rows[name].ticked:
                    self.port.unsubscribe(name)
                    self.port.subscribe(name)
        self._updating = True
        try:
            for name in [n for n in self._items if n not in self.topics.rows]:
                self.topicTree.takeTopLevelItem(self.topicTree.indexOfTopLevelItem(self._items.pop(name)))
            for i, (name, row) in enumerate(self.topics.rows.items()):
                item = self._items.get(name)
                if item is None:
                    item = QTreeWidgetItem([name, row.type, "", "", ""])
                    item.setFlags(item.flags() | Qt.ItemIsUserCheckable)
                    item.setCheckState(COL_TOPIC, Qt.Unchecked)
                    item.setToolTip(COL_TOPIC, "tick to subscribe: rate, bandwidth and the last value")
                    self.topicTree.insertTopLevelItem(i, item)
                    self._items[name] = item
                _set_text(item, COL_TYPE, row.type)
                item.setForeground(COL_TOPIC, QBrush(QColor("#000" if row.published else "#888")))
        finally:
            self._updating = False
        for name in [n for n in self._tick_later if n in self._items and self.port is not None]:
            self._tick_later.discard(name)
            self.set_ticked(name, True)
        shown = len(self.topics.rows)
        self.topicStatus.setText(error or f"{shown} topics on the master, "
                                           f"{sum(r.ticked for r in self.topics.rows.values())} monitored")

    def refresh_values(self) -> None:
        """Rates, bandwidths and last values of the ticked topics."""
        if self.port is None:
            return
        self._updating = True
        try:
            for name, row in self.topics.rows.items():
                if not row.ticked:
                    continue
                item = self._items[name]
                st = self.port.stats(name)
                _set_text(item, COL_RATE, fmt_rate(st))
                _set_text(item, COL_BW, fmt_bandwidth(st.bandwidth_bps))
                self._refresh_value(name, row.type, row.published, st, item)
        finally:
            self._updating = False

    def _refresh_value(self, name: str, typ: str, published: bool, st: Stats, item: QTreeWidgetItem) -> None:
        gone = "" if published else "no longer published (kept while ticked; untick to drop)"
        msg = None
        try:
            serial, msg = self.port.last_message(name, typ)
            status = gone or ("no message yet" if msg is None else f"{st.total} received")
        except DecodeError as e:
            status = f"{gone}; {e}" if gone else str(e)
        _set_text(item, COL_VALUE, status)
        item.setToolTip(COL_VALUE, status)
        if msg is not None and self._serials.get(name) != serial:
            self._serials[name] = serial
            sync_tree(item, message_tree(msg, typ=typ).children)

    def _item_changed(self, item: QTreeWidgetItem, column: int) -> None:
        if self._updating or column != COL_TOPIC or item.parent() is not None or self.port is None:
            return
        name = item.text(COL_TOPIC)
        if name not in self.topics.rows:
            return
        ticked = item.checkState(COL_TOPIC) == Qt.Checked
        if self.topics.rows[name].ticked == ticked:
            return
        row = self.topics.set_ticked(name, ticked)
        if ticked:
            self.port.subscribe(name)
            _set_text(item, COL_VALUE, "subscribing…")
            item.setExpanded(True)
            return
        self.port.unsubscribe(name)
        self._serials.pop(name, None)
        self._updating = True
        try:
            for col in (COL_RATE, COL_BW, COL_VALUE):
                item.setText(col, "")
            item.takeChildren()
            if row.name not in self.topics.rows:  # unticked after it disappeared: drop the row
                self.topicTree.takeTopLevelItem(self.topicTree.indexOfTopLevelItem(self._items.pop(name)))
        finally:
            self._updating = False


# ---------------------------------------------------------------------- Image View
NO_IMAGE_TOPIC = "(no image topic)"


class ImageViewWidget(QWidget):
    """Any ``sensor_msgs/Image`` topic, scaled to the widget with its aspect ratio."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.port: MonitorPort | None = None
        self._serial = -1
        self._pixmap: QPixmap | None = None
        self.image: QImage | None = None  # the last image shown, full size
        self.imageTopicCombo = QComboBox(self, objectName="imageTopicCombo")
        self.imageTopicCombo.addItem(NO_IMAGE_TOPIC)
        self.imageTopicCombo.currentTextChanged.connect(self._topic_chosen)
        self.imageLabel = QLabel(self, objectName="imageLabel", alignment=Qt.AlignCenter)
        self.imageLabel.setMinimumSize(160, 120)
        self.imageLabel.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Ignored)
        self.imageLabel.setStyleSheet("background: #202020; color: #ddd;")
        self.imageStatus = QLabel("no image topic selected", self, objectName="imageStatus")
        self.imageStatus.setWordWrap(True)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(self.imageTopicCombo)
        lay.addWidget(self.imageLabel, 1)
        lay.addWidget(self.imageStatus)

    def update_topics(self, topics: list[str]) -> None:
        """Offer these image topics; the chosen one stays even if it disappears (marked)."""
        current = self.imageTopicCombo.currentText()
        wanted = [NO_IMAGE_TOPIC, *topics]
        if current not in wanted:
            wanted.append(current)
        have = [self.imageTopicCombo.itemText(i) for i in range(self.imageTopicCombo.count())]
        if have != wanted:
            self.imageTopicCombo.blockSignals(True)
            self.imageTopicCombo.clear()
            self.imageTopicCombo.addItems(wanted)
            self.imageTopicCombo.setCurrentText(current)
            self.imageTopicCombo.blockSignals(False)

    def choose(self, topic: str | None) -> None:
        """Show ``topic`` (None: nothing), as if picked in the combo box."""
        topic = topic or NO_IMAGE_TOPIC
        if self.imageTopicCombo.findText(topic) < 0:
            self.imageTopicCombo.addItem(topic)
        self.imageTopicCombo.setCurrentText(topic)

    def _topic_chosen(self, text: str) -> None:
        self._pixmap = self.image = None
        self.imageLabel.clear()
        if self.port is not None:
            self.port.set_image_topic(None if text == NO_IMAGE_TOPIC else text)

    def refresh(self) -> None:
        """Show the latest frame, or why there is none."""
        if self.port is None:
            return
        f = self.port.latest_image()
        rate = f" — {fmt_rate(f.stats)}" if f.stats.rate_hz is not None else ""
        if f.serial != self._serial:
            self._serial = f.serial
            if f.image is not None:
                a = f.image.rgb
                h, w = a.shape[:2]
                self.image = QImage(a.tobytes(), w, h, 3 * w, QImage.Format_RGB888).copy()  # copy: owns its pixels
                self._pixmap = QPixmap.fromImage(self.image)
                self._rescale()
        text = f"{f.topic}: {f.image.note}" if f.image is not None and not f.error else (f.error or "")
        if f.error and self._pixmap is not None:
            text += " (showing the last good image)"
        self.imageStatus.setText(text + rate)

    def _rescale(self) -> None:
        if self._pixmap is not None:
            self.imageLabel.setPixmap(self._pixmap.scaled(self.imageLabel.size(), Qt.KeepAspectRatio,
                                                          Qt.SmoothTransformation))

    def resizeEvent(self, event: Any) -> None:
        """Rescale the image to the new size."""
        super().resizeEvent(event)
        self._rescale()


# ---------------------------------------------------------------------- the window
class RobotMonitorWindow(QMainWindow):
    """Topic Monitor in the middle, Image View docked right, Console docked below (rqt_gui's layout).

    :meth:`attach` a :class:`MonitorPort` to start; until then the window says
    it waits for ROS.  ``closed`` is emitted when the user closes the window.
    """

    closed = pyqtSignal()

    def __init__(self, capacity: int = DEFAULT_CAPACITY, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("ChefBot — robot monitor")
        self.resize(1280, 800)
        self.port: MonitorPort | None = None
        self._listing_serial = -1
        self._ticks = 0
        self.console = ConsoleWidget(capacity, self)
        self.topic_monitor = TopicMonitorWidget(self)
        self.image_view = ImageViewWidget(self)
        self.setCentralWidget(self.topic_monitor)
        for name, title, widget, area in (("imageDock", "Image View", self.image_view, Qt.RightDockWidgetArea),
                                          ("consoleDock", "Console", self.console, Qt.BottomDockWidgetArea)):
            dock = QDockWidget(title, self, objectName=name)
            dock.setWidget(widget)
            dock.setFeatures(QDockWidget.DockWidgetMovable | QDockWidget.DockWidgetFloatable)
            self.addDockWidget(area, dock)
        self.resizeDocks([self.findChild(QDockWidget, "imageDock")], [400], Qt.Horizontal)
        self.resizeDocks([self.findChild(QDockWidget, "consoleDock")], [260], Qt.Vertical)
        self.statusBar().showMessage("waiting for a ROS master…")
        self._timer = QTimer(self)
        self._timer.timeout.connect(self.refresh)

    def attach(self, port: MonitorPort) -> None:
        """Start showing what ``port`` collects."""
        self.port = self.topic_monitor.port = self.image_view.port = port
        self.statusBar().showMessage("connected to ROS")
        current = self.image_view.imageTopicCombo.currentText()
        if current != NO_IMAGE_TOPIC:
            port.set_image_topic(current)
        self._timer.start(TICK_MS)
        self.refresh()

    @pyqtSlot(str, bool)
    def on_master(self, uri: str, reachable: bool) -> None:
        """Slot: the ROS master at ``uri`` became reachable or not."""
        self.statusBar().showMessage(f"ROS master at {uri}" if reachable else f"no ROS master at {uri} — retrying")

    def refresh(self) -> None:
        """Pull what ROS delivered since the last tick (GUI thread)."""
        if self.port is None:
            return
        self.console.add_entries(self.port.drain_logs())
        self.image_view.refresh()
        self._ticks += 1
        serial, listing, error = self.port.topics()
        listed = serial != self._listing_serial
        if listed:
            self._listing_serial = serial
            self.topic_monitor.update_listing(listing, error)
            self.image_view.update_topics(self.topic_monitor.topics.of_type(IMAGE_TYPE))
        if listed or self._ticks % TOPIC_EVERY_TICKS == 0:
            self.topic_monitor.refresh_values()

    def stop(self) -> None:
        """Stop pulling (the owner shuts the port down)."""
        self._timer.stop()

    def closeEvent(self, event: Any) -> None:
        """Stop pulling and tell the owner (``closed``)."""
        self.stop()
        self.closed.emit()
        super().closeEvent(event)
