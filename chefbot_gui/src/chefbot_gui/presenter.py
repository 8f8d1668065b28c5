"""The delivery presenter: order queue, robot state machine and status texts.

Qt-free and ROS-free.  The view calls the ``on_*``/action methods from the GUI
thread and renders the :class:`ViewState` handed to its listeners; the robot
is reached through the small :class:`RobotPort` interface (the ROS bridge in
the node, a fake in the unit tests).  Time comes from an injected clock
(seconds, monotonic) so waiting and time-outs are testable without sleeping.

States shown to staff (``ViewState.status``):
``no ROS master at http://… — retrying``, ``connecting…``, ``robot not connected``, ``ready``,
``driving to Table 4 (3.2 m, ~12 s)``, ``returning home (…)``,
``arrived at Table 4 — waiting for Served``, ``arrived home — ready``,
``cancelling…``, ``cancelled``, ``failed: <reason from the server>``.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

from chefbot_gui import geometry
from chefbot_gui.geometry import Point

HOME = "home"
LOW_BATTERY_PERCENT = 20
# A global plan whose last point is further than this from the current goal is
# a stale plan of an earlier goal and is not used for the distance (m).
PLAN_GOAL_TOLERANCE_M = 0.75


class PoseLike(Protocol):
    """Anything with a planar pose: ``x``, ``y`` (m) and ``yaw`` (rad) in the map frame."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class Pose:
    """A planar robot pose in the map frame (m, m, rad)."""

    x: float
    y: float
    yaw: float = 0.0


class Phase(Enum):
    """What the delivery run is doing (independent of the server connection)."""

    IDLE = "idle"
    DRIVING = "driving"        # a goal (table or home) is out at the server
    CANCELLING = "cancelling"  # staff pressed Cancel, waiting for the server to confirm
    WAITING = "waiting"        # at a table, waiting for Served or the wait time
    STOPPED = "stopped"        # cancelled by staff; queue kept, Go continues
    FAILED = "failed"          # the server aborted/rejected; Go retries


class Outcome(Enum):
    """How a goal ended, mapped from actionlib's terminal states by the bridge."""

    SUCCEEDED = "succeeded"
    ABORTED = "aborted"
    REJECTED = "rejected"
    PREEMPTED = "preempted"  # cancelled (by us or another client) or replaced
    LOST = "lost"            # the server went away while the goal was out


class OrderMode(Enum):
    """In which order queued tables are served."""

    FIFO = "in order"
    NEAREST = "nearest first"


@dataclass(frozen=True)
class Destination:
    """A named delivery pose: ``key`` as in the tables YAML, ``label`` for staff."""

    key: str
    label: str
    pose: PoseLike


class RobotPort(Protocol):
    """What the presenter needs from the robot; both calls must not block."""

    def send_goal(self, goal_id: int, dest: Destination) -> None:
        """Send a navigation goal to ``dest.pose``; results come back tagged with ``goal_id``."""

    def cancel_goal(self) -> None:
        """Cancel the goal that is out at the server, if any."""


@dataclass(frozen=True)
class ViewState:
    """Everything the view shows; a fresh immutable snapshot after every change."""

    status: str
    hint: str
    connected: bool | None
    phase: Phase
    go_enabled: bool
    home_enabled: bool
    cancel_enabled: bool
    served_enabled: bool
    remove_enabled: bool
    queue: tuple[str, ...]              # keys of pending destinations, in the order they will be served
    queue_labels: tuple[str, ...]
    current: str | None                 # key of the goal out at the server / the table we wait at
    selected: str | None
    order_mode: OrderMode
    wait_time_s: float
    remaining_m: float | None
    eta_s: float | None
    progress: float | None              # 0..1 along the current route
    battery_percent: int | None
    battery_text: str
    battery_low: bool
    health_level: int | None            # diagnostic_msgs/DiagnosticStatus level of the worst entry
    health_text: str
    robot_pose: Pose | None
    plan: tuple[Point, ...] = field(default=())


def table_label(key: str) -> str:
    """Staff-facing name of a destination key: ``table_4`` → ``Table 4``, ``home`` → ``Home``.

    Only the canonical spelling gets the short form: ``table_04`` stays
    ``Table 04`` so it cannot be confused with ``table_4``.
    """
    m = re.fullmatch(r"table_(\d+)", key)
    if m and m.group(1) == str(int(m.group(1))):
        return f"Table {int(m.group(1))}"
    return key.replace("_", " ").strip().capitalize()


def _sort_key(key: str) -> tuple[int, int, str]:
    m = re.fullmatch(r"table_(\d+)", key)
    return (0, int(m.group(1)), "") if m else (1, 0, key)


def make_destinations(poses: Mapping[str, PoseLike],
                      destinations: Sequence[str] | None = None) -> tuple[Destination, list[Destination]]:
    """Split loaded poses into ``home`` and the tables, tables numerically sorted, labels unique.

    ``destinations``: the keys that are tables (the tables file's ``destinations`` list); default
    every pose but ``home``, whatever its name.  Raises ``ValueError`` when ``home`` is missing,
    a destination is not a pose, or there is no table.
    """
    if HOME not in poses:
        raise ValueError("the tables file has no 'home' pose")
    if destinations is not None and (unknown := [k for k in destinations if k not in poses or k == HOME]):
        raise ValueError(f"destinations {unknown} are not table poses of the tables file")
    chosen = set(poses if destinations is None else destinations)
    keys = [k for k in sorted(poses, key=_sort_key) if k != HOME and k in chosen]
    if not keys:
        raise ValueError("the tables file has no table poses")
    labels = [table_label(k) for k in keys]
    taken = [*labels, "Home"]
    # keys that read the same for staff (``table 4``, ``Table_4`` next to ``table_4``) also show
    # the key; the canonical spelling of a label (``table_4`` for "Table 4") keeps the short form
    labels = [f"{lab} ({k})" if taken.count(lab) > 1 and k != lab.lower().replace(" ", "_") else lab
              for k, lab in zip(keys, labels, strict=True)]
    tables = [Destination(k, lab, poses[k]) for k, lab in zip(keys, labels, strict=True)]
    return Destination(HOME, "Home", poses[HOME]), tables


def fmt_metres(m: float) -> str:
    """A distance for staff: ``3.2``; %g beyond 10 km so a huge coordinate stays short (``1e+300``)."""
    return f"{m:.1f}" if abs(m) < 1e4 else f"{m:.3g}"


def fmt_eta(seconds: float) -> str:
    """An ETA for staff: ``~12 s``, ``~4 min``; %g when absurdly long."""
    if seconds >= 6e5:  # more than a week: %g, not a 300-digit number
        return f"~{seconds / 60:.3g} min"
    if seconds >= 90:
        return f"~{round(seconds / 60)} min"
    return f"~{round(seconds)} s"


class DeliveryPresenter:
    """State machine of a delivery run: queue → drive → wait → … → home.

    Parameters: ``poses`` (map-frame poses by key, must include ``home``), ``destinations``
    (the keys staff can send the robot to; default every pose but ``home``),
    ``robot`` (a :class:`RobotPort`), ``clock`` (monotonic seconds),
    ``connect_timeout_s`` (how long "connecting…" may last before "robot not
    connected"), ``wait_time_s`` (time at a table before moving on; 0 = only
    the Served button), ``speed_mps`` (nominal speed for the ETA),
    ``diagnostics_timeout_s`` (diagnostic entries older than this count as stale).
    """

    def __init__(self, poses: Mapping[str, PoseLike], robot: RobotPort, clock: Callable[[], float],
                 connect_timeout_s: float = 5.0, wait_time_s: float = 30.0, speed_mps: float = 0.3,
                 order_mode: OrderMode = OrderMode.FIFO, diagnostics_timeout_s: float = 5.0,
                 destinations: Sequence[str] | None = None) -> None:
        if speed_mps <= 0:
            raise ValueError(f"speed_mps must be > 0, got {speed_mps}")
        if wait_time_s < 0:
            raise ValueError(f"wait_time_s must be >= 0, got {wait_time_s}")
        self.home, self.tables = make_destinations(poses, destinations)
        self._by_key = {d.key: d for d in [self.home, *self.tables]}
        self._robot = robot
        self._clock = clock
        self._connect_timeout = connect_timeout_s
        self._connect_deadline = clock() + connect_timeout_s
        self._speed = speed_mps
        self._diag_timeout = diagnostics_timeout_s
        self._listeners: list[Callable[[ViewState], None]] = []

        self.connected: bool | None = None
        self.master_missing: str | None = None  # ROS master URI while it cannot be reached
        self.phase = Phase.IDLE
        self.order_mode = order_mode
        self.wait_time_s = float(wait_time_s)
        self.queue: list[str] = []
        self.selected: str | None = None
        self.current: str | None = None
        self._goal_id = 0
        self._wait_deadline: float | None = None
        self._message = ""       # reason for FAILED / note for STOPPED and IDLE
        self._arrived_home = False
        self._pose: Pose | None = None
        self._plan: tuple[Point, ...] = ()
        self._route_total: float | None = None
        self._battery: tuple[float, float, bool] | None = None
        self._diag: dict[str, tuple[int, str, float]] = {}
        self._last_state: ViewState | None = None

    # ------------------------------------------------------------------ plumbing
    def subscribe(self, listener: Callable[[ViewState], None]) -> None:
        """Call ``listener(state)`` now and after every change."""
        self._listeners.append(listener)
        listener(self.state())

    def _changed(self) -> None:
        st = self.state()
        if st == self._last_state:
            return
        self._last_state = st
        for listener in list(self._listeners):
            listener(st)

    def attach_robot(self, robot: RobotPort) -> None:
        """Use ``robot`` from now on (the ROS bridge exists only once the master is reachable)."""
        self._robot = robot

    def destination(self, key: str) -> Destination:
        """The destination named ``key`` (``KeyError`` if unknown)."""
        return self._by_key[key]

    # ------------------------------------------------------------------ staff actions
    def select(self, key: str | None) -> None:
        """Staff picked a table (list or map click); ``None`` clears the choice."""
        if key is not None and (key not in self._by_key or key == HOME):
            raise KeyError(f"unknown table {key!r}")
        self.selected = key
        self._changed()

    def go(self) -> None:
        """Queue the selected table (if any) and start or continue the run."""
        if not self.connected or self.phase == Phase.CANCELLING:
            return
        sel = self.selected
        if sel is not None and sel not in self.queue and not (
                sel == self.current and self.phase in (Phase.DRIVING, Phase.WAITING)):
            self.queue.append(sel)
        driving_home = self.phase == Phase.DRIVING and self.current == HOME
        if self.phase in (Phase.IDLE, Phase.STOPPED, Phase.FAILED) or driving_home:
            self._start_next()
        self._changed()

    def home_now(self) -> None:
        """Drop the pending queue and drive home (the book's Home button)."""
        if not self.connected:
            return
        self.queue.clear()
        self._send(HOME)
        self._changed()

    def cancel(self) -> None:
        """Stop the robot: cancel the goal that is out; pending tables stay queued."""
        if self.phase == Phase.DRIVING:
            self.phase = Phase.CANCELLING
            self._robot.cancel_goal()
        elif self.phase == Phase.WAITING:
            self._stop("cancelled")
        self._changed()

    def served(self) -> None:
        """The food was taken at the table: continue with the next destination."""
        if self.phase == Phase.WAITING:
            self._leave_table()
            self._changed()

    def remove(self, index: int) -> None:
        """Remove the pending queue item at ``index`` (position in ``ViewState.queue``)."""
        ordered = self._ordered_queue()
        if 0 <= index < len(ordered):
            self.queue.remove(ordered[index])
            self._changed()

    def set_order_mode(self, mode: OrderMode) -> None:
        """Serve queued tables in the order they were added or nearest first."""
        self.order_mode = mode
        self._changed()

    def set_wait_time(self, seconds: float) -> None:
        """Time (s) to wait at a table before moving on; 0 = wait for Served only."""
        if seconds < 0:
            raise ValueError(f"wait time must be >= 0, got {seconds}")
        self.wait_time_s = float(seconds)
        if self.phase == Phase.WAITING:
            self._wait_deadline = self._clock() + seconds if seconds > 0 else None
        self._changed()

    # ------------------------------------------------------------------ robot events
    def on_master(self, uri: str, reachable: bool) -> None:
        """The ROS master at ``uri`` cannot be reached (False) or was just reached (True).

        While it is missing every robot action is disabled; once it answers the
        usual "connecting…" time-out for the navigation server starts.
        """
        missing = None if reachable else uri
        if missing == self.master_missing:
            return
        self.master_missing = missing
        if reachable:
            self.connected = None
            self._connect_deadline = self._clock() + self._connect_timeout
        else:
            self.on_server(False)
        self._changed()

    def on_server(self, connected: bool) -> None:
        """The navigation action server appeared (True) or went away (False)."""
        if connected == self.connected:
            return
        was = self.connected
        self.connected = connected
        if not connected and was and self.phase in (Phase.DRIVING, Phase.CANCELLING):
            self._lost_goal()
        self._changed()

    def on_goal_done(self, goal_id: int, outcome: Outcome, text: str = "") -> None:
        """The server finished goal ``goal_id``; ``text`` is its status text (may be empty)."""
        if goal_id != self._goal_id or self.phase not in (Phase.DRIVING, Phase.CANCELLING):
            return  # a result of a goal we already replaced
        text = text.strip()
        if self.phase == Phase.CANCELLING and outcome != Outcome.SUCCEEDED:
            self._stop("cancelled")
        elif outcome == Outcome.SUCCEEDED:
            self._arrived()
        elif outcome == Outcome.LOST:
            self._lost_goal()
        else:
            default = {Outcome.ABORTED: "the navigation server aborted the goal",
                       Outcome.REJECTED: "the navigation server rejected the goal",
                       Outcome.PREEMPTED: "the goal was cancelled by another client"}[outcome]
            self._fail(text or default)
        self._changed()

    def on_robot_pose(self, pose: PoseLike) -> None:
        """Latest robot pose in the map frame (tf, amcl_pose or action feedback)."""
        self._pose = Pose(float(pose.x), float(pose.y), float(pose.yaw))
        self._update_route()
        self._changed()

    def on_plan(self, points: Sequence[Point]) -> None:
        """Latest global plan (map-frame points); empty when the planner has none."""
        self._plan = tuple((float(x), float(y)) for x, y in points)
        self._update_route()
        self._changed()

    def on_battery(self, percentage: float, voltage: float = math.nan, present: bool = True) -> None:
        """``sensor_msgs/BatteryState``: ``percentage`` 0..1 (NaN = unknown), ``voltage`` V."""
        self._battery = (percentage, voltage, present)
        self._changed()

    def on_diagnostic(self, name: str, level: int, message: str) -> None:
        """One ``diagnostic_msgs/DiagnosticStatus`` entry (level 0 OK … 3 STALE)."""
        self._diag[name] = (int(level), message, self._clock())
        self._changed()

    def tick(self) -> None:
        """Advance time: connection time-out, wait at table, stale diagnostics."""
        now = self._clock()
        if self.connected is None and self.master_missing is None and now >= self._connect_deadline:
            self.connected = False
        if self.phase == Phase.WAITING and self._wait_deadline is not None and now >= self._wait_deadline:
            self._leave_table()
        self._changed()

    # ------------------------------------------------------------------ transitions
    def _origin(self) -> Point:
        if self._pose is not None:
            return self._pose.x, self._pose.y
        ref = self._by_key[self.current] if self.current else self.home
        return ref.pose.x, ref.pose.y

    def next_in_queue(self) -> str | None:
        """Key of the table that would be driven to next (``None`` when the queue is empty)."""
        if not self.queue:
            return None
        if self.order_mode == OrderMode.FIFO:
            return self.queue[0]
        pts = [(self._by_key[k].pose.x, self._by_key[k].pose.y) for k in self.queue]
        return self.queue[geometry.nearest_index(self._origin(), pts)]

    def _start_next(self) -> None:
        nxt = self.next_in_queue()
        if nxt is None:
            return
        self.queue.remove(nxt)
        self._send(nxt)

    def _send(self, key: str) -> None:
        self._goal_id += 1
        self.current = key
        self.phase = Phase.DRIVING
        self._wait_deadline = None
        self._message = ""
        self._arrived_home = False
        self._plan = ()
        self._route_total = None
        self._update_route()
        self._robot.send_goal(self._goal_id, self._by_key[key])

    def _arrived(self) -> None:
        if self.current == HOME:
            self.phase = Phase.IDLE
            self._arrived_home = True
            self.current = None
            # tables queued while driving home are started by go(); nothing pending here
            return
        self.phase = Phase.WAITING
        self._wait_deadline = self._clock() + self.wait_time_s if self.wait_time_s > 0 else None
        self._plan = ()

    def _leave_table(self) -> None:
        self._wait_deadline = None
        if self.queue:
            self._start_next()
        else:
            self._send(HOME)

    def _stop(self, note: str) -> None:
        self.phase = Phase.STOPPED
        self._message = note
        self.current = None
        self._wait_deadline = None
        self._plan = ()
        self._route_total = None

    def _fail(self, reason: str) -> None:
        # keep the failed table first in line so Go retries it; staff may Remove it
        if self.current and self.current != HOME:
            self.queue.insert(0, self.current)
        self.phase = Phase.FAILED
        self._message = reason
        self.current = None
        self._plan = ()
        self._route_total = None

    def _lost_goal(self) -> None:
        if self.current and self.current != HOME and self.phase == Phase.DRIVING:
            self.queue.insert(0, self.current)
        self._robot.cancel_goal()
        self._stop("connection to the navigation server lost")

    def _update_route(self) -> None:
        # the longest remaining distance seen for this goal is the route length, so
        # progress never runs backwards when a replanned route gets shorter
        if self.phase != Phase.DRIVING:
            return
        remaining = self._remaining()
        if remaining is not None and (self._route_total is None or remaining > self._route_total):
            self._route_total = remaining

    def _remaining(self) -> float | None:
        if self.current is None or self._pose is None:
            return None
        goal = self._by_key[self.current].pose
        g = (goal.x, goal.y)
        plan = self._plan if self._plan and geometry.distance(self._plan[-1], g) <= PLAN_GOAL_TOLERANCE_M else None
        return geometry.remaining_distance((self._pose.x, self._pose.y), g, plan)

    # ------------------------------------------------------------------ view state
    def state(self) -> ViewState:
        """Snapshot of everything the view shows."""
        connected = bool(self.connected)
        active = self.phase in (Phase.DRIVING, Phase.CANCELLING)
        remaining = eta = progress = None
        if self.phase == Phase.DRIVING:
            remaining = self._remaining()
            if remaining is not None:
                eta = geometry.eta_seconds(remaining, self._speed)
                if self._route_total:
                    progress = max(0.0, min(1.0, 1.0 - remaining / self._route_total))
        status, hint = self._texts(remaining, eta)
        can_resume = bool(self.queue) and self.phase in (Phase.IDLE, Phase.STOPPED, Phase.FAILED)
        bat_pct, bat_text, bat_low = self._battery_view()
        h_level, h_text = self._health_view()
        return ViewState(
            status=status, hint=hint, connected=self.connected, phase=self.phase,
            go_enabled=connected and self.phase != Phase.CANCELLING and (self.selected is not None or can_resume),
            home_enabled=connected and self.phase != Phase.CANCELLING and not (active and self.current == HOME),
            cancel_enabled=connected and self.phase in (Phase.DRIVING, Phase.WAITING),
            served_enabled=self.phase == Phase.WAITING,
            remove_enabled=bool(self.queue),
            queue=tuple(self._ordered_queue()),
            queue_labels=tuple(self._by_key[k].label for k in self._ordered_queue()),
            current=self.current, selected=self.selected, order_mode=self.order_mode,
            wait_time_s=self.wait_time_s, remaining_m=remaining, eta_s=eta, progress=progress,
            battery_percent=bat_pct, battery_text=bat_text, battery_low=bat_low,
            health_level=h_level, health_text=h_text, robot_pose=self._pose,
            plan=self._plan if active else (),
        )

    def _ordered_queue(self) -> list[str]:
        """The queue in service order (nearest-first is re-evaluated from each stop)."""
        if self.order_mode == OrderMode.FIFO:
            return list(self.queue)
        out, left = [], list(self.queue)
        origin = self._origin() if self.current is None else (
            self._by_key[self.current].pose.x, self._by_key[self.current].pose.y)
        while left:
            pts = [(self._by_key[k].pose.x, self._by_key[k].pose.y) for k in left]
            k = left.pop(geometry.nearest_index(origin, pts))
            out.append(k)
            origin = (self._by_key[k].pose.x, self._by_key[k].pose.y)
        return out

    def _texts(self, remaining: float | None, eta: float | None) -> tuple[str, str]:
        n = len(self.queue)
        queued = f"{n} table{'s' if n != 1 else ''} queued"
        if self.master_missing is not None:
            extra = f" ({queued})" if n else ""
            return (f"no ROS master at {self.master_missing} — retrying",
                    f"start roscore (or the robot's launch file); the GUI connects by itself{extra}")
        if self.connected is None:
            return "connecting…", "waiting for the navigation server (move_base)"
        if not self.connected:
            extra = f" — {queued}" if n else ""
            return "robot not connected", ("the navigation server (move_base) is not running; "
                                           f"the GUI reconnects by itself{extra}")
        label = self._by_key[self.current].label if self.current else ""
        if self.phase == Phase.DRIVING:
            where = "returning home" if self.current == HOME else f"driving to {label}"
            if remaining is not None and eta is not None:
                where += f" ({fmt_metres(remaining)} m, {fmt_eta(eta)})"
            return where, (f"then: {queued}" if n else "press Cancel to stop the robot")
        if self.phase == Phase.CANCELLING:
            return "cancelling…", "waiting for the robot to stop"
        if self.phase == Phase.WAITING:
            if self._wait_deadline is not None:
                left = max(0, math.ceil(self._wait_deadline - self._clock()))
                return f"arrived at {label}", f"press Served when the food is taken (continuing in {left} s)"
            return f"arrived at {label}", "press Served when the food is taken"
        if self.phase == Phase.FAILED:
            return f"failed: {self._message}", (f"press Go to retry ({queued}) or Remove the table"
                                                if n else "press Go or Home to continue")
        if self.phase == Phase.STOPPED:
            return self._message, (f"{queued} — press Go to continue" if n else "robot stopped")
        if self._arrived_home:
            return "arrived home — ready", "pick a table and press Go"
        return "ready", (f"{queued} — press Go to start" if n else "pick a table and press Go")

    def _battery_view(self) -> tuple[int | None, str, bool]:
        if self._battery is None:
            return None, "battery: no data", False
        pct, volts, present = self._battery
        if not present:
            return None, "battery: not present", False
        vtxt = f" ({volts:.1f} V)" if math.isfinite(volts) else ""
        if not math.isfinite(pct):
            return None, f"battery: unknown{vtxt}", False
        p = max(0, min(100, round(pct * 100)))
        return p, f"battery {p} %{vtxt}", p < LOW_BATTERY_PERCENT

    def _health_view(self) -> tuple[int | None, str]:
        if not self._diag:
            return None, "hardware: no diagnostics"
        now = self._clock()
        worst_level, worst_text = -1, ""
        for name, (level, msg, t) in sorted(self._diag.items()):
            if now - t > self._diag_timeout:
                level, msg = 3, "no diagnostics received (stale)"
            if level > worst_level:
                worst_level, worst_text = level, f"{name}: {msg}"
        word = {0: "OK", 1: "warning", 2: "error", 3: "stale"}.get(worst_level, "error")
        if worst_level == 0:
            return 0, "hardware OK"
        return worst_level, f"hardware {word} — {worst_text}"
