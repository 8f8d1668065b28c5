"""The fleet presenter: robots, the dispatcher's order queue, staff commands and status texts.

Qt-free and ROS-free, the fleet counterpart of :mod:`chefbot_gui.presenter`.  The ROS bridge
turns the dispatcher's messages into the plain records below (:class:`RobotReport` from
``/fleet/robots``, :class:`QueueSnapshot` from ``/fleet/orders``) and the view feeds them in
from the GUI thread; staff commands leave through the small :class:`FleetPort` interface (the
bridge in the node, a fake in the unit tests), tagged with a request number so each reply can
be shown in the reply line.  Time comes from an injected monotonic clock (s), so "connecting…"
and stale robots are testable without sleeping.

Status lines (``FleetViewState.status``): ``no ROS master at http://… — retrying``,
``connecting…``, ``no dispatcher on /fleet — is dispatcher.launch running?``,
``dispatcher on /fleet without its services``, ``fleet: 2 of 3 robots in service, 4 open orders``.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from chefbot_gui.geometry import Point
from chefbot_gui.presenter import LOW_BATTERY_PERCENT, PoseLike, fmt_eta, make_destinations, table_label

# Robot colours in the order robots are met (fleet file order first); none is a table marker colour.
PALETTE = ("#1e88e5", "#d81b60", "#8e24aa", "#00897b", "#f4511e", "#7cb342", "#5e35b1", "#fdd835",
           "#6d8fa3", "#a1887f")
UNKNOWN_COLOUR = "#757575"   # an order's robot that is on neither robot list
FINAL_STATES = frozenset({"served", "cancelled", "failed"})
# dispatcher robot states (chefbot_fleet/FleetRobot.state) in staff words
ROBOT_WORDS = {
    "idle": "idle", "to_kitchen": "to the kitchen", "loading": "loading at the kitchen",
    "delivering": "delivering", "serving": "serving", "parking": "parking",
    "to_charger": "to its charger", "charging": "charging", "paused": "paused",
    "fault": "fault", "offline": "offline", "lost": "lost (not sure where it is)",
}
OUT_OF_SERVICE = frozenset({"paused", "fault", "offline", "lost", "to_charger", "charging"})
ORDER_WORDS = {"queued": "queued", "assigned": "assigned", "loading": "loading", "on_the_way": "on the way",
               "served": "served", "cancelled": "cancelled", "failed": "failed"}
COMMANDS = ("pause", "resume", "charge")


@dataclass(frozen=True)
class RobotReport:
    """One robot's ``chefbot_msgs/RobotState``: pose (m, m, rad) in the map frame, its footprint
    polygon in its base frame (m; empty = a circle of ``radius`` m), its remaining path (map
    frame, m) and its free-text state."""

    name: str
    x: float
    y: float
    yaw: float
    footprint: tuple[Point, ...] = ()
    radius: float = 0.178
    path: tuple[Point, ...] = ()
    text: str = ""


@dataclass(frozen=True)
class DispatchRobot:
    """One ``chefbot_fleet/FleetRobot`` of the dispatcher's queue (``battery`` 0..1, -1 unknown)."""

    name: str
    state: str
    place: str = ""
    stops: tuple[str, ...] = ()
    orders: tuple[str, ...] = ()
    reason: str = ""
    battery: float = -1.0


@dataclass(frozen=True)
class OrderInfo:
    """One ``chefbot_fleet/Order``: ``eta`` s until its last table is served (-1: none)."""

    id: str
    tables: tuple[str, ...]
    state: str
    assigned: str = ""
    reason: str = ""
    eta: float = -1.0
    priority: float = 1.0
    robot: str = ""


@dataclass(frozen=True)
class QueueSnapshot:
    """One ``chefbot_fleet/OrderQueue``: orders oldest first, robots in fleet file order."""

    orders: tuple[OrderInfo, ...] = ()
    robots: tuple[DispatchRobot, ...] = ()


class FleetPort(Protocol):
    """What the presenter needs from the dispatcher; no call may block (replies come back later)."""

    def send_order(self, request: int, tables: Sequence[str], priority: float, robot: str) -> None:
        """One ``/fleet/deliver`` goal; answered by ``on_order_accepted/refused/done(request, …)``."""

    def cancel_order(self, request: int, order_id: str) -> None:
        """``/fleet/cancel_order``; answered by ``on_reply(request, ok, message)``."""

    def set_robot(self, request: int, robot: str, command: str) -> None:
        """``/fleet/set_robot`` (``pause``, ``resume`` or ``charge``); answered by ``on_reply``."""


@dataclass(frozen=True)
class RobotRow:
    """A robot as staff see it: table row and map drawing (pose, footprint and path in the map frame)."""

    name: str
    colour: str
    state: str            # the dispatcher's state word ("" when the dispatcher does not list it)
    state_text: str
    battery_percent: int | None
    battery_text: str
    battery_low: bool
    trip_text: str
    stale: bool           # no RobotState for longer than the stale time-out (or never)
    dispatched: bool      # listed by the dispatcher
    pose: tuple[float, float, float] | None
    footprint: tuple[Point, ...] = ()   # map-frame polygon; empty: a circle of radius
    radius: float = 0.178
    path: tuple[Point, ...] = ()


@dataclass(frozen=True)
class OrderRow:
    """An order row: ``eta_text`` ``~2 min`` or ``—``; ``robot_colour`` of the robot serving it."""

    id: str
    tables_text: str
    state: str
    state_text: str
    robot: str
    robot_colour: str | None
    eta_text: str
    reason: str
    final: bool


@dataclass(frozen=True)
class FleetViewState:
    """Everything the fleet window shows; a fresh immutable snapshot after every change."""

    status: str
    hint: str
    tone: str                          # bad | wait | good | neutral (the status colour)
    reply: str                         # the last command's outcome, for the reply line
    reply_ok: bool | None
    robots: tuple[RobotRow, ...]
    orders: tuple[OrderRow, ...]
    selected_tables: tuple[str, ...]
    selected_order: str | None
    selected_robot: str | None
    priority: float
    robot_choice: str                  # "" = any robot
    robot_choices: tuple[str, ...]     # robots an order may name
    add_enabled: bool
    cancel_enabled: bool
    pause_enabled: bool
    resume_enabled: bool
    charge_enabled: bool
    open_tables: tuple[str, ...] = field(default=())   # tables of open orders (map markers)


def battery_view(battery: float) -> tuple[int | None, str, bool]:
    """Percent, text and low flag of a state of charge ``battery`` 0..1 (negative or NaN: unknown)."""
    if not math.isfinite(battery) or battery < 0:
        return None, "?", False
    p = max(0, min(100, round(battery * 100)))
    return p, f"{p} %", p < LOW_BATTERY_PERCENT


def footprint_in_map(report: RobotReport) -> tuple[Point, ...]:
    """The report's footprint polygon moved to its pose (map frame, m); empty stays empty."""
    c, s = math.cos(report.yaw), math.sin(report.yaw)
    return tuple((report.x + c * px - s * py, report.y + s * px + c * py) for px, py in report.footprint)


class FleetPresenter:
    """The fleet window's logic: rows, colours, stale robots, staff commands and their replies.

    Parameters: ``poses`` (the tables file's map-frame poses, with ``home``), ``destinations``
    (the keys staff can order to; default every pose but ``home``), ``port`` (a
    :class:`FleetPort`), ``clock`` (monotonic s), ``fleet`` (the fleet file's robot names: their
    colour order), ``fleet_ns`` (the dispatcher's namespace, for the texts),
    ``connect_timeout_s`` (s of "connecting…"), ``stale_timeout_s`` (a robot silent on
    ``/fleet/robots`` this long is shown stale, s), ``max_final_rows`` (served, cancelled and
    failed orders shown below the open ones, newest first).
    """

    def __init__(self, poses: Mapping[str, PoseLike], port: FleetPort, clock: Callable[[], float],
                 fleet: Sequence[str] = (), fleet_ns: str = "/fleet", connect_timeout_s: float = 5.0,
                 stale_timeout_s: float = 5.0, max_final_rows: int = 10,
                 destinations: Sequence[str] | None = None) -> None:
        if stale_timeout_s <= 0:
            raise ValueError(f"stale_timeout_s must be > 0, got {stale_timeout_s}")
        if max_final_rows < 0:
            raise ValueError(f"max_final_rows must be >= 0, got {max_final_rows}")
        self.home, self.tables = make_destinations(poses, destinations)
        self._labels = {d.key: d.label for d in self.tables}
        self._port = port
        self._clock = clock
        self.fleet_ns = fleet_ns.rstrip("/") or "/"
        self._connect_timeout = connect_timeout_s
        self._connect_deadline = clock() + connect_timeout_s
        self._stale = stale_timeout_s
        self._max_final = max_final_rows
        self._listeners: list[Callable[[FleetViewState], None]] = []
        self._colours: dict[str, str] = {}
        for name in fleet:
            self._colour(name)

        self.master_missing: str | None = None
        self.action_ok: bool | None = None    # None: connecting
        self.services_ok = False
        self.queue = QueueSnapshot()
        self._reports: dict[str, tuple[RobotReport, float]] = {}   # name -> (report, clock at arrival)
        self.selected_tables: list[str] = []
        self.selected_order: str | None = None
        self.selected_robot: str | None = None
        self.priority = 1.0
        self.robot_choice = ""
        self._request = 0
        self._requests: dict[int, str] = {}   # request -> what it was, for its reply
        self._reply = ""
        self._reply_ok: bool | None = None
        self._last: FleetViewState | None = None

    # ------------------------------------------------------------------ plumbing
    def subscribe(self, listener: Callable[[FleetViewState], None]) -> None:
        """Call ``listener(state)`` now and after every change."""
        self._listeners.append(listener)
        self._last = self.state()
        listener(self._last)

    def _changed(self) -> None:
        st = self.state()
        if st == self._last:
            return
        self._last = st
        for listener in list(self._listeners):
            listener(st)

    def attach_port(self, port: FleetPort) -> None:
        """Use ``port`` from now on (the ROS bridge exists only once the master answers)."""
        self._port = port

    def label(self, key: str) -> str:
        """Staff name of a place: a table's label, else ``table_label`` (``kitchen`` → ``Kitchen``)."""
        return self._labels.get(key) or table_label(key)

    def _colour(self, name: str) -> str:
        if name not in self._colours:
            self._colours[name] = PALETTE[len(self._colours) % len(PALETTE)]
        return self._colours[name]

    @property
    def connected(self) -> bool:
        """The dispatcher's action server answers (orders can be sent)."""
        return bool(self.action_ok) and self.master_missing is None

    # ------------------------------------------------------------------ staff actions
    def toggle_table(self, key: str) -> None:
        """Add a table to the new order's tables, or take it out again (list or map click)."""
        if key not in self._labels:
            raise KeyError(f"unknown table {key!r}")
        if key in self.selected_tables:
            self.selected_tables.remove(key)
        else:
            self.selected_tables.append(key)
        self._changed()

    def set_tables(self, keys: Sequence[str]) -> None:
        """The new order's tables, in the order staff picked them."""
        unknown = [k for k in keys if k not in self._labels]
        if unknown:
            raise KeyError(f"unknown table(s) {unknown}")
        self.selected_tables = list(dict.fromkeys(keys))
        self._changed()

    def set_priority(self, priority: float) -> None:
        """The new order's priority (>= 1; 2 counts its wait twice)."""
        if not math.isfinite(priority) or priority < 1:
            raise ValueError(f"priority must be >= 1, got {priority}")
        self.priority = float(priority)
        self._changed()

    def set_robot_choice(self, robot: str) -> None:
        """Only this robot may serve the new order (``""``: any robot)."""
        self.robot_choice = robot
        self._changed()

    def select_order(self, order_id: str | None) -> None:
        """Staff picked an order row (``None``: none)."""
        self.selected_order = order_id
        self._changed()

    def select_robot(self, name: str | None) -> None:
        """Staff picked a robot row (``None``: none)."""
        self.selected_robot = name
        self._changed()

    def _next_request(self, what: str) -> int:
        self._request += 1
        self._requests[self._request] = what
        self._set_reply(f"{what}…", None)
        return self._request

    def add_order(self) -> None:
        """Send the picked tables as one order (priority, robot) and clear the pick."""
        if not self.state().add_enabled:
            return
        tables = list(self.selected_tables)
        names = ", ".join(self.label(k) for k in tables)
        req = self._next_request(f"order for {names}")
        self.selected_tables = []
        self._port.send_order(req, tables, self.priority, self.robot_choice)
        self._changed()

    def cancel_order(self) -> None:
        """Cancel the selected order at the dispatcher."""
        if not self.state().cancel_enabled or self.selected_order is None:
            return
        req = self._next_request(f"cancel {self.selected_order}")
        self._port.cancel_order(req, self.selected_order)
        self._changed()

    def robot_command(self, command: str) -> None:
        """``pause``, ``resume`` or ``charge`` (send to its charger) the selected robot."""
        if command not in COMMANDS:
            raise ValueError(f"command must be one of {COMMANDS}, got {command!r}")
        st = self.state()
        enabled = {"pause": st.pause_enabled, "resume": st.resume_enabled, "charge": st.charge_enabled}[command]
        if not enabled or self.selected_robot is None:
            return
        req = self._next_request(f"{command} {self.selected_robot}")
        self._port.set_robot(req, self.selected_robot, command)
        self._changed()

    # ------------------------------------------------------------------ dispatcher events
    def on_master(self, uri: str, reachable: bool) -> None:
        """The ROS master at ``uri`` cannot be reached (False) or was just reached (True)."""
        missing = None if reachable else uri
        if missing == self.master_missing:
            return
        self.master_missing = missing
        if reachable:
            self.action_ok = None
            self._connect_deadline = self._clock() + self._connect_timeout
        else:
            self.action_ok, self.services_ok = False, False
        self._changed()

    def on_dispatcher(self, action_ok: bool, services_ok: bool) -> None:
        """The dispatcher's ``deliver`` action server and its ``cancel_order``/``set_robot`` services
        answer (True) or not."""
        self.action_ok, self.services_ok = bool(action_ok), bool(services_ok)
        self._changed()

    def on_queue(self, queue: QueueSnapshot) -> None:
        """A new ``/fleet/orders`` snapshot."""
        self.queue = queue
        for r in queue.robots:
            self._colour(r.name)
        ids = {o.id for o in queue.orders}
        if self.selected_order is not None and self.selected_order not in ids:
            self.selected_order = None
        self._changed()

    def on_robot_report(self, report: RobotReport) -> None:
        """A robot's ``/fleet/robots`` message (its time of arrival is now)."""
        self._colour(report.name)
        self._reports[report.name] = (report, self._clock())
        self._changed()

    def on_order_accepted(self, request: int, status_text: str) -> None:
        """The dispatcher accepted order request ``request``; ``status_text`` is ``order <id>``."""
        what = self._requests.get(request, "order")
        words = status_text.split()
        # the dispatcher accepts with "order <id>"; a goal finished before it was seen active carries
        # its final text instead, so the id is only taken from the accepting form
        accepted = f"accepted as {words[1]}" if len(words) == 2 and words[0] == "order" else "accepted"
        self._set_reply(f"{what}: {accepted}", True)
        self._changed()

    def on_order_refused(self, request: int, reason: str) -> None:
        """The dispatcher refused order request ``request`` (unknown table, robot, …)."""
        what = self._requests.pop(request, "order")
        self._set_reply(f"{what}: refused: {reason.strip() or 'no reason given'}", False)
        self._changed()

    def on_order_done(self, request: int, order_id: str, state: str, reason: str) -> None:
        """Order request ``request`` ended: ``state`` served, cancelled, failed or lost (no contact)."""
        what = self._requests.pop(request, "order")
        oid = order_id or "?"
        if state == "lost":
            self._set_reply(f"{what}: lost contact with the dispatcher (its database keeps accepted orders)", False)
        else:
            tail = f": {reason}" if reason else ""
            self._set_reply(f"order {oid} {state}{tail}", state == "served")
        self._changed()

    def on_reply(self, request: int, ok: bool, message: str) -> None:
        """A service reply (or a failed call) for request ``request``."""
        what = self._requests.pop(request, "command")
        self._set_reply(f"{what}: {message.strip() or ('done' if ok else 'refused')}", ok)
        self._changed()

    def _set_reply(self, text: str, ok: bool | None) -> None:
        self._reply, self._reply_ok = text, ok

    def tick(self) -> None:
        """Advance time: the connection time-out and stale robots."""
        if self.action_ok is None and self.master_missing is None and self._clock() >= self._connect_deadline:
            self.action_ok = False
        self._changed()

    # ------------------------------------------------------------------ view state
    def _robot_names(self) -> list[str]:
        names = [r.name for r in self.queue.robots]
        names += sorted(n for n in self._reports if n not in names)
        return names

    def _robot_row(self, name: str, now: float) -> RobotRow:
        disp = next((r for r in self.queue.robots if r.name == name), None)
        rep, t = self._reports.get(name, (None, -math.inf))
        stale = now - t > self._stale
        if disp is None:
            state, text = "", "not dispatched"
            if rep is not None and rep.text:
                text += f" ({rep.text})"
            pct, btext, low, trip = None, "?", False, "—"
        else:
            state = disp.state
            text = ROBOT_WORDS.get(disp.state, disp.state or "?")
            # the dispatcher's own places ("parking:chefbot1", "charger:chefbot1") are in the state word
            own = disp.place.partition(":")[0] in ("parking", "charger")
            if disp.place and not own and disp.state not in ("idle", "paused", "fault", "offline", "lost"):
                text += f" — {self.label(disp.place)}"
            if disp.reason:
                text += f" ({disp.reason})"
            pct, btext, low = battery_view(disp.battery)
            stops = " → ".join(self.label(s) for s in disp.stops)
            orders = ", ".join(disp.orders)
            trip = (f"{stops} ({orders})" if stops and orders else stops or orders) or "—"
        if rep is None:
            text += " — no position reported"
        elif stale:
            text += f" — no report for {now - t:.0f} s"
        return RobotRow(
            name=name, colour=self._colour(name), state=state, state_text=text, battery_percent=pct,
            battery_text=btext, battery_low=low, trip_text=trip, stale=stale, dispatched=disp is not None,
            pose=(rep.x, rep.y, rep.yaw) if rep else None,
            footprint=footprint_in_map(rep) if rep else (), radius=rep.radius if rep else 0.178,
            path=rep.path if rep and not stale else ())

    def _order_rows(self, known: set[str]) -> list[OrderRow]:
        open_orders = [o for o in self.queue.orders if o.state not in FINAL_STATES]
        final = [o for o in reversed(self.queue.orders) if o.state in FINAL_STATES][:self._max_final]
        rows = []
        for o in [*open_orders, *final]:
            is_final = o.state in FINAL_STATES
            robot, colour = o.assigned or "—", None
            if o.assigned:
                colour = self._colours[o.assigned] if o.assigned in known else UNKNOWN_COLOUR
                if o.assigned not in known:
                    robot += " (unknown robot)"
            eta = fmt_eta(o.eta) if o.eta >= 0 and math.isfinite(o.eta) and not is_final else "—"
            rows.append(OrderRow(id=o.id, tables_text=", ".join(self.label(t) for t in o.tables), state=o.state,
                                 state_text=ORDER_WORDS.get(o.state, o.state), robot=robot, robot_colour=colour,
                                 eta_text=eta, reason=o.reason, final=is_final))
        return rows

    def state(self) -> FleetViewState:
        """Snapshot of everything the window shows."""
        now = self._clock()
        names = self._robot_names()
        robots = tuple(self._robot_row(n, now) for n in names)
        orders = tuple(self._order_rows(set(names)))
        open_orders = [o for o in self.queue.orders if o.state not in FINAL_STATES]
        ok = self.connected
        services = ok and self.services_ok
        sel_order = next((o for o in self.queue.orders if o.id == self.selected_order), None)
        sel_robot = next((r for r in robots if r.name == self.selected_robot and r.dispatched), None)
        robot_state = sel_robot.state if sel_robot else ""
        status, hint, tone = self._texts(robots, len(open_orders))
        dispatched = tuple(r.name for r in self.queue.robots)
        return FleetViewState(
            status=status, hint=hint, tone=tone, reply=self._reply, reply_ok=self._reply_ok,
            robots=robots, orders=orders, selected_tables=tuple(self.selected_tables),
            selected_order=self.selected_order, selected_robot=self.selected_robot,
            priority=self.priority, robot_choice=self.robot_choice, robot_choices=dispatched,
            add_enabled=ok and bool(self.selected_tables),
            cancel_enabled=services and sel_order is not None and sel_order.state not in FINAL_STATES,
            pause_enabled=services and sel_robot is not None and robot_state != "paused",
            resume_enabled=services and sel_robot is not None and robot_state in OUT_OF_SERVICE,
            charge_enabled=services and sel_robot is not None and robot_state not in ("to_charger", "charging"),
            open_tables=tuple(dict.fromkeys(t for o in open_orders for t in o.tables)),
        )

    def _texts(self, robots: Sequence[RobotRow], n_open: int) -> tuple[str, str, str]:
        ns = self.fleet_ns
        if self.master_missing is not None:
            return (f"no ROS master at {self.master_missing} — retrying",
                    "start roscore (or the site's launch files); the GUI connects by itself", "neutral")
        if self.action_ok is None:
            return "connecting…", f"waiting for the dispatcher ({ns}/deliver)", "neutral"
        if not self.action_ok:
            return (f"no dispatcher on {ns} — is dispatcher.launch running?",
                    "orders, cancel and robot commands are off; the GUI reconnects by itself", "bad")
        if not self.services_ok:
            return (f"dispatcher on {ns} without its services",
                    f"{ns}/cancel_order and {ns}/set_robot do not answer: orders only", "bad")
        dispatched = [r for r in robots if r.dispatched]
        in_service = [r for r in dispatched if r.state not in OUT_OF_SERVICE and not r.stale]
        orders = f"{n_open} open order{'s' if n_open != 1 else ''}"
        status = f"fleet: {len(in_service)} of {len(dispatched)} robots in service, {orders}"
        stale = [r.name for r in robots if r.stale]
        hint = (f"no position from {', '.join(stale)}" if stale
                else "pick tables and press Add order; pick an order or a robot for the other buttons")
        return status, hint, "good" if len(in_service) == len(dispatched) and not stale else "wait"
