"""The fleet window: loads ``ui/fleet_gui.ui`` and renders the fleet presenter's state.

Qt only (no rospy), the fleet counterpart of :mod:`chefbot_gui.window`.  Widget signals call
presenter actions; :meth:`FleetWindow.render` shows each
:class:`~chefbot_gui.fleet_presenter.FleetViewState`.  The ``on_*`` slots receive the fleet
bridge's signals (queued into the GUI thread) and forward them to the presenter, so ROS never
touches a widget.
"""
from __future__ import annotations

from collections.abc import Sequence

from PyQt5 import uic
from PyQt5.QtCore import Qt, QTimer, pyqtSlot
from PyQt5.QtGui import QBrush, QColor
from PyQt5.QtWidgets import QHeaderView, QListWidgetItem, QTableWidget, QTableWidgetItem, QWidget

from chefbot_common.grid import GridInfo
from chefbot_gui.fleet_presenter import FleetPresenter, FleetViewState, OrderRow, RobotRow
from chefbot_gui.map_view import FleetMarker, Marker
from chefbot_gui.window import STATUS_COLOURS, ui_path

TICK_MS = 500  # presenter clock: connection time-out, stale robots
REPLY_COLOURS = {True: "#1b5e20", False: "#b71c1c", None: "#37474f"}


class FleetWindow(QWidget):
    """The staff's fleet window.  Stable objectNames: ``mapView``, ``statusLabel``, ``hintLabel``,
    ``replyLabel``, ``robotTable``, ``pauseButton``, ``resumeButton``, ``chargeButton``,
    ``orderTable``, ``cancelOrderButton``, ``tableList``, ``prioritySpin``, ``robotCombo``,
    ``addOrderButton``.

    ``places``: fixed places drawn on the map (the fleet file's kitchen and chargers).
    """

    def __init__(self, presenter: FleetPresenter, places: Sequence[Marker] = (),
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        uic.loadUi(str(ui_path("fleet_gui.ui")), self)
        self.presenter = presenter
        self.state: FleetViewState | None = None
        self._rendering = False
        self._status_style = self.statusLabel.styleSheet().split("background")[0].strip()
        self._robot_rows: tuple[RobotRow, ...] | None = None
        self._order_rows: tuple[OrderRow, ...] | None = None

        self.tableList.setFocusPolicy(Qt.ClickFocus)   # no "current" table highlighted at start
        for dest in presenter.tables:
            item = QListWidgetItem(dest.label)
            item.setData(Qt.UserRole, dest.key)
            item.setTextAlignment(Qt.AlignCenter)
            self.tableList.addItem(item)
        for table in (self.robotTable, self.orderTable):
            table.setFocusPolicy(Qt.ClickFocus)   # no focus frame that reads as a selected robot or order
            table.verticalHeader().setVisible(False)
            table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
            table.horizontalHeader().setStretchLastSection(True)
        # no Home: the tables file's home is one robot's start; the fleet's robots park by the fleet file
        self.mapView.set_markers(None, [Marker(d.key, d.label, d.pose.x, d.pose.y, d.pose.yaw)
                                        for d in presenter.tables])
        self.mapView.set_places(places)

        self.tableList.itemSelectionChanged.connect(self._tables_changed)
        self.mapView.tableClicked.connect(presenter.toggle_table)
        self.mapView.robotClicked.connect(presenter.select_robot)
        self.robotTable.itemSelectionChanged.connect(self._robot_changed)
        self.orderTable.itemSelectionChanged.connect(self._order_changed)
        self.prioritySpin.valueChanged.connect(lambda v: presenter.set_priority(max(1.0, float(v))))
        self.robotCombo.currentIndexChanged.connect(self._robot_choice_changed)
        self.addOrderButton.clicked.connect(presenter.add_order)
        self.cancelOrderButton.clicked.connect(presenter.cancel_order)
        self.pauseButton.clicked.connect(lambda: presenter.robot_command("pause"))
        self.resumeButton.clicked.connect(lambda: presenter.robot_command("resume"))
        self.chargeButton.clicked.connect(lambda: presenter.robot_command("charge"))

        self._timer = QTimer(self)
        self._timer.timeout.connect(presenter.tick)
        self._timer.start(TICK_MS)
        presenter.subscribe(self.render)

    # ------------------------------------------------------------------ widgets → presenter
    def _tables_changed(self) -> None:
        if self._rendering:
            return
        picked = {i.data(Qt.UserRole) for i in self.tableList.selectedItems()}
        before = [k for k in self.presenter.selected_tables if k in picked]
        listed = [self.tableList.item(i).data(Qt.UserRole) for i in range(self.tableList.count())]
        self.presenter.set_tables(before + [k for k in listed if k in picked and k not in before])

    def _selected_key(self, table: QTableWidget) -> str | None:
        rows = table.selectionModel().selectedRows()
        item = table.item(rows[0].row(), 0) if rows else None
        return item.data(Qt.UserRole) if item is not None else None

    def _robot_changed(self) -> None:
        if not self._rendering:
            self.presenter.select_robot(self._selected_key(self.robotTable))

    def _order_changed(self) -> None:
        if not self._rendering:
            self.presenter.select_order(self._selected_key(self.orderTable))

    def _robot_choice_changed(self, index: int) -> None:
        if not self._rendering:
            self.presenter.set_robot_choice((self.robotCombo.itemData(index) or "") if index > 0 else "")

    # ------------------------------------------------------------------ bridge → presenter
    @pyqtSlot(str, bool)
    def on_master(self, uri: str, reachable: bool) -> None:
        """Slot: the ROS master at ``uri`` became reachable or not."""
        self.presenter.on_master(uri, reachable)

    @pyqtSlot(bool, bool)
    def on_dispatcher(self, action_ok: bool, services_ok: bool) -> None:
        """Slot: the dispatcher's action server / services answer or not."""
        self.presenter.on_dispatcher(action_ok, services_ok)

    @pyqtSlot(object)
    def on_queue(self, queue) -> None:
        """Slot: a new order queue (``QueueSnapshot``)."""
        self.presenter.on_queue(queue)

    @pyqtSlot(object)
    def on_robot(self, report) -> None:
        """Slot: one robot's state (``RobotReport``)."""
        self.presenter.on_robot_report(report)

    @pyqtSlot(object, object)
    def on_map(self, grey: bytes, grid: GridInfo) -> None:
        """Slot: a new map image and its grid geometry."""
        self.mapView.set_map(grey, grid)

    @pyqtSlot(int, str)
    def on_order_accepted(self, request: int, text: str) -> None:
        """Slot: the dispatcher accepted an order (status text ``order <id>``)."""
        self.presenter.on_order_accepted(request, text)

    @pyqtSlot(int, str)
    def on_order_refused(self, request: int, reason: str) -> None:
        """Slot: the dispatcher refused an order."""
        self.presenter.on_order_refused(request, reason)

    @pyqtSlot(int, str, str, str)
    def on_order_done(self, request: int, order_id: str, state: str, reason: str) -> None:
        """Slot: an order ended (served, cancelled, failed, lost)."""
        self.presenter.on_order_done(request, order_id, state, reason)

    @pyqtSlot(int, bool, str)
    def on_reply(self, request: int, ok: bool, message: str) -> None:
        """Slot: a service reply."""
        self.presenter.on_reply(request, ok, message)

    # ------------------------------------------------------------------ presenter → widgets
    def render(self, st: FleetViewState) -> None:
        """Show a presenter snapshot (called in the GUI thread only)."""
        self.state = st
        self._rendering = True
        try:
            self.statusLabel.setText(st.status)
            self.statusLabel.setStyleSheet(f"{self._status_style} background: {STATUS_COLOURS[st.tone]};")
            self.hintLabel.setText(st.hint)
            self.replyLabel.setText(st.reply)
            self.replyLabel.setStyleSheet(f"color: {REPLY_COLOURS[st.reply_ok]};")
            self.addOrderButton.setEnabled(st.add_enabled)
            self.cancelOrderButton.setEnabled(st.cancel_enabled)
            self.pauseButton.setEnabled(st.pause_enabled)
            self.resumeButton.setEnabled(st.resume_enabled)
            self.chargeButton.setEnabled(st.charge_enabled)
            self._render_tables(st)
            self._render_robot_choices(st)
            if abs(self.prioritySpin.value() - st.priority) > 1e-9:
                self.prioritySpin.setValue(st.priority)
            if st.robots != self._robot_rows:
                self._robot_rows = st.robots
                self._fill(self.robotTable, [self._robot_cells(r) for r in st.robots], [r.name for r in st.robots])
            if st.orders != self._order_rows:
                self._order_rows = st.orders
                self._fill(self.orderTable, [self._order_cells(o) for o in st.orders], [o.id for o in st.orders])
            self._select(self.robotTable, st.selected_robot)
            self._select(self.orderTable, st.selected_order)
            self.mapView.set_fleet([FleetMarker(r.name, r.colour, *r.pose, footprint=r.footprint, radius=r.radius,
                                                path=r.path, stale=r.stale) for r in st.robots if r.pose])
            self.mapView.set_selected_tables(st.selected_tables)
            self.mapView.set_route((), None, None, st.open_tables)
        finally:
            self._rendering = False

    def _render_tables(self, st: FleetViewState) -> None:
        for i in range(self.tableList.count()):
            item = self.tableList.item(i)
            want = item.data(Qt.UserRole) in st.selected_tables
            if item.isSelected() != want:
                item.setSelected(want)

    def _render_robot_choices(self, st: FleetViewState) -> None:
        shown = [self.robotCombo.itemData(i) for i in range(1, self.robotCombo.count())]
        choices = list(st.robot_choices)
        if st.robot_choice and st.robot_choice not in choices:
            choices.append(st.robot_choice)
        if shown != choices:
            while self.robotCombo.count() > 1:
                self.robotCombo.removeItem(1)
            for name in choices:
                self.robotCombo.addItem(name, name)
        index = choices.index(st.robot_choice) + 1 if st.robot_choice else 0
        if self.robotCombo.currentIndex() != index:
            self.robotCombo.setCurrentIndex(index)

    @staticmethod
    def _robot_cells(r: RobotRow) -> list[tuple[str, str | None]]:
        return [(f"● {r.name}", r.colour), (r.state_text, "#9e9e9e" if r.stale else None),
                (r.battery_text, "#c62828" if r.battery_low else None), (r.trip_text, None)]

    @staticmethod
    def _order_cells(o: OrderRow) -> list[tuple[str, str | None]]:
        grey = "#9e9e9e" if o.final else None
        return [(o.id, grey), (o.tables_text, grey), (o.state_text, grey), (o.robot, o.robot_colour or grey),
                (o.eta_text, grey), (o.reason, grey)]

    @staticmethod
    def _fill(table: QTableWidget, rows: list[list[tuple[str, str | None]]], keys: list[str]) -> None:
        table.setRowCount(len(rows))
        for r, (cells, key) in enumerate(zip(rows, keys, strict=True)):
            for c, (text, colour) in enumerate(cells):
                item = QTableWidgetItem(text)
                item.setToolTip(text)     # cut texts (a long trip or reason) in full
                item.setData(Qt.UserRole, key)
                if colour:
                    item.setForeground(QBrush(QColor(colour)))
                table.setItem(r, c, item)

    @staticmethod
    def _select(table: QTableWidget, key: str | None) -> None:
        want = next((r for r in range(table.rowCount()) if table.item(r, 0).data(Qt.UserRole) == key), None)
        rows = table.selectionModel().selectedRows()
        now = rows[0].row() if rows else None
        if want == now:
            return
        if want is None:
            table.clearSelection()
        else:
            table.selectRow(want)

    def cell_texts(self, table: QTableWidget) -> list[list[str]]:
        """The texts of ``table``'s rows (tests, automation)."""
        return [[table.item(r, c).text() for c in range(table.columnCount())] for r in range(table.rowCount())]

    def table_item(self, key: str) -> QListWidgetItem | None:
        """The table list's row of table ``key``, or None."""
        for i in range(self.tableList.count()):
            item = self.tableList.item(i)
            if item.data(Qt.UserRole) == key:
                return item
        return None
