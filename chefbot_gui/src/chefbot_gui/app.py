"""Glue between the ROS bridge, the presenter and the window; parameters; screenshots.

No rospy here: the node script reads the ROS parameters with the workspace's
shared reader (``chefbot_common.params.read_config``, which checks types and
names the parameter in its errors) into :class:`GuiParams`, whose own checks
cover the values.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from PyQt5.QtCore import QObject, Qt, QTimer
from PyQt5.QtWidgets import QWidget

from chefbot_gui.presenter import OrderMode

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
