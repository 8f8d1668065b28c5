"""Live map widget: occupancy grid, global plan, table markers, robot; in fleet mode every robot.

Qt only (no ROS): it is given plain data by the window and emits
``tableClicked(key)`` when staff click near a table marker.  The fleet window adds
:class:`FleetMarker` robots (own colour, footprint, remaining path; stale ones hollow) and
fixed places (kitchen, chargers) with :meth:`MapView.set_fleet` and :meth:`MapView.set_places`.  Coordinates go
map frame (m) → grid image pixels (:class:`chefbot_common.grid.GridInfo`) →
widget pixels (uniform scale + offset that fit the image in the widget).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from PyQt5.QtCore import QPointF, QRectF, Qt, pyqtSignal
from PyQt5.QtGui import QBrush, QColor, QFont, QImage, QMouseEvent, QPainter, QPaintEvent, QPen, QPolygonF
from PyQt5.QtWidgets import QWidget

from chefbot_common.grid import GridInfo
from chefbot_gui.geometry import Point

ROBOT_RADIUS_M = 0.178  # the book's base collision cylinder
CLICK_RADIUS_PX = 28.0
CLICK_RADIUS_M = 0.9
# Without a map yet, the view frames the tables with this margin (m) at this resolution (m/px).
NO_MAP_MARGIN_M = 1.5
NO_MAP_RESOLUTION = 0.05

SELECTED = QColor("#2e7d32")
QUEUED = QColor("#ef6c00")
CURRENT = QColor("#1565c0")
TABLE = QColor("#6d4c41")
PLAN = QColor(21, 101, 192, 200)
ROBOT = QColor("#c62828")


@dataclass(frozen=True)
class Marker:
    """A named destination drawn on the map: map-frame position (m) and heading (rad)."""

    key: str
    label: str
    x: float
    y: float
    yaw: float = 0.0


@dataclass(frozen=True)
class FleetMarker:
    """One robot of a fleet: colour ``#rrggbb``, pose (m, m, rad), footprint polygon in the map
    frame (m; empty: a circle of ``radius`` m), remaining path (map frame, m); ``stale``: its pose
    is old (drawn hollow, no path)."""

    name: str
    colour: str
    x: float
    y: float
    yaw: float = 0.0
    footprint: tuple[Point, ...] = ()
    radius: float = ROBOT_RADIUS_M
    path: tuple[Point, ...] = ()
    stale: bool = False


class MapView(QWidget):
    """Draws the restaurant map with tables, route and robot; click a table to select it."""

    tableClicked = pyqtSignal(str)
    robotClicked = pyqtSignal(str)   # fleet mode: a click on a robot (not on a table)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._image: QImage | None = None
        self._image_bytes = b""  # QImage does not copy: keep the buffer alive
        self._grid: GridInfo | None = None
        self._markers: list[Marker] = []
        self._home: Marker | None = None
        self._pose: tuple[float, float, float] | None = None
        self._plan: tuple[Point, ...] = ()
        self._selected: str | None = None
        self._current: str | None = None
        self._queued: tuple[str, ...] = ()
        self._selected_many: frozenset[str] = frozenset()
        self._fleet: tuple[FleetMarker, ...] = ()
        self._places: tuple[Marker, ...] = ()
        self.setMouseTracking(False)
        self.setAutoFillBackground(True)

    # ------------------------------------------------------------------ data in
    def set_map(self, grey: bytes, grid: GridInfo) -> None:
        """Show a grey-level image (top row first, ``grid.width`` bytes per row)."""
        self._image_bytes = bytes(grey)
        self._image = QImage(self._image_bytes, grid.width, grid.height, grid.width, QImage.Format_Grayscale8)
        self._grid = grid
        self.update()

    def has_map(self) -> bool:
        """True once a map has been set."""
        return self._image is not None

    def set_markers(self, home: Marker | None, tables: Sequence[Marker]) -> None:
        """The destinations to draw (from the shared tables YAML); ``home`` None: no home marker."""
        self._home = home
        self._markers = list(tables)
        self.update()

    def set_robot(self, pose: tuple[float, float, float] | None) -> None:
        """Robot pose (x m, y m, yaw rad) in the map frame, or ``None`` when unknown."""
        self._pose = pose
        self.update()

    def set_route(self, plan: Sequence[Point], selected: str | None, current: str | None,
                  queued: Sequence[str]) -> None:
        """Global plan and which tables are selected, being driven to, and queued."""
        self._plan = tuple(plan)
        self._selected, self._current, self._queued = selected, current, tuple(queued)
        self.update()

    def set_fleet(self, robots: Sequence[FleetMarker]) -> None:
        """The fleet's robots to draw (fleet mode); empty: none."""
        self._fleet = tuple(robots)
        self.update()

    def fleet(self) -> tuple[FleetMarker, ...]:
        """The fleet robots drawn now."""
        return self._fleet

    def set_selected_tables(self, keys: Sequence[str]) -> None:
        """Tables drawn as selected besides ``set_route``'s one (the fleet's new order)."""
        self._selected_many = frozenset(keys)
        self.update()

    def set_places(self, places: Sequence[Marker]) -> None:
        """Fixed places drawn as small diamonds (kitchen, chargers)."""
        self._places = tuple(places)
        self.update()

    # ------------------------------------------------------------------ geometry
    def _frame(self) -> GridInfo:
        if self._grid is not None:
            return self._grid
        pts = [(m.x, m.y) for m in self._markers] + ([(self._home.x, self._home.y)] if self._home else [])
        if self._pose:
            pts.append(self._pose[:2])
        pts += [(r.x, r.y) for r in self._fleet] + [(m.x, m.y) for m in self._places]
        if not pts:
            pts = [(0.0, 0.0)]
        x0 = min(p[0] for p in pts) - NO_MAP_MARGIN_M
        y0 = min(p[1] for p in pts) - NO_MAP_MARGIN_M
        w = max(p[0] for p in pts) + NO_MAP_MARGIN_M - x0
        h = max(p[1] for p in pts) + NO_MAP_MARGIN_M - y0
        return GridInfo(NO_MAP_RESOLUTION, max(1, round(w / NO_MAP_RESOLUTION)),
                        max(1, round(h / NO_MAP_RESOLUTION)), x0, y0)

    def _fit(self, grid: GridInfo) -> tuple[float, float, float]:
        """Scale (widget px per image px) and offset that centre the image in the widget."""
        s = min(self.width() / grid.width, self.height() / grid.height)
        return s, (self.width() - s * grid.width) / 2.0, (self.height() - s * grid.height) / 2.0

    def world_to_widget(self, x: float, y: float) -> QPointF:
        """Widget pixel of a map-frame point (m)."""
        grid = self._frame()
        s, ox, oy = self._fit(grid)
        u, v = grid.world_to_image(x, y)
        return QPointF(ox + s * u, oy + s * v)

    def widget_to_world(self, px: float, py: float) -> tuple[float, float]:
        """Map-frame point (m) under a widget pixel."""
        grid = self._frame()
        s, ox, oy = self._fit(grid)
        return grid.image_to_world((px - ox) / s, (py - oy) / s)

    def metres_to_pixels(self, m: float) -> float:
        """A length in metres as widget pixels at the current zoom."""
        grid = self._frame()
        return m / grid.resolution * self._fit(grid)[0]

    def table_at(self, px: float, py: float) -> str | None:
        """Key of the table marker under (or near) a widget pixel, if any."""
        best, best_d = None, math.inf
        limit = max(CLICK_RADIUS_PX, self.metres_to_pixels(CLICK_RADIUS_M))
        for m in self._markers:
            p = self.world_to_widget(m.x, m.y)
            d = math.hypot(p.x() - px, p.y() - py)
            if d < best_d and d <= limit:
                best, best_d = m.key, d
        return best

    def robot_at(self, px: float, py: float) -> str | None:
        """Name of the fleet robot under (or near) a widget pixel, if any."""
        best, best_d = None, math.inf
        for r in self._fleet:
            p = self.world_to_widget(r.x, r.y)
            d = math.hypot(p.x() - px, p.y() - py)
            if d < best_d and d <= max(CLICK_RADIUS_PX * 0.6, self.metres_to_pixels(r.radius * 1.5)):
                best, best_d = r.name, d
        return best

    # ------------------------------------------------------------------ Qt events
    def mousePressEvent(self, event: QMouseEvent) -> None:
        """Qt: a left click on a table marker emits tableClicked with its key; elsewhere, on a
        fleet robot, robotClicked with its name."""
        if event.button() == Qt.LeftButton:
            key = self.table_at(event.pos().x(), event.pos().y())
            robot = self.robot_at(event.pos().x(), event.pos().y()) if key is None else None
            if key is not None:
                self.tableClicked.emit(key)
            elif robot is not None:
                self.robotClicked.emit(robot)
        super().mousePressEvent(event)

    def paintEvent(self, event: QPaintEvent) -> None:
        """Qt: draw the map, markers, plan and robot."""
        qp = QPainter(self)
        qp.setRenderHint(QPainter.Antialiasing)
        qp.fillRect(self.rect(), QColor("#9e9e9e"))
        grid = self._frame()
        s, ox, oy = self._fit(grid)
        if self._image is not None:
            qp.drawImage(QRectF(ox, oy, s * grid.width, s * grid.height), self._image)
        else:
            qp.fillRect(QRectF(ox, oy, s * grid.width, s * grid.height), QColor("#f5f5f5"))
            qp.setPen(QColor("#616161"))
            qp.drawText(QRectF(ox, oy + 4, s * grid.width, 24), Qt.AlignHCenter, "waiting for the map…")
        self._paint_plan(qp)
        self._paint_fleet_paths(qp)
        self._paint_markers(qp)
        self._paint_places(qp)
        self._paint_robot(qp)
        self._paint_fleet(qp)
        self._paint_scale(qp)
        qp.end()

    def _paint_plan(self, qp: QPainter) -> None:
        if len(self._plan) < 2:
            return
        qp.setPen(QPen(PLAN, max(2.0, self.metres_to_pixels(0.06)), Qt.SolidLine, Qt.RoundCap, Qt.RoundJoin))
        qp.setBrush(Qt.NoBrush)
        qp.drawPolyline(QPolygonF([self.world_to_widget(x, y) for x, y in self._plan]))

    def _paint_markers(self, qp: QPainter) -> None:
        r = max(7.0, self.metres_to_pixels(0.25))
        font = QFont(qp.font())
        font.setBold(True)
        font.setPointSizeF(max(7.0, min(11.0, r * 0.9)))
        qp.setFont(font)
        for m in self._markers:
            colour = TABLE
            if m.key in self._queued:
                colour = QUEUED
            if m.key == self._current:
                colour = CURRENT
            selected = m.key == self._selected or m.key in self._selected_many
            if selected:
                colour = SELECTED
            c = self.world_to_widget(m.x, m.y)
            width = 3.0 if selected else 1.5
            qp.setPen(QPen(QColor("white"), width))
            qp.setBrush(QBrush(colour))
            qp.drawEllipse(c, r, r)
            number = m.label.split()[-1] if m.label.startswith("Table ") else m.label[:2]
            qp.setPen(QColor("white"))
            qp.drawText(QRectF(c.x() - r, c.y() - r, 2 * r, 2 * r), Qt.AlignCenter, number)
            self._paint_label(qp, c, r, m.label, colour.darker(130))
        if self._home is not None:
            c = self.world_to_widget(self._home.x, self._home.y)
            qp.setPen(QPen(QColor("#37474f"), 1.5))
            qp.setBrush(QBrush(QColor("#cfd8dc")))
            qp.drawRect(QRectF(c.x() - r, c.y() - r, 2 * r, 2 * r))
            qp.setPen(QColor("#37474f"))
            qp.drawText(QRectF(c.x() - r, c.y() - r, 2 * r, 2 * r), Qt.AlignCenter, "H")
            self._paint_label(qp, c, r, "Home", QColor("#37474f"))

    @staticmethod
    def _paint_label(qp: QPainter, c: QPointF, r: float, text: str, colour: QColor) -> None:
        """Name under a marker on a light plate, readable over walls and tables."""
        box = qp.fontMetrics().boundingRect(text)
        rect = QRectF(c.x() - box.width() / 2 - 3, c.y() + r + 2, box.width() + 6, box.height() + 2)
        qp.setPen(Qt.NoPen)
        qp.setBrush(QColor(255, 255, 255, 210))
        qp.drawRoundedRect(rect, 3, 3)
        qp.setPen(colour)
        qp.drawText(rect, Qt.AlignCenter, text)

    def _paint_robot(self, qp: QPainter) -> None:
        if self._pose is None:
            return
        x, y, yaw = self._pose
        c = self.world_to_widget(x, y)
        r = max(6.0, self.metres_to_pixels(ROBOT_RADIUS_M))
        nose = self.world_to_widget(x + 2.2 * ROBOT_RADIUS_M * math.cos(yaw),
                                    y + 2.2 * ROBOT_RADIUS_M * math.sin(yaw))
        dx, dy = nose.x() - c.x(), nose.y() - c.y()
        n = math.hypot(dx, dy) or 1.0
        nose = QPointF(c.x() + dx / n * max(n, 1.8 * r), c.y() + dy / n * max(n, 1.8 * r))
        qp.setPen(QPen(QColor("white"), 2.0))
        qp.setBrush(QBrush(ROBOT))
        qp.drawEllipse(c, r, r)
        qp.setPen(QPen(ROBOT, 3.0, Qt.SolidLine, Qt.RoundCap))
        qp.drawLine(c, nose)

    def _paint_fleet_paths(self, qp: QPainter) -> None:
        for r in self._fleet:
            if r.stale or len(r.path) < 2:
                continue
            colour = QColor(r.colour)
            colour.setAlpha(190)
            qp.setPen(QPen(colour, max(2.0, self.metres_to_pixels(0.06)), Qt.DashLine, Qt.RoundCap, Qt.RoundJoin))
            qp.setBrush(Qt.NoBrush)
            qp.drawPolyline(QPolygonF([self.world_to_widget(x, y) for x, y in ((r.x, r.y), *r.path)]))

    def _paint_places(self, qp: QPainter) -> None:
        r = max(5.0, self.metres_to_pixels(0.15))
        for m in self._places:
            c = self.world_to_widget(m.x, m.y)
            qp.setPen(QPen(QColor("#455a64"), 1.5))
            qp.setBrush(QBrush(QColor("#eceff1")))
            qp.drawPolygon(QPolygonF([QPointF(c.x(), c.y() - r), QPointF(c.x() + r, c.y()),
                                      QPointF(c.x(), c.y() + r), QPointF(c.x() - r, c.y())]))
            self._paint_label(qp, c, r, m.label, QColor("#455a64"))

    def _paint_fleet(self, qp: QPainter) -> None:
        font = QFont(qp.font())
        font.setBold(True)
        qp.setFont(font)
        for rob in self._fleet:
            colour = QColor(rob.colour)
            c = self.world_to_widget(rob.x, rob.y)
            r = max(6.0, self.metres_to_pixels(rob.radius))
            if rob.stale:
                qp.setPen(QPen(colour, 2.0, Qt.DashLine))
                qp.setBrush(QBrush(QColor(255, 255, 255, 160)))
            else:
                qp.setPen(QPen(QColor("white"), 2.0))
                qp.setBrush(QBrush(colour))
            if len(rob.footprint) >= 3:
                qp.drawPolygon(QPolygonF([self.world_to_widget(x, y) for x, y in rob.footprint]))
            else:
                qp.drawEllipse(c, r, r)
            ahead = self.world_to_widget(rob.x + math.cos(rob.yaw), rob.y + math.sin(rob.yaw))
            dx, dy = ahead.x() - c.x(), ahead.y() - c.y()
            n = math.hypot(dx, dy) or 1.0
            nose = QPointF(c.x() + dx / n * 1.8 * r, c.y() + dy / n * 1.8 * r)
            qp.setPen(QPen(colour if not rob.stale else QColor("#9e9e9e"), 3.0, Qt.SolidLine, Qt.RoundCap))
            qp.drawLine(c, nose)
            self._paint_label(qp, c, r, rob.name + (" (stale)" if rob.stale else ""), colour.darker(120))

    def _paint_scale(self, qp: QPainter) -> None:
        px = self.metres_to_pixels(1.0)
        if px < 4:
            return
        x0, y0 = 12.0, self.height() - 14.0
        qp.setPen(QPen(QColor("black"), 2.0))
        qp.drawLine(QPointF(x0, y0), QPointF(x0 + px, y0))
        qp.drawText(QPointF(x0 + px + 4, y0 + 4), "1 m")
