"""Glue of the fleet window: its parameters, the fleet file's places, wiring, start-up orders.

No rospy here (as :mod:`chefbot_gui.app`, whose master watcher, event loop and screenshot the
fleet node reuses): the node script reads the ROS parameters into :class:`FleetGuiParams`.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

from PyQt5.QtCore import QObject, Qt

from chefbot_common.fleet_file import load_fleet, load_kitchen
from chefbot_gui.map_view import Marker


@dataclass(frozen=True)
class FleetGuiParams:
    """The fleet window's private parameters (defaults in ``param/fleet_gui.yaml``)."""

    tables_file: str = ""          # the site's tables file: the tables staff can order (required)
    fleet_file: str = ""           # the site's fleet file: robot colours in file order, kitchen, chargers ('' = none)
    fleet_ns: str = "/fleet"       # the dispatcher's namespace (deliver, cancel_order, set_robot, orders)
    robots_topic: str = "/fleet/robots"   # the robots' chefbot_msgs/RobotState
    map_frame: str = "map"         # frame of the map and of the robots' poses and paths
    server_timeout: float = 5.0    # [s] of "connecting..." before "no dispatcher"
    stale_timeout: float = 5.0     # [s] a robot silent on robots_topic this long is shown stale
    service_timeout: float = 2.0   # [s] a cancel or robot command waits this long for the dispatcher
    final_rows: int = 10           # served, cancelled and failed orders listed below the open ones

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type == "float" and (not math.isfinite(v) or v <= 0):
                raise ValueError(f"{f.name} must be a finite number > 0 s, got {v!r}")
            if f.type == "str" and f.name not in ("tables_file", "fleet_file") and not v.strip():
                raise ValueError(f"{f.name} must be a non-empty string, got {v!r}")
        if self.final_rows < 0:
            raise ValueError(f"final_rows must be >= 0, got {self.final_rows}")


def fleet_places(fleet_file: str) -> tuple[list[str], list[Marker]]:
    """The robot names (file order) and the places to draw (kitchen, chargers) of a fleet file;
    ``""``: none.  Raises ``chefbot_common.fleet_file.FleetFileError`` naming the file."""
    if not fleet_file:
        return [], []
    robots = load_fleet(fleet_file)
    places = [Marker(f"charger_{r.name}", "charger", r.charger.x, r.charger.y, r.charger.yaw)
              for r in robots if r.charger is not None]
    kitchen = load_kitchen(fleet_file)
    if kitchen is not None:
        places.insert(0, Marker("kitchen", "Kitchen", kitchen.x, kitchen.y, kitchen.yaw))
    return [r.name for r in robots], places


def parse_orders(text: str) -> list[list[str]]:
    """``"table_2,table_5 table_7"`` → ``[["table_2", "table_5"], ["table_7"]]`` (orders by spaces,
    tables by commas)."""
    return [[t for t in word.split(",") if t] for word in text.split() if word.strip(",")]


def wire_fleet(bridge: QObject, window: QObject) -> None:
    """Connect the fleet bridge's signals to the window's slots, queued into the GUI thread."""
    q = Qt.QueuedConnection
    bridge.dispatcherChanged.connect(window.on_dispatcher, q)
    bridge.queueReceived.connect(window.on_queue, q)
    bridge.robotReceived.connect(window.on_robot, q)
    bridge.mapReceived.connect(window.on_map, q)
    bridge.orderAccepted.connect(window.on_order_accepted, q)
    bridge.orderRefused.connect(window.on_order_refused, q)
    bridge.orderDone.connect(window.on_order_done, q)
    bridge.replyReceived.connect(window.on_reply, q)


class OfflineFleet:
    """The presenter's dispatcher until the ROS bridge exists: nothing is sent (buttons are off)."""

    def send_order(self, request: int, tables: Sequence[str], priority: float, robot: str) -> None:
        """Nothing to send to without a ROS master."""

    def cancel_order(self, request: int, order_id: str) -> None:
        """Nothing to cancel without a ROS master."""

    def set_robot(self, request: int, robot: str, command: str) -> None:
        """No robot to command without a ROS master."""
