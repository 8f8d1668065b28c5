"""Glue between the ROS bridge, the presenter and the window; parameters; screenshots.

No rospy here: the node script reads the ROS parameters into a dict and calls
:func:`GuiParams.from_dict`, which validates them with messages naming the
parameter.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from PyQt5.QtCore import QObject, Qt, QTimer
from PyQt5.QtWidgets import QWidget

from chefbot_gui.presenter import OrderMode

ORDER_NAMES = {"in_order": OrderMode.FIFO, "nearest_first": OrderMode.NEAREST}


class ParamError(ValueError):
    """An invalid GUI parameter; the message names it."""


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

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> GuiParams:
        """Build from a ``{name: value}`` mapping (unknown names ignored), validating each value."""
        kwargs: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in values:
                continue
            v = values[f.name]
            if f.type == "float":
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ParamError(f"~{f.name}: expected a number, got {v!r}")
                v = float(v)
            elif not isinstance(v, str) or not v.strip():
                raise ParamError(f"~{f.name}: expected a non-empty string, got {v!r}")
            kwargs[f.name] = v
        p = cls(**kwargs)
        if p.server_timeout <= 0:
            raise ParamError(f"~server_timeout: must be > 0 s, got {p.server_timeout}")
        if p.wait_time < 0:
            raise ParamError(f"~wait_time: must be >= 0 s, got {p.wait_time}")
        if p.nominal_speed <= 0:
            raise ParamError(f"~nominal_speed: must be > 0 m/s, got {p.nominal_speed}")
        if p.order not in ORDER_NAMES:
            raise ParamError(f"~order: must be one of {sorted(ORDER_NAMES)}, got {p.order!r}")
        return p

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
